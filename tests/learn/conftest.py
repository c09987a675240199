"""A small rendered scene with its roads, and a road model trained on it (shared by the
learn tests)."""
import numpy as np
import pytest

from gisroads.synthetic import make_scene, render_image


@pytest.fixture(scope="session")
def scene_image():
    """A 300 x 300 m synthetic scene rendered at 0.5 m (R, G, B, NIR) and its scene."""
    scene = make_scene(seed=0, size_m=(300.0, 300.0))
    image, _ = render_image(scene, pixel_m=0.5)
    return scene, image


@pytest.fixture(scope="session")
def scene_model(scene_image):
    """A 30-tree model trained on the scene's whole road layer."""
    pytest.importorskip("sklearn")
    from gisroads.learn.training import train_from_layer

    scene, image = scene_image
    return train_from_layer(image, scene.roads, width_field="width_m", samples=8000,
                            max_iter=30, seed=0)


def scene_samples(model_features: int, n: int = 5000, seed: int = 0):
    """Random feature samples with a learnable road label (and some NaNs)."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((model_features, n)).astype(np.float32)
    y = (X[0] + X[1] * X[2] + 0.5 * rng.standard_normal(n)) > 0
    X[3, :200] = np.nan
    return X, y
