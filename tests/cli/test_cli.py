"""The gisroads command as a user runs it: a subprocess, exit codes, stdout/stderr, files."""
import json
import sqlite3
import subprocess
import sys

import numpy as np
import pytest
import shapely

from gisroads.io.vector import list_layers, read_layer, write_geopackage
from tests.road_layers import assert_empty_road_layers


def gisroads(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "gisroads.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


def test_help_explains_every_subcommand():
    top = gisroads("--help")
    assert top.returncode == 0
    for command in ("info", "synth", "evaluate", "lidar", "image", "snakes", "blocks", "demo"):
        assert command in top.stdout
        sub = gisroads(command, "--help")
        assert sub.returncode == 0 and "--json" in sub.stdout and "metres" in sub.stdout


def test_info_reports_units_of_every_real_file(lidar_dir):
    for path in sorted(lidar_dir.glob("*.laz")):
        result = gisroads("info", path, "--json")
        assert result.returncode == 0, result.stderr
        info = json.loads(result.stdout)
        assert info["point_count"] > 0 and info["horizontal_unit"]
        if path.name == "autzen_trim.laz":
            assert info["horizontal_unit"] == "foot" and info["unit_to_metre"] == 0.3048
            assert info["extent_m"][2] - info["extent_m"][0] == pytest.approx(
                (info["extent"][2] - info["extent"][0]) * 0.3048)
    text = gisroads("info", lidar_dir / "fusa.laz")
    assert "WGS 84 / UTM zone 54S" in text.stdout and "277573" in text.stdout


@pytest.mark.parametrize("content", ["truncated", "empty", "garbage"])
def test_info_on_broken_laz_is_one_line_and_nonzero(lidar_dir, tmp_path, content):
    data = (lidar_dir / "fusa.laz").read_bytes()
    bad = tmp_path / "bad.laz"
    bad.write_bytes({"truncated": data[:len(data) // 3], "empty": b"",
                     "garbage": b"LASF" + b"\0" * 500}[content])
    result = gisroads("info", bad)
    assert result.returncode == 2
    assert result.stdout == ""
    assert len(result.stderr.strip().splitlines()) == 1
    assert result.stderr.startswith("gisroads: error: ") and "bad.laz" in result.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["bad.laz"]


def test_evaluate_real_truth_against_itself_and_shifted(lidar_dir, tmp_path):
    truth = lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson"
    same = json.loads(gisroads("evaluate", truth, truth, "--json").stdout)
    for key in ("completeness", "correctness", "quality"):
        assert same["buffer"][key] == pytest.approx(1.0, abs=1e-9)
    assert same["buffer"]["rms_m"] == pytest.approx(0.0, abs=1e-9)
    shifted = read_layer(truth)
    shifted.geometry = shapely.offset_curve(shifted.geometry.values, 5.0)  # 5 m sideways
    write_geopackage(tmp_path / "shifted.gpkg", {"road_centrelines": shifted})
    result = gisroads("evaluate", tmp_path / "shifted.gpkg", truth, "--buffer", "3",
                      "--qa", tmp_path / "qa.gpkg", "--json")
    assert result.returncode == 0, result.stderr
    worse = json.loads(result.stdout)["buffer"]
    assert worse["completeness"] < 0.6 and worse["correctness"] < 0.6
    assert read_layer(tmp_path / "qa.gpkg", "eval_reference").status.isin(["TP", "FN"]).all()
    text = gisroads("evaluate", tmp_path / "shifted.gpkg", truth)
    assert "completeness" in text.stdout.lower()


def test_evaluate_missing_file_is_an_error(tmp_path):
    result = gisroads("evaluate", tmp_path / "none.gpkg", tmp_path / "none.gpkg")
    assert result.returncode == 2 and "no such file" in result.stderr


def test_synth_writes_scene_and_truth(tmp_path):
    result = gisroads("synth", "-o", tmp_path / "s", "--size", "300", "--density", "1",
                      "--pixel", "2", "--json")
    assert result.returncode == 0, result.stderr
    paths = json.loads(result.stdout)
    assert set(paths) == {"truth", "cloud", "image", "dsm"}
    info = json.loads(gisroads("info", paths["cloud"], "--json").stdout)
    assert 0.9 * 90_000 < info["point_count"] < 1.1 * 90_000
    con = sqlite3.connect(paths["truth"])
    styled = {row[0] for row in con.execute("SELECT f_table_name FROM layer_styles")}
    con.close()
    assert styled == set(list_layers(paths["truth"])) and len(styled) == 13


def test_bad_option_values_are_refused():
    result = gisroads("synth", "-o", "x", "--size", "10x10")
    assert result.returncode == 2 and "at least 100" in result.stderr


def test_lidar_writes_network_tagged_cloud_and_quicklook(tmp_path):
    from gisroads.io.las import read_las
    from gisroads.synthetic import make_scene, write_cloud
    write_cloud(make_scene(seed=2, size_m=(300.0, 300.0)), tmp_path / "c.laz",
                density_per_m2=3.0)
    result = gisroads("lidar", tmp_path / "c.laz", "-o", tmp_path / "roads.gpkg",
                      "--tagged-las", tmp_path / "tagged.laz", "--quicklook",
                      tmp_path / "roads.png", "--background", tmp_path / "beneath.tif",
                      "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["roads"] > 0 and summary["tagged_points"] > 1000
    # the default cue: every cue the cloud carries, the paper's intensity among them
    assert summary["cue"] == "evidence" and "intensity" in summary["cues"].split(",")
    assert list_layers(tmp_path / "roads.gpkg") == [
        "road_centrelines", "road_polygons", "junctions", "junction_connections", "gap_edges",
        "rejected", "service_centrelines"]
    tagged = read_las(tmp_path / "tagged.laz")
    assert (tagged.classification == 11).sum() == summary["tagged_points"]
    assert (tmp_path / "roads.png").stat().st_size > 10_000
    # the ground intensity to show beneath the roads, in the cloud's CRS, on the evidence's
    # cells (0.5 m, wider for a sparse cloud)
    from gisroads.io.raster import read_raster
    assert summary["background_kind"] == "ground intensity"
    assert 'type="singlebandgray"' in (tmp_path / "beneath.qml").read_text()  # its style
    beneath = read_raster(summary["background"])
    roads = read_layer(tmp_path / "roads.gpkg", "road_centrelines")
    assert 0.5 <= beneath.transform.a <= 1.0 and beneath.crs == roads.crs
    bounds = beneath.bounds
    assert bounds[2] - bounds[0] > 290 and bounds[3] - bounds[1] > 290
    lines = roads.geometry.values
    points = shapely.get_coordinates(shapely.line_interpolate_point(
        lines, np.linspace(0.1, 0.9, 9)[:, None] * shapely.length(lines)))
    cols, rows = ~beneath.transform * points.T
    on_roads = beneath.data.reshape(beneath.shape)[rows.astype(int), cols.astype(int)]
    assert np.nanmedian(on_roads) < np.nanmedian(beneath.data)  # asphalt is dark


def test_lidar_on_a_cloud_without_roads_writes_empty_layers_and_warns(lidar_dir, tmp_path):
    forest = lidar_dir / "crop_1.laz"  # buildings and trees, no public road, under a tile
    result = gisroads("lidar", forest, "-o", tmp_path / "roads.gpkg", "--tagged-las",
                      tmp_path / "tagged.laz", "--quicklook", tmp_path / "roads.png", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert (summary["roads"], summary["length_m"], summary["tagged_points"]) == (0, 0.0, 0)
    assert result.stderr.strip() == (f"gisroads: warning: no road found in {forest}; "
                                     "wrote empty layers")
    assert list_layers(tmp_path / "roads.gpkg") == [
        "road_centrelines", "road_polygons", "junctions", "junction_connections", "gap_edges",
        "rejected", "service_centrelines"]
    assert_empty_road_layers(tmp_path / "roads.gpkg")
    assert (tmp_path / "roads.png").stat().st_size > 10_000
    # a corrupt cloud is still an error that writes nothing
    cut = tmp_path / "cut.laz"
    cut.write_bytes(forest.read_bytes()[:100_000])
    broken = gisroads("lidar", cut, "-o", tmp_path / "cut.gpkg")
    assert broken.returncode == 2 and broken.stderr.startswith("gisroads: error: ")
    assert len(broken.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "cut.gpkg").exists()


def test_demo_runs_both_pipelines_on_the_bundled_data(tmp_path):
    result = gisroads("demo", "--out", tmp_path, "--json", "--progress-json")
    assert result.returncode == 0, result.stderr
    demo = json.loads(result.stdout)
    # the progress says which pipeline is running
    messages = [json.loads(line)["message"] for line in result.stderr.splitlines()
                if line.startswith("{")]
    labels = {m.split(":")[0] for m in messages[:-1] if m}
    assert labels == {"imagery", "LiDAR", "LiDAR, the paper's cue"}, labels
    # the default path: the convolutional network's probability through the network stage;
    # on this tile it draws the N-S street and the NE street (3 roads, 309 m), not the
    # street in shadow nor, since the rural training cycle, the SE street
    assert demo["image"]["cues"] == "model" and demo["image"]["model"] == "road_convnet.onnx"
    assert demo["image"]["roads"] >= 3 and demo["image"]["length_m"] > 250
    # OpenStreetMap's lines run 2-5 m off the road centres: a 3 m buffer scores low for any
    # method (measured completeness 0.33, correctness 0.71; the boosted trees 0.28 / 0.79,
    # the papers' pipeline alone 0.23 / 0.40)
    buffer = demo["image_evaluation"]["buffer"]
    assert buffer["completeness"] > 0.3 and buffer["correctness"] > 0.55
    # the default (evidence) cue finds the town's street network: measured 16.4 km, 180
    # junctions; the paper's cue alone a few fragments
    lidar = demo["lidar"]
    assert lidar["cue"] == "evidence" and lidar["length_m"] > 10_000
    assert lidar["junctions"] >= 100
    assert demo["lidar_intensity"]["cue"] == "intensity"
    assert demo["lidar_intensity"]["roads"] >= 5 and demo["lidar_intensity"]["length_m"] > 500
    for name in ("image_roads", "lidar_roads", "lidar_intensity_roads"):
        assert list_layers(tmp_path / f"{name}.gpkg")[:3] == ["road_centrelines",
                                                              "road_polygons", "junctions"]
        assert (tmp_path / f"{name}.png").stat().st_size > 50_000
