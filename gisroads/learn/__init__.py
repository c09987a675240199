"""Learned road cues: a convolutional network applied with onnxruntime (the default), and
boosted trees on per-pixel features in metres evaluated with numpy.

:mod:`.convnet` applies the network (:mod:`.convnet_training` trains and fine-tunes it
with PyTorch, the ``train`` extra, imported only for that); :mod:`.features` computes the
trees' features; :mod:`.model` trains (scikit-learn), exports, saves, loads and applies the
trees tile by tile (numpy only); :mod:`.training` samples training pixels from labelled
tiles, from a road layer over the user's own image, or from an image's own most confident
pixels; :mod:`.context` re-scores a probability from its own shape (auto-context);
:mod:`.scores` scores a probability raster.
"""
from .context import context_probability, load_context_model
from .convnet import ConvNet, convnet_probability, load_convnet
from .model import (DEFAULT_MODEL_PATH, RoadModel, fit_model, load_model,
                    predict_probability, save_model)
from .training import adapt_to_image, adapted_probability, train_from_layer

__all__ = ["DEFAULT_MODEL_PATH", "ConvNet", "RoadModel", "adapt_to_image",
           "adapted_probability", "context_probability", "convnet_probability", "fit_model",
           "load_context_model", "load_convnet", "load_model", "predict_probability",
           "save_model", "train_from_layer"]
