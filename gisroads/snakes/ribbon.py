"""Ribbon snakes along a map line (Boyko & Funkhouser, 2011, Sec. 2.4; Fua, 1997).

A ribbon is a centre line and a half width along the map line of a road patch, sampled every
``step_m`` (1 m in the paper). At sample ``i`` with position ``P_i`` and unit left normal
``N_i`` of the map line, the ribbon has the offset ``t_i`` of its centre along ``N_i`` and the
half width ``w_i``; its left and right boundary points are ``P_i + (t_i +- w_i) N_i``. The
paper writes the snake as ``v(s) = (u(s), w(s))`` with ``u = t - t_avg``: the internal energy

    E_int = (alpha |v_s|^2 + beta |v_ss|^2) / 2          (Eq. 6)

only sees derivatives, so the whole ribbon moves sideways by ``t_avg`` (the map's offset)
without penalty, while its shape follows the map line's. The external force at each sample
is the GVF field ``f`` (:mod:`gisroads.snakes.gvf`) at the two boundary points, projected on
the normal: ``F_t = f_l + f_r`` moves the centre, ``F_w = f_l - f_r`` the half width. The
semi-implicit iteration of Kass et al.

    (kappa A + gamma I) v_t = gamma v_{t-1} + F(v_{t-1})

with ``A = alpha D1'D1 + beta D2'D2`` (first and second differences, free ends) is solved
with one banded Cholesky factorisation of the pentadiagonal matrix for all iterations.

Initialisation (:func:`initial_ribbon`) is this module's addition. The paper starts the
ribbon on the map line with the width of one lane and lets the snake find the kerbs; when
the map is off by more than the half width of the road, one boundary then starts beyond the
near kerb and the GVF, which points to the nearest attractor, pulls both boundaries onto that
kerb. So the initial offset and width are read from the cross profile of the attractor map,
averaged along ``window_m`` of the line: the pair of profile peaks, one on each side of the
ribbon, that best explains it (largest summed attraction, between the minimum and maximum
road width); the snake then refines the boundary sample by sample.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from affine import Affine
from scipy import ndimage
from scipy.linalg import cho_solve_banded, cholesky_banded
from scipy.sparse import diags

from ..errors import GisroadsError
from ..geo import GeoRaster
from .attractor import LANE_M

#: Table 1 of the paper.
ALPHA_SNAKE = 0.01
BETA_SNAKE = 100.0
GAMMA_SNAKE = 10.0
KAPPA_SNAKE = 1.0
#: Spline samples every metre (Table 1).
STEP_M = 1.0
MAX_ITERATIONS = 500
TOL_M = 0.005
#: Weight of the clutter between two boundary candidates in :func:`initial_ribbon`: at 4.4
#: points/m2 (fusa) the kerbs barely rise above the clutter of the verges beyond them, and
#: the strongest pair of peaks spans gardens and parked cars; a road's surface is quiet.
#: Swept on fusa (map shifted 3 m) and the synthetic overpass scene: 2 -> q 0.64 / 0.92,
#: 4 -> 0.68 / 0.90, 6 -> 0.70 / 0.85, 8 -> 0.69 / 0.75.
INTERIOR_WEIGHT = 4.0
#: A ribbon stays at least this wide (metres, half width), so its two sides stay apart.
MIN_HALF_WIDTH_M = 0.5


def resample_line(line_xy, step_m: float = STEP_M) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``step_m`` along a polyline (ends included) and their unit left normals.

    Returns
    -------
    points : ndarray, shape (k, 2)
    normals : ndarray, shape (k, 2)
        The tangent turned 90 degrees counter-clockwise.
    """
    xy = np.asarray(line_xy, float)[:, :2]
    keep = np.r_[True, np.hypot(*np.diff(xy, axis=0).T) > 1e-9]
    xy = xy[keep]
    if len(xy) < 2:
        raise GisroadsError("the map line needs two distinct vertices")
    stations = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    count = max(2, int(round(stations[-1] / step_m)) + 1)
    along = np.linspace(0.0, stations[-1], count)
    points = np.column_stack([np.interp(along, stations, xy[:, 0]),
                              np.interp(along, stations, xy[:, 1])])
    tangent = np.gradient(points, axis=0)
    tangent /= np.maximum(np.hypot(tangent[:, 0], tangent[:, 1]), 1e-12)[:, None]
    return points, np.column_stack([-tangent[:, 1], tangent[:, 0]])


def _pixel_coordinates(transform: Affine, xy: np.ndarray) -> np.ndarray:
    """(row, col) of map points in the continuous index space of pixel centres."""
    inverse = ~transform
    col = inverse.a * xy[:, 0] + inverse.b * xy[:, 1] + inverse.c - 0.5
    row = inverse.d * xy[:, 0] + inverse.e * xy[:, 1] + inverse.f - 0.5
    return np.vstack([row, col])


def sample_bilinear(array: np.ndarray, transform: Affine, xy: np.ndarray) -> np.ndarray:
    """Bilinear samples of a raster at map points; 0 outside it."""
    return ndimage.map_coordinates(array, _pixel_coordinates(transform, xy), order=1,
                                   mode="constant", cval=0.0)


def internal_matrix(count: int, *, alpha: float = ALPHA_SNAKE, beta: float = BETA_SNAKE,
                    step_m: float = STEP_M):
    """``A = alpha D1'D1 + beta D2'D2``: the derivative of Eq. 6 for ``count`` samples
    ``step_m`` apart, free ends (sparse, pentadiagonal)."""
    d1 = diags([-np.ones(count - 1), np.ones(count - 1)], [0, 1],
               shape=(count - 1, count)) / step_m
    d2 = diags([np.ones(count - 2), -2 * np.ones(count - 2), np.ones(count - 2)], [0, 1, 2],
               shape=(max(count - 2, 0), count)) / step_m ** 2
    return (alpha * (d1.T @ d1) + beta * (d2.T @ d2)).tocsr()


def _banded_factor(matrix, count: int) -> np.ndarray:
    """Upper banded Cholesky factor of a symmetric pentadiagonal matrix."""
    bands = np.zeros((3, count))
    for k in range(3):
        if k < count:
            bands[2 - k, k:] = matrix.diagonal(k)
    return cholesky_banded(bands, lower=False)


def initial_ribbon(attractor: GeoRaster, line_xy, *, step_m: float = STEP_M,
                   min_width_m: float = LANE_M, max_width_m: float = 10 * LANE_M,
                   reach_m: float = 6 * LANE_M, window_m: float = 40.0,
                   offset_step_m: float | None = None, interior_weight: float = INTERIOR_WEIGHT,
                   centre_weight: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Initial centre offset and half width of a ribbon from the attractor's cross profile.

    At every sample the attractor is read along the normal from ``-reach_m`` to ``reach_m``
    and averaged over ``window_m`` of the line; the initial boundaries are the two offsets
    ``d_r < d_l`` with ``min_width_m <= d_l - d_r <= max_width_m`` that maximise
    ``profile(d_l) + profile(d_r) - interior_weight mean(profile(d_r < d < d_l))
    - centre_weight |d_l + d_r| / 2``: two strong attractors with a quiet surface between
    them (a road, not a strip of gardens and parked cars), nearest the map line.

    Parameters
    ----------
    attractor : GeoRaster
        The patch's attractor map.
    line_xy : ndarray, shape (k, 2)
        The map line.
    step_m : float
        Sample spacing along the line (metres).
    min_width_m, max_width_m : float
        Road width bounds (metres; one and ten lanes, Table 1).
    reach_m : float
        Farthest boundary offset from the map line (metres; six lanes, Sec. 2.3).
    window_m : float
        Length of line over which the profile is averaged (metres).
    offset_step_m : float, optional
        Spacing of the profile (metres); the raster's pixel by default.
    interior_weight : float
        Weight of the mean attraction between the boundaries.
    centre_weight : float
        Attractor units per metre of centre offset.

    Returns
    -------
    shift_m, half_width_m : ndarray, shape (n,)
        Per resampled sample (:func:`resample_line`).
    """
    points, normals = resample_line(line_xy, step_m)
    spacing = attractor.pixel_size if offset_step_m is None else offset_step_m
    offsets = np.arange(-reach_m, reach_m + spacing / 2, spacing)
    probes = points[:, None, :] + offsets[None, :, None] * normals[:, None, :]
    profile = sample_bilinear(attractor.data.astype(float), attractor.transform,
                              probes.reshape(-1, 2)).reshape(len(points), len(offsets))
    window = max(1, int(round(window_m / step_m)))
    profile = ndimage.uniform_filter1d(profile, window, axis=0, mode="nearest")
    right, left = np.meshgrid(np.arange(len(offsets)), np.arange(len(offsets)), indexing="ij")
    width = offsets[left] - offsets[right]
    allowed = (width >= min_width_m) & (width <= max_width_m)
    right, left = right[allowed], left[allowed]
    if len(right) == 0:
        raise GisroadsError("no boundary pair fits between min_width_m and max_width_m "
                            "within reach_m of the map line")
    centre = (offsets[left] + offsets[right]) / 2
    # mean attraction strictly between the two boundaries, from cumulative sums
    cumulative = np.concatenate([np.zeros((len(points), 1)), np.cumsum(profile, axis=1)], axis=1)
    between = np.maximum(left - right - 1, 1)
    interior = (cumulative[:, left] - cumulative[:, right + 1]) / between
    score = (profile[:, left] + profile[:, right] - interior_weight * interior
             - centre_weight * np.abs(centre))
    best = np.argmax(score, axis=1)
    return centre[best], (offsets[left[best]] - offsets[right[best]]) / 2


@dataclass(frozen=True)
class SnakeOptions:
    """The options of :func:`ribbon_snake`: its internal energy, balloon force, step and
    convergence (Table 1 of the paper).

    Attributes
    ----------
    alpha, beta : float
        Elasticity and rigidity of Eq. 6 (0.01, 100).
    gamma : float
        Step-size weight of the semi-implicit iteration (10).
    kappa : float
        Weight of the internal energy (1).
    step_m : float
        Sample spacing (metres; 1 m in the paper).
    max_iterations : int
        Iteration cap.
    tol_m : float
        Converged when no offset or width moves by more than this (metres) in an iteration.
    min_half_width_m : float
        Floor of the half width (metres).
    """

    alpha: float = ALPHA_SNAKE
    beta: float = BETA_SNAKE
    gamma: float = GAMMA_SNAKE
    kappa: float = KAPPA_SNAKE
    step_m: float = STEP_M
    max_iterations: int = MAX_ITERATIONS
    tol_m: float = TOL_M
    min_half_width_m: float = MIN_HALF_WIDTH_M


def ribbon_snake(gvf_u: np.ndarray, gvf_v: np.ndarray, transform: Affine, line_xy,
                 options: SnakeOptions = SnakeOptions(), *, width0_m, shift0_m=0.0,
                 **changes) -> tuple[np.ndarray, np.ndarray, bool]:
    """Fit a ribbon snake along a map line to a GVF field (Sec. 2.4).

    Parameters
    ----------
    gvf_u, gvf_v : ndarray, shape (rows, cols)
        GVF of the attractor map along the array's columns and rows (per pixel), as
        :func:`gisroads.snakes.gvf.gradient_vector_flow` returns it.
    transform : affine.Affine
        The raster's georeferencing (square pixels, north-up or not).
    line_xy : ndarray, shape (k, 2)
        The map line (metres); resampled every ``step_m``.
    width0_m : float or ndarray
        Initial full width (metres), one value or one per resampled sample.
    shift0_m : float or ndarray
        Initial offset of the centre to the left of the map line (metres).
    options : SnakeOptions
        Energy weights, step and convergence (:class:`SnakeOptions`).
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    centre_xy : ndarray, shape (n, 2)
        The ribbon's centre line.
    half_widths_m : ndarray, shape (n,)
    converged : bool
        Whether the tolerance was met before the cap.
    """
    options = replace(options, **changes)
    if gvf_u.shape != gvf_v.shape or gvf_u.ndim != 2:
        raise GisroadsError("gvf_u and gvf_v must be 2-D arrays of one shape")
    if options.gamma <= 0 or options.step_m <= 0 or options.max_iterations < 1:
        raise GisroadsError("gamma, options.step_m and options.max_iterations must be positive")
    points, normals = resample_line(line_xy, options.step_m)
    count = len(points)
    state = np.column_stack([np.broadcast_to(np.asarray(shift0_m, float), (count,)),
                             np.broadcast_to(np.asarray(width0_m, float) / 2, (count,))])
    if not np.isfinite(state).all() or (state[:, 1] <= 0).any():
        raise GisroadsError("width0_m must be positive and finite, shift0_m finite")
    state[:, 1] = np.maximum(state[:, 1], options.min_half_width_m)
    internal = internal_matrix(count, alpha=options.alpha, beta=options.beta,
                               step_m=options.step_m)
    factor = _banded_factor(options.kappa * internal + diags(np.full(count, options.gamma)),
                            count)
    pixel = abs(transform.a)
    # GVF per pixel along columns/rows -> per metre along map x/y
    fx, fy = np.sign(transform.a) * gvf_u / pixel, np.sign(transform.e) * gvf_v / pixel
    converged = False
    for _ in range(options.max_iterations):
        sides = np.concatenate([points + (state[:, :1] + state[:, 1:]) * normals,
                                points + (state[:, :1] - state[:, 1:]) * normals])
        force = (sample_bilinear(fx, transform, sides) * np.tile(normals[:, 0], 2)
                 + sample_bilinear(fy, transform, sides) * np.tile(normals[:, 1], 2))
        left, right = force[:count], force[count:]
        new = cho_solve_banded((factor, False), options.gamma * state
                               + np.column_stack([left + right, left - right]))
        new[:, 1] = np.maximum(new[:, 1], options.min_half_width_m)
        moved = float(np.abs(new - state).max())
        state = new
        if moved < options.tol_m:
            converged = True
            break
    return points + state[:, :1] * normals, state[:, 1].copy(), converged
