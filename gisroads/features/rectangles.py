"""Rectangular road filters on rotated images with integral images (Zhu & Mordohai, Sec. 4.2).

The boundary filter of Eq. (1)-(2) and the interior filter of Eq. (3)-(4) are evaluated
over many rectangular windows at once: the image is rotated so that a road orientation
becomes the +column axis (:func:`rotate_to`), then every axis-aligned box sum costs four
look-ups in a summed-area table (:func:`integral_image`, :func:`box_sums`; Viola & Jones
2001, the paper's [25]).

Conventions
-----------
Orientations (``theta_rad``) are angles of a LINE, counter-clockwise from the +column axis
(east) with rows drawn upwards (north up), as for the edge maps of
:mod:`gisroads.features.edges`; :func:`direction_in_pixels` is the only place that converts
them to pixel steps. Pixel boxes are half-open, ``rows [r0, r1) x cols [c0, c1)``; the
rotation mapping works on pixel *corner* coordinates ``(col, row)``, in which pixel
``(r, c)`` spans ``[c, c + 1] x [r, r + 1]``, the convention of affine geotransforms, so
``compose(geotransform, to_image)`` places rotated pixels on the map.

NaN cells are missing data: every mean is taken over the valid cells of its box, from two
integral images, one of the values with NaN set to 0 and one of the valid-cell counts.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from affine import Affine
from scipy import ndimage

from ..errors import GisroadsError

THETA2_RAD = float(np.radians(15.0))
"""Orientation tolerance of the interior filter, Eq. (3): theta_2 = 15 deg (paper)."""


def direction_in_pixels(theta_rad):
    """Unit pixel step ``(d_col, d_row)`` along orientation ``theta_rad``.

    The one place that fixes the orientation convention: counter-clockwise from +column
    (east) with north up, so a positive angle moves *up* the rows (``d_row = -sin``).
    """
    theta = np.asarray(theta_rad, dtype=float)
    return np.cos(theta), -np.sin(theta)


def compose(outer: Affine, inner: Affine) -> Affine:
    """The affine map ``outer`` after ``inner``, e.g. ``compose(geotransform, to_image)``.

    Spelt out because affine 3 deprecates ``outer * inner`` and the ``@`` that replaces it
    does not exist in Debian's affine 2.
    """
    return Affine(outer.a * inner.a + outer.b * inner.d, outer.a * inner.b + outer.b * inner.e,
                  outer.a * inner.c + outer.b * inner.f + outer.c,
                  outer.d * inner.a + outer.e * inner.d, outer.d * inner.b + outer.e * inner.e,
                  outer.d * inner.c + outer.e * inner.f + outer.f)


def rotated_frame(shape: tuple[int, int], theta_rad: float) -> tuple[Affine, tuple[int, int]]:
    """The rotated grid of :func:`rotate_to` for an image of ``shape`` (nothing resampled).

    The rotated +column axis runs along ``theta_rad`` and the rotated +row axis 90 degrees
    clockwise from it (on screen), so the mapping is a proper rotation; the rotated grid is
    the bounding box of the rotated image.

    Returns
    -------
    to_image : affine.Affine
        Rotated pixel corner ``(col', row')`` to image pixel corner ``(col, row)``.
    shape : (rows', cols')
    """
    # Rounded so that cos(pi/2) is 0 and a quarter turn resamples pixel centres exactly
    # instead of missing the first row or column by 1e-16 of a pixel.
    d_col, d_row = (round(float(v), 12) for v in direction_in_pixels(theta_rad))
    # rotated (col', row') -> image (col, row): col' axis -> (d_col, d_row), row' -> (-d_row, d_col)
    turn = Affine(d_col, -d_row, 0.0, d_row, d_col, 0.0)
    rows, cols = shape
    corner_cols = np.array([0.0, cols, 0.0, cols])
    corner_rows = np.array([0.0, 0.0, rows, rows])
    back = ~turn
    rot_cols = back.a * corner_cols + back.b * corner_rows
    rot_rows = back.d * corner_cols + back.e * corner_rows
    # Shave round-off so an axis-aligned rotation keeps its exact shape.
    out_shape = (int(np.ceil(np.ptp(rot_rows) - 1e-9)), int(np.ceil(np.ptp(rot_cols) - 1e-9)))
    origin = Affine.translation(round(rot_cols.min(), 9), round(rot_rows.min(), 9))
    return compose(turn, origin), out_shape


def rotate_to(image, theta_rad: float, *, order: int = 1, cval=np.nan) -> tuple[np.ndarray, Affine]:
    """Rotate an image so that orientation ``theta_rad`` becomes the +column axis.

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
        Float images may hold NaN (missing); use ``order=0`` for labels.
    theta_rad : float
        Orientation (see the module conventions) that becomes the rotated +column axis.
    order : int
        Spline order of :func:`scipy.ndimage.affine_transform`: 1 (bilinear; a NaN spreads
        to the <= 1 pixel it is interpolated into) or 0 (nearest, for labels).
    cval : scalar
        Value of rotated pixels that fall outside the image (NaN; -1 for labels).

    Returns
    -------
    rotated : ndarray
        The bounding box of the rotated image, same dtype as ``image``.
    to_image : affine.Affine
        Rotated pixel corner ``(col', row')`` to image pixel corner ``(col, row)``;
        ``~to_image`` goes back, ``compose(geotransform, to_image)`` is the rotated
        image's geotransform.
    """
    image = np.asarray(image)
    if image.ndim != 2:
        raise GisroadsError(f"expected a 2-D image, got shape {image.shape}")
    to_image, out_shape = rotated_frame(image.shape, theta_rad)
    # affine_transform maps output index (row', col') to input index (row, col), with pixel
    # centres at integers: shift the corner mapping by half a pixel on both sides.
    centre_col = to_image.a * 0.5 + to_image.b * 0.5 + to_image.c - 0.5
    centre_row = to_image.d * 0.5 + to_image.e * 0.5 + to_image.f - 0.5
    matrix = np.array([[to_image.e, to_image.d], [to_image.b, to_image.a]])
    rotated = ndimage.affine_transform(image, matrix, offset=(centre_row, centre_col),
                                       output_shape=out_shape, output=image.dtype,
                                       order=order, mode="constant", cval=cval,
                                       prefilter=False)
    return rotated, to_image


def integral_image(a) -> np.ndarray:
    """Summed-area table with a zero first row and column, float64.

    ``ii[r, c]`` is the sum of ``a[:r, :c]``, so a box ``[r0, r1) x [c0, c1)`` sums to
    ``ii[r1, c1] - ii[r0, c1] - ii[r1, c0] + ii[r0, c0]`` (see :func:`box_sums`).
    """
    a = np.asarray(a, dtype=np.float64)
    ii = np.zeros((a.shape[0] + 1, a.shape[1] + 1))
    np.cumsum(a, axis=0, out=ii[1:, 1:])
    np.cumsum(ii[1:, 1:], axis=1, out=ii[1:, 1:])
    return ii


def box_sums(ii, r0, c0, r1, c1) -> np.ndarray:
    """Sums over the half-open boxes ``rows [r0, r1) x cols [c0, c1)``, vectorised.

    Parameters
    ----------
    ii : ndarray, shape (rows + 1, cols + 1)
        From :func:`integral_image`.
    r0, c0, r1, c1 : array_like of int
        Box bounds in pixels, broadcast together. Boxes are clipped to the image, so the
        part of a box outside it sums to 0 (an empty box too).
    """
    rows, cols = ii.shape[0] - 1, ii.shape[1] - 1
    r0 = np.clip(r0, 0, rows)
    c0 = np.clip(c0, 0, cols)
    r1 = np.clip(r1, r0, rows)
    c1 = np.clip(c1, c0, cols)
    return ii[r1, c1] - ii[r0, c1] - ii[r1, c0] + ii[r0, c0]


def interior_sign(edge_theta_rad, window_theta_rad, *, theta2_rad: float = THETA2_RAD):
    """The interior filter's weight F_int of Eq. (3) for edges of a given orientation.

    +1 for edges within ``theta2_rad`` of the window (road) direction (lane markings,
    separators), -1 for oblique edges between ``theta2_rad`` and ``pi/2 - theta2_rad``, 0
    for near-orthogonal ones (crosswalks, junctions are not penalised). Non-finite
    orientations get 0.

    Returns
    -------
    ndarray of int8, the broadcast shape of the inputs
    """
    delta = np.mod(np.asarray(edge_theta_rad, float) - window_theta_rad, np.pi)
    off = np.minimum(delta, np.pi - delta)
    sign = np.where(off <= theta2_rad, 1, np.where(off < np.pi / 2 - theta2_rad, -1, 0))
    return np.where(np.isfinite(off), sign, 0).astype(np.int8)


@dataclass(frozen=True)
class RotatedFeatures:
    """Integral images of one orientation's rotated frame (see :func:`rotated_features`).

    Attributes
    ----------
    theta_rad : float
        The orientation that is the rotated +column axis.
    to_image : affine.Affine
        Rotated pixel corners to image pixel corners (see :func:`rotate_to`).
    intensity : ndarray
        Integral image of the rotated intensity, NaN counted as 0.
    valid : ndarray
        Integral image of the rotated valid-cell indicator.
    signed_edges : ndarray
        Integral image of the rotated ``F_int * magnitude`` edge map (Eq. 3-4).
    """

    theta_rad: float
    to_image: Affine
    intensity: np.ndarray
    valid: np.ndarray
    signed_edges: np.ndarray


def rotated_features(intensity, magnitude, orientation_rad, theta_rad: float, *,
                     theta2_rad: float = THETA2_RAD) -> RotatedFeatures:
    """Rotate the intensity and the signed edge map to ``theta_rad``; build their tables.

    Parameters
    ----------
    intensity : ndarray, shape (rows, cols)
        Float intensity image, road darker than its surroundings; NaN = no data.
    magnitude, orientation_rad : ndarray, shape (rows, cols)
        Edge strength (>= 0) and edge-line orientation in [0, pi) (module conventions);
        non-finite cells carry no edge.
    theta_rad : float
        Road direction of the windows.
    theta2_rad : float
        Tolerance of Eq. (3).
    """
    intensity = np.asarray(intensity, dtype=np.float64)
    magnitude = np.asarray(magnitude, dtype=np.float64)
    signed = interior_sign(orientation_rad, theta_rad, theta2_rad=theta2_rad) * magnitude
    signed[~np.isfinite(signed)] = 0.0
    rotated, to_image = rotate_to(intensity, theta_rad, order=1)
    signed_rotated, _ = rotate_to(signed, theta_rad, order=1, cval=0.0)
    valid = np.isfinite(rotated)
    return RotatedFeatures(
        theta_rad=float(theta_rad), to_image=to_image,
        intensity=integral_image(np.where(valid, rotated, 0.0)),
        valid=integral_image(valid), signed_edges=integral_image(signed_rotated))


def _band_mean(features: RotatedFeatures, r0, r1, c0, c1) -> np.ndarray:
    count = box_sums(features.valid, r0, c0, r1, c1)
    total = box_sums(features.intensity, r0, c0, r1, c1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def boundary_strength(features: RotatedFeatures, r0, c0, width_px, length_px, *,
                      band_px) -> np.ndarray:
    """Boundary strength S_bd of windows, Eq. (1)-(2) on both long sides.

    A window covers rows ``[r0, r0 + width_px)`` and columns ``[c0, c0 + length_px)`` of
    the rotated frame. At each long side the polarised filter of Eq. (1) compares a band
    of ``band_px`` rows outside the window with one inside it: mean outside minus mean
    inside, positive when the inside is darker (road darker than its surroundings). The
    far side uses the mirrored filter. Means (over valid cells) instead of the paper's sums
    make S_bd an intensity contrast, comparable across window sizes.

    S_bd is the *smaller* of the two side contrasts: a road has both boundaries, and a
    window too wide for its road has a far side in uniform ground with no contrast, which
    is what lets the per-width likelihood maps select the width.

    Parameters
    ----------
    features : RotatedFeatures
    r0, c0, width_px, length_px : array_like of int
        Window top-left corner and size in rotated pixels, broadcast together.
    band_px : int or array_like of int
        Band width w1 of Eq. (1); capped at half the window width so that the two inside
        bands do not overlap.

    Returns
    -------
    ndarray of float
        NaN where a band has no valid cell.
    """
    r0, c0 = np.asarray(r0), np.asarray(c0)
    width_px, length_px = np.asarray(width_px), np.asarray(length_px)
    band = np.maximum(np.minimum(band_px, width_px // 2), 1)
    c1 = c0 + length_px
    r_far = r0 + width_px
    near_side = (_band_mean(features, r0 - band, r0, c0, c1)
                 - _band_mean(features, r0, r0 + band, c0, c1))
    far_side = (_band_mean(features, r_far, r_far + band, c0, c1)
                - _band_mean(features, r_far - band, r_far, c0, c1))
    return np.minimum(near_side, far_side)


def side_step(features: RotatedFeatures, line_row, c0, c1, band, outward) -> np.ndarray:
    """The step of Eq. (1) at a line, over columns ``[c0, c1)``: mean intensity in the band of
    ``band`` rows outside a window side minus that in the
    band inside it; the side lies between rows ``line_row - 1`` and ``line_row`` and the
    outside is above it (``outward = -1``) or below it (``outward = +1``)."""
    above = _band_mean(features, line_row - band, line_row, c0, c1)
    below = _band_mean(features, line_row, line_row + band, c0, c1)
    return np.where(outward < 0, above - below, below - above)


def sides_on_strongest_edges(features: RotatedFeatures, r0, c0, width_px, length_px, *,
                             edge_band_px, slack_px, ratio: float = 0.5,
                             min_step: float = 0.0, end_px: int = 0) -> np.ndarray:
    """Whether the long sides of windows are the road's edges: steps from bright to dark,
    with no line inside a window stepping as strongly.

    The step at a line is the contrast of Eq. (1) with a thin band of ``edge_band_px``
    rows (:func:`side_step`, for a side's polarity); a side's step is the greatest within
    ``slack_px`` rows of it. A window fails when

    - a side's step over the whole window, or over either end of ``end_px`` columns, is
      below ``min_step`` (a long window a degree off its road has an end off the kerbs);
    - a line inside it, more than ``slack_px`` rows from its sides, has a step of either
      side's polarity above ``ratio`` times that side's step.

    A window as wide as the road and its sidewalks has its sides on the sidewalk-grass
    line and the kerbs, a stronger step, inside; one over both carriageways of a dual road
    and their median has the median's edges inside; both fail. A window on the kerbs, or
    a little inside them (the sampled widths are a few metres apart), passes: only lane
    markings and noise step inside it.

    Parameters
    ----------
    features : RotatedFeatures
    r0, c0, width_px, length_px : array_like of int
        Windows as in :func:`boundary_strength`, broadcast together.
    edge_band_px, slack_px : int
    ratio, min_step : float
    end_px : int
        Length of the end pieces checked; 0 checks the whole sides only.

    Returns
    -------
    ndarray of bool, the broadcast shape of the windows
    """
    shape = np.broadcast_shapes(*(np.shape(a) for a in (r0, c0, width_px, length_px)))
    r0, c0, width_px, length_px = (np.broadcast_to(a, shape).ravel()
                                   for a in (r0, c0, width_px, length_px))
    c1 = c0 + length_px

    def step(line, outward, start, stop):
        # a side's step is the greatest within the slack of it: the sampled width may put
        # the far side up to a metre or two off the kerb
        return np.max([side_step(features, line + k, start, stop, edge_band_px, outward)
                       for k in range(-slack_px, slack_px + 1)], axis=0)

    near = step(r0, -1, c0, c1)
    far = step(r0 + width_px, 1, c0, c1)
    ok = (near >= min_step) & (far >= min_step)
    if end_px:
        # a long window a degree off its road has the sides of one end or both off the kerbs
        piece = np.minimum(end_px, c1 - c0)
        for start, stop in ((c0, c0 + piece), (c1 - piece, c1)):
            for line, outward in ((r0, -1), (r0 + width_px, 1)):
                ok &= ~(step(line, outward, start, stop) < min_step)
    for offset in range(slack_px + 1, int(width_px.max(initial=0)) - slack_px):
        inner = offset < width_px - slack_px
        at = np.flatnonzero(inner & ok)
        if len(at) == 0:
            continue
        line = r0[at] + offset
        down = side_step(features, line, c0[at], c1[at], edge_band_px, -1)
        ok[at] = ~((down > ratio * near[at]) | (-down > ratio * far[at]))
    return ok.reshape(shape)


def valid_fraction(features: RotatedFeatures, r0, c0, width_px, length_px) -> np.ndarray:
    """Share of each window's cells (inside the rotated frame or not) that hold data."""
    area = np.asarray(width_px) * np.asarray(length_px)
    return box_sums(features.valid, r0, c0, np.asarray(r0) + width_px,
                    np.asarray(c0) + length_px) / area


def interior_strength(features: RotatedFeatures, r0, c0, width_px, length_px) -> np.ndarray:
    """Interior strength S_int of windows, Eq. (3)-(4), per valid cell of the window.

    The sum of ``F_int * magnitude`` over the window (parallel edges count +, oblique
    edges -, near-orthogonal 0), divided by its number of valid cells so that windows of
    any size compare. NaN for a window without valid cells.
    """
    r1 = np.asarray(r0) + width_px
    c1 = np.asarray(c0) + length_px
    count = box_sums(features.valid, r0, c0, r1, c1)
    total = box_sums(features.signed_edges, r0, c0, r1, c1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)
