import numpy as np
import pytest
from affine import Affine

from gisroads.geo import GeoRaster
from gisroads.imagery.cues import (cues_used, excess_green, ground_surface, image_cues,
                                   intensity, ndvi, normalised_dsm, resample_to, saturation,
                                   scale_bands)

CRS = "EPSG:32633"
T = Affine(0.5, 0, 500000.0, 0, -0.5, 4500100.0)


def _rgb(seed=0, shape=(60, 80)):
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, (3, *shape)).astype(np.uint8)


def test_8_and_16_bit_give_the_same_intensity():
    eight = _rgb()
    sixteen = eight.astype(np.uint16) * 257  # the same picture stored on 16 bits
    a = intensity(GeoRaster(eight, T, CRS))
    b = intensity(GeoRaster(sixteen, T, CRS))
    np.testing.assert_allclose(a, b, atol=1e-6)
    assert 0.0 <= a.min() and a.max() <= 1.0 and a.std() > 0.05
    # an 11-bit sensor in a 16-bit file: same picture, same cue
    eleven = (eight.astype(np.uint16) * 8 + 3)
    np.testing.assert_allclose(intensity(GeoRaster(eleven, T, CRS)), a, atol=1e-6)


def test_scaling_maps_percentiles_to_0_and_1_and_keeps_nodata():
    band = np.arange(101, dtype=np.float32).reshape(1, 1, 101)
    band[0, 0, 50] = np.nan
    scaled = scale_bands(GeoRaster(band, T, CRS), percentiles=(0, 100))
    assert scaled[0, 0, 0] == 0.0 and scaled[0, 0, 100] == 1.0
    assert scaled[0, 0, 25] == pytest.approx(0.25)
    assert np.isnan(scaled[0, 0, 50])
    with pytest.raises(ValueError, match="no valid pixel"):
        scale_bands(GeoRaster(np.full((1, 2, 2), np.nan), T, CRS))


def test_intensity_leaves_the_nir_band_out_and_works_on_pan():
    rgbn = np.zeros((4, 10, 10), np.uint8)
    rgbn[:3, :, :5] = 50
    rgbn[:3, :, 5:] = 150
    rgbn[3] = np.random.default_rng(1).integers(0, 256, (10, 10))
    lit = intensity(GeoRaster(rgbn, T, CRS), nir_band=4)
    assert set(np.unique(lit)) == {0.0, 1.0}  # NIR noise would blur the two halves
    pan = intensity(GeoRaster(rgbn[0], T, CRS))
    np.testing.assert_array_equal(pan, lit)
    with pytest.raises(ValueError, match="NIR band 5 does not exist"):
        intensity(GeoRaster(rgbn, T, CRS), nir_band=5)


def test_ndvi_exact_values_and_band_defaults():
    rgbn = np.zeros((4, 1, 3), np.uint8)
    rgbn[0] = [[60, 100, 0]]   # red
    rgbn[3] = [[180, 100, 0]]  # nir
    index = ndvi(GeoRaster(rgbn, T, CRS), nir_band=4)
    np.testing.assert_allclose(index[0, :2], [0.5, 0.0])
    assert np.isnan(index[0, 2])  # 0 / 0
    cir = rgbn[[3, 0, 1]]  # NIR, R, G: red is band 2
    np.testing.assert_array_equal(ndvi(GeoRaster(cir, T, CRS), nir_band=1), index)
    with pytest.raises(ValueError, match="same band"):
        ndvi(GeoRaster(rgbn, T, CRS), nir_band=1, red_band=1)


def test_excess_green_exact_values_and_scale_invariance():
    rgb = np.array([[[80, 86, 0]], [[112, 88, 0]], [[52, 91, 0]]], np.uint8)  # grass, asphalt
    index = excess_green(GeoRaster(rgb, T, CRS))
    np.testing.assert_allclose(index[0, :2], [92 / 244, -1 / 265], rtol=1e-6)
    assert np.isnan(index[0, 2])  # black
    sixteen = excess_green(GeoRaster(rgb.astype(np.uint16) * 257, T, CRS))
    np.testing.assert_allclose(sixteen, index, rtol=1e-6)
    with pytest.raises(ValueError, match="blue band 3 does not exist"):
        excess_green(GeoRaster(rgb[:2], T, CRS))


def test_saturation_exact_values_scale_invariance_and_only_for_rgb():
    rgb = np.array([[[80, 86, 200]], [[112, 88, 40]], [[52, 91, 40]]], np.uint8)
    value = saturation(GeoRaster(rgb, T, CRS))  # grass, asphalt, a red roof
    np.testing.assert_allclose(value[0], [60 / 112, 5 / 91, 160 / 200], rtol=1e-6)
    sixteen = saturation(GeoRaster(rgb.astype(np.uint16) * 257, T, CRS))
    np.testing.assert_allclose(sixteen, value, rtol=1e-5)
    np.testing.assert_array_equal(image_cues(GeoRaster(rgb, T, CRS)).saturation, value)
    assert image_cues(GeoRaster(rgb, T, CRS), nir_band=1).saturation is None
    assert image_cues(GeoRaster(rgb[0], T, CRS)).saturation is None
    with pytest.raises(ValueError, match="band 3 does not exist"):
        saturation(GeoRaster(rgb[:2], T, CRS))


def test_ground_surface_removes_buildings_and_keeps_slopes_and_plateaus():
    rows, cols = np.mgrid[0:200, 0:200]
    terrain = 100.0 + 0.05 * cols * 0.5          # 5 % slope
    terrain[:40] += 8.0                           # a plateau 20 m deep along the top
    dsm = terrain.copy()
    dsm[100:140, 60:100] += 9.0                  # a 20 x 20 m building
    dsm[150:160, 150:160] += 12.0                # a 5 x 5 m tree
    ground = ground_surface(dsm, 0.5, window_m=30.0, cell_m=1.0)
    height = dsm - ground
    assert np.all(height >= -1e-4)               # an opening never rises above the DSM
    assert np.median(height[100:140, 60:100]) == pytest.approx(9.0, abs=0.1)
    assert np.median(height[150:160, 150:160]) == pytest.approx(12.0, abs=0.1)
    free = np.ones_like(dsm, bool)
    free[96:144, 56:104] = free[146:164, 146:164] = False
    free[36:44] = False                          # the plateau edge, within one block
    free[:, -30:] = False   # half a window from the uphill edge: see ground_surface
    assert np.percentile(np.abs(height[free]), 99) < 0.1


def test_normalised_dsm_is_resampled_to_the_image_grid():
    dsm = np.full((100, 100), 50.0, np.float32)  # 1 m cells
    dsm[40:60, 40:60] = 57.0                     # a 20 m square building, 7 m high
    dsm_raster = GeoRaster(dsm, Affine(1.0, 0, 500000.0, 0, -1.0, 4500100.0), CRS)
    image = GeoRaster(np.zeros((3, 200, 200), np.uint8), T, CRS)  # 0.5 m, same extent
    height = normalised_dsm(dsm_raster, image, window_m=30.0)
    assert height.shape == (200, 200)
    assert height[100, 100] == pytest.approx(7.0, abs=1e-4)   # roof centre
    assert height[20, 20] == pytest.approx(0.0, abs=1e-4)     # open ground
    # the roof edge (x = 40 m) falls between image rows/cols 79 and 80
    assert height[100, 78] == pytest.approx(0.0, abs=1e-4)
    assert height[100, 81] == pytest.approx(7.0, abs=1e-4)
    shifted = GeoRaster(dsm, Affine(1.0, 0, 500010.0, 0, -1.0, 4500100.0), CRS)
    moved = resample_to(shifted, image)
    assert np.isnan(moved[:, :19]).all()                       # west of the shifted DSM
    with pytest.raises(ValueError, match="no valid cell"):
        normalised_dsm(GeoRaster(np.full((5, 5), np.nan), T, CRS), image)


def test_image_cues_record_which_cues_were_used():
    rgbn = np.random.default_rng(2).integers(1, 256, (4, 20, 20)).astype(np.uint8)
    dsm = GeoRaster(np.zeros((20, 20), np.float32), T, CRS)
    full = image_cues(GeoRaster(rgbn, T, CRS), nir_band=4, dsm=dsm)
    assert full.record() == {"cues": "rgb+nir+dsm", "image": "rgb", "bands": 4,
                             "nir_band": 4, "ndvi": True, "dsm": True}
    assert full.ndsm.shape == full.ndvi.shape == (20, 20)
    assert full.exg.shape == (20, 20)  # the NIR band is band 4: bands 1-3 are RGB
    rgb = image_cues(GeoRaster(rgbn[:3], T, CRS))
    assert rgb.record()["cues"] == "rgb" and rgb.exg is not None and rgb.ndvi is None
    cir = image_cues(GeoRaster(rgbn[:3], T, CRS), nir_band=1)
    assert cir.record()["cues"] == "cir+nir" and cir.exg is None
    pan = image_cues(GeoRaster(rgbn[0], T, CRS))
    assert pan.record()["cues"] == "pan" and pan.ndvi is None and pan.ndsm is None
    assert pan.exg is None
    # the same record without computing anything
    assert cues_used(GeoRaster(rgbn, T, CRS), nir_band=4, dsm=dsm) == full.record()
    assert cues_used(GeoRaster(rgbn[0], T, CRS)) == pan.record()
    with pytest.raises(ValueError, match="NIR band 7"):
        cues_used(GeoRaster(rgbn, T, CRS), nir_band=7)
