"""'Road raster to network' through qgis_process: a geographic 8-bit mask with a cut T."""
import geopandas as gpd
import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from gisroads.io.vector import list_layers


def write_mask(path, mask, transform, crs):
    with rasterio.open(path, "w", driver="GTiff", width=mask.shape[1], height=mask.shape[0],
                       count=1, dtype="uint8", crs=crs, transform=transform, nodata=None) as dst:
        dst.write(mask, 1)
    return path


def t_mask():
    """A T of 8 m roads at 0.5 m pixels, the stem cut by a 6 m gap (0-255 values)."""
    mask = np.zeros((400, 400), np.uint8)
    mask[192:208, :] = 255
    mask[200:, 192:208] = 255
    mask[290:302, 192:208] = 0
    return mask


def test_geographic_mask_gives_one_t_junction_and_closes_the_cut(qgis_process, tmp_path):
    # about 0.5 m pixels near 45 N, in degrees
    raster = write_mask(tmp_path / "roads.tif", t_mask(),
                        from_origin(15.0, 45.0, 0.5 / 78_850, 0.5 / 111_130), "EPSG:4326")
    out = tmp_path / "network.gpkg"
    result = qgis_process.run("roadrastertonetwork", INPUT=raster, THRESHOLD=0.5, OUTPUT=out)
    # the raster's cut repair closes the 6 m cut before the skeleton (no gap edge left to
    # bridge); an open cut would leave the stem's far piece as a fourth road
    assert result["JUNCTIONS"] == 1 and result["GAPS_BRIDGED"] == 0
    assert result["ROADS"] == 3
    assert result["LENGTH_M"] == pytest.approx(300.0, rel=0.05)
    assert set(list_layers(out)) >= {"road_centrelines", "road_polygons", "junctions",
                                     "gap_edges", "junction_connections", "rejected"}
    centrelines = gpd.read_file(out, layer="road_centrelines")
    assert centrelines.crs == "EPSG:4326"                     # back in the raster's CRS
    np.testing.assert_allclose(centrelines.width_m, 8.0, atol=1.0)
    assert gpd.read_file(out, layer="junctions").degree.tolist() == [3]


def test_raster_without_roads_gives_empty_layers_and_a_warning(qgis_process, tmp_path):
    raster = write_mask(tmp_path / "empty.tif", np.zeros((100, 100), np.uint8),
                        from_origin(500000, 4500000, 1.0, 1.0), "EPSG:32633")
    out = tmp_path / "empty.gpkg"
    completed = qgis_process("--json", "run", "gisroads:roadrastertonetwork", "--",
                             f"INPUT={raster}", f"OUTPUT={out}")
    assert "no road found" in completed.stdout + completed.stderr
    assert len(gpd.read_file(out, layer="road_centrelines")) == 0


def test_wide_areas_give_the_street_through_a_car_park(qgis_process, tmp_path):
    """WIDE_AREAS: the street alone, not the car park's outline and aisles (one road
    against five or more without it)."""
    from gisroads.io.raster import write_geotiff
    from tests.network.test_areas import _street_with_car_park

    raster = write_geotiff(tmp_path / "p.tif", _street_with_car_park(access=True))
    plain = qgis_process.run("roadrastertonetwork", INPUT=raster, OUTPUT=tmp_path / "a.gpkg")
    areas = qgis_process.run("roadrastertonetwork", INPUT=raster, WIDE_AREAS=True,
                             OUTPUT=tmp_path / "b.gpkg")
    assert plain["ROADS"] >= 5
    assert areas["ROADS"] == 1 and 135 < areas["LENGTH_M"] < 160
