"""'Road-part shape filtering' through qgis_process on an image with a road and a parking lot."""
import geopandas as gpd
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS

from gisroads.geo import GeoRaster
from gisroads.io.raster import write_geotiff
from gisroads.io.vector import STYLES_DIR, write_geopackage

EPSG = "EPSG:32633"
PX = 0.5
X0, Y0 = 500000.0, 4500000.0
GRID = Affine(PX, 0, X0, 0, -PX, Y0 + 160.0)  # 160 x 160 m
ROAD = shapely.box(X0 + 20, Y0 + 116, X0 + 140, Y0 + 124)   # 120 x 8 m
LOT = shapely.box(X0 + 30, Y0 + 20, X0 + 80, Y0 + 60)       # 50 x 40 m


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("roadparts")
    rows, cols = np.mgrid[0:320, 0:320]
    x, y = X0 + (cols + 0.5) * PX, GRID.f - (rows + 0.5) * PX
    image = np.empty((3, 320, 320))
    image[:] = np.array([80.0, 112.0, 52.0])[:, None, None]            # grass
    for polygon in (ROAD, LOT):
        image[:, shapely.contains_xy(polygon, x, y)] = np.array([86.0, 88.0, 91.0])[:, None]
    image += np.random.default_rng(0).normal(0, 4, image.shape)
    write_geotiff(folder / "image.tif",
                  GeoRaster(np.clip(image, 0, 255).astype(np.uint8), GRID, CRS(EPSG)))
    heights = np.zeros((320, 320), np.float32)
    heights[shapely.contains_xy(ROAD, x, y)] = 6.0   # the 'road' is a long roof in this DSM
    write_geotiff(folder / "dsm.tif", GeoRaster(heights, GRID, CRS(EPSG)))
    extent = shapely.box(X0, Y0, X0 + 160, Y0 + 160)
    segments = gpd.GeoDataFrame({"segment_id": [0, 1, 2]},
                                geometry=[extent.difference(ROAD).difference(LOT), ROAD, LOT],
                                crs=EPSG)
    write_geopackage(folder / "segments.gpkg", {"segments": segments})
    return folder


def test_road_passes_lot_fails_with_its_reason(qgis_process, inputs, tmp_path):
    result = qgis_process.run("roadparts", IMAGE=inputs / "image.tif",
                              SEGMENTS=f"{inputs / 'segments.gpkg'}|layername=segments",
                              OUTPUT_SEGMENTS=tmp_path / "tested.gpkg",
                              ROAD_PARTS=tmp_path / "parts.gpkg")
    assert result["PARTS"] == 1 and result["CUES"] == "rgb"
    tested = gpd.read_file(tmp_path / "tested.gpkg").set_index("segment_id")
    assert tested.crs == CRS(EPSG)
    assert bool(tested.passed[1]) and tested.reason[1] == ""
    assert not tested.passed[2] and tested.reason[2] == "not elongated"
    assert "too wide" in tested.failures[2]
    assert tested.width_m[1] == pytest.approx(8.0, abs=0.5)
    parts = gpd.read_file(tmp_path / "parts.gpkg")
    assert parts.segment_id.tolist() == [1]
    assert parts.length_m[0] == pytest.approx(120.0, rel=0.05)
    assert shapely.hausdorff_distance(parts.geometry[0], shapely.LineString(
        [(X0 + 20, Y0 + 120), (X0 + 140, Y0 + 120)])) < 1.0
    assert 0 < parts.quality[0] <= 1


def test_dsm_and_thresholds_are_used(qgis_process, inputs, tmp_path):
    result = qgis_process.run("roadparts", IMAGE=inputs / "image.tif",
                              SEGMENTS=f"{inputs / 'segments.gpkg'}|layername=segments",
                              DSM=inputs / "dsm.tif", MAX_WIDTH=60, ELONGATION=10,
                              ELONGATION_CURVED=20, MERGE=False,
                              OUTPUT_SEGMENTS=tmp_path / "tested.gpkg",
                              ROAD_PARTS=tmp_path / "parts.gpkg")
    assert result["PARTS"] == 1 and result["CUES"] == "rgb+dsm"
    tested = gpd.read_file(tmp_path / "tested.gpkg").set_index("segment_id")
    assert tested.reason[1] == "too high"        # the roof
    assert bool(tested.passed[2])               # the lot, with the shape tests loosened
    assert tested.height_m[1] == pytest.approx(6.0, abs=0.1)


def test_edge_contrast_threshold_is_used(qgis_process, inputs, tmp_path):
    tested_path = tmp_path / "tested.gpkg"
    result = qgis_process.run("roadparts", IMAGE=inputs / "image.tif",
                              SEGMENTS=f"{inputs / 'segments.gpkg'}|layername=segments",
                              MIN_EDGE_CONTRAST=1000, OUTPUT_SEGMENTS=tested_path,
                              ROAD_PARTS=tmp_path / "parts.gpkg")
    tested = gpd.read_file(tested_path).set_index("segment_id")
    assert result["PARTS"] == 0
    assert tested.reason[1] == "no border edges"
    assert 1 < tested.edge_contrast[1] < 1000   # the road's border is the grass edge


def test_road_parts_style_colours_by_quality(qgis_app, tmp_path):
    from qgis.core import QgsRenderContext, QgsVectorLayer
    lines = gpd.GeoDataFrame({"part_id": [0, 1], "quality": [0.1, 0.9]},
                             geometry=[shapely.LineString([(0, 0), (10, 0)]),
                                       shapely.LineString([(0, 5), (10, 5)])], crs=EPSG)
    write_geopackage(tmp_path / "parts.gpkg", {"road_parts": lines})
    layer = QgsVectorLayer(f"{tmp_path / 'parts.gpkg'}|layername=road_parts", "parts", "ogr")
    assert layer.loadNamedStyle(str(STYLES_DIR / "road_parts.qml"))[1]
    renderer = layer.renderer()
    render_context = QgsRenderContext()
    renderer.startRender(render_context, layer.fields())
    colours = {feature["part_id"]: renderer.symbolForFeature(feature, render_context)
               .color().name() for feature in layer.getFeatures()}
    renderer.stopRender(render_context)
    assert colours == {0: "#d7191c", 1: "#1a9641"}   # poor red, good green
