"""Learned road cue: per-pixel features in metres, boosted trees evaluated with numpy.

:mod:`.features` computes the features; :mod:`.model` trains (scikit-learn), exports,
saves, loads and applies the model tile by tile (numpy only); :mod:`.training` samples
training pixels from labelled tiles, from a road layer over the user's own image, or from
an image's own most confident pixels; :mod:`.context` re-scores a probability from its own
shape (auto-context); :mod:`.scores` scores a probability raster.
"""
from .context import context_probability, load_context_model
from .model import (DEFAULT_MODEL_PATH, RoadModel, fit_model, load_model,
                    predict_probability, save_model)
from .training import adapt_to_image, adapted_probability, train_from_layer

__all__ = ["DEFAULT_MODEL_PATH", "RoadModel", "adapt_to_image", "adapted_probability",
           "context_probability", "fit_model", "load_context_model", "load_model",
           "predict_probability", "save_model", "train_from_layer"]
