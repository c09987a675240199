"""What a new user hits at the command line: outputs refused before any work, plain numbers
in ``gisroads info``, images without georeferencing, closed pipes, unreadable road maps,
formatted timings and the progress display on a terminal and in a log."""
import fcntl
import json
import os
import pty
import re
import struct
import subprocess
import sys
import termios
import warnings

import geopandas as gpd
import numpy as np
import pytest
import rasterio
import rasterio.errors
import shapely

from gisroads.cli.report import print_result
from gisroads.io.vector import write_geopackage

GISROADS = [sys.executable, "-m", "gisroads.cli"]


def gisroads(*args, cwd=None):
    return subprocess.run([*GISROADS, *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


def one_line_error(result) -> str:
    """The single stderr line of a refused command (exit status 2, nothing on stdout)."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr  # no progress before it, no traceback, no warning
    assert lines[0].startswith("gisroads: error: ")
    return lines[0]


@pytest.fixture(scope="module")
def png(tmp_path_factory):
    """A plain PNG: an image with a road across and no georeferencing."""
    path = tmp_path_factory.mktemp("png") / "photo.png"
    data = np.zeros((3, 150, 200), np.uint8)
    data[:, 70:80, :] = 255
    with warnings.catch_warnings():  # rasterio: the PNG has no geotransform, as intended
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(path, "w", driver="PNG", width=200, height=150, count=3,
                           dtype="uint8") as dst:
            dst.write(data)
    return path


@pytest.mark.parametrize("command, option, expected", [
    (["lidar", "{laz}", "-o", "{tmp}/roads.shp"], "-o/--out", ".gpkg"),
    (["lidar", "{laz}", "-o", "{tmp}/r.gpkg", "--tagged-las", "{tmp}/t.txt"], "--tagged-las",
     ".las or .laz"),
    (["lidar", "{laz}", "-o", "{tmp}/r.gpkg", "--quicklook", "{tmp}/q.jpg"], "--quicklook",
     ".png"),
    (["lidar", "{laz}", "-o", "{tmp}/r.gpkg", "--rasters", "{tmp}/a_file"], "--rasters",
     "is a file"),
    (["lidar", "{laz}", "-o", "{tmp}/a_file/roads.gpkg"], "-o/--out", "is a file"),
    (["lidar", "{laz}", "-o", "{tmp}"], "-o/--out", ".gpkg"),
    (["snakes", "{laz}", "{tmp}/map.geojson", "-o", "{tmp}/r.gpkg", "--attractor",
      "{tmp}/a.png"], "--attractor", ".tif or .tiff"),
    (["image", "{png}", "-o", "{tmp}/roads.geojson"], "-o/--out", ".gpkg"),
    (["vectorize", "{png}", "-o", "{tmp}/roads.shp"], "-o/--out", ".gpkg"),
    (["blocks", "{png}", "-o", "{tmp}/blocks.shp"], "-o/--out", ".gpkg"),
    (["evaluate", "{tmp}/map.geojson", "{tmp}/map.geojson", "--qa", "{tmp}/qa.shp"], "--qa",
     ".gpkg"),
    (["synth", "-o", "{tmp}/a_file"], "-o/--out", "is a file"),
    (["demo", "-o", "{tmp}/a_file/demo"], "-o/--out", "is a file"),
    (["update", "{tmp}/map.geojson", "{tmp}/map.geojson", "-o", "{tmp}/changes.shp"],
     "-o/--out", ".gpkg"),
])
def test_outputs_are_refused_before_any_work(lidar_dir, png, tmp_path, command, option,
                                             expected):
    (tmp_path / "a_file").write_text("in the way")
    lines = gpd.GeoDataFrame(geometry=[shapely.LineString([(0, 0), (50, 0)])], crs=32654)
    lines.to_file(tmp_path / "map.geojson")
    before = sorted(p.name for p in tmp_path.iterdir())
    args = [a.format(laz=lidar_dir / "fusa.laz", png=png, tmp=tmp_path) for a in command]
    line = one_line_error(gisroads(*args))  # one line: no progress was printed before it
    assert option in line and expected in line
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_missing_output_folders_are_still_made(tmp_path):
    result = gisroads("synth", "-o", tmp_path / "new" / "scene", "--size", "300",
                      "--density", "0.5", "--pixel", "2", "--no-cloud", "--json")
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "new" / "scene" / "truth.gpkg").exists()


def test_a_quicklook_of_a_cloud_without_crs_is_drawn(lidar_dir, tmp_path):
    # zurich.laz declares no CRS: the layers stay in its coordinates
    result = gisroads("lidar", lidar_dir / "zurich.laz", "-o", tmp_path / "z.gpkg",
                      "--quicklook", tmp_path / "z.png", "--json")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert (tmp_path / "z.png").stat().st_size > 10_000
    assert json.loads(result.stdout)["quicklook"].endswith("z.png")


def test_info_prints_plain_numbers(lidar_dir):
    result = gisroads("info", lidar_dir / "autzen_trim.laz")
    assert result.returncode == 0, result.stderr
    assert "np." not in result.stdout and "float64" not in result.stdout
    assert "  extent: [636001.76, 848935.2, 637179.22, 849497.9]" in result.stdout.splitlines()
    info = json.loads(gisroads("info", "--json", lidar_dir / "autzen_trim.laz").stdout)
    assert info["extent"][0] == pytest.approx(636001.76)


def test_info_on_an_image_without_georeferencing_says_so(png):
    as_json = gisroads("info", "--json", png)
    assert as_json.returncode == 0 and as_json.stderr == ""  # no rasterio warning
    info = json.loads(as_json.stdout)
    assert (info["georeferenced"], info["extent"], info["pixel_size"]) == (False, None, None)
    assert (info["width"], info["height"]) == (200, 150)
    text = gisroads("info", png)
    assert text.stderr == ""
    assert "  georeferenced: no (no geotransform and no CRS;" in text.stdout
    assert "--pixel and --crs" in text.stdout
    assert "  extent: none" in text.stdout.splitlines() and "150.0" not in text.stdout


@pytest.mark.parametrize("command", ["image", "vectorize"])
def test_an_image_without_georeferencing_names_pixel_and_crs(png, tmp_path, command):
    line = one_line_error(gisroads(command, png, "-o", tmp_path / "roads.gpkg"))
    assert "photo.png" in line and "no georeferencing" in line
    assert "--pixel" in line and "--crs" in line
    assert not (tmp_path / "roads.gpkg").exists()


def test_info_of_an_empty_layer_shows_its_declared_geometry(tmp_path):
    empty = gpd.GeoDataFrame({"junction_id": np.array([], int)},
                             geometry=gpd.GeoSeries([], crs=2154))
    lines = gpd.GeoDataFrame(geometry=[shapely.LineString([(0, 0), (50, 0)])], crs=2154)
    write_geopackage(tmp_path / "n.gpkg", {"road_centrelines": lines, "junctions": empty})
    text = gisroads("info", tmp_path / "n.gpkg")
    assert text.returncode == 0, text.stderr
    assert "junctions: 0 features, Point (declared), CRS RGF93 v1 / Lambert-93 (EPSG 2154), " \
           "no extent" in text.stdout.splitlines()
    layers = json.loads(gisroads("info", "--json", tmp_path / "n.gpkg").stdout)["layers"]
    assert [(layer["layer"], layer["geometry"]) for layer in layers] == [
        ("road_centrelines", ["LineString"]), ("junctions", ["Point"])]


def test_json_into_a_closed_pipe_ends_quietly(lidar_dir):
    # as `gisroads info --json f | head -0`: the reader is gone before anything is written
    process = subprocess.Popen([*GISROADS, "info", "--json", str(lidar_dir / "fusa.laz")],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()
    stderr = process.stderr.read()
    process.wait(timeout=120)
    assert stderr == b""
    assert process.returncode == 141  # 128 + SIGPIPE, as a command killed by it


def test_a_truncated_road_map_is_a_one_line_error(lidar_dir, tmp_path):
    text = (lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson").read_text()
    cut = tmp_path / "map.geojson"
    cut.write_text(text[:len(text) // 2])
    line = one_line_error(gisroads("snakes", lidar_dir / "fusa.laz", cut, "-o",
                                   tmp_path / "roads.gpkg"))
    assert "map.geojson" in line and "not a readable vector file" in line
    info = one_line_error(gisroads("info", cut))
    assert "map.geojson" in info


def test_timings_and_numbers_print_formatted(capsys):
    print_result({"roads": 3, "length_m": 392.188116950236,
                  "timings_s": {"segmentation": 0.7794340670002384,
                                "total": 1.7867650389998744}},
                 False)
    assert capsys.readouterr().out.splitlines() == [
        "roads: 3", "length_m: 392.188117", "timings_s: segmentation 0.78 s, total 1.79 s"]


def synth_args(tmp_path):
    return ["synth", "-o", str(tmp_path / "scene"), "--size", "300", "--density", "0.5",
            "--pixel", "2"]


def test_progress_in_a_log_is_a_line_per_ten_percent(tmp_path):
    result = gisroads(*synth_args(tmp_path))
    assert result.returncode == 0, result.stderr
    lines = result.stderr.splitlines()
    assert "\r" not in result.stderr and 2 <= len(lines) <= 11
    percents = [int(re.match(r"^ *(\d+)% ", line).group(1)) for line in lines]
    assert percents == sorted(percents) and percents[-1] == 100
    assert len({p // 10 for p in percents}) == len(percents)  # one line per tens


def test_progress_on_a_terminal_is_a_tqdm_bar(tmp_path):
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    process = subprocess.Popen([*GISROADS, *synth_args(tmp_path)], stdout=subprocess.PIPE,
                               stderr=slave)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the terminal closed with the process
            break
        if not chunk:
            break
        chunks.append(chunk)
    process.wait(timeout=120)
    os.close(master)
    screen = b"".join(chunks).decode()
    assert process.returncode == 0, screen
    # redrawn in place (carriage returns), with tqdm's elapsed<remaining times, closed at 100
    assert screen.count("\r") >= 2
    assert re.search(r"100%\|.*\| \d\d:\d\d<\d\d:\d\d done", screen)
    assert screen.endswith("\n")  # the closed bar leaves its line


def test_progress_as_json_lines_for_a_driving_program(tmp_path):
    result = gisroads(*synth_args(tmp_path), "--json", "--progress-json")
    assert result.returncode == 0, result.stderr
    assert set(json.loads(result.stdout)) == {"truth", "cloud", "image", "dsm"}
    events = [json.loads(line) for line in result.stderr.splitlines()]
    assert len(events) >= 5 and all(set(e) == {"progress", "message"} for e in events)
    fractions = [e["progress"] for e in events]
    assert fractions == sorted(fractions) and fractions[0] == 0.0 and fractions[-1] == 1.0
    assert any("LiDAR tile" in e["message"] for e in events)


def test_sigterm_cancels_and_leaves_nothing(tmp_path):
    from gisroads.resources import demo_dir
    out = tmp_path / "out"
    out.mkdir()
    process = subprocess.Popen([*GISROADS, "lidar",
                                str(demo_dir() / "ign_lidar_hd_0292_6833_thinned.laz"),
                                "-o", str(out / "roads.gpkg"), "--rasters", str(out / "r"),
                                "--workers", "1", "--progress-json"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines = []
    for line in process.stderr:  # wait until the work is well under way
        lines.append(line)
        if line.startswith("{") and json.loads(line)["progress"] >= 0.1:
            break
    process.terminate()
    rest = process.stderr.read()
    process.wait(timeout=120)
    assert process.returncode == 130, (lines, rest)
    assert rest.strip().splitlines()[-1] == "gisroads: cancelled; nothing written"
    assert "Traceback" not in rest
    written = [p for p in out.rglob("*") if p.is_file()]
    assert not [p for p in written if p.suffix in {".gpkg", ".tif"} or p.name.startswith(".")]


def test_vectorize_refuses_a_photo_unless_a_band_is_named(tmp_path):
    """An RGB photo read as a probability drew junk roads; now it says what it expects."""
    from gisroads.jobs import DEMO_IMAGE
    from gisroads.resources import demo_dir

    photo = demo_dir() / DEMO_IMAGE
    line = one_line_error(gisroads("vectorize", photo, "-o", tmp_path / "r.gpkg"))
    assert "3 bands, like an image" in line and "--band" in line and "gisroads image" in line
    assert not (tmp_path / "r.gpkg").exists()
    named = gisroads("vectorize", photo, "-o", tmp_path / "r.gpkg", "--band", "1")
    assert named.returncode == 0, named.stderr


def test_evaluate_takes_the_reference_junctions(lidar_dir):
    """fusa's truth has 7 digitised junctions; its lines share a vertex at 3 of them."""
    truth = lidar_dir / "ground_truth" / "fusa"
    derived = gisroads("evaluate", truth / "centrelines.geojson", truth / "centrelines.geojson")
    assert "3 reference" in derived.stdout, derived.stderr
    given = gisroads("evaluate", truth / "centrelines.geojson", truth / "centrelines.geojson",
                     "--reference-junctions", truth / "junctions.geojson")
    assert "7 reference" in given.stdout, given.stderr


def test_the_last_count_in_the_progress_is_the_summarys(lidar_dir, tmp_path):
    """The progress said "30 roads" and the summary 31: the network stage counted before
    its clip to the data. And it jumped from 5 % to 48 % inside the one tile's evidence."""
    done = gisroads("lidar", lidar_dir / "fusa.laz", "-o", tmp_path / "r.gpkg", "--json",
                    "--progress-json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    events = [json.loads(line) for line in done.stderr.splitlines() if line.startswith("{")]
    counts = [e["message"] for e in events if " roads, " in e["message"]]
    assert counts[-1].startswith(f"{result['roads']} roads, {result['junctions']} junctions")
    # the road evidence of a one-tile cloud reports its cues, not one jump of 43 %
    fractions = [e["progress"] for e in events]
    assert fractions == sorted(fractions)
    messages = [e["message"] for e in events]
    first = messages.index("tile 1 of 1: references")
    last = messages.index("road evidence done")
    inside = [e["progress"] for e in events[first:last + 1]]
    assert {"terrain", "ground planes", "kerbs and the rule"} <= set(messages[first:last])
    assert max(np.diff(inside)) < 0.15


def test_city_blocks_end_where_the_cloud_ends(lidar_dir, tmp_path):
    """fusa covers 250 x 250 m of its 300 m tile: the blocks drew the empty 50 m margin
    too. The likelihood rasters are NaN past the cloud now."""
    done = gisroads("lidar", lidar_dir / "fusa.laz", "-o", tmp_path / "r.gpkg", "--cue",
                    "intensity", "--rasters", tmp_path / "rasters")
    assert done.returncode == 0, done.stderr
    likelihood = tmp_path / "rasters" / "tile_r0_c0_likelihood_level_0.tif"
    with rasterio.open(likelihood) as source:
        assert source.bounds.right - source.bounds.left == 300.0
        margin = source.read(1)[:, -60:]            # the tile's 30 m east of the cloud
    assert np.isnan(margin).all()
    done = gisroads("blocks", likelihood, "-o", tmp_path / "blocks.gpkg")
    assert done.returncode == 0, done.stderr
    blocks = gpd.read_file(tmp_path / "blocks.gpkg", layer="city_blocks")
    x0, y0, x1, y1 = blocks.total_bounds
    assert len(blocks) >= 3
    assert x1 <= 278000.0 + 3.0 and y1 <= 6122500.0 + 3.0  # the cloud's east and north edges
