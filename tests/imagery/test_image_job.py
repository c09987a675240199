"""`gisroads image` as a user runs it, and the image reader behind it."""
import json
import subprocess
import sys

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from gisroads.errors import NoRoadFoundWarning
from gisroads.geo import GeoRaster
from gisroads.io.raster import RasterError, write_geotiff
from gisroads.io.vector import list_layers, read_layer
from gisroads.jobs import image_job, read_image
from gisroads.progress import Cancelled
from gisroads.synthetic import make_scene
from gisroads.synthetic.image import write_image
from tests.road_layers import assert_empty_road_layers


def gisroads(*args):
    return subprocess.run([sys.executable, "-m", "gisroads.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def image_files(tmp_path_factory):
    out = tmp_path_factory.mktemp("image_job")
    write_image(make_scene(seed=1, size_m=(300.0, 300.0)), out / "image.tif", out / "dsm.tif",
                pixel_m=0.5)
    return out


def test_image_command_writes_every_layer_with_the_cues_used(image_files, tmp_path):
    result = gisroads("image", image_files / "image.tif", "-o", tmp_path / "roads.gpkg",
                      "--nir-band", 4, "--dsm", image_files / "dsm.tif", "--model", "none",
                      "--quicklook", tmp_path / "roads.png", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["roads"] > 3 and report["cues"] == "rgb+nir+dsm"
    assert list_layers(tmp_path / "roads.gpkg") == [
        "road_centrelines", "road_polygons", "junctions", "segments", "road_parts",
        "gap_edges", "junction_connections"]
    lines = read_layer(tmp_path / "roads.gpkg", "road_centrelines")
    assert (lines.cues == "rgb+nir+dsm").all() and lines.crs.to_epsg() == 32633
    assert (tmp_path / "roads.png").stat().st_size > 10_000


def test_a_band_the_image_lacks_is_an_input_error(image_files, tmp_path):
    result = gisroads("image", image_files / "image.tif", "-o", tmp_path / "r.gpkg",
                      "--nir-band", 7)
    assert result.returncode == 2 and "no NIR band 7" in result.stderr
    assert result.stdout == "" and not (tmp_path / "r.gpkg").exists()


def test_a_geographic_image_is_read_in_its_utm_zone(shared_data):
    image, source_crs = read_image(shared_data / "imagery/spacenet/RGB-PanSharpen_img1447.tif")
    assert source_crs.to_epsg() == 4326
    assert image.crs.to_epsg() == 32631  # Paris: UTM 31N
    assert 0.2 <= image.pixel_size <= 0.3  # 0.2 m east-west, 0.3 m north-south pixels


GRID = Affine(0.5, 0, 500000.0, 0, -0.5, 4500000.0)


def test_an_image_without_roads_gives_empty_layers_and_a_warning(tmp_path):
    rng = np.random.default_rng(0)
    lawn = np.array([80.0, 112.0, 52.0])[:, None, None] + rng.normal(0, 4, (3, 400, 400))
    write_geotiff(tmp_path / "lawn.tif", GeoRaster(lawn.clip(0, 255).astype(np.uint8), GRID,
                                                   CRS("EPSG:32633")))
    with pytest.warns(NoRoadFoundWarning, match="no road found in .*lawn.tif; wrote empty"):
        result = image_job(tmp_path / "lawn.tif", tmp_path / "roads.gpkg")
    assert (result["roads"], result["length_m"], result["junctions"]) == (0, 0.0, 0)
    assert_empty_road_layers(tmp_path / "roads.gpkg")
    command = gisroads("image", tmp_path / "lawn.tif", "-o", tmp_path / "cli.gpkg",
                       "--quicklook", tmp_path / "cli.png", "--json")
    assert command.returncode == 0, command.stderr
    assert json.loads(command.stdout)["roads"] == 0
    assert command.stderr.strip() == (f"gisroads: warning: no road found in "
                                      f"{tmp_path / 'lawn.tif'}; wrote empty layers")
    assert_empty_road_layers(tmp_path / "cli.gpkg")
    assert (tmp_path / "cli.png").stat().st_size > 10_000


@pytest.mark.parametrize("content, message", [
    ("nan", "every cell is NaN or nodata"),
    ("junk", "not a readable raster"),
])
def test_unreadable_or_empty_images_are_one_line_errors(tmp_path, content, message):
    path = tmp_path / "image.tif"
    if content == "nan":
        write_geotiff(path, GeoRaster(np.full((3, 50, 50), np.nan, np.float32), GRID,
                                      CRS("EPSG:32633")))
    else:
        path.write_bytes(b"II*\x00" + bytes(range(256)) * 2)
    with pytest.raises(RasterError, match=message):
        image_job(path, tmp_path / "roads.gpkg")
    result = gisroads("image", path, "-o", tmp_path / "roads.gpkg")
    assert result.returncode == 2 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "roads.gpkg").exists()


def test_a_cancelled_job_leaves_no_output(image_files, tmp_path):
    seen = []

    def cancel_in_grouping(fraction, message):
        seen.append(message)
        if fraction >= 0.45:
            raise Cancelled

    with pytest.raises(Cancelled):
        image_job(image_files / "image.tif", tmp_path / "roads.gpkg", model="none",
                  progress=cancel_in_grouping)
    assert any("grouping" in message for message in seen)
    assert list(tmp_path.iterdir()) == []
