"""'Subgraph linking (integer program)' through qgis_process on hand-made road parts."""
import geopandas as gpd
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS
from qgis.core import QgsProcessingException

from gisroads.geo import GeoRaster
from gisroads.io.raster import write_geotiff
from gisroads.io.vector import STYLES_DIR, write_geopackage

EPSG = "EPSG:32633"
COS20, SIN20 = np.cos(np.radians(20)), np.sin(np.radians(20))


def write_parts(path, rows, crs=EPSG):
    """rows: (part_id, coords, width_m, quality)."""
    frame = gpd.GeoDataFrame(
        {"part_id": [r[0] for r in rows], "segment_id": [r[0] for r in rows],
         "width_m": [r[2] for r in rows],
         "length_m": [shapely.LineString(r[1]).length for r in rows],
         "quality": [r[3] for r in rows], "mean_b1": 0.4, "mean_b2": 0.4,
         "mean_intensity": 0.4},
        geometry=[shapely.LineString(r[1]) for r in rows], crs=EPSG).to_crs(crs)
    write_geopackage(path, {"road_parts": frame})
    return f"{path}|layername=road_parts"


def test_collinear_link_kept_branch_rejected_and_styled(qgis_process, qgis_app, tmp_path):
    parts = write_parts(tmp_path / "parts.gpkg", [
        (1, [(0, 0), (50, 0)], 6.0, 0.9), (2, [(60, 0), (110, 0)], 6.0, 0.8),
        (3, [(58, 3), (58 + 50 * COS20, 3 + 50 * SIN20)], 4.0, 0.7)])
    result = qgis_process.run("subgraphlinking", ROAD_PARTS=parts,
                              GAP_EDGES=tmp_path / "gaps.gpkg",
                              ROAD_STRINGS=tmp_path / "strings.gpkg")
    assert (result["SELECTED"], result["STRINGS"]) == (1, 2)
    gaps = gpd.read_file(tmp_path / "gaps.gpkg")
    assert list(zip(gaps.from_part, gaps.to_part, gaps.selected)) == [(1, 2, True),
                                                                     (1, 3, False)]
    assert (gaps.weight > 0).all() and gaps.crs == CRS(EPSG)
    strings = gpd.read_file(tmp_path / "strings.gpkg")
    assert strings.part_ids.tolist() == ["1,2", "3"]
    assert strings.length_m[0] == 110.0

    # the gap_edges style: kept links solid, rejected hypotheses dashed
    from qgis.core import QgsExpressionContextUtils, QgsRenderContext, QgsVectorLayer
    layer = QgsVectorLayer(str(tmp_path / "gaps.gpkg"), "gap_edges", "ogr")
    assert layer.loadNamedStyle(str(STYLES_DIR / "gap_edges.qml"))[1]
    renderer = layer.renderer()
    render_context = QgsRenderContext()   # as the map canvas sets it up: layer scope, feature
    render_context.expressionContext().appendScopes(
        QgsExpressionContextUtils.globalProjectLayerScopes(layer))
    renderer.startRender(render_context, layer.fields())
    styles = {}
    for feature in layer.getFeatures():
        render_context.expressionContext().setFeature(feature)
        symbol = renderer.symbolForFeature(feature, render_context)
        styles[bool(feature["selected"])] = symbol.symbolLayer(0).properties()["line_style"]
    renderer.stopRender(render_context)
    assert styles == {True: "solid", False: "dash"}


def test_a_building_in_the_dsm_blocks_the_gap_a_tree_does_not(qgis_process, tmp_path):
    parts = write_parts(tmp_path / "parts.gpkg", [
        (1, [(0, 0), (40, 0)], 6.0, 0.9), (2, [(60, 0), (100, 0)], 6.0, 0.9),
        (3, [(0, 100), (40, 100)], 6.0, 0.9), (4, [(60, 100), (100, 100)], 6.0, 0.9)])
    grid = Affine(1, 0, -10, 0, -1, 120)               # x -10..110, y -20..120
    heights = np.full((140, 120), 50.0, np.float32)    # ground at 50 m
    heights[115:125, 55:65] = 58.0                     # an 8 m building in the gap at y = 0
    heights[15:25, 55:65] = 59.0                       # a 9 m tree in the gap at y = 100
    noise = np.random.default_rng(0).integers(-3, 4, (1, 140, 120))
    image = (np.array([120, 120, 120, 80])[:, None, None] + noise).astype(np.uint8)  # asphalt
    image[:, 60:70], image[:, 70:80] = 20, 230   # dark and bright strips away from the gaps
    image[:, 15:25, 55:65] = np.array([60, 120, 60, 220], np.uint8)[:, None, None]  # a tree
    write_geotiff(tmp_path / "dsm.tif", GeoRaster(heights, grid, CRS(EPSG)))
    write_geotiff(tmp_path / "image.tif", GeoRaster(image, grid, CRS(EPSG)))
    qgis_process.run("subgraphlinking", ROAD_PARTS=parts, DSM=tmp_path / "dsm.tif",
                     IMAGE=tmp_path / "image.tif", NIR_BAND=4,
                     GAP_EDGES=tmp_path / "gaps.gpkg", ROAD_STRINGS=tmp_path / "strings.gpkg")
    gaps = gpd.read_file(tmp_path / "gaps.gpkg")
    assert list(zip(gaps.from_part, gaps.to_part, gaps.n_building, gaps.n_tree,
                    gaps.selected)) == [(1, 2, 1, 0, False), (3, 4, 0, 1, True)]
    # asphalt on both sides of the building, around the tree: two appearances each
    assert gaps.n_asphalt.tolist() == [2, 2] and gaps.occlusion.tolist() == [0.0, 0.5]
    assert gaps.context_weight.tolist() == [-10 + 0.75, 0.75 + 0.5]
    assert gaps.context_cues[0] == "ndvi,ndsm,intensity,rgb"
    strings = gpd.read_file(tmp_path / "strings.gpkg")
    assert sorted(strings.part_ids) == ["1", "2", "3,4"]


def run_in_process(run_algorithm, **params):
    return run_algorithm("subgraphlinking", {k: str(v) for k, v in params.items()})


def test_edited_gap_edges_override_the_program(run_algorithm, tmp_path):
    parts = write_parts(tmp_path / "parts.gpkg", [
        (1, [(0, 0), (50, 0)], 6.0, 0.9), (2, [(60, 0), (110, 0)], 6.0, 0.8),
        (3, [(58, 3), (58 + 50 * COS20, 3 + 50 * SIN20)], 4.0, 0.7)])
    run_in_process(run_algorithm, ROAD_PARTS=parts, GAP_EDGES=tmp_path / "gaps.gpkg",
                   ROAD_STRINGS=tmp_path / "strings.gpkg")
    edited = gpd.read_file(tmp_path / "gaps.gpkg")
    assert edited.selected.tolist() == [True, False]
    edited["selected"] = [False, True]           # the user prefers the branch
    write_geopackage(tmp_path / "edited.gpkg", {"gap_edges": edited})
    result = run_in_process(run_algorithm, ROAD_PARTS=parts,
                            EDITED_GAP_EDGES=tmp_path / "edited.gpkg",
                            GAP_EDGES=tmp_path / "gaps2.gpkg",
                            ROAD_STRINGS=tmp_path / "strings2.gpkg")
    assert (result["SELECTED"], result["STRINGS"]) == (1, 2)
    assert gpd.read_file(tmp_path / "strings2.gpkg").part_ids.tolist() == ["1,3", "2"]
    edited["selected"] = True                     # both at part 1's end: refused
    write_geopackage(tmp_path / "edited.gpkg", {"gap_edges": edited})
    with pytest.raises(QgsProcessingException, match="part 1 end 1 has more than one"):
        run_in_process(run_algorithm, ROAD_PARTS=parts,
                       EDITED_GAP_EDGES=tmp_path / "edited.gpkg",
                       GAP_EDGES=tmp_path / "gaps3.gpkg", ROAD_STRINGS=tmp_path / "s3.gpkg")


def test_a_dsm_alone_gives_the_context_in_process(run_algorithm, tmp_path):
    parts = write_parts(tmp_path / "parts.gpkg", [(1, [(0, 0), (40, 0)], 6.0, 0.9),
                                                  (2, [(60, 0), (100, 0)], 6.0, 0.9)])
    heights = np.zeros((40, 120), np.float32)          # x -10..110, y -20..20
    heights[15:25, 55:65] = 8.0                        # a building in the gap
    write_geotiff(tmp_path / "dsm.tif",
                  GeoRaster(heights, Affine(1, 0, -10, 0, -1, 20), CRS(EPSG)))
    result = run_in_process(run_algorithm, ROAD_PARTS=parts, DSM=tmp_path / "dsm.tif",
                            GAP_EDGES=tmp_path / "gaps.gpkg",
                            ROAD_STRINGS=tmp_path / "strings.gpkg")
    assert (result["SELECTED"], result["STRINGS"]) == (0, 2)
    gaps = gpd.read_file(tmp_path / "gaps.gpkg")
    assert gaps.n_building.tolist() == [1] and gaps.context_cues.tolist() == ["ndsm"]


def test_geographic_road_parts_fail_cleanly(qgis_process, tmp_path):
    parts = write_parts(tmp_path / "parts.gpkg", [(1, [(0, 0), (50, 0)], 6.0, 0.9)],
                        crs="EPSG:4326")
    result = qgis_process("run", "gisroads:subgraphlinking", "--", f"ROAD_PARTS={parts}",
                          f"GAP_EDGES={tmp_path / 'g.gpkg'}",
                          f"ROAD_STRINGS={tmp_path / 's.gpkg'}", check=False)
    assert result.returncode == 1
    assert "projected CRS" in result.stdout + result.stderr
