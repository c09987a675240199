"""Scores of a road-probability raster: pixel AUC, and centre lines for buffer metrics."""
from __future__ import annotations

import geopandas as gpd
import numpy as np
from scipy import stats

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..vectorize.skeleton import skeleton_lines


def pixel_auc(probability: np.ndarray, road: np.ndarray, valid: np.ndarray | None = None,
              *, max_pixels: int = 2_000_000) -> float:
    """Area under the ROC curve of probabilities against a road mask (Mann-Whitney U).

    Parameters
    ----------
    probability : ndarray, shape (rows, cols)
        NaN pixels are left out.
    road : ndarray of bool, same shape
    valid : ndarray of bool, optional
        Pixels to score (all finite ones by default).
    max_pixels : int
        At most this many evenly spaced pixels are scored.

    Returns
    -------
    float
        NaN when the scored pixels hold only one class.
    """
    probability = np.asarray(probability, np.float64)
    road = np.asarray(road, bool)
    if probability.shape != road.shape:
        raise GisroadsError(f"probability {probability.shape} and road {road.shape} differ")
    keep = np.isfinite(probability) if valid is None else np.isfinite(probability) & valid
    p, r = probability[keep], road[keep]
    step = max(1, len(p) // max_pixels)
    p, r = p[::step], r[::step]
    n_pos = int(r.sum())
    n_neg = len(r) - n_pos
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    ranks = stats.rankdata(p)
    return float((ranks[r].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def probability_lines(probability: GeoRaster, *, threshold: float = 0.5,
                      min_length_m: float = 0.0) -> gpd.GeoDataFrame:
    """Centre lines of the pixels above ``threshold``: the skeleton of that mask
    (:func:`~gisroads.vectorize.skeleton.skeleton_lines`), with ``width_m``."""
    mask = np.nan_to_num(np.asarray(probability.data, np.float64), nan=0.0) > threshold
    return skeleton_lines(mask, probability.transform, probability.crs,
                          min_length_m=min_length_m, simplify_m=probability.pixel_size)
