"""Features in metres: the same ground gives the same features at any pixel size."""
import numpy as np
import pytest
from affine import Affine
from scipy import ndimage

from gisroads.geo import GeoRaster
from gisroads.learn import features as ft
from gisroads.learn.model import WorkGrid

CRS = "EPSG:32633"


def _stripe(pixel_m: float, width_m: float = 8.0, size_m: float = 120.0, seed: int = 0):
    """A dark horizontal road of ``width_m`` across a bright textured field, RGB uint8."""
    n = int(round(size_m / pixel_m))
    y = (np.arange(n) + 0.5) * pixel_m - size_m / 2
    road = np.abs(y) < width_m / 2
    rng = np.random.default_rng(seed)
    base = np.where(road[:, None], 90.0, 160.0) + rng.normal(0, 3, (n, n))
    rgb = np.stack([base, base * 0.95, base * 0.9]).clip(0, 255).astype(np.uint8)
    return GeoRaster(rgb, Affine(pixel_m, 0, 500000, 0, -pixel_m, 4500000 + size_m), CRS)


def _centre_features(image):
    grid = WorkGrid(image)
    values, _ = grid.features(0, grid.shape[0], 0, grid.shape[1])
    r, c = grid.shape[0] // 2, grid.shape[1] // 2
    return dict(zip(ft.feature_names(), values[:, r, c]))


def test_feature_names_match_the_computed_stack():
    image = _stripe(1.0)
    grid = WorkGrid(image)
    values, valid = grid.features(0, grid.shape[0], 0, grid.shape[1])
    assert values.shape == (len(ft.feature_names()), *grid.shape)
    assert values.dtype == np.float32 and valid.all() and np.isfinite(values).all()


@pytest.mark.parametrize("fine_m", [0.3, 0.5])
def test_features_are_measured_in_metres(fine_m):
    fine, coarse = _centre_features(_stripe(fine_m)), _centre_features(_stripe(1.0))
    for name in ("smooth_2m", "ridge_4m", "valley_4m", "stddev_8m", "contrast",
                 *(n for n in ft.feature_names() if n.startswith("line_"))):
        assert fine[name] == pytest.approx(coarse[name], rel=0.15, abs=0.1), name
    # the dark road is a valley-free ridge of the intensity at its own scale, darker than
    # the parallel lines beside it over 24 and 48 m
    assert fine["ridge_4m"] > 0.5
    assert fine["line_dark_10m_24m"] < -1.0 and fine["line_dark_10m_48m"] < -1.0


@pytest.mark.parametrize("pixel_m", [0.6, 1.0])
def test_doubled_lines_are_running_means_along_the_line(pixel_m):
    """The lines built by doubling equal a plain running mean of their length along a row,
    and the northward lines the eastward ones of the image turned a quarter, away from
    the edges."""
    z = np.random.default_rng(1).standard_normal((170, 170)).astype(np.float32)
    reach = int(max(ft.LINE_LENGTHS_M) / pixel_m)
    core = (slice(reach, -reach), slice(reach, -reach))
    east = ft._line_means(z, pixel_m, 0.0)
    north = ft._line_means(np.rot90(z, 1), pixel_m, np.pi / 2)
    for length_m, (mean, square), (turned, _) in zip(ft.LINE_LENGTHS_M, east, north):
        size = int(round(length_m / pixel_m))
        np.testing.assert_allclose(mean[core], ndimage.uniform_filter1d(z, size)[core],
                                   atol=1e-5)
        np.testing.assert_allclose(square[core],
                                   ndimage.uniform_filter1d(z * z, size)[core], atol=1e-5)
        np.testing.assert_allclose(np.rot90(turned, -1)[core], mean[core], atol=1e-5)


def test_bundled_model_uses_these_features():
    from gisroads.learn.model import load_model

    assert load_model().feature_names == ft.feature_names()


def test_fine_images_are_read_on_a_coarser_work_grid():
    assert ft.work_factor(0.3) == 2 and ft.work_factor(0.5) == 1 and ft.work_factor(1.0) == 1
    grid = WorkGrid(_stripe(0.3))
    assert grid.factor == 2 and grid.pixel_m == pytest.approx(0.6)
    assert grid.shape == (200, 200)


def test_one_band_and_extra_bands():
    rgb = _stripe(1.0)
    pan = GeoRaster(rgb.data[:1], rgb.transform, rgb.crs)
    values = _centre_features(pan)
    assert values["chroma_r_1m"] == pytest.approx(1 / 3) and values["saturation_4m"] == 0
    four = GeoRaster(np.concatenate([rgb.data, rgb.data[:1]]), rgb.transform, rgb.crs)
    assert _centre_features(four) == _centre_features(rgb)


@pytest.mark.parametrize("crs, shape, message", [
    ("EPSG:4326", (3, 50, 50), "projected"),
    (None, (3, 50, 50), "no CRS"),
    ("EPSG:2263", (3, 50, 50), "metre"),  # New York State Plane, US feet
    (CRS, (2, 50, 50), "1-band or 3"),
])
def test_bad_images_are_refused(crs, shape, message):
    image = GeoRaster(np.zeros(shape, np.uint8), Affine(1, 0, 0, 0, -1, 50), crs)
    with pytest.raises(ValueError, match=message):
        WorkGrid(image)


def test_statistics_ignore_nodata():
    image = _stripe(1.0)
    data = image.data.copy()
    data[:, :, :40] = 0
    masked = WorkGrid(GeoRaster(data, image.transform, image.crs, nodata=0))
    plain = WorkGrid(GeoRaster(image.data[:, :, 40:], image.transform, image.crs))
    assert masked.stats.median == pytest.approx(plain.stats.median, rel=0.02)
    np.testing.assert_allclose(masked.stats.band_median, plain.stats.band_median, rtol=0.02)
