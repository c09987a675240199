"""The LiDAR stages one file at a time, as the QGIS stage algorithms run them: chained, they
give exactly what the tiled pipeline gives on the same points."""
import numpy as np
import pytest
import shapely

from gisroads.io.las import read_las
from gisroads.io.raster import read_raster
from gisroads.io.vector import list_layers, read_layer, write_geopackage
from gisroads.jobs import (ground_intensity_job, lidar_segmentation_job, likelihood_job,
                           min_cover_job, rectangles_network_job)
from gisroads.lidar.pipeline import extract_tile
from gisroads.tiling.tiles import Tile
from gisroads.synthetic import make_scene, write_cloud

LENGTHS = (40.0, 80.0, 150.0)


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    out = tmp_path_factory.mktemp("stages")
    scene = make_scene(seed=3, size_m=(300.0, 300.0))
    write_cloud(scene, out / "cloud.laz", density_per_m2=5.0, seed=0)
    results = {
        "ground": ground_intensity_job(out / "cloud.laz", out / "intensity.tif", cell_m=0.5),
        "segments": lidar_segmentation_job(out / "intensity.tif", out / "segments.tif",
                                           edges_path=out / "edges.tif"),
        "likelihood": likelihood_job(out / "intensity.tif", out / "segments.tif",
                                     out / "likelihood.tif", out / "hypotheses.gpkg",
                                     lengths_m=LENGTHS),
        "cover": min_cover_job(out / "hypotheses.gpkg", out / "likelihood.tif",
                               out / "rectangles.gpkg"),
        "network": rectangles_network_job(out / "rectangles.gpkg", out / "roads.gpkg"),
    }
    return scene, out, results


def test_every_stage_writes_its_files(chain):
    _, out, results = chain
    assert results["ground"]["levels"] >= 1
    intensity = read_raster(out / "intensity.tif")
    assert intensity.data.shape[0] == results["ground"]["levels"]
    assert np.nanmin(intensity.data) >= 0 and np.nanmax(intensity.data) <= 1
    assert read_raster(out / "intensity_ground_heights.tif").data.shape == intensity.data.shape
    segments = read_raster(out / "segments.tif").data[0]
    assert 100 <= results["segments"]["n_segments"] == segments.max() + 1 <= 200
    assert read_raster(out / "edges.tif").data.shape[0] == 2
    assert read_raster(out / "likelihood.tif").data.shape[0] == 6  # one band per width
    assert list_layers(out / "roads.gpkg") == ["road_centrelines", "road_polygons",
                                               "junctions", "rectangles"]
    assert results["network"]["length_m"] > 300


def test_chained_stages_equal_the_pipeline_on_the_same_points(chain):
    _, out, results = chain
    cloud = read_las(out / "cloud.laz")
    bounds = (*cloud.xyz[:, :2].min(axis=0), *cloud.xyz[:, :2].max(axis=0))
    tile = extract_tile(cloud, Tile(0, 0, bounds, bounds), cell_m=0.5, lengths_m=LENGTHS)
    level0 = tile.rectangles[tile.rectangles.level == 0]
    staged = read_layer(out / "rectangles.gpkg", "rectangles")
    assert len(staged) == len(level0) == results["cover"]["n_rectangles"]
    assert np.array_equal(np.sort(staged.hyp_id), np.sort(level0.hyp_id))


def test_exact_cover_of_a_small_instance_is_not_worse_than_greedy(chain, tmp_path):
    _, out, _ = chain
    hypotheses = read_layer(out / "hypotheses.gpkg", "hypotheses")
    # a small instance: the hypotheses inside a 100 m square in the scene
    x0, y0 = hypotheses.total_bounds[:2] + 80.0
    inside = hypotheses.geometry.within(shapely.box(x0, y0, x0 + 100.0, y0 + 100.0))
    small = hypotheses[inside]
    assert 20 <= len(small) <= 2000, len(small)
    write_geopackage(tmp_path / "small.gpkg", {"hypotheses": small})
    greedy = min_cover_job(tmp_path / "small.gpkg", out / "likelihood.tif", tmp_path / "g.gpkg")
    exact = min_cover_job(tmp_path / "small.gpkg", out / "likelihood.tif", tmp_path / "e.gpkg",
                          exact=True)
    assert exact["cover_cost"] <= greedy["cover_cost"] + 1e-6


def test_stage_inputs_are_checked(chain, tmp_path):
    _, out, _ = chain
    with pytest.raises(ValueError, match="no level 7"):
        lidar_segmentation_job(out / "intensity.tif", tmp_path / "s.tif", level=7)
    with pytest.raises(ValueError, match="not on the grid"):
        likelihood_job(out / "intensity.tif", _shifted_copy(out / "segments.tif", tmp_path),
                       tmp_path / "l.tif", tmp_path / "h.gpkg")
    with pytest.raises(ValueError, match="not a hypotheses layer"):
        min_cover_job(out / "roads.gpkg", out / "likelihood.tif", tmp_path / "r.gpkg")
    polygons = tmp_path.parent / f"{tmp_path.name}_polygons.gpkg"
    write_geopackage(polygons, {"road_polygons": read_layer(out / "roads.gpkg", "road_polygons")})
    with pytest.raises(ValueError, match="theta_rad"):
        rectangles_network_job(polygons, tmp_path / "n.gpkg")
    assert not any(tmp_path.iterdir())


def _shifted_copy(path, tmp_path):
    from affine import Affine

    from gisroads.geo import GeoRaster
    from gisroads.io.raster import write_geotiff
    raster = read_raster(path)
    t = raster.transform
    shifted = GeoRaster(raster.data, Affine(t.a, t.b, t.c + 3.0, t.d, t.e, t.f), raster.crs,
                        raster.nodata)
    target = tmp_path.parent / f"{tmp_path.name}_shifted.tif"
    return write_geotiff(target, shifted)
