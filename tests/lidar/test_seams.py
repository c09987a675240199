"""A road crossing the seam of a two-tile run is one line: no break, no duplicate."""
import numpy as np
import pytest
import shapely

from gisroads.evaluate import buffer_metrics
from gisroads.lidar.pipeline import extract_roads
from gisroads.tiling.tiles import tile_grid
from gisroads.synthetic import make_scene, write_cloud


@pytest.fixture(scope="module")
def two_tiles(tmp_path_factory):
    scene = make_scene(seed=0, size_m=(500.0, 300.0), features=("buildings", "trees"))
    path = tmp_path_factory.mktemp("seam") / "cloud.laz"
    write_cloud(scene, path, density_per_m2=8.0, seed=0)
    return scene, extract_roads(path, cue="intensity", tile_m=300.0, overlap_m=100.0)


def test_the_run_has_two_tiles_and_scores_like_one(two_tiles):
    scene, roads = two_tiles
    assert len(tile_grid(scene.extent, tile_m=300.0, overlap_m=100.0)) == 2
    assert len(roads.tiles) == 2
    scores = buffer_metrics(roads.network.centrelines, scene.truth.centrelines, buffer_m=3.0)
    assert scores.completeness >= 0.9 and scores.correctness >= 0.9  # measured 0.99 / 0.97


def test_roads_cross_the_seam_as_one_line(two_tiles):
    scene, roads = two_tiles
    left, right = tile_grid(scene.extent, tile_m=300.0, overlap_m=100.0)
    seam_x = left.core[2]
    xmin, ymin, xmax, ymax = scene.extent
    seam = shapely.LineString([(seam_x, ymin - 1), (seam_x, ymax + 1)])
    lines = roads.network.centrelines.geometry.values
    crossing_truth = [g for g in scene.truth.centrelines.geometry if g.intersects(seam)]
    assert len(crossing_truth) >= 2  # the avenue and the street along the upper border
    for road in crossing_truth:
        at_seam = shapely.get_coordinates(shapely.intersection(road, seam))[0]
        near = shapely.Point(at_seam).buffer(30.0)
        local = [g for g in lines if g.intersects(shapely.Point(at_seam).buffer(3.0))]
        # exactly one extracted line passes the seam on this road (no duplicate) ...
        assert len(local) == 1, len(local)
        # ... and it runs on across the seam on both sides (no break)
        piece = shapely.intersection(local[0], near)
        xs = shapely.get_coordinates(piece)[:, 0]
        assert xs.min() < seam_x - 25 and xs.max() > seam_x + 25
        assert np.isclose(shapely.length(piece), 60.0, atol=3.0), piece.wkt
