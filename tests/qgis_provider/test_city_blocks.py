"""'City blocks (normalized cut)' through qgis_process: a synthetic road-probability grid
with one road segment missing, and a raster with no data."""
import json
import sqlite3

import numpy as np
import shapely
from affine import Affine
from pyproj import CRS

from gisroads.geo import GeoRaster
from gisroads.io.raster import write_geotiff
from gisroads.io.vector import read_layer

BLOCK_M, ROAD_M = 100.0, 15.0
PERIOD = BLOCK_M + ROAD_M
SIZE_M = 3 * BLOCK_M + 4 * ROAD_M
X0, Y0 = 500000.0, 4500000.0


def probability_grid(path):
    """3 x 3 blocks of 100 m, roads of 15 m with probability 1, noise up to 0.1 elsewhere;
    the road between the two western blocks of the top row is missing."""
    centre = np.arange(SIZE_M) + 0.5
    values = np.random.default_rng(0).uniform(0.0, 0.1, (len(centre), len(centre)))
    road = centre % PERIOD < ROAD_M
    values[road, :] = 1.0
    values[:, road] = 1.0
    gap_rows = (centre >= ROAD_M) & (centre < PERIOD)
    gap_cols = (centre >= PERIOD) & (centre < PERIOD + ROAD_M)
    values[np.ix_(gap_rows, gap_cols)] = 0.05
    return write_geotiff(path, GeoRaster(values.astype("float32"),
                                         Affine(1.0, 0, X0, 0, -1.0, Y0 + SIZE_M),
                                         CRS.from_epsg(32633)))


def test_city_blocks_separates_the_blocks_of_a_missed_road(qgis_process, tmp_path):
    out = tmp_path / "blocks.gpkg"
    result = qgis_process.run("cityblocks", INPUT=probability_grid(tmp_path / "p.tif"),
                              OUTPUT=out)
    assert result["N_BLOCKS"] == 9
    blocks = read_layer(out, "city_blocks")
    assert len(blocks) == 9 and blocks.crs.to_epsg() == 32633
    top = Y0 + SIZE_M - ROAD_M - BLOCK_M / 2
    west = blocks[blocks.contains(shapely.Point(X0 + ROAD_M + BLOCK_M / 2, top))]
    east = blocks[blocks.contains(shapely.Point(X0 + PERIOD + ROAD_M + BLOCK_M / 2, top))]
    assert len(west) == len(east) == 1
    assert west.block_id.iloc[0] != east.block_id.iloc[0]
    assert blocks.area_m2.between(9000, 12000).all()
    with sqlite3.connect(out) as con:
        assert con.execute("SELECT count(*) FROM layer_styles WHERE f_table_name = "
                           "'city_blocks'").fetchone()[0] == 1


def test_city_blocks_refuses_a_raster_without_data(qgis_process, tmp_path):
    nan = write_geotiff(tmp_path / "nan.tif", GeoRaster(
        np.full((50, 50), np.nan, "float32"), Affine(1.0, 0, X0, 0, -1.0, Y0),
        CRS.from_epsg(32633)))
    result = qgis_process("run", "gisroads:cityblocks", "--", f"INPUT={nan}",
                          f"OUTPUT={tmp_path / 'out.gpkg'}", check=False)
    assert result.returncode == 1
    assert "nan" in (result.stdout + result.stderr).lower()
    assert not (tmp_path / "out.gpkg").exists()


def test_city_blocks_is_listed_with_help_for_every_parameter(qgis_process):
    described = json.loads(qgis_process("--json", "help", "gisroads:cityblocks").stdout)
    details = described["algorithm_details"]
    assert details["name"] == "City blocks (normalized cut)" and details["group"] == "LiDAR"
    assert len(details["short_description"]) > 30
    assert set(described["parameters"]) == {"INPUT", "POINTS", "BLOCKS", "SPACING",
                                            "MAX_EDGE", "OUTPUT"}
    for name, spec in described["parameters"].items():
        assert spec.get("help"), name
