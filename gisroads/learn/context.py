"""Auto-context: a road probability re-scored from its own shape around each pixel.

Beyond the papers. A per-pixel classifier sees each pixel with its colour and
texture, but not whether the probability it gives forms a long, narrow band, which is what
a road is and what a driveway, a roof or a field margin is not. Following Tu and Bai's
auto-context (IEEE PAMI 32(10), 2010), a second model of boosted trees takes as features
only the first probability and its shape (:func:`context_features`: its Gaussian means over
1-8 m and its oriented line means over 24 m, 48 m and 96 m, as
:func:`~gisroads.learn.features.line_features` computes them on the image's intensity) and
gives the road probability again (:func:`context_probability`). It sees no colour, so it
carries across sensors better than the first model. It is trained on probabilities the
first stage gives on training tiles it was not trained on (out-of-fold), so that it learns
the first stage's errors as they are on unseen images (``scripts/train_context_model.py``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import GisroadsError
from ..geo import GeoRaster
from . import features as ft
from .model import RoadModel, load_model, sigmoid

#: Gaussian means of the probability, sigma in metres.
SMOOTHING_M = (1.0, 2.0, 4.0, 8.0)
#: Oriented line means of the probability, line lengths in metres: 96 m as well as the image
#: model's 24 m and 48 m lifted the default path's quality on the 13 benchmark images from
#: 0.324 to 0.353 (0.360 with another training seed).
LINE_LENGTHS_M = (24.0, 48.0, 96.0)
#: The context model predicts every second pixel of the working grid's rows and columns
#: (:func:`context_probability`): on the 13 benchmark images the default path's quality was
#: 0.324 against 0.316 predicting every pixel (the context model's first version, lines over
#: 24 m and 48 m), in a quarter of the trees' time.
STRIDE = 2
DEFAULT_CONTEXT_MODEL_PATH = (Path(__file__).resolve().parent / "models"
                              / "default_context_model.npz")


def context_feature_names() -> tuple[str, ...]:
    """Names of the features :func:`context_features` returns, in order."""
    return ("context_probability", *(f"context_mean_{s:g}m" for s in SMOOTHING_M),
            *(f"context_{name}" for name in ft.line_feature_names(
                extremes=True, lengths_m=LINE_LENGTHS_M)))


def context_halo_px(pixel_m: float) -> int:
    """Pixels (at ``pixel_m``) the context features reach beyond their own pixel."""
    reach_m = max(ft.TRUNCATE * max(SMOOTHING_M),
                  max(LINE_LENGTHS_M) / 2 + max(ft.LINE_OFFSETS_M))
    return int(np.ceil(reach_m / pixel_m)) + 2


def context_features(probability: np.ndarray, pixel_m: float) -> np.ndarray:
    """The features of :func:`context_feature_names` for every pixel of a probability.

    Parameters
    ----------
    probability : ndarray, shape (rows, cols)
        Road probability in [0, 1]; NaN (no data) counts as 0.
    pixel_m : float
        Pixel side, metres.

    Returns
    -------
    ndarray of float32, shape (n_features, rows, cols)
    """
    p = np.nan_to_num(np.asarray(probability, np.float32), nan=0.0)
    means = [ft._gaussian(p, s / pixel_m) for s in SMOOTHING_M]
    lines = ft.line_features(p, pixel_m, extremes=True, lengths_m=LINE_LENGTHS_M)
    return np.stack([p, *means, *lines]).astype(np.float32, copy=False)


def load_context_model(path=None) -> RoadModel:
    """The bundled context model (``path`` None) or one written by
    :func:`~gisroads.learn.model.save_model` (see :func:`~gisroads.learn.model.load_model`)."""
    return load_model(DEFAULT_CONTEXT_MODEL_PATH if path is None else path,
                      feature_names=context_feature_names())


def context_probability(probability: GeoRaster, model: RoadModel | None = None, *,
                        stride: int = STRIDE, tile_px: int = 512) -> GeoRaster:
    """The road probability given again by a context model, tile by tile.

    Parameters
    ----------
    probability : GeoRaster
        A road probability in [0, 1] (NaN or the raster's nodata where there is no data)
        in a projected metre CRS, e.g. :func:`~gisroads.learn.model.predict_probability`'s.
        Rasters finer than :data:`~gisroads.learn.features.WORK_PIXEL_M` are read
        block-averaged, as the image is.
    model : RoadModel, optional
        Default: the bundled context model (:func:`load_context_model`).
    stride : int
        The model predicts every ``stride``-th pixel of the working grid's rows and columns,
        each value standing for its ``stride`` x ``stride`` block (a pixel without data
        keeps NaN); 1 predicts every pixel. Default :data:`STRIDE`.
    tile_px : int
        Tile side on the working grid (rounded up to a multiple of ``stride``); tiles
        overlap by the features' reach, so the result does not depend on it.

    Returns
    -------
    GeoRaster
        float32 probabilities on the input's grid, NaN where it has no data.

    Raises
    ------
    ValueError
        A probability outside [0, 1], a multi-band raster or a model of other features.
    """
    model = load_context_model() if model is None else model
    if model.feature_names != context_feature_names():
        raise GisroadsError("the model was not trained on context features")
    data = np.asarray(probability.data)
    if data.ndim == 3:
        if data.shape[0] != 1:
            raise GisroadsError("the probability must have one band")
        data = data[0]
    data = data.astype(np.float32)
    valid = np.isfinite(data)
    if probability.nodata is not None and not np.isnan(probability.nodata):
        valid &= data != probability.nodata
    if valid.any() and (data[valid].min() < 0 or data[valid].max() > 1):
        raise GisroadsError("the probability must lie in [0, 1] (scale a 0-255 raster first)")
    factor = ft.work_factor(ft.metric_pixel_size(probability))
    pixel_m = probability.pixel_size * factor
    (work,), work_valid = ft.block_mean(data[None], valid, factor)
    rows, cols = work.shape
    halo = context_halo_px(pixel_m)
    tile_px = -(-tile_px // stride) * stride
    log_odds = np.full(work.shape, np.nan)
    for r0 in range(0, rows, tile_px):
        for c0 in range(0, cols, tile_px):
            r1, c1 = min(r0 + tile_px, rows), min(c0 + tile_px, cols)
            h0, k0 = max(0, r0 - halo), max(0, c0 - halo)
            values = context_features(work[h0:min(rows, r1 + halo), k0:min(cols, c1 + halo)],
                                      pixel_m)[:, r0 - h0:r1 - h0:stride, c0 - k0:c1 - k0:stride]
            sampled = work_valid[r0:r1:stride, c0:c1:stride]
            decision = np.full(sampled.shape, np.nan)
            decision[sampled] = model.decision(values[:, sampled])
            blocks = np.repeat(np.repeat(decision, stride, 0), stride, 1)
            log_odds[r0:r1, c0:c1] = blocks[:r1 - r0, :c1 - c0]
    out = sigmoid(log_odds).astype(np.float32)
    if factor > 1:
        out = np.repeat(np.repeat(out, factor, axis=0), factor, axis=1)[:data.shape[0],
                                                                        :data.shape[1]]
    return GeoRaster(np.where(valid, out, np.float32(np.nan)), probability.transform,
                     probability.crs, float("nan"))
