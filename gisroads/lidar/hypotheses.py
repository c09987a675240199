"""Rectangular road hypotheses and per-width road likelihood maps (Zhu & Mordohai, Sec. 4.3).

A hypothesis is a rectangle ``H(x, y, theta, w, l)``: a corner on a long, straight boundary
of the intensity segmentation, a road direction among the dominant edge orientations, a
width and a length. Each is scored by the boundary strength S_bd (Eq. 1-2) and the interior
strength S_int (Eq. 3-4) of :mod:`gisroads.features.rectangles`, computed for all windows
of one orientation at once on integral images of the rotated image. Windows with
``S_bd >= t_bd`` and ``S_int >= t_int`` are valid; each votes ``beta_bd S_bd + beta_int
S_int`` on the pixels it covers, one likelihood map per width, capped at ``l_max`` (Eq. 5).

Width selection. The paper selects a road's width by the competition of the per-width
maps in the minimum cover (Fig. 3, case 3), which needs L_k higher at the right width. With
means over 4 m bands a window 2-4 m too wide, its sides on the sidewalk-grass line, passes
T_bd as well as the right one and both maps saturate at L_max, so the cover took the wider
(more seeds per fixed cost A): 16 and 25 m rectangles on 9 and 21 m roads, and one 25 m
rectangle over both carriageways of a dual road. A valid window must therefore also have
its sides on the road's edges (:func:`gisroads.features.rectangles.sides_on_strongest_edges`,
the boundary filter of Eq. 1 used as an edge detector with non-maximum suppression across
the window): each side, over the whole window and over each 40 m end, steps from bright to
dark by at least T_bd in a 1 m band, and no line inside steps half as much. Corners are
moved to the strongest step within 2 m of NCut's boundary (:data:`SNAP_M`), since NCut may
split at the sidewalk's outer line rather than at the kerb. Windows are at least three times
as long as wide: the paper's elongation, which tells roads from parking lots (Sec. 1).

The paper gives no thresholds, band width or cap. The defaults were chosen on the ground
intensity of synthetic scenes (:mod:`gisroads.synthetic`, 300-400 m, 10 pulses/m2) and
checked on the real suburb tile ``fusa.laz``, with the default sampling (corners every 2 m,
four lengths, five fanned orientations per histogram peak). Before the edge checks 57-80 %
of the road pixels reached half the cap (55 % on fusa) and parking lots 10-27; with them,
the right width's map saturates on straight roads and the others stay low (on a 9 m
street about 19 in the 9 m map, 0-10 in the 6 and 12 m maps). The cap depends on that
sampling: halving ``corner_step_m`` doubles every pixel's votes.
With these rules (and the split-pulse gain of :mod:`gisroads.lidar.intensity`) completeness
/ correctness of ``extract_roads`` at 3 m went, on one 300 m tile at 8 pulses/m2, from
0.85/0.79 to 0.98/0.95 with buildings and trees, from 0.71/0.63 to 0.90/0.97 with every
feature, and on fusa.laz from 0.16/0.37 to 0.52/0.95 (with the cover's d_max at 1).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import geopandas as gpd
import numpy as np
import shapely
from affine import Affine
from scipy import ndimage

from ..errors import GisroadsError
from ..features.edges import dominant_orientations
from ..features.rectangles import (THETA2_RAD, boundary_strength, compose,
                                   interior_strength, rotate_to, rotated_features,
                                   rotated_frame, side_step, sides_on_strongest_edges,
                                   valid_fraction)
from ..geo import GeoRaster
from ..progress import Progress, report
from ..segmentation.ncut import segment_boundaries

DEFAULT_WIDTHS_M = (6.0, 9.0, 12.0, 16.0, 20.0, 25.0)
"""Window widths (metres): the paper samples 10-25 m (arterials); 6-12 m add the 7-12 m
carriageways of a suburb."""
DEFAULT_LENGTHS_M = (40.0, 80.0, 150.0, 300.0)
"""Window lengths (metres), the paper's range of 40-300 m."""
T_BD = 0.08
"""Least boundary contrast, in normalised intensity on both long sides, of a valid window:
asphalt against a verge is 0.2-0.5. On the synthetic scenes 0.12 drops 3-4 % more road
pixels below half the cap, 0.05 lifts the parking lots' likelihood by a third to a half."""
T_INT = 0.0
"""Least interior strength: a road's parallel edge energy (markings, its own kerbs) must at
least balance the oblique energy, which noise and clutter (a share 2/3 of random
orientations) make negative."""
L_MAX = 25.0
"""Cap of the likelihood maps, Eq. (5). With the default sampling a pixel on a straight
synthetic road sums hundreds of votes of 0.2-0.5 at its width, one on a parking lot or a
short road-like patch 5-27; on fusa only about half the road pixels reach 25. A sweep of
the cap (15, 25, 50) with the cover's d_max (0.5, 0.7, 0.85) scored best at 25 with 0.7 on
both fusa and a synthetic scene (see the minimum-cover module)."""
BAND_M = 4.0
"""Band width w1 of the boundary filter, Eq. (1), metres: wide enough to reach past a
kerb-side strip of parked cars, tree shadow or sidewalk to the bright verge."""
EDGE_BAND_M = 1.0
"""Band of the thin step filter that checks where a window's sides lie, metres: the
sidewalk-grass line and the kerb 2 m inside it are separate steps."""
EDGE_RATIO = 0.5
"""A line inside a valid window steps at most half as much as its sides (lane markings do
a tenth to a fifth; a sidewalk's kerb or a median's edge as much as the sides)."""
EDGE_SLACK_M = 1.0
"""Steps within this distance of a side are the side's (widths are sampled metres apart)."""
EDGE_END_M = 40.0
"""Both ends of a window, over this length (the shortest window), must have their sides on
steps of at least T_bd too: a 300 m window 1 degree off its road drifts 5 m across it, and
its mean step along the whole side hides that (20 m also cut windows on curved streets)."""
SNAP_M = 2.0
"""A corner's boundary row moves to the strongest step within this distance (metres), a
sidewalk's width: windows start on the kerb whichever line NCut split at."""
MIN_ELONGATION = 3.0
"""Least length / width of a window: elongation is what tells a road from a parking lot
(Sec. 1); a 25 m x 40 m window fitted a 25 m x 33 m lot."""
OVERHANG_M = 20.0
"""Farthest a window's centre line may reach off the image, metres: half the shortest
window; a 300 m window reaching 110 m off was valid on its part inside, 2 degrees off
the road."""
"""A window's side must be the strongest step within this distance (metres), a sidewalk's
width and a bit: 0 turns the check off."""
FAN_RAD = tuple(np.radians((-3.0, -1.5, 0.0, 1.5, 3.0)))
"""Offsets tried around each dominant orientation: roads a few degrees apart share one
histogram peak, and a rigid 150 m window 2 degrees off drifts 5 m across its road."""
CORNER_STEP_M = 2.0
"""Spacing of the corners sampled along a boundary, metres."""
STRAIGHT_M = 10.0
"""A corner's boundary must run straight along the window direction over this length."""
VOTE_QUANTA = 2.0 ** 20
"""Votes are summed in units of 1/VOTE_QUANTA (about 1e-6), exactly."""


def boundary_orientations(labels, magnitude, orientation_rad, *, n_bins: int = 90,
                          max_peaks: int = 6) -> np.ndarray:
    """Dominant road orientations: peaks of the magnitude-weighted orientation histogram of
    the edges on segment boundaries (Sec. 4.3).

    Only edges within one pixel of a boundary between two valid labels count, where the
    corners are sampled: the texture of grass and noise, whose orientations the filter bank
    biases to its own directions, stays out of the histogram. Bins are 2 degrees (``n_bins
    = 90``) so that nearby road directions keep apart; see
    :func:`gisroads.features.edges.dominant_orientations`.

    Returns
    -------
    ndarray of float
        Orientations in [0, pi), radians, strongest first.
    """
    near = ndimage.binary_dilation(segment_boundaries(labels), structure=np.ones((3, 3), bool))
    return dominant_orientations(np.where(near, magnitude, 0.0), orientation_rad,
                                 n_bins=n_bins, max_peaks=max_peaks)


def _fanned(orientations_rad, fan_rad, *, merge_rad: float = np.radians(1.0)) -> np.ndarray:
    """Each orientation with the offsets ``fan_rad`` added, in [0, pi); orientations within
    ``merge_rad`` of an earlier one are dropped."""
    fanned = np.mod(np.add.outer(np.asarray(orientations_rad, float),
                                 np.asarray(fan_rad, float)).ravel(), np.pi)
    gap = np.abs(fanned[:, None] - fanned[None, :])
    near_earlier = np.tril(np.minimum(gap, np.pi - gap) < merge_rad, k=-1).any(axis=1)
    return fanned[~near_earlier]


def _straight_boundary_corners(rotated_labels, *, step_px: int, straight_px: int,
                               min_straight: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """Corners on segment boundaries that run straight along the rotated +column axis.

    A boundary runs between rows ``r - 1`` and ``r`` where two valid labels differ; it is
    straight at a pixel when at least ``min_straight`` of the ``straight_px`` columns around
    it also hold such a boundary within one row (the tolerance of a staircase boundary;
    over the default 10 m, boundaries up to about 10 degrees off the axis pass). The
    survivors are thinned to one per ``step_px`` columns and two rows, the straightest.

    Returns
    -------
    line_row, col : ndarray of int
        The boundary lies at pixel-corner row ``line_row`` (between rows ``line_row - 1``
        and ``line_row``), at column ``col``.
    """
    above, below = rotated_labels[:-1], rotated_labels[1:]
    boundary = (above != below) & (above >= 0) & (below >= 0)
    near = ndimage.maximum_filter1d(boundary.view(np.uint8), 3, axis=0)
    straight = ndimage.uniform_filter1d(near.astype(np.float32), straight_px, axis=1,
                                        mode="constant")
    rows, cols = np.nonzero(boundary & (straight >= min_straight))
    cell = (rows // 2) * (rotated_labels.shape[1] // step_px + 1) + cols // step_px
    order = np.lexsort((-straight[rows, cols], cell))
    _, first = np.unique(cell[order], return_index=True)
    keep = order[first]
    return rows[keep] + 1, cols[keep]


def _windows(line_rows, col, width_px, length_px) -> tuple[np.ndarray, ...]:
    """Every window with a long side on a corner's boundary, on either side of it and
    running forwards or backwards from the corner, deduplicated.

    ``line_rows`` holds per corner the boundary row of the windows below it and that of
    the windows above it (see :func:`_snapped_rows`).

    Returns ``r0, c0, width_index, length_index``, one entry per window.
    """
    n, n_w, n_l = len(line_rows), len(width_px), len(length_px)
    shape = (n, 2, 2, n_w, n_l)
    below_or_above = np.arange(2).reshape(1, 2, 1, 1, 1)
    forward_or_back = np.arange(2).reshape(1, 1, 2, 1, 1)
    w_index = np.broadcast_to(np.arange(n_w).reshape(1, 1, 1, n_w, 1), shape).ravel()
    l_index = np.broadcast_to(np.arange(n_l).reshape(1, 1, 1, 1, n_l), shape).ravel()
    r0 = np.broadcast_to(np.asarray(line_rows).reshape(n, 2, 1, 1, 1)
                         - below_or_above * width_px.reshape(1, 1, 1, n_w, 1), shape).ravel()
    c0 = np.broadcast_to(col.reshape(n, 1, 1, 1, 1)
                         - forward_or_back * length_px.reshape(1, 1, 1, 1, n_l), shape).ravel()
    # One int64 key per window (a 1-D unique sorts far faster than rows of a 2-D one);
    # shifting by the largest size keeps both coordinates non-negative.
    shift = int(max(width_px.max(), length_px.max()))
    span_c = int(c0.max(initial=0)) + 2 * shift + 1
    key = (((r0 + shift) * span_c + (c0 + shift)) * n_w + w_index) * n_l + l_index
    _, first = np.unique(key, return_index=True)
    return r0[first], c0[first], w_index[first], l_index[first]


def _snapped_rows(features, line_row, col, *, reach_px: int, span_px: int, band_px: int
                  ) -> np.ndarray:
    """Each corner's boundary row moved to the strongest step within ``reach_px`` rows, over
    the ``span_px`` columns around it: one row for windows below the boundary (brighter
    above) and one for windows above it (brighter below).

    NCut puts a boundary at the kerb or at the sidewalk's outer line, whichever its
    intensity groups split at; the window's side belongs on the stronger step, the kerb.

    Returns
    -------
    ndarray of int, shape (n, 2)
    """
    offsets = np.arange(-reach_px, reach_px + 1)
    rows = line_row[:, None] + offsets[None, :]
    c0 = (col - span_px // 2)[:, None]
    snapped = []
    for outward in (-1, 1):
        step = side_step(features, rows, c0, c0 + span_px, band_px, outward)
        best = np.argmax(np.where(np.isfinite(step), step, -np.inf), axis=1)
        snapped.append(line_row + offsets[best])
    return np.stack(snapped, axis=1)


def _centre_line_inside(to_image: Affine, shape, r0, c0, width_px, length_px, *,
                        overhang_px: float) -> np.ndarray:
    """Whether both ends of rotated windows' centre lines lie within ``overhang_px`` of the
    image.

    Windows may hold up to half their cells without data (trees, cars), but one reaching
    far off the image would be judged on the part inside alone: a long window a degree or
    two off a road's direction drifts across it beyond the border unseen.
    """
    row = np.asarray(r0) + np.asarray(width_px) / 2.0
    ok = np.ones(row.shape, dtype=bool)
    for col in (np.asarray(c0), np.asarray(c0) + np.asarray(length_px)):
        x = to_image.a * col + to_image.b * row + to_image.c
        y = to_image.d * col + to_image.e * row + to_image.f
        ok &= ((x >= -overhang_px) & (x <= shape[1] + overhang_px)
               & (y >= -overhang_px) & (y <= shape[0] + overhang_px))
    return ok


def _rectangles_on_map(to_map, r0, c0, width_px, length_px):
    """Map polygons of rotated windows and the map coordinates of their first corner.

    ``to_map`` holds one affine ``(a, b, c, d, e, f, 0, 0, 1)`` per window: its rotated
    frame's pixel corners to map coordinates.
    """
    cols = np.stack([c0, c0 + length_px, c0 + length_px, c0], axis=1).astype(float)
    rows = np.stack([r0, r0, r0 + width_px, r0 + width_px], axis=1).astype(float)
    a, b, c, d, e, f = (to_map[:, i:i + 1] for i in range(6))
    x = a * cols + b * rows + c
    y = d * cols + e * rows + f
    return shapely.polygons(np.stack([x, y], axis=2)), x[:, 0], y[:, 0]


def _check_north_up(transform: Affine) -> None:
    """Orientations are angles on a north-up grid (see :mod:`gisroads.features.edges`), and
    the rectangles need square pixels."""
    if transform.b != 0 or transform.d != 0 or transform.e >= 0 or transform.a <= 0:
        raise GisroadsError("road hypotheses need a north-up grid (no rotation, rows "
                            "southward)")
    if not np.isclose(transform.a, -transform.e):
        raise GisroadsError("road hypotheses need square pixels")


def _image_array(image: GeoRaster) -> np.ndarray:
    data = np.asarray(image.data, dtype=np.float64)
    if data.ndim == 3 and data.shape[0] == 1:
        data = data[0]
    if data.ndim != 2:
        raise GisroadsError(f"expected a single-band intensity image, got shape {data.shape}")
    return data


@dataclass(frozen=True)
class HypothesisOptions:
    """The options of :func:`road_hypotheses` (Sec. 4.3): the windows tried, the validity
    thresholds and the check that a window's sides are the road's edges.

    Attributes
    ----------
    widths_m, lengths_m : sequence of float
        Window widths and lengths, metres (:data:`DEFAULT_WIDTHS_M`,
        :data:`DEFAULT_LENGTHS_M`).
    orientations_rad : sequence of float, optional
        Road directions to try, exactly; by default :func:`boundary_orientations` (the
        magnitude-weighted orientation histogram's peaks, Sec. 4.3, at most six), each
        fanned out by ``fan_rad``.
    fan_rad : sequence of float
        Offsets added to each dominant orientation (:data:`FAN_RAD`); unused with
        ``orientations_rad``.
    corner_step_m : float
        Spacing of the corners sampled along straight boundaries.
    straight_m : float
        Length over which a corner's boundary must run along the window direction.
    t_bd, t_int : float
        Validity thresholds T_bd (intensity contrast) and T_int (signed edge magnitude
        per cell); :data:`T_BD`, :data:`T_INT`.
    theta2_rad : float
        Orientation tolerance of Eq. (3), 15 degrees.
    band_m : float
        Band width w1 of Eq. (1) (capped at half the window width).
    edge_band_m, edge_ratio, edge_slack_m, edge_min_step, edge_end_m : float
        The check that a window's sides are the road's edges
        (:func:`gisroads.features.rectangles.sides_on_strongest_edges`): thin band of the
        step filter, greatest share of a side's step allowed inside the window, how far
        from a side a step counts as the side's (metres), least step of a side (default
        ``T_BD``) and length of the ends checked on their own (metres); ``edge_ratio = 0``
        turns the check off (:data:`EDGE_BAND_M`, :data:`EDGE_RATIO`,
        :data:`EDGE_SLACK_M`, :data:`EDGE_END_M`).
    snap_m : float
        Corners move to the strongest step within this distance, metres (:data:`SNAP_M`);
        0 keeps them on the segment boundary.
    min_elongation : float
        Least length / width of a window (:data:`MIN_ELONGATION`).
    overhang_m : float
        How far the ends of a window's centre line may lie off the image, metres
        (:data:`OVERHANG_M`).
    min_valid_fraction : float
        Least share of a window's cells holding data (cells off the image hold none). Half:
        cars parked at the kerb and trees leave 30-40 % of the cells along a road empty in
        the synthetic scenes.
    beta_bd, beta_int : float
        Weights of ``score = beta_bd * s_bd + beta_int * s_int`` (Eq. 5).
    max_hypotheses : int or None
        Keep only this many, the highest scores (bounds memory on large tiles).
    """

    widths_m: tuple = DEFAULT_WIDTHS_M
    lengths_m: tuple = DEFAULT_LENGTHS_M
    orientations_rad: tuple | None = None
    fan_rad: tuple = FAN_RAD
    corner_step_m: float = CORNER_STEP_M
    straight_m: float = STRAIGHT_M
    t_bd: float = T_BD
    t_int: float = T_INT
    theta2_rad: float = THETA2_RAD
    band_m: float = BAND_M
    edge_band_m: float = EDGE_BAND_M
    edge_ratio: float = EDGE_RATIO
    edge_slack_m: float = EDGE_SLACK_M
    edge_min_step: float = T_BD
    edge_end_m: float = EDGE_END_M
    overhang_m: float = OVERHANG_M
    min_elongation: float = MIN_ELONGATION
    snap_m: float = SNAP_M
    min_valid_fraction: float = 0.5
    beta_bd: float = 1.0
    beta_int: float = 1.0
    max_hypotheses: int | None = 200_000


def road_hypotheses(image: GeoRaster, magnitude, orientation_rad, labels,
                    options: HypothesisOptions = HypothesisOptions(), *,
                    progress: Progress = None, **changes) -> gpd.GeoDataFrame:
    """Valid rectangular road hypotheses of an intensity image (Sec. 4.3).

    Parameters
    ----------
    image : GeoRaster
        Intensity in [0, 1], road darker than its surroundings, NaN = no data; square
        pixels of side ``cell_m`` (its ``pixel_size``), map units metres.
    magnitude, orientation_rad : ndarray, shape (rows, cols)
        Edge strength and edge-line orientation in [0, pi), counter-clockwise from east
        (see :mod:`gisroads.features.rectangles`).
    labels : ndarray of int, shape (rows, cols)
        Segmentation (NCut over-segmentation), -1 = masked; corners are sampled on the
        boundaries between valid labels.
    options : HypothesisOptions
        Windows, thresholds and edge checks; defaults from the paper.
    progress : callable, optional
        ``progress(fraction, message)`` once per orientation.
    **changes
        Fields of ``options`` to change for this call, e.g. ``widths_m=(6.0, 9.0)``.

    Returns
    -------
    GeoDataFrame
        One rectangle per valid hypothesis in the image's CRS, best score first:
        ``hyp_id``; ``x0_m, y0_m``, the corner where the window's left long side starts
        (left of the road direction); ``theta_rad``, the road direction from that corner
        along the long side, counter-clockwise from east; ``width_m, length_m`` (the
        window's extent right of and along that side); ``s_bd, s_int, score``;
        ``width_index`` into ``widths_m``.
    """
    options = replace(options, **changes)
    widths_m, lengths_m = options.widths_m, options.lengths_m
    orientations_rad = options.orientations_rad
    intensity = _image_array(image)
    labels = np.asarray(labels, dtype=np.int32)
    magnitude = np.asarray(magnitude, dtype=np.float64)
    if labels.shape != intensity.shape or magnitude.shape != intensity.shape:
        raise GisroadsError("image, magnitude, orientation and labels must have one shape")
    _check_north_up(image.transform)
    cell_m = image.pixel_size
    widths_m = np.asarray(widths_m, dtype=float)
    lengths_m = np.asarray(lengths_m, dtype=float)
    width_px = np.round(widths_m / cell_m).astype(np.int64)
    length_px = np.round(lengths_m / cell_m).astype(np.int64)
    if width_px.min(initial=2) < 2 or length_px.min(initial=1) < 1:
        raise GisroadsError("windows must be at least 2 pixels wide and 1 pixel long")
    band_px = max(int(round(options.band_m / cell_m)), 1)
    edge_band_px = max(int(round(options.edge_band_m / cell_m)), 1)
    snap_px = int(round(options.snap_m / cell_m))
    edge_slack_px = max(int(round(options.edge_slack_m / cell_m)), 1)
    step_px = max(int(round(options.corner_step_m / cell_m)), 1)
    straight_px = max(int(round(options.straight_m / cell_m)), 3)
    if orientations_rad is None:
        orientations_rad = _fanned(boundary_orientations(labels, magnitude, orientation_rad),
                                   options.fan_rad)
    # On a north-up grid the map angle is the pixel angle (edges.py convention).
    orientations_rad = np.mod(np.atleast_1d(np.asarray(orientations_rad, dtype=float)),
                              2 * np.pi)

    found, to_map = [], []
    for index, theta in enumerate(orientations_rad):
        report(progress, index / len(orientations_rad),
               f"road hypotheses at {np.degrees(theta):.0f} deg")
        features = rotated_features(intensity, magnitude, orientation_rad, theta,
                                    theta2_rad=options.theta2_rad)
        rotated_labels, _ = rotate_to(labels, theta, order=0, cval=-1)
        line_row, col = _straight_boundary_corners(rotated_labels, step_px=step_px,
                                                   straight_px=straight_px)
        line_rows = (_snapped_rows(features, line_row, col, reach_px=snap_px, span_px=straight_px,
                                   band_px=edge_band_px) if snap_px
                     else np.stack([line_row, line_row], axis=1))
        r0, c0, w_index, l_index = _windows(line_rows, col, width_px, length_px)
        elongated = np.flatnonzero(length_px[l_index] >= options.min_elongation * width_px[w_index])
        r0, c0, w_index, l_index = (a[elongated] for a in (r0, c0, w_index, l_index))
        # S_bd first: it rejects most windows, the rest need S_int and the data check.
        s_bd = boundary_strength(features, r0, c0, width_px[w_index], length_px[l_index],
                                 band_px=band_px)
        keep = np.flatnonzero(s_bd >= options.t_bd)
        r0, c0, w_index, l_index, s_bd = (a[keep] for a in (r0, c0, w_index, l_index, s_bd))
        w, length = width_px[w_index], length_px[l_index]
        s_int = interior_strength(features, r0, c0, w, length)
        keep = (s_int >= options.t_int) & (valid_fraction(features, r0, c0, w, length)
                                         >= options.min_valid_fraction)
        keep &= _centre_line_inside(features.to_image, intensity.shape, r0, c0, w, length,
                                    overhang_px=options.overhang_m / cell_m)
        if options.edge_ratio > 0:
            at = np.flatnonzero(keep)
            keep[at] = sides_on_strongest_edges(
                features, r0[at], c0[at], w[at], length[at], edge_band_px=edge_band_px,
                slack_px=edge_slack_px, ratio=options.edge_ratio, min_step=options.edge_min_step,
                end_px=int(round(options.edge_end_m / cell_m)))
        keep = np.flatnonzero(keep)
        found.append(np.stack([r0[keep], c0[keep], w_index[keep], l_index[keep],
                               np.full(len(keep), index), s_bd[keep], s_int[keep]], axis=1))
        to_map.append(compose(image.transform, features.to_image))
    report(progress, 1.0, "road hypotheses done")

    found = np.concatenate(found) if found else np.empty((0, 7))
    score = options.beta_bd * found[:, 5] + options.beta_int * found[:, 6]
    order = np.argsort(-score, kind="stable")[:options.max_hypotheses]
    found, score = found[order], score[order]
    r0, c0, w_index, l_index, o_index = found[:, :5].astype(np.int64).T
    polygons, x0, y0 = _rectangles_on_map(np.array(to_map).reshape(-1, 9)[o_index], r0, c0,
                                          width_px[w_index], length_px[l_index])
    columns = {"hyp_id": np.arange(len(found), dtype=np.int64), "x0_m": x0, "y0_m": y0,
               "theta_rad": orientations_rad[o_index],
               "width_m": widths_m[w_index], "length_m": lengths_m[l_index],
               "s_bd": found[:, 5], "s_int": found[:, 6], "score": score,
               "width_index": w_index}
    return gpd.GeoDataFrame(columns, geometry=gpd.GeoSeries(polygons, crs=image.crs),
                            crs=image.crs)


def _votes_at_cells(frame_shape, cells_read, n_maps: int, map_index, r0, c0, width_px,
                    length_px, vote) -> np.ndarray:
    """Per map, the sum of the votes of the windows of a rotated grid covering given cells.

    A summed-area table run backwards: +v and -v at the four corners of each window (clipped
    to the grid) in its map, then cumulative sums along both grid axes; then read at the
    flat cell indices ``cells_read`` (``row' * cols' + col'``).

    Returns
    -------
    ndarray, shape (n_maps,) + cells_read.shape
    """
    rows_f, cols_f = frame_shape
    r_start, r_stop = np.clip(r0, 0, rows_f), np.clip(r0 + width_px, 0, rows_f)
    c_start, c_stop = np.clip(c0, 0, cols_f), np.clip(c0 + length_px, 0, cols_f)
    size = (rows_f + 1) * (cols_f + 1)
    cells = np.concatenate([map_index * size + r * (cols_f + 1) + c for r, c in
                            [(r_start, c_start), (r_start, c_stop), (r_stop, c_start),
                             (r_stop, c_stop)]])
    # Votes in whole multiples of 2**-20 keep every partial sum an integer below 2**53, so
    # the float sums are exact: a cell no window covers gets exactly 0, not a rounding
    # residue of the +v/-v pairs.
    quanta = np.round(np.asarray(vote, float) * VOTE_QUANTA)
    weights = np.concatenate([quanta, -quanta, -quanta, quanta])
    shape = (n_maps, rows_f + 1, cols_f + 1)
    table = np.bincount(cells, weights, n_maps * size).reshape(shape)
    np.cumsum(table, axis=1, out=table)
    np.cumsum(table, axis=2, out=table)
    # the table has a spare last row and column: cell (r, c) is at r * (cols' + 1) + c
    flat = cells_read + cells_read // cols_f
    return np.take(table.reshape(n_maps, -1), flat, axis=1) / VOTE_QUANTA


def likelihood_maps(hypotheses: gpd.GeoDataFrame, image: GeoRaster, *,
                    widths_m=DEFAULT_WIDTHS_M, beta_bd: float = 1.0, beta_int: float = 1.0,
                    l_max: float = L_MAX) -> GeoRaster:
    """Road likelihood maps L_k, one per window width, Eq. (5).

    Every hypothesis of width ``widths_m[k]`` adds ``beta_bd * s_bd + beta_int * s_int`` to
    the pixels whose centres it covers in map k; the sums are capped at ``l_max``, above
    which a pixel is surely road. The result is that of rasterising the rectangles with
    ``rasterio.features.rasterize(..., merge_alg=MergeAlg.add)``, computed instead on the
    rotated grid of each orientation (:func:`gisroads.features.rectangles.rotated_frame`),
    where the rectangles of :func:`road_hypotheses` have whole-pixel corners: a summed-area
    table costs O(pixels) per orientation where rasterising costs the area of every
    rectangle (seconds for the tens of thousands of overlapping windows of a tile).

    Parameters
    ----------
    hypotheses : GeoDataFrame
        From :func:`road_hypotheses` on the same grid: ``x0_m, y0_m, theta_rad, width_m,
        length_m, s_bd, s_int``. Rectangles are snapped to the pixel lattice of their
        orientation's rotated grid (a no-op for those).
    image : GeoRaster
        The grid of the maps: shape, north-up transform and CRS (its data is not used).
    widths_m : sequence of float
        One map per width, in this order; other widths are left out.
    beta_bd, beta_int : float
        Weights of the two strengths.
    l_max : float
        The cap L_max (:data:`L_MAX`).

    Returns
    -------
    GeoRaster
        ``(K, rows, cols)`` float32 in [0, ``l_max``], on the image's grid.
    """
    _check_north_up(image.transform)
    widths_m = np.asarray(widths_m, dtype=float)
    cell_m = image.pixel_size
    maps = np.zeros((len(widths_m),) + image.shape, dtype=np.float64)
    width = hypotheses["width_m"].to_numpy(float)
    width_index = np.argmin(np.abs(width[:, None] - widths_m[None, :]), axis=1)
    listed = np.isclose(width, widths_m[width_index])
    vote = (beta_bd * hypotheses["s_bd"].to_numpy(float)
            + beta_int * hypotheses["s_int"].to_numpy(float))
    theta = hypotheses["theta_rad"].to_numpy(float)
    col = (hypotheses["x0_m"].to_numpy(float) - image.transform.c) / cell_m
    row = (image.transform.f - hypotheses["y0_m"].to_numpy(float)) / cell_m
    width_px = np.round(width / cell_m).astype(np.int64)
    length_px = np.round(hypotheses["length_m"].to_numpy(float) / cell_m).astype(np.int64)
    centre_col, centre_row = np.meshgrid(np.arange(image.shape[1]) + 0.5,
                                         np.arange(image.shape[0]) + 0.5)
    for theta_rad in np.unique(theta[listed]):
        to_image, frame_shape = rotated_frame(image.shape, theta_rad)
        to_frame = ~to_image
        chosen = listed & (theta == theta_rad)
        c0 = np.round(to_frame.a * col + to_frame.b * row + to_frame.c).astype(np.int64)
        r0 = np.round(to_frame.d * col + to_frame.e * row + to_frame.f).astype(np.int64)
        u = np.floor(to_frame.a * centre_col + to_frame.b * centre_row + to_frame.c)
        v = np.floor(to_frame.d * centre_col + to_frame.e * centre_row + to_frame.f)
        cells_read = (np.clip(v, 0, frame_shape[0] - 1).astype(np.int64) * frame_shape[1]
                      + np.clip(u, 0, frame_shape[1] - 1).astype(np.int64))
        at = np.flatnonzero(chosen)
        maps += _votes_at_cells(frame_shape, cells_read, len(widths_m), width_index[at],
                                r0[at], c0[at], width_px[at], length_px[at], vote[at])
    return GeoRaster(np.clip(maps, 0.0, l_max).astype(np.float32), image.transform, image.crs)
