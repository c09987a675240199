"""``gisroads vectorize``: a real mask PNG to a network, and bad rasters refused."""
import json
import subprocess
import sys

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from gisroads.io.vector import list_layers, read_layer
from gisroads.imagery.datasets import DATA_DIR


def gisroads(*args):
    return subprocess.run([sys.executable, "-m", "gisroads.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


def test_massachusetts_mask_png_to_a_connected_network(tmp_path):
    mask = DATA_DIR / "massachusetts" / "masks" / "10078660_15.png"
    if not mask.exists():
        pytest.skip("../shared/data/imagery is not beside the repository")
    out = tmp_path / "roads.gpkg"
    done = gisroads("vectorize", mask, "-o", out, "--pixel", 1, "--crs", "EPSG:32619",
                    "--quicklook", tmp_path / "roads.png", "--json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    # measured: 25 roads, 4.19 km, 13 junctions
    assert result["junctions"] >= 10 and 3800 < result["length_m"] < 4600
    assert {"road_centrelines", "road_polygons", "junctions", "gap_edges",
            "junction_connections", "rejected"} <= set(list_layers(out))
    widths = read_layer(out, "road_centrelines").width_m
    assert widths.between(4, 12).all()          # the masks draw roads about 7 m wide
    assert (tmp_path / "roads.png").stat().st_size > 0


def test_nan_raster_is_one_error_line_and_nothing_written(tmp_path):
    path = tmp_path / "nan.tif"
    with rasterio.open(path, "w", driver="GTiff", width=20, height=20, count=1,
                       dtype="float32", crs="EPSG:32633",
                       transform=from_origin(500000, 4500000, 1, 1)) as dst:
        dst.write(np.full((1, 20, 20), np.nan, np.float32))
    out = tmp_path / "out.gpkg"
    done = gisroads("vectorize", path, "-o", out)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1].startswith("gisroads: error:")
    assert not out.exists()


def test_wide_areas_flag_draws_the_street_not_the_car_park(tmp_path):
    """``--wide-areas``: a street with a car park off it gives the street alone; without
    the flag the car park's outline and aisles are drawn as roads."""
    from gisroads.io.raster import write_geotiff
    from tests.network.test_areas import _street_with_car_park

    raster = write_geotiff(tmp_path / "p.tif", _street_with_car_park(access=True))
    summaries = {}
    for name, flags in (("plain", []), ("areas", ["--wide-areas"])):
        done = gisroads("vectorize", raster, "-o", tmp_path / f"{name}.gpkg", *flags, "--json")
        assert done.returncode == 0, done.stderr
        summaries[name] = json.loads(done.stdout)
    assert summaries["plain"]["roads"] >= 5
    assert summaries["areas"]["roads"] == 1
    assert 135 < summaries["areas"]["length_m"] < 160  # the 150 m street
    rejected = read_layer(tmp_path / "areas.gpkg", "rejected")
    assert (rejected.reason == "wide paved area").sum() >= 4
