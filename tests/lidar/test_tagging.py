import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import shapely
from affine import Affine

from gisroads.io.las import read_las
from gisroads.io.vector import write_geopackage
from gisroads.jobs import tag_job
from gisroads.lidar.tagging import level_heights, road_point_mask, tag_road_points
from gisroads.synthetic import make_scene, road_surface_mask, write_cloud


def test_level_heights_means_and_fills_small_gaps_only():
    xyz = np.array([[0.5, 9.5, 1.0], [0.6, 9.4, 3.0], [5.5, 9.5, 7.0], [0.5, 9.5, 20.0]])
    level = np.array([0, 0, 0, 1])
    h = level_heights(xyz, level, 2, transform=Affine(1, 0, 0, 0, -1, 10), shape=(10, 10),
                      fill_cells=2)
    assert h.data[0, 0, 0] == 2.0 and h.data[0, 0, 5] == 7.0
    assert h.data[0, 0, 2] in (2.0, 7.0) and np.isnan(h.data[0, 9, 9])
    assert h.data[1, 0, 0] == 20.0 and np.isnan(h.data[1, 0, 5])


@pytest.fixture(scope="module")
def bridge_scene(tmp_path_factory):
    scene = make_scene(seed=1, size_m=(300.0, 300.0))
    path = tmp_path_factory.mktemp("tag") / "cloud.laz"
    write_cloud(scene, path, density_per_m2=3.0, seed=0)
    return scene, path


def truth_inputs(scene, cloud):
    """Per-level heights and level-tagged road polygons from the scene's exact truth."""
    deck = shapely.union_all(scene.bridges.geometry.values)
    level = np.where(cloud.classification == 2, 0, np.where(cloud.classification == 17, 1, -1))
    t = Affine(0.5, 0, scene.extent[0], 0, -0.5, scene.extent[3])
    shape = (int((scene.extent[3] - scene.extent[1]) / 0.5),
             int((scene.extent[2] - scene.extent[0]) / 0.5))
    heights = level_heights(cloud.xyz, level, 2, transform=t, shape=shape, crs=cloud.crs)
    polygons = scene.truth.polygons
    bridge_roads = set(scene.bridges.road_id)
    on_deck = polygons[polygons.road_id.isin(bridge_roads)].copy()
    on_deck["geometry"] = shapely.intersection(on_deck.geometry.values, deck)
    off_deck = polygons.copy()
    off_deck["geometry"] = np.where(polygons.road_id.isin(bridge_roads),
                                    shapely.difference(polygons.geometry.values, deck),
                                    polygons.geometry.values)
    levelled = gpd.GeoDataFrame(pd.concat([off_deck.assign(level=0), on_deck.assign(level=1)]),
                                crs=polygons.crs)
    return heights, levelled


def test_tagging_matches_the_exact_road_surface(bridge_scene, tmp_path):
    scene, path = bridge_scene
    cloud = read_las(path)
    heights, polygons = truth_inputs(scene, cloud)
    tagged = tag_road_points(path, tmp_path / "tagged.laz", polygons, heights)
    out = read_las(tmp_path / "tagged.laz")
    road = out.classification == 11
    assert tagged == road.sum()
    truth = road_surface_mask(scene, out.xyz)
    precision = (road & truth).sum() / road.sum()
    recall = (road & truth).sum() / truth.sum()
    assert precision > 0.97 and recall > 0.95
    # the bridge: deck points on the bridge road are road, and none of the under-road's
    deck = shapely.union_all(scene.bridges.geometry.values)
    on_deck = shapely.contains_xy(deck, out.xyz[:, 0], out.xyz[:, 1])
    deck_points = on_deck & (cloud.classification == 17)
    assert road[deck_points].mean() > 0.9
    under = scene.truth.polygons[scene.truth.polygons.road_id.isin(scene.bridges.under_road_id)]
    inside_under = shapely.contains_xy(shapely.union_all(under.geometry.values),
                                       out.xyz[:, 0], out.xyz[:, 1])
    assert road[inside_under & deck_points].mean() > 0.9
    # ... because of the deck road's level-1 polygon, never the road below: without it, no
    # deck point inside the lower road's polygon is road
    lower_only = road_point_mask(out.xyz, polygons[polygons.level == 0], heights)
    assert (inside_under & deck_points).sum() > 50
    assert not lower_only[inside_under & deck_points].any()


def test_points_off_the_surface_are_not_road(bridge_scene):
    scene, path = bridge_scene
    cloud = read_las(path)
    heights, polygons = truth_inputs(scene, cloud)
    road = road_point_mask(cloud.xyz, polygons, heights)
    assert not road[cloud.classification == 1].any()  # car roofs
    assert road[cloud.classification == 5].mean() < 0.01  # canopy over roads


def test_heights_from_the_clouds_own_ground_planes_tag_as_well(bridge_scene, tmp_path):
    scene, path = bridge_scene
    cloud = read_las(path)
    _, polygons = truth_inputs(scene, cloud)
    write_geopackage(tmp_path / "roads.gpkg", {"road_polygons": polygons})
    result = tag_job(path, tmp_path / "roads.gpkg", tmp_path / "tagged.laz")
    out = read_las(tmp_path / "tagged.laz")
    road = out.classification == 11
    assert result["tagged_points"] == road.sum()
    truth = road_surface_mask(scene, out.xyz)
    assert (road & truth).sum() / road.sum() > 0.95
    assert (road & truth).sum() / truth.sum() > 0.9
    deck_points = shapely.contains_xy(shapely.union_all(scene.bridges.geometry.values),
                                      out.xyz[:, 0], out.xyz[:, 1]) & (cloud.classification == 17)
    assert road[deck_points].mean() > 0.9
