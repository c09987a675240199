"""The numpy road model: equal to scikit-learn, safe to load, the same tiled or not."""
import numpy as np
import pytest
from affine import Affine

from gisroads.geo import GeoRaster
from gisroads.learn import features as ft
from gisroads.learn import model as rm

from .conftest import scene_samples

N_FEATURES = len(ft.feature_names())


@pytest.fixture(scope="module")
def fitted():
    sklearn = pytest.importorskip("sklearn.ensemble")
    X, y = scene_samples(N_FEATURES)
    classifier = sklearn.HistGradientBoostingClassifier(
        max_iter=40, max_leaf_nodes=15, min_samples_leaf=20, early_stopping=False,
        random_state=0).fit(X.T, y)
    return classifier, rm.from_sklearn(classifier, ft.feature_names()), X


def test_numpy_prediction_equals_scikit_learn(fitted):
    classifier, model, X = fitted
    expected = classifier.predict_proba(X.T)[:, 1]
    np.testing.assert_allclose(model.predict(X), expected, rtol=0, atol=1e-6)
    # NaN features follow the trees' missing-value branches
    assert np.isnan(X).any()
    assert model.n_trees == 40


def test_fit_model_is_seeded_and_exported(fitted):
    X, y = scene_samples(N_FEATURES, n=3000, seed=1)
    first = rm.fit_model(X, y, max_iter=10, min_samples_leaf=20, seed=3)
    second = rm.fit_model(X, y, max_iter=10, min_samples_leaf=20, seed=3)
    np.testing.assert_array_equal(first.predict(X), second.predict(X))
    assert first.metadata["parameters"]["seed"] == 3 and first.metadata["samples"] == 3000
    with pytest.raises(ValueError, match="both"):
        rm.fit_model(X, np.ones(len(y), bool))


def test_saved_model_predicts_identically(fitted, tmp_path):
    _, model, X = fitted
    path = rm.save_model(rm.with_metadata(model, note="test"), tmp_path / "m.npz")
    loaded = rm.load_model(path)
    np.testing.assert_array_equal(loaded.predict(X), model.predict(X))
    assert loaded.metadata == {"note": "test"}
    assert loaded.feature_names == ft.feature_names()


def _rewrite(path, **changes):
    with np.load(path, allow_pickle=False) as archive:
        arrays = {k: archive[k] for k in archive.files}
    arrays.update(changes)
    np.savez(path, **arrays)


def test_bad_model_files_are_refused(fitted, tmp_path):
    _, model, _ = fitted
    path = rm.save_model(model, tmp_path / "m.npz")
    _rewrite(path, version=np.array(rm.MODEL_VERSION + 1))
    with pytest.raises(ValueError, match="version"):
        rm.load_model(path)
    path = rm.save_model(model, tmp_path / "m.npz")
    _rewrite(path, scales_m=np.array([1.0]))
    with pytest.raises(ValueError, match="other features"):
        rm.load_model(path)
    path = rm.save_model(model, tmp_path / "m.npz")
    left = model.left.copy()
    left[model.roots[0]] = len(left) + 5
    _rewrite(path, left=left)
    with pytest.raises(ValueError, match="outside"):
        rm.load_model(path)
    path = rm.save_model(model, tmp_path / "m.npz")
    left = model.left.copy()
    left[model.roots[0] + 1] = model.roots[0]  # a child pointing back at its root: a loop
    _rewrite(path, left=left)
    with pytest.raises(ValueError, match="deeper|invalid"):
        rm.load_model(path)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, format=np.array([{"evil": 1}], dtype=object))
    with pytest.raises(ValueError, match="not a road model"):
        rm.load_model(pickled)
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(ValueError, match="not a road model"):
        rm.load_model(tmp_path / "text.npz")
    with pytest.raises(FileNotFoundError):
        rm.load_model(tmp_path / "missing.npz")


def test_blend_is_weighted_log_odds(fitted):
    _, model, X = fitted
    other = rm.RoadModel(**{**model.__dict__, "value": -model.value,
                            "baseline": -model.baseline})
    blend = rm.blend_models(model, other, 0.25)
    np.testing.assert_allclose(blend.decision(X), 0.5 * model.decision(X), atol=1e-9)


def _image(pixel_m, shape=(3, 333, 301), seed=0):
    rng = np.random.default_rng(seed)
    data = rng.integers(60, 200, shape).astype(np.uint8)
    data[:, 100:120, :] = 80  # a road
    data[:, :30, :50] = 0     # no data
    return GeoRaster(data, Affine(pixel_m, 0, 500000, 0, -pixel_m, 4500100), "EPSG:32633", 0)


@pytest.mark.parametrize("pixel_m", [0.5, 0.25])
def test_tiled_prediction_equals_untiled(fitted, pixel_m):
    _, model, _ = fitted
    image = _image(pixel_m)
    whole = rm.predict_probability(image, model, tile_px=1000).data
    tiled = rm.predict_probability(image, model, tile_px=64).data
    assert whole.dtype == np.float32 and whole.shape == image.shape
    nodata = (image.data == 0).all(axis=0)
    assert np.isnan(whole[nodata]).all() and np.isfinite(whole[~nodata]).all()
    assert np.nanmin(whole) >= 0 and np.nanmax(whole) <= 1
    np.testing.assert_allclose(tiled, whole, rtol=0, atol=1e-5)


def test_default_model_is_bundled_and_small():
    assert rm.DEFAULT_MODEL_PATH.stat().st_size < 2e6
    model = rm.load_model()
    assert model.n_trees > 0 and "ETH" in model.metadata["data"]
    card = rm.DEFAULT_MODEL_PATH.with_suffix(".md").read_text()
    assert "pixel AUC" in card and "massachusetts" in card
    probability = rm.predict_probability(_image(0.6, shape=(3, 120, 100)), model)
    assert np.nanmax(probability.data) <= 1 and np.isnan(probability.data[0, 0])


def test_non_metric_image_is_refused(fitted):
    _, model, _ = fitted
    image = GeoRaster(np.zeros((3, 20, 20), np.uint8), Affine(1e-5, 0, 2, 0, -1e-5, 48),
                      "EPSG:4326")
    with pytest.raises(ValueError, match="projected"):
        rm.predict_probability(image, model)
