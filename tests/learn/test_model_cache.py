"""Features computed once per image: the work grid's feature cache and the adapted
probability, equal to the adapted model predicted from scratch."""
from dataclasses import replace

import numpy as np
import pytest

from gisroads.learn import features as ft
from gisroads.learn import model as rm
from gisroads.learn.training import adapt_to_image, adapted_probability, fit_to_image

pytest.importorskip("sklearn")

ADAPT = dict(samples=6000, max_iter=20)
"""A small adaptation (the defaults fit 40 000 samples with 30 trees)."""


@pytest.fixture()
def feature_calls(monkeypatch):
    """Counts the calls of :func:`gisroads.learn.features.compute_features`."""
    calls = []
    compute = ft.compute_features

    def counted(*args, **kwargs):
        calls.append(args[0].shape)
        return compute(*args, **kwargs)

    monkeypatch.setattr(ft, "compute_features", counted)
    return calls


@pytest.fixture(scope="module")
def holed_image(scene_image):
    """The scene image with a no-data corner, so that some tiles are partly empty."""
    _, image = scene_image
    data = image.data.copy()
    data[:, :90, :130] = 0
    return replace(image, data=data, nodata=0)


def test_cached_features_are_computed_once_and_equal(holed_image, feature_calls):
    cached = rm.WorkGrid(holed_image, cache_mb=64)
    plain = rm.WorkGrid(holed_image)
    first = cached.features(0, 128, 128, 256)
    again = cached.features(0, 128, 128, 256)
    assert len(feature_calls) == 1 and again[0] is first[0]
    expected = plain.features(0, 128, 128, 256)
    np.testing.assert_array_equal(first[0], expected[0])
    np.testing.assert_array_equal(first[1], expected[1])
    assert not first[0].flags.writeable and not first[1].flags.writeable
    # the uncached grid computes it every time
    plain.features(0, 128, 128, 256)
    assert len(feature_calls) == 3


def test_the_cache_keeps_no_more_than_its_budget(holed_image, feature_calls):
    window_mb = len(ft.feature_names()) * 128 * 128 * 4 / 2 ** 20
    grid = rm.WorkGrid(holed_image, cache_mb=1.5 * window_mb)
    for _ in range(2):
        grid.features(0, 128, 0, 128)    # kept
        grid.features(128, 256, 0, 128)  # past the budget: computed again
    assert len(feature_calls) == 3
    assert len(grid._cache) == 1


def test_adapted_probability_equals_the_adapted_model_predicted(holed_image, scene_model,
                                                                 feature_calls):
    """The default path's shortcut (features once, the model's log-odds reused) gives the
    probability of the blended model predicted from scratch, where the adaptation fits a
    model and where it keeps the model as it is."""
    image = holed_image
    tiles = len(list(rm.WorkGrid(image).tiles(128)))
    # a model trained on a road layer keeps its share by default (LAYER_MODEL_WEIGHT 0.75)
    fast = adapted_probability(image, scene_model, tile_px=128, **ADAPT).data
    assert len(feature_calls) == tiles  # once per tile, not three times
    adapted = adapt_to_image(image, scene_model, tile_px=128, **ADAPT)
    assert adapted.n_trees == scene_model.n_trees + ADAPT["max_iter"]
    slow = rm.predict_probability(image, adapted, tile_px=128).data
    plain = rm.predict_probability(image, scene_model, tile_px=128).data
    nodata = (image.data == 0).all(axis=0)
    assert fast.dtype == np.float32 and np.isnan(fast[nodata]).all()
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(slow))
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-6)
    assert np.nanmax(np.abs(fast - plain)) > 0.1  # the adaptation changed the probability
    # no road-like pixel: no adaptation, the model's own probability
    kept = adapted_probability(image, scene_model, tile_px=128, weight=0.75,
                               road_like=np.zeros(image.shape, bool), **ADAPT).data
    np.testing.assert_allclose(kept, plain, rtol=0, atol=1e-6)


def test_default_adaptation_is_the_own_model_fitted_on_samples_chosen_every_second_pixel(
        holed_image, scene_model, feature_calls, monkeypatch):
    """Weight 1 (the default for the bundled model): the image's own model alone, its samples
    chosen from the
    bundled model's log-odds on every second pixel, which the bundled model's trees see
    alone; features once per tile; without an own model, the bundled model's probability
    at every pixel."""
    image = holed_image
    tiles = len(list(rm.WorkGrid(image).tiles(128)))
    predicted = []
    decision = rm.RoadModel.decision

    def counted(model, X):
        predicted.append((model.n_trees, X.shape[1]))
        return decision(model, X)

    monkeypatch.setattr(rm.RoadModel, "decision", counted)
    fast = adapted_probability(image, scene_model, tile_px=128, weight=1.0, **ADAPT).data
    assert len(feature_calls) == tiles
    grid = rm.WorkGrid(image)
    valid = sum(grid.features(*t)[1].sum() for t in grid.tiles(128))
    bundled = sum(n for trees, n in predicted if trees == scene_model.n_trees)
    own = sum(n for trees, n in predicted if trees == ADAPT["max_iter"])
    assert bundled == pytest.approx(valid / 4, rel=0.05)  # every second row and column
    assert own == valid  # the own model predicts every pixel
    # the own model's probability: refitted on the same samples, predicted from scratch
    selection = rm.sigmoid(rm.work_decision(grid, scene_model, tile_px=128, stride=2))
    refit = fit_to_image(grid, selection.astype(np.float32), scene_model, tile_px=128, **ADAPT)
    slow = rm.predict_probability(image, refit, tile_px=128).data
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-6)
    plain = rm.predict_probability(image, scene_model, tile_px=128).data
    assert np.nanmax(np.abs(fast - plain)) > 0.1
    kept = adapted_probability(image, scene_model, tile_px=128, weight=1.0,
                               road_like=np.zeros(image.shape, bool), **ADAPT).data
    np.testing.assert_allclose(kept, plain, rtol=0, atol=1e-6)
