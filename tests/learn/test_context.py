"""The context model (auto-context, beyond the papers): its features, its tiling, the
bundled model's preference for long narrow bands, and bad input."""
import numpy as np
import pytest
from affine import Affine

from gisroads.geo import GeoRaster
from gisroads.learn import context as cx
from gisroads.learn.model import DEFAULT_MODEL_PATH, load_model


def _probability(pixel_m: float, *, size_m: float = 160.0) -> GeoRaster:
    """0.1 everywhere; a road 6 m wide and 120 m long at 0.7; a 24 m square at 0.7; no
    data in a corner."""
    n = int(round(size_m / pixel_m))
    y, x = (np.mgrid[0:n, 0:n] + 0.5) * pixel_m
    p = np.full((n, n), 0.1, np.float32)
    p[(np.abs(y - 40) <= 3) & (x >= 20) & (x <= 140)] = 0.7
    p[(np.abs(y - 110) <= 12) & (np.abs(x - 80) <= 12)] = 0.7
    p[:int(10 / pixel_m), :int(30 / pixel_m)] = np.nan
    return GeoRaster(p, Affine(pixel_m, 0, 500000, 0, -pixel_m, 4500000), "EPSG:32633",
                     float("nan"))


def test_feature_names_match_the_computed_stack():
    values = cx.context_features(np.random.default_rng(0).random((50, 60)), 1.0)
    assert values.shape == (len(cx.context_feature_names()), 50, 60)
    assert values.dtype == np.float32 and np.isfinite(values).all()
    assert len(set(cx.context_feature_names())) == len(cx.context_feature_names())


@pytest.mark.parametrize("pixel_m", [0.5, 0.25])
def test_tiled_context_equals_untiled(pixel_m):
    probability = _probability(pixel_m)
    whole = cx.context_probability(probability, tile_px=2000).data
    tiled = cx.context_probability(probability, tile_px=50).data
    assert whole.shape == probability.shape and whole.dtype == np.float32
    nodata = np.isnan(probability.data)
    assert np.isnan(whole[nodata]).all() and np.isfinite(whole[~nodata]).all()
    assert np.nanmin(whole) >= 0 and np.nanmax(whole) <= 1
    np.testing.assert_allclose(tiled, whole, rtol=0, atol=1e-5)


def test_bundled_model_prefers_a_long_band_to_a_blob():
    """The first probability is 0.7 on both; the context model gives the road's centre line
    more than the square's centre and far more than the background."""
    pixel_m = 0.5
    out = cx.context_probability(_probability(pixel_m)).data
    at = lambda x, y: out[int(y / pixel_m), int(x / pixel_m)]  # noqa: E731
    road, blob, background = at(80, 40), at(80, 110), at(80, 75)
    assert road > blob + 0.2 and road > 0.5 > background
    # the same numbers in both environments (PyPI's and Debian's numpy and scipy)
    assert (road, blob, background) == pytest.approx((0.854037, 0.271062, 0.031473),
                                                      abs=1e-6)


def test_bundled_context_model_and_card():
    model = cx.load_context_model()
    assert model.feature_names == cx.context_feature_names() and model.n_trees > 0
    assert cx.DEFAULT_CONTEXT_MODEL_PATH.stat().st_size < 1e6
    card = cx.DEFAULT_CONTEXT_MODEL_PATH.with_suffix(".md").read_text()
    assert "out-of-fold" in card.lower() and "pixel AUC" in card


def test_bad_input_is_refused():
    probability = _probability(1.0)
    scaled = GeoRaster(probability.data * 255, probability.transform, probability.crs)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        cx.context_probability(scaled)
    two = GeoRaster(np.stack([probability.data] * 2), probability.transform, probability.crs)
    with pytest.raises(ValueError, match="one band"):
        cx.context_probability(two)
    with pytest.raises(ValueError, match="context features"):
        cx.context_probability(probability, load_model())
    with pytest.raises(ValueError, match="other features"):
        cx.load_context_model(DEFAULT_MODEL_PATH)
    geographic = GeoRaster(probability.data, Affine(1e-5, 0, 2, 0, -1e-5, 48), "EPSG:4326")
    with pytest.raises(ValueError, match="projected"):
        cx.context_probability(geographic)
