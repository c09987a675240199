"""The plugin zip, installed in a throwaway profile, run by the real qgis_process.bin."""
import json
import re
from pathlib import Path
from xml.etree import ElementTree

import geopandas as gpd
import pytest
import shapely

from gisroads.io.las import read_las
from gisroads.io.vector import list_layers, read_layer, write_geopackage

ALGORITHM_DIR = Path(__file__).resolve().parents[2] / "processing_provider" / "algorithms"
MODEL_DIR = ALGORITHM_DIR.parent / "models"
# every NAME = "..." declared by a module of processing_provider/algorithms, and the name of
# every Processing model shipped in processing_provider/models
ALGORITHMS = sorted(re.findall(r'^    NAME = "(\w+)"', "".join(
    p.read_text() for p in ALGORITHM_DIR.glob("*.py")), flags=re.M) + [
    ElementTree.parse(p).find(".//Option[@name='model_name']").get("value")
    for p in MODEL_DIR.glob("*.model3")])


def test_provider_lists_every_algorithm(qgis_process):
    listed = re.findall(r"^\s*gisroads:([^\t]+)\t", qgis_process("list").stdout, flags=re.M)
    assert sorted(listed) == ALGORITHMS
    assert len(ALGORITHMS) >= 5
    assert any(" " in name for name in ALGORITHMS)  # a model is listed


def test_every_parameter_has_help(qgis_process):
    for name in ALGORITHMS:
        described = json.loads(qgis_process("--json", "help", f"gisroads:{name}").stdout)
        assert len(described["algorithm_details"]["short_description"]) > 30, name
        assert len(qgis_process("help", f"gisroads:{name}").stdout.split("Description")[1]) \
            > 300, name
        for param, spec in described["parameters"].items():
            assert spec.get("help"), f"{name}: parameter {param} has no help text"


def test_synthetic_scene_writes_cloud_image_and_truth(scene_dir):
    # GDAL keeps raster statistics in *.aux.xml beside the rasters other tests opened
    written = sorted(p.name for p in scene_dir.iterdir() if not p.name.endswith(".aux.xml"))
    assert written == ["cloud.laz", "dsm.tif", "image.tif", "truth.gpkg"]
    cloud = read_las(scene_dir / "cloud.laz")
    density = len(cloud) / (300 * 300)
    assert 1.8 < density < 2.2
    assert cloud.crs is not None
    truth = read_layer(scene_dir / "truth.gpkg", "road_centrelines")
    assert truth.crs == cloud.crs and len(truth) >= 5
    assert truth.width_m.between(4, 25).all()


def test_evaluate_scores_identity_and_shift(qgis_process, scene_dir, tmp_path):
    truth = f"{scene_dir / 'truth.gpkg'}|layername=road_centrelines"
    same = qgis_process.run("evaluateroadnetwork", EXTRACTED=truth, REFERENCE=truth, BUFFER=3,
                            EXTRACTED_QA=tmp_path / "e.gpkg", REFERENCE_QA=tmp_path / "r.gpkg")
    assert same["COMPLETENESS"] == pytest.approx(1.0, abs=1e-9)
    assert same["CORRECTNESS"] == pytest.approx(1.0, abs=1e-9)
    assert same["QUALITY"] == pytest.approx(1.0, abs=1e-9)
    shifted = read_layer(scene_dir / "truth.gpkg", "road_centrelines")
    shifted.geometry = shapely.offset_curve(shifted.geometry.values, 5.0)  # 5 m sideways
    write_geopackage(tmp_path / "shifted.gpkg", {"road_centrelines": shifted})
    worse = qgis_process.run("evaluateroadnetwork", EXTRACTED=tmp_path / "shifted.gpkg",
                             REFERENCE=truth, BUFFER=3, EXTRACTED_QA=tmp_path / "e2.gpkg",
                             REFERENCE_QA=tmp_path / "r2.gpkg")
    assert worse["COMPLETENESS"] < 0.6 and worse["CORRECTNESS"] < 0.6
    report = json.loads(worse["REPORT"])
    assert report["buffer"]["completeness"] == pytest.approx(worse["COMPLETENESS"])
    qa = gpd.read_file(tmp_path / "e2.gpkg")
    assert set(qa.status) == {"TP", "FP"}
    fp = qa[qa.status == "FP"].length.sum() / qa.length.sum()
    assert fp == pytest.approx(1 - worse["CORRECTNESS"], abs=0.02)


def test_bad_input_fails_cleanly(qgis_process, tmp_path):
    (tmp_path / "empty.geojson").write_text('{"type": "FeatureCollection", "features": []}')
    result = qgis_process("run", "gisroads:evaluateroadnetwork", "--",
                          f"EXTRACTED={tmp_path / 'empty.geojson'}",
                          f"REFERENCE={tmp_path / 'empty.geojson'}",
                          f"EXTRACTED_QA={tmp_path / 'e.gpkg'}",
                          f"REFERENCE_QA={tmp_path / 'r.gpkg'}", check=False)
    assert result.returncode == 1
    assert "reference" in (result.stdout + result.stderr).lower()
    assert not (tmp_path / "e.gpkg").exists()


def test_geopackage_opens_with_every_layer_styled(qgis_process, scene_dir):
    truth = scene_dir / "truth.gpkg"
    styles = json.loads(qgis_process.run("openroadnetwork", INPUT=truth)["STYLES"])
    assert set(styles) == set(list_layers(truth))
    assert len(styles) == 13  # contract layers and the scene's objects
    for name, style in styles.items():
        assert style["styled_from_file"], name
    # the colours of styles/*.qml, not QGIS's random default colours
    assert styles["road_centrelines"]["colors"] == ["#e31a1c"]
    assert styles["road_polygons"]["colors"] == ["#ffd250"]
    assert styles["junctions"]["colors"] == ["#1f78b4"]


def test_lidar_road_network_then_tag_road_points(qgis_process, scene_dir, tmp_path):
    result = qgis_process.run("lidarroadnetwork", INPUT=scene_dir / "cloud.laz", CUE=0,
                              LENGTHS="40,80,150", OUTPUT=tmp_path / "roads.gpkg",
                              TAGGED_LAS=tmp_path / "tagged.laz", RASTERS=tmp_path / "rasters")
    assert result["ROADS"] > 0 and result["LENGTH_M"] > 100
    assert list_layers(tmp_path / "roads.gpkg")[:3] == ["road_centrelines", "road_polygons",
                                                        "junctions"]
    in_pipeline = read_las(tmp_path / "tagged.laz").classification == 11
    assert in_pipeline.sum() > 1000
    # the same tagging as a stage of its own, from the pipeline's outputs
    tagged = qgis_process.run("tagroadpoints", INPUT=scene_dir / "cloud.laz",
                              POLYGONS=tmp_path / "roads.gpkg",
                              HEIGHTS=tmp_path / "rasters" / "ground_heights.tif",
                              OUTPUT=tmp_path / "tagged_again.laz")
    again = read_las(tmp_path / "tagged_again.laz").classification == 11
    assert tagged["TAGGED"] == again.sum() == in_pipeline.sum()


def test_lidar_bad_input_fails_cleanly(qgis_process, tmp_path):
    (tmp_path / "bad.laz").write_bytes(b"LASF" + bytes(300))
    result = qgis_process("run", "gisroads:lidarroadnetwork", "--",
                          f"INPUT={tmp_path / 'bad.laz'}", f"OUTPUT={tmp_path / 'r.gpkg'}",
                          check=False)
    assert result.returncode == 1 and "bad.laz" in result.stdout + result.stderr
    assert not (tmp_path / "r.gpkg").exists()
