import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import CRS

from gisroads.geo import GeoRaster
from gisroads.io.raster import RasterError, raster_info, read_raster, write_geotiff

MASSACHUSETTS_PNG = "imagery/massachusetts/images/10078660_15.png"


def test_geotiff_round_trip_keeps_georeferencing(tmp_path):
    data = np.arange(2 * 300 * 400, dtype=np.float32).reshape(2, 300, 400)
    data[0, 0, 0] = np.nan
    transform = Affine(0.5, 0, 277750.0, 0, -0.5, 6122500.0)
    path = write_geotiff(tmp_path / "r.tif", GeoRaster(data, transform, CRS("EPSG:32754")),
                         band_names=["a", "b"])
    back = read_raster(path)
    assert back.transform == transform and back.crs.to_epsg() == 32754
    np.testing.assert_array_equal(back.data, data)
    info = raster_info(path)
    assert info["band_names"] == ["a", "b"] and info["pixel_size"] == [0.5, 0.5]
    with rasterio.open(path) as src:
        assert src.profile["tiled"] and src.compression.name == "deflate"


def test_plain_png_needs_pixel_size_and_crs(shared_data):
    path = shared_data / MASSACHUSETTS_PNG
    with pytest.raises(RasterError, match="no georeferencing"):
        read_raster(path)
    with pytest.raises(RasterError, match="both"):
        read_raster(path, pixel_size=1.0)
    r = read_raster(path, pixel_size=1.0, crs="EPSG:26986", origin=(200000.0, 900000.0))
    assert r.data.shape == (3, 1500, 1500)
    assert r.bounds == (200000.0, 898500.0, 201500.0, 900000.0)


def test_all_nan_raster_is_refused(tmp_path):
    path = write_geotiff(tmp_path / "nan.tif",
                         GeoRaster(np.full((10, 10), np.nan, np.float32),
                                   Affine(1, 0, 0, 0, -1, 10), CRS("EPSG:32633")))
    with pytest.raises(RasterError, match="NaN"):
        read_raster(path)


def test_unreadable_raster(tmp_path):
    (tmp_path / "x.tif").write_bytes(b"garbage" * 50)
    with pytest.raises(RasterError, match="not a readable raster"):
        read_raster(tmp_path / "x.tif")
    for read in (read_raster, raster_info):
        with pytest.raises(RasterError, match="missing.tif: no such file$"):
            read(tmp_path / "missing.tif")
