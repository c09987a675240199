"""Kerbs: height steps of the ground surface (beyond the papers).

A kerb is a 10-20 cm step between a carriageway and its footway or verge. Seen from the
air, the lowest return of each cell traces the ground surface, and its detail (smoothed at
0.5 m, minus its trend at 3 m) rises across a kerb while a steady slope or a camber stay
flat. The LiDAR road evidence uses the steps to find medians between carriageways
(:mod:`gisroads.lidar.evidence`); the ribbon snakes use them as their attractor's curb term
(:mod:`gisroads.snakes.attractor`), so both read one kerb.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

KERB_GRADIENT = 0.06
"""Rise over run of the ground surface's detail (:func:`kerb_steps`) from which a cell is on
a kerb: on 0.5 m cells a clean step of h metres peaks at about 0.51 h (central differences
over 1 m of the smoothed step), so 0.06 is a 12 cm step."""


def _normalised(values: np.ndarray, known: np.ndarray, sigma_cells: float) -> np.ndarray:
    """Gaussian of the known values over the Gaussian of where they are known (NaN where
    nothing is)."""
    def smooth(array):
        return ndimage.gaussian_filter(array, sigma_cells, mode="constant", truncate=3.0)

    weight = smooth(known.astype(float))
    out = np.full(values.shape, np.nan)
    np.divide(smooth(np.where(known, values, 0.0)), weight, out=out, where=weight > 1e-6)
    return out


def kerb_steps(ground_low: np.ndarray, cell_m: float, *, sigma_m: float = 0.5,
               trend_m: float = 3.0) -> np.ndarray:
    """Height steps of the ground surface: the gradient of its detail.

    The lowest ground return per cell, smoothed at ``sigma_m`` minus its trend at
    ``trend_m`` (normalised convolution, so scan gaps and buildings do not pull it), and the
    magnitude of its gradient: a steady slope gives about 0, a camber little, a kerb of h
    metres a ridge along it (about 0.51 h on 0.5 m cells; :data:`KERB_GRADIENT`).

    Parameters
    ----------
    ground_low : ndarray, shape (rows, cols)
        Lowest ground return per cell, metres; NaN without one.
    cell_m : float
        Cell side, metres.
    sigma_m, trend_m : float
        Detail and trend scales (Gaussian sigma), metres.

    Returns
    -------
    ndarray
        Rise over run per cell; NaN where the ground returns within ``sigma_m`` carry less
        than 0.3 of the smoothing's weight.

    Examples
    --------
    A flat street 0.15 m below its footway, on 0.5 m cells:

    >>> import numpy as np
    >>> from gisroads.features.kerbs import KERB_GRADIENT, kerb_steps
    >>> ground = np.zeros((20, 40))
    >>> ground[:, 20:] = 0.15
    >>> steps = kerb_steps(ground, 0.5)
    >>> bool(steps[10, 19] >= KERB_GRADIENT), bool(steps[10, 5] < 0.01)
    (True, True)
    """
    known = np.isfinite(ground_low)
    detail = max(sigma_m, cell_m) / cell_m
    weight = ndimage.gaussian_filter(known.astype(float), detail, mode="constant",
                                     truncate=3.0)
    surface = (_normalised(ground_low, known, detail)
               - _normalised(ground_low, known, trend_m / cell_m))
    gy, gx = np.gradient(surface, cell_m)
    steps = np.hypot(gx, gy)
    steps[~(weight > 0.3)] = np.nan
    return steps


def kerb_membership(steps: np.ndarray) -> np.ndarray:
    """How surely a cell is on a kerb: 1 from :data:`KERB_GRADIENT`, 0 up to half of it
    (a 6 cm step: a dropped kerb, a rut), linear between; NaN counts 0.

    Parameters
    ----------
    steps : ndarray
        :func:`kerb_steps`, rise over run.

    Returns
    -------
    ndarray of float, in [0, 1]
    """
    values = np.nan_to_num(np.asarray(steps, float), nan=0.0)
    return np.clip(values / (KERB_GRADIENT / 2) - 1.0, 0.0, 1.0)
