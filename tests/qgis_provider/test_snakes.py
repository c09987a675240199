"""'Curb attractor map' and 'Ribbon-snake road boundaries' run by the real qgis_process.bin."""
import numpy as np
import pytest
import shapely

from gisroads.evaluate import area_metrics
from gisroads.io.las import read_las
from gisroads.io.raster import read_raster
from gisroads.io.vector import list_layers, read_layer
from gisroads.snakes.ribbon import sample_bilinear
from gisroads.synthetic import road_surface_mask
from tests.qgis_provider.map_scenes import cloud_and_map, map_inputs


@pytest.fixture(scope="module")
def streets(tmp_path_factory):
    """A 300 m grid of kerbed streets at 8 points/m2, and a map of its edges shifted 2.5 m
    and jittered, in geographic coordinates (the algorithms reproject it)."""
    return cloud_and_map(tmp_path_factory.mktemp("snakes"), seed=4, features=(),
                         density_per_m2=8.0)


def test_ribbon_snakes_find_the_road_area(qgis_process, streets, tmp_path):
    scene, folder = streets
    result = qgis_process.run("ribbonsnakeroads", **map_inputs(folder), SNAP=6.0,
                              OUTPUT=tmp_path / "roads.gpkg", TAGGED_LAS=tmp_path / "t.laz",
                              ATTRACTOR=tmp_path / "a.tif")
    layers = set(list_layers(tmp_path / "roads.gpkg"))
    assert {"road_centrelines", "road_polygons", "junctions", "ribbon_patches",
            "registered_map"} <= layers
    polygons = read_layer(tmp_path / "roads.gpkg", "road_polygons")
    assert polygons.crs == read_las(folder / "cloud.laz").crs
    xmin, ymin, xmax, ymax = scene.extent
    valid = shapely.box(xmin + 5, ymin + 5, xmax - 5, ymax - 5)
    metrics = area_metrics(polygons, scene.truth.polygons, valid_area=[valid])
    print("qgis ribbon snakes:", metrics.as_dict())
    assert metrics.quality >= 0.8
    lines = read_layer(tmp_path / "roads.gpkg", "road_centrelines")
    truth = shapely.union_all(scene.truth.centrelines.geometry.values)
    probes = shapely.line_interpolate_point(lines.geometry.values, 0.5, normalized=True)
    assert np.median(shapely.distance(probes, truth)) < 1.0   # the map was 2.5 m off
    assert result["ROADS"] == len(lines) > 0
    tagged = read_las(tmp_path / "t.laz")
    road = tagged.classification == 11
    truth_road = road_surface_mask(scene, tagged.xyz)
    assert (road & truth_road).sum() >= 0.85 * road.sum()        # tagged points are road
    assert (road & truth_road).sum() >= 0.8 * truth_road.sum()   # most road points tagged
    assert read_raster(tmp_path / "a.tif").data.max() > 0.5


def test_the_curb_attractor_is_bright_on_the_kerbs_and_dark_mid_road(qgis_process, streets,
                                                                     tmp_path):
    scene, folder = streets
    qgis_process.run("curbattractormap", **map_inputs(folder), SNAP=6.0,
                     OUTPUT=tmp_path / "attractor.tif")
    raster = read_raster(tmp_path / "attractor.tif")
    a = raster.data[0] if raster.data.ndim == 3 else raster.data
    xmin, ymin, xmax, ymax = scene.extent
    inner = shapely.box(xmin + 30, ymin + 30, xmax - 30, ymax - 30)
    roads = shapely.union_all(scene.truth.polygons.geometry.values)
    kerb = shapely.intersection(shapely.boundary(roads), inner)
    kerb_xy = shapely.get_coordinates(shapely.segmentize(kerb, 1.0))
    middle = shapely.intersection(
        shapely.union_all(scene.truth.centrelines.geometry.values), inner)
    middle_xy = shapely.get_coordinates(shapely.segmentize(middle, 1.0))
    on_kerb = sample_bilinear(a.astype(float), raster.transform, kerb_xy)
    mid_road = sample_bilinear(a.astype(float), raster.transform, middle_xy)
    assert np.median(on_kerb) > 3 * np.median(mid_road) + 0.1


def test_tag_road_points_takes_the_ribbons_without_a_height_raster(qgis_process, streets,
                                                                   tmp_path):
    scene, folder = streets
    qgis_process.run("ribbonsnakeroads", **map_inputs(folder), SNAP=6.0,
                     OUTPUT=tmp_path / "roads.gpkg")
    result = qgis_process.run("tagroadpoints", INPUT=folder / "cloud.laz",
                              POLYGONS=tmp_path / "roads.gpkg", OUTPUT=tmp_path / "t.laz")
    tagged = read_las(tmp_path / "t.laz")
    road = tagged.classification == 11
    assert result["TAGGED"] == road.sum() > 1000
    truth_road = road_surface_mask(scene, tagged.xyz)
    assert (road & truth_road).sum() >= 0.85 * road.sum()
    assert (road & truth_road).sum() >= 0.8 * truth_road.sum()
