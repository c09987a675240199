"""Issue 4's quality targets for the whole LiDAR pipeline on synthetic clouds with exact truth.

Scenes are one 300 m tile (the paper's tile size) at 8 pulses/m2, so ``extract_roads`` runs
one tile over the scene's extent.

*Clean suburban grid*: ``features=("buildings", "trees")``, the setting of the paper's
suburban tiles: a street grid with a 21 m avenue and 9-10 m streets, each with 2 m
sidewalks and grass verges, houses and street trees whose crowns overhang the roads (the
ground under them is seen only by split pulses), but no cars, markings, cliff, bridge,
dual carriageway or parking lot. Not the easiest toy: the trees and sidewalks are what made
the rectangles 16 and 25 m wide on 9 and 21 m roads before the width selection was fixed.
*Full scene*: every feature of :func:`gisroads.synthetic.make_scene` (cliff, bridge, dual
carriageway, diagonal, cul-de-sac, parking lot, cars, markings).
"""
import numpy as np
import pytest
import shapely

from gisroads.evaluate import buffer_metrics
from gisroads.lidar.pipeline import extract_roads
from gisroads.synthetic import make_scene, write_cloud

DENSITY = 8.0


def _run(tmp_path_factory, name, **scene_args):
    scene = make_scene(seed=0, size_m=(300.0, 300.0), **scene_args)
    path = tmp_path_factory.mktemp(name) / "cloud.laz"
    write_cloud(scene, path, density_per_m2=DENSITY, seed=0)
    return scene, extract_roads(path, cue="intensity")


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return _run(tmp_path_factory, "clean", features=("buildings", "trees"))


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    return _run(tmp_path_factory, "full")


def _road(scene, name):
    roads = scene.object_layers()["roads"]
    return roads[roads.name == name].geometry.iloc[0]


def _found_share(line, roads, buffer_m=3.0):
    """Share of a truth line within ``buffer_m`` of the extracted centre lines."""
    zone = shapely.buffer(shapely.union_all(roads.network.centrelines.geometry.values),
                          buffer_m)
    return shapely.length(shapely.intersection(line, zone)) / shapely.length(line)


def _rectangles_along(roads, line, *, within_m=3.0):
    """Selected rectangles whose centre lies on ``line`` and that run along it."""
    rects = roads.network.qa["rectangles"]
    (x0, y0), (x1, y1) = np.asarray(line.coords)[[0, -1], :2]
    direction = np.arctan2(y1 - y0, x1 - x0)
    on = rects[(rects.geometry.centroid.distance(line) < within_m)
               & (np.abs(np.cos(rects.theta_rad - direction)) > 0.95)]
    return on


def test_clean_suburban_grid_is_found_completely_and_correctly(clean):
    scene, roads = clean
    scores = buffer_metrics(roads.network.centrelines, scene.truth.centrelines, buffer_m=3.0)
    # measured 0.983 / 0.950 (before the width selection: 0.85 / 0.79)
    assert scores.completeness >= 0.9
    assert scores.correctness >= 0.9


def test_a_20_m_road_is_covered_by_20_m_rectangles(clean, full):
    for scene, roads in (clean, full):
        avenue = _road(scene, "avenue")
        widths = _rectangles_along(roads, avenue).width_m
        # measured [20, 20] and [20, 20, 20] (before: 16 and 25 m)
        assert len(widths) >= 1
        assert (widths == 20.0).all(), widths.tolist()
        assert _found_share(avenue, roads) >= 0.9


def test_full_scene_scores(full):
    scene, roads = full
    scores = buffer_metrics(roads.network.centrelines, scene.truth.centrelines, buffer_m=3.0)
    # measured 0.903 / 0.971 (before: 0.71 / 0.63); the cul-de-sac lane (4.7 m) is
    # narrower than the narrowest window and the bridge deck is too small a level
    assert scores.completeness >= 0.85
    assert scores.correctness >= 0.85


def test_roads_on_the_cliff_top_and_under_the_bridge_are_found(full):
    scene, roads = full
    assert _found_share(_road(scene, "cliff_top"), roads) >= 0.9  # measured 1.0
    assert _found_share(_road(scene, "cliff_foot"), roads) >= 0.9  # measured 1.0
    bridge = scene.object_layers()["bridges"].iloc[0]
    under = shapely.intersection(_road(scene, "avenue"),
                                 shapely.Point(bridge.crossing_x, bridge.crossing_y).buffer(20))
    assert _found_share(under, roads) >= 0.9  # measured 1.0: the deck hides 10-15 m of it


def test_dual_carriageway_is_two_roads(full):
    scene, roads = full
    for name in ("dual_carriageway_a", "dual_carriageway_b"):
        carriageway = _road(scene, name)
        assert _found_share(carriageway, roads) >= 0.9  # measured 1.0 (before: 0.06)
        assert (_rectangles_along(roads, carriageway).width_m <= 9.0).all()


def test_parking_lot_is_not_a_road(full):
    scene, roads = full
    lot = scene.object_layers()["parking_lots"].geometry.iloc[0]
    inside = shapely.intersection(
        shapely.union_all(roads.network.centrelines.geometry.values), lot.buffer(-2.0))
    assert shapely.length(inside) <= 5.0  # measured 0 (before the elongation rule: 28 m)


@pytest.mark.parametrize("features, floors", [(("buildings", "trees"), (0.95, 0.95)),
                                              (None, (0.95, 0.90))])
def test_evidence_cue_finds_the_network_with_its_junctions(tmp_path, features, floors):
    # measured: clean grid 0.989 / 1.000 and 4 of 4 junctions; every feature 0.986 / 0.941
    # and 10 of 11 junctions (the paper's cue: 0.967 / 0.949 and 0.903 / 0.970)
    from gisroads.evaluate.topology import topology_metrics

    scene = make_scene(seed=0, size_m=(300.0, 300.0),
                       **({"features": features} if features else {}))
    path = tmp_path / "cloud.laz"
    write_cloud(scene, path, density_per_m2=DENSITY, seed=0)
    roads = extract_roads(path, cue="evidence")
    scores = buffer_metrics(roads.network.centrelines, scene.truth.centrelines, buffer_m=3.0)
    assert scores.completeness >= floors[0] and scores.correctness >= floors[1]
    topology = topology_metrics(roads.network.centrelines, scene.truth.centrelines)
    assert topology["junction_recall"] >= 0.75
    assert roads.evidence is not None and {"intensity", "height"} <= set(roads.cues)
    assert (roads.network.centrelines["cues"].str.contains("intensity")).all()
