"""Road evidence from what a real airborne point cloud carries: a road-likelihood raster.

The paper's stages look at one image, the intensity of the ground. Real ALS data carries
more: the shape of the lowest surface, what stands on it, how many returns each pulse gave,
and often the agency's own classification. :func:`road_evidence` measures each of these per
cell of the lowest surface (the ground level, or a bridge deck where the file marks one),
turns each measure into a *membership* in [0, 1] ("could this cell be road, by this cue
alone?") with a piecewise-linear ramp whose ends are set by the physics of the measurement
(:class:`EvidenceRule`), and combines the memberships into one likelihood.

Cues (every point and cell through :func:`numpy.bincount` and :mod:`scipy.ndimage`):

``height``
    Lowest return of the cell above the terrain (metres). Roofs and cars are opaque: no
    pulse reaches the ground under them, so their lowest return stands 1-10 m above it;
    a kerb is 0.15 m. Full membership up to 0.25 m, none from 0.8 m (a car's bonnet).
``density``
    Returns of the ground surface per m2, as a share of the open-ground density (the 75th
    percentile over the cloud's cells). Asphalt returns every pulse; buildings leave no
    ground return and water almost none; the ground under a tree crown still gets the
    crown's gap fraction (about 0.4). None at 0.05, full from 0.3.
``pulses``
    Pulses (first returns) per m2, as a share of the cloud's median. Asphalt, concrete,
    grass and roofs return nearly every pulse at 1064 nm; water is specular and absorbs, so
    most pulses that reach it come back with nothing (on the ponds of the Megaplot forest
    plot 8-22 % of the median, their few returns dark, single and classed ground); so does a
    data gap. The count is smoothed over a window of about 12 pulses (sigma 0.75-2.5 m) and
    divided by the smoothed *footprint* (the cells with a return within ``max(1.5 m, 2.5
    cells)``), not by the window's area: at the edge of the data, where half the window
    holds no cell of the cloud, the measure is the cloud's density, not half of it. None at
    0.15, full from 0.4 (truth roads: at least 0.51 on fusa, 0.36 on the thinned IGN tile
    for 99 % of their cells, where the scan pattern and the thinning leave half the median
    in places).
``roughness``
    Residual (m, one standard deviation) of a plane fitted to the ground returns within
    the plane window. Pavement is flat to the ranging noise; grass adds a few cm, shrubs and
    rubble decimetres. Measured relative to the file's noise floor (its 10th percentile
    over the cells, at least 1 cm): full membership up to the floor + 3 cm, the rule's
    floor (0.3) from the floor + 15 cm. It only lowers the likelihood: a kerb in the window
    adds about 7 cm, and a sparse cloud's window (sigma 2.5 m) spans the camber, kerbs and
    verges of a whole street (on the thinned IGN tile, a roughness that could reach 0 was
    what lost 70 % of the truth road cells the likelihood missed).
``slope``
    Gradient of that plane (rise over run). Streets rarely exceed 10 %, hardly ever 25 %.
``intensity``
    Mean intensity of the ground returns (split-pulse returns brought to the single-return
    scale as in :mod:`gisroads.lidar.intensity`), as a ratio to the bright ground (the 90th
    percentile over the cells: grass, whose 1064 nm reflectance is 0.4-0.6). Asphalt
    reflects 0.05-0.15 at 1064 nm when fresh or typical (up to 0.25 worn), concrete
    0.3-0.45: full membership up to a ratio of 0.3, none from 0.6, where worn asphalt ends
    (0.25 over grass at 0.4-0.5) and the concrete and paving of footpaths, kerbs, medians and
    plazas begin. Of the full ends 0.25, 0.3 and 0.4, 0.3 separated the roads of a synthetic
    scene best (its asphalt over grass is 0.27, concrete 0.67). The none end was 0.8 before:
    footpaths along the roads then scored about 0.75 and joined the carriageways in the
    mask (``bench/lidar_evidence_network.py``, network at threshold 0.8: fusa correctness
    0.464 -> 0.513, 0.713 -> 0.803 counting its car-park aisles, completeness 0.800 ->
    0.750, which the network stage's hysteresis brings back; no false road left on zurich
    or the extra-bytes file). A concrete road as bright as grass is not seen by this cue.
``returns``
    Share of the cell's returns that come from pulses with several returns (vegetation, edges
    of roofs). A road is open to the sky but may lie under a street tree, so this cue only
    lowers the likelihood: full membership up to 0.15, the rule's floor (0.3) from 0.75.
``classification``
    When the file classifies its points (it has class 2, ground): ground is class 2, the
    road surface class 11 and a bridge deck class 17 (the surface where the file has it);
    other points are never ground, and noise (classes 7, 18) is left out. Membership: one
    minus the share of the cell's low returns (within ``height`` of the terrain) that are
    low vegetation, buildings or water (classes 3, 6, 9); when the file has road-surface
    points (class 11), also times ``0.3 + 0.7 * share of class 11`` among them.

``kerbs``
    Medians and traffic islands between two carriageways, known by their kerbs (beyond the
    paper). A kerb is a 10-20 cm step of the ground surface: the lowest ground return per
    cell, smoothed at sigma 0.5 m, minus its trend at 3 m, has a gradient of at least
    :data:`KERB_GRADIENT` (0.06: on 0.5 m cells a clean step of h metres peaks at about
    0.5 h per metre, so 0.06 is a 12 cm kerb; ranging noise lets most 10 cm ones through).
    The paved cells (likelihood of the other cues at least
    :data:`PAVED_LIKELIHOOD`, the network stage's low threshold) in which a disk of
    :data:`LANE_RADIUS_M` (1.5 m: a lane fits, a 1.5-3 m sidewalk between kerbs does not)
    fits once the kerbs are out are the carriageways; paved cells outside them that a 2 m
    closing of the carriageways spans lie between two of them (the kerbs and paved nose of a
    raised median); a band of them at least :data:`MEDIAN_LENGTH_M` long (a car: shorter
    bands are notches of a carriageway's edge) gets membership 0, every other cell 1. A
    gate: with the median's nose out, the carriageways on either side stay apart and the
    network stage draws one centre line on each. Cells over 1 m cannot resolve a kerb: the
    cue is then missing.

Without a classification the terrain is the progressive morphological filter of the
lowest returns (Zhang et al. 2003: openings of growing windows, each cell kept while it
rises less than ``dh0_m + slope * window growth`` above the opening, up to ``dh_max_m``),
and the ground returns are those within ``ground_tolerance_m`` of it.

**Rule.** Two kinds of cue. *Gates* say where a road cannot be: ``height`` (a roof, a
car), ``density`` (a building, water), ``pulses`` (water, a data gap), ``slope`` and
``classification`` (vegetation, building, water classes at the ground); their memberships
multiply. ``kerbs`` is a gate on the likelihood the others give (it needs their paved
cells). *Graded* cues say what
the surface looks like: ``intensity`` (weight 2: the only cue that tells pavement from
grass), ``roughness`` (1) and ``returns`` (0.5); they enter as their weighted geometric
mean, ``G = exp(sum w_k log m_k / sum w_k)``, so that three cues at 0.8 give 0.8 rather
than 0.51. The likelihood is ``L = (product of the gates) * G``. A cue missing from the
file (no intensity, a single return per pulse, no classes) or without a value in a cell
(too few returns for the plane) is left out there; the cues used are recorded in
:attr:`RoadEvidence.used`, the missing ones with the reason in :attr:`RoadEvidence.missing`.

**Cells and windows.** Cells are ``cell_m`` (default: 0.5 m, or one mean point spacing for
sparser clouds, as :func:`gisroads.lidar.intensity.auto_cell_m`). Per-cell sums are
smoothed by Gaussians (normalised convolution), which also fills scan-line gaps: the
intensity, height, returns and class window holds about 3 ground returns (sigma at least
half a cell), the plane window about 12 (sigma 0.75-2.5 m; a plane needs 5 returns).
The terrain under buildings is the mean of the ground around them (normalised convolution
at growing scales). Cells with no return within ``max(1.5 m, 2.5 cells)`` are outside the
data: NaN.

**Car-park aisles.** No cue of a cell tells a car park's asphalt from a road's; what
lines its aisles does: :func:`vehicle_cells` marks the objects of a vehicle's height,
:func:`vehicle_flank_share` measures how much of a network road's flanks they cover and
:func:`without_car_park_aisles` sets the likelihood of the lined roads to 0 for a second
run of the network stage (beyond the paper, like this whole module); the pipeline keeps
the aisles as service ways in their own layer
(:func:`gisroads.lidar.pipeline.service_lines`).

**Shores.** Once the ponds are out, the open ground left between a pond and the forest is a
strip as wide as a street, flat, open to the sky, and skeletonised into a road. What lines
it is the water: :func:`dropout_cells` marks the cells of the ``pulses`` cue's none end, and
:func:`without_flanked_roads` takes a network road whose flanks (:func:`flank_share`,
0.5-5.5 m past its edges, both sides) are at least :data:`SHORE_FLANK_SHARE` (0.1) dropouts
out, with the car-park aisles, before the second run of the network stage. Roads of the
truth measure 0.0 (fusa, the IGN tile, the synthetic scenes; every line of the IGN tile's
network at most 0.011, autzen's by its river up to 0.12); Megaplot's two shores 0.16 and
0.18 (0.5 would be one flank all water: a curved shore's flank also reaches the forest). A
road along a lake or river with no verge between it and the water is lost the same way
(beyond the paper, like this whole module).

Figures: ``docs/lidar.md`` (measured by ``make bench`` and ``bench/lidar_evidence*.py``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy import ndimage

from ..errors import GisroadsError
from ..features.kerbs import KERB_GRADIENT, kerb_steps
from ..geo import GeoRaster, free_line_ends
from ..io.las import (BRIDGE_DECK_CLASS, GROUND_CLASS, NOISE_CLASSES, NOT_ROAD_CLASSES,
                      ROAD_SURFACE_CLASS, PointCloud)
from ..network.rasters import without_lines
from ..progress import Progress, report
from .intensity import auto_cell_m, image_grid, split_share

FILL_SIGMA_M = 16.0
"""Widest Gaussian (sigma, metres) that fills the terrain under buildings; beyond it the
nearest ground."""
#: Likelihood of a paved cell for the ``kerbs`` cue: the network stage's low threshold
#: (``gisroads.lidar.pipeline.EVIDENCE_PARTS`` takes it from here).
PAVED_LIKELIHOOD = 0.6
#: A carriageway holds a disk of this radius once its kerbs are out, metres.
LANE_RADIUS_M = 1.5
#: Paved cells between two carriageways form a median's band when at least this long
#: (bounding-box diagonal), metres: shorter bands are notches of a carriageway's edge.
MEDIAN_LENGTH_M = 5.0
CARRIAGEWAY_SPAN_M = 8.0
CARRIAGEWAY_DEPTH_M = (0.06, 0.03)
CARRIAGEWAY_TOO_DEEP_M = (0.25, 0.40)
CARRIAGEWAY_LENGTH_M = 40.0
TROUGH_SMOOTHING_M = 0.5

@dataclass(frozen=True)
class EvidenceRule:
    """Membership ramps and weights of :func:`road_evidence` (see the module docstring).

    Each ramp is ``(full, none)``: the membership is 1 at ``full``, 0 (or the cue's floor)
    at ``none``, linear between; ``full > none`` for measures where high means road.

    Attributes
    ----------
    height_m : (float, float)
        Lowest return above the terrain, metres.
    density : (float, float)
        Ground-return density as a share of the open-ground density.
    roughness_m : (float, float)
        Plane residual above the file's noise floor, metres.
    slope : (float, float)
        Plane gradient, rise over run.
    pulses : (float, float)
        Pulse density (first returns) as a share of the cloud's typical pulse density.
    intensity : (float, float)
        Ground intensity as a ratio to the bright ground.
    returns : (float, float)
        Share of returns from multi-return pulses.
    returns_floor, roughness_floor : float
        Lowest membership these cues can give.
    gates : tuple of str
        Cues whose memberships multiply.
    weights : tuple of (str, float)
        The other cues and their weights in the geometric mean (a cue not listed weighs 0).
    """

    height_m: tuple[float, float] = (0.25, 0.8)
    density: tuple[float, float] = (0.3, 0.05)
    roughness_m: tuple[float, float] = (0.03, 0.15)
    slope: tuple[float, float] = (0.10, 0.25)
    pulses: tuple[float, float] = (0.4, 0.15)
    intensity: tuple[float, float] = (0.3, 0.6)
    returns: tuple[float, float] = (0.15, 0.75)
    returns_floor: float = 0.3
    roughness_floor: float = 0.3
    gates: tuple[str, ...] = ("height", "density", "pulses", "slope", "classification")
    weights: tuple[tuple[str, float], ...] = (
        ("intensity", 2.0), ("roughness", 1.0), ("returns", 0.5))


@dataclass(frozen=True)
class EvidenceReferences:
    """The cloud-wide references the measures are normalised by (module docstring).

    Measured on the cloud given to :func:`road_evidence`; pass those of a whole file back in
    when it is processed tile by tile, so that every tile is normalised alike.

    Attributes
    ----------
    open_density : float
        Ground returns per m2 of open ground.
    noise_floor_m : float
        Plane residual of the flattest ground, metres.
    bright_intensity : float or None
        Ground intensity of the bright ground (after the split-pulse gain).
    split_share : float
        Share of a pulse's intensity a return of a split pulse keeps (1: not measured).
    pulse_density : float or None
        Pulses (first returns) per m2 of the covered cells (None: not measured).
    """

    open_density: float
    noise_floor_m: float
    bright_intensity: float | None = None
    split_share: float = 1.0
    pulse_density: float | None = None


@dataclass(frozen=True)
class RoadEvidence:
    """Road likelihood of a point cloud and the cues it was made of.

    Attributes
    ----------
    likelihood : GeoRaster
        ``(rows, cols)`` float32 in [0, 1]; NaN outside the data.
    memberships : dict of str to GeoRaster
        Each cue used, its membership (float32 in [0, 1], NaN where it has no value).
    measures : dict of str to GeoRaster
        Each cue used, its raw measure (units in the module docstring).
    used : dict of str to str
        Each cue used and how it was measured.
    missing : dict of str to str
        Each cue not used and why.
    references : EvidenceReferences
    cell_m : float
    """

    likelihood: GeoRaster
    memberships: dict
    measures: dict
    used: dict
    missing: dict
    references: EvidenceReferences
    cell_m: float


def ramp(value, full: float, none: float, floor: float = 0.0) -> np.ndarray:
    """Piecewise-linear membership: 1 at ``full``, ``floor`` at ``none``, linear between
    (either order); NaN stays NaN."""
    t = np.clip((np.asarray(value, np.float64) - none) / (full - none), 0.0, 1.0)
    return floor + (1.0 - floor) * t


def _smooth(array: np.ndarray, sigma_cells: float) -> np.ndarray:
    return ndimage.gaussian_filter(array, sigma_cells, mode="constant", truncate=3.0)


def _ratio(total: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Normalised convolution: ``total / weight``, NaN where there is no weight."""
    out = np.full(total.shape, np.nan)
    np.divide(total, weight, out=out, where=weight > 1e-6)
    return out


def _cell_min(cell: np.ndarray, values: np.ndarray, size: int) -> np.ndarray:
    out = np.full(size, np.inf)
    np.minimum.at(out, cell, values)
    out[np.isinf(out)] = np.nan
    return out


def _fill_terrain(grid: np.ndarray, max_sigma_cells: float) -> np.ndarray:
    """NaN cells of a terrain grid filled by normalised convolution at growing scales: a
    Gaussian of sigma 1, 2, 4, ... cells (up to ``max_sigma_cells``) fills the cells where
    the cells with a value carry a tenth of its weight, so a hole under a building takes the
    mean of the ground around it; what is left takes the nearest value."""
    filled = grid.copy()
    known = np.isfinite(grid)
    sigma = 1.0
    while sigma <= max_sigma_cells and known.any() and not np.isfinite(filled).all():
        weight = _smooth(known.astype(float), sigma)
        near = _ratio(_smooth(np.where(known, grid, 0.0), sigma), weight)
        fill = np.isnan(filled) & (weight > 0.1)
        filled[fill] = near[fill]
        sigma *= 2.0
    return _fill_nearest(filled)


def _fill_nearest(grid: np.ndarray) -> np.ndarray:
    """NaN cells take the value of the nearest cell with one."""
    missing = np.isnan(grid)
    if not missing.any() or missing.all():
        return grid
    index = ndimage.distance_transform_edt(missing, return_distances=False,
                                           return_indices=True)
    return grid[tuple(index)]


def morphological_terrain(lowest: np.ndarray, cell_m: float, *, max_window_m: float = 40.0,
                          slope: float = 0.3, dh0_m: float = 0.3,
                          dh_max_m: float = 2.5) -> np.ndarray:
    """Terrain heights from a grid of lowest returns: the progressive morphological filter.

    Openings of windows 1, 3, 7, 15, ... cells up to ``max_window_m``; a cell stays ground
    while it rises less than ``min(dh0_m + slope * (w_k - w_(k-1)) * cell_m, dh_max_m)``
    above the opening of window ``w_k`` (Zhang et al. 2003). The terrain is the lowest
    return of the ground cells, filled from the nearest ground cell elsewhere.

    Parameters
    ----------
    lowest : ndarray, shape (rows, cols)
        Lowest return per cell, metres; NaN for empty cells.
    cell_m : float
        Cell side, metres.
    max_window_m : float
        Largest window, metres: wider than the widest building.
    slope : float
        Terrain slope allowed (rise over run).
    dh0_m, dh_max_m : float
        Initial and largest height thresholds, metres.

    Returns
    -------
    ndarray
        Terrain height per cell, metres (NaN only if ``lowest`` is all NaN).
    """
    surface = _fill_nearest(lowest)
    if np.isnan(surface).all():
        return surface
    ground = np.isfinite(lowest)
    window, previous = 3, 1
    while (window - 2) * cell_m <= max_window_m:
        opened = ndimage.grey_opening(surface, size=(window, window))
        dh = min(dh0_m + slope * (window - previous) * cell_m, dh_max_m)
        ground &= surface - opened <= dh
        surface, previous, window = opened, window, 2 * window + 1
    return _fill_terrain(np.where(ground, lowest, np.nan), FILL_SIGMA_M / cell_m)


def _disk(radius_cells: float) -> np.ndarray:
    r = int(np.ceil(radius_cells))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return xx ** 2 + yy ** 2 <= radius_cells ** 2


def carriageway_troughs(ground_low: np.ndarray, no_returns: np.ndarray, cell_m: float, *,
                        span_m: float = CARRIAGEWAY_SPAN_M,
                        depth_m: tuple[float, float] = CARRIAGEWAY_DEPTH_M,
                        too_deep_m: tuple[float, float] = CARRIAGEWAY_TOO_DEEP_M,
                        min_length_m: float = CARRIAGEWAY_LENGTH_M) -> np.ndarray:
    """Membership of the cells of carriageways between kerbs, whatever their surface.

    A carriageway with kerbs is a long trough of the ground surface, a kerb's height below
    the footways on both sides. The lowest ground return per cell (buildings' cells filled
    with the nearest ground) is closed with a disk of diameter ``span_m`` (a grey closing
    fills every trough narrower than it) after smoothing at :data:`TROUGH_SMOOTHING_M` and
    taking out the trend at ``span_m`` (Gaussian sigma: a slope or a street's crossfall would
    leave only the part below the lower rim); areas without any return at least 2 m across
    inside the cloud's convex hull (water: a canal, a pond) stand as walls, so a street
    along a quay is a trough too. The
    depth of each cell below the closed surface ramps in over ``depth_m`` and out over
    ``too_deep_m`` (ditches, steps of terrain); troughs shorter than ``min_length_m`` (their
    longest axis) are dropped.

    Parameters
    ----------
    ground_low : ndarray, shape (rows, cols)
        Lowest ground return per cell, metres; NaN without one.
    no_returns : ndarray of bool, shape (rows, cols)
        Cells without any return.
    cell_m : float
        Cell side, metres.
    span_m : float
        Widest carriageway, metres.
    depth_m, too_deep_m : (full, none)
        Ramps of the depth below the closed surface, metres.
    min_length_m : float
        Shortest carriageway, metres.

    Returns
    -------
    ndarray of float
        Membership in [0, 1].
    """
    from skimage.measure import regionprops_table
    from skimage.morphology import convex_hull_image

    known = np.isfinite(ground_low)
    out = np.zeros(ground_low.shape)
    if known.sum() < 2:
        return out
    # the closing lifts to the ranging noise's highs: smooth it away first
    sigma = max(TROUGH_SMOOTHING_M, cell_m) / cell_m
    ground = _fill_nearest(_ratio(_smooth(np.where(known, ground_low, 0.0), sigma),
                                  _smooth(known.astype(float), sigma)))
    # walls are open water inside the cloud, not the odd cell that no pulse hit nor the
    # empty margin of a tile past the cloud's edge
    walls = (ndimage.binary_opening(no_returns & ~known, structure=_disk(1.0 / cell_m))
             & convex_hull_image(~no_returns))
    # the street's crossfall and the terrain's slope out: a flat disk closes to the lower rim
    land = (known & ~walls).astype(float)
    trend = _fill_nearest(_ratio(_smooth(np.where(land > 0, ground, 0.0), span_m / cell_m),
                                 _smooth(land, span_m / cell_m)))
    detail = ground - trend
    surface = np.where(walls, np.nanmax(np.abs(detail)) + 10.0, detail)
    closed = ndimage.grey_closing(surface, footprint=_disk(span_m / 2 / cell_m))
    depth = closed - detail
    member = np.where(known, ramp(depth, *depth_m) * ramp(depth, *too_deep_m), 0.0)
    band = ndimage.binary_opening(member >= 0.5, structure=_disk(0.5 / cell_m))
    labels, count = ndimage.label(band)
    if count == 0:
        return out
    props = regionprops_table(labels, properties=("label", "axis_major_length"))
    long = np.zeros(count + 1, bool)
    long[props["label"]] = props["axis_major_length"] * cell_m >= min_length_m
    return np.where(long[labels], member, 0.0)


def _lift_carriageways(memberships: dict, measures: dict, ground_low: np.ndarray,
                       no_returns: np.ndarray, cell_m: float) -> None:
    """Add the ``carriageway`` membership and measure (:func:`carriageway_troughs` on a
    smooth, single-return surface, not a forest floor's; the measure is the trough
    membership before that condition) and raise the ``intensity`` membership to it: a
    street between kerbs is paved whatever it is paved with."""
    smooth = memberships["roughness"] >= 1.0
    if "returns" in memberships:
        smooth &= np.nan_to_num(memberships["returns"], nan=1.0) >= 1.0
    measures["carriageway"] = carriageway_troughs(ground_low, no_returns, cell_m)
    carriageway = np.where(smooth, measures["carriageway"], 0.0)
    memberships["carriageway"] = carriageway
    memberships["intensity"] = np.where(carriageway > 0,
                                        np.fmax(memberships["intensity"], carriageway),
                                        memberships["intensity"])


def median_cells(paved: np.ndarray, kerb: np.ndarray, cell_m: float, *,
                 lane_radius_m: float = LANE_RADIUS_M, closing_m: float = 2.0,
                 min_length_m: float = MEDIAN_LENGTH_M) -> np.ndarray:
    """Paved cells between two carriageways: the kerbs and paved nose of a raised median or
    traffic island (the ``kerbs`` cue of :func:`road_evidence`).

    The carriageways are the paved cells in which a disk of ``lane_radius_m`` fits once
    the kerb cells are out (a morphological opening); the paved cells outside them that a
    closing of the carriageways (disk of ``closing_m``: a median up to about twice as wide)
    spans lie between two of them, and the connected bands of those at least
    ``min_length_m`` long (bounding-box diagonal) are returned.

    Parameters
    ----------
    paved, kerb : ndarray of bool, shape (rows, cols)
        Paved cells; cells on a kerb step (:func:`kerb_steps` >= :data:`KERB_GRADIENT`).
    cell_m : float
        Cell side, metres.
    lane_radius_m, closing_m, min_length_m : float
        Metres.

    Returns
    -------
    ndarray of bool
    """
    carriageway = ndimage.binary_opening(paved & ~kerb, _disk(lane_radius_m / cell_m))
    between = ndimage.binary_closing(carriageway, _disk(closing_m / cell_m)) & ~carriageway
    between &= paved
    labels, count = ndimage.label(between, structure=np.ones((3, 3)))
    if count == 0:
        return between
    index = np.arange(1, count + 1)
    rows, cols = np.indices(labels.shape)
    extent = [ndimage.maximum(axis, labels, index) - ndimage.minimum(axis, labels, index) + 1
              for axis in (rows, cols)]
    long = np.zeros(count + 1, bool)
    long[1:] = np.hypot(*extent) * cell_m >= min_length_m
    return long[labels]


def _ground_planes(xyz: np.ndarray, window_sum, sigma_plane: float, cell_m: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Residual (metres) and gradient of a least-squares plane fitted to the ground returns
    in each cell's window; NaN where the window holds too few returns to fit one.

    ``xyz`` are the points about a local origin; ``window_sum(values)`` sums values of the
    ground returns over each cell's window (``window_sum(None)``: their count)."""
    gx, gy, gz = xyz.T
    n = window_sum(None)
    enough = n * 2 * np.pi * sigma_plane ** 2 >= 5.0  # ground returns in the window
    mean = {name: _ratio(window_sum(v), n) for name, v in (
        ("x", gx), ("y", gy), ("z", gz), ("xx", gx * gx), ("xy", gx * gy), ("yy", gy * gy),
        ("xz", gx * gz), ("yz", gy * gz), ("zz", gz * gz))}
    cxx = mean["xx"] - mean["x"] ** 2
    cxy = mean["xy"] - mean["x"] * mean["y"]
    cyy = mean["yy"] - mean["y"] ** 2
    cxz = mean["xz"] - mean["x"] * mean["z"]
    cyz = mean["yz"] - mean["y"] * mean["z"]
    czz = mean["zz"] - mean["z"] ** 2
    det = cxx * cyy - cxy ** 2
    enough &= det > (0.05 * cell_m) ** 4
    with np.errstate(invalid="ignore", divide="ignore"):
        a = (cyy * cxz - cxy * cyz) / det
        b = (cxx * cyz - cxy * cxz) / det
        residual = np.sqrt(np.clip(czz - a * cxz - b * cyz, 0.0, None))
    residual[~enough] = np.nan
    gradient = np.hypot(a, b)
    gradient[~enough] = np.nan
    return residual, gradient


def _combined_likelihood(memberships: dict, rule: EvidenceRule, shape) -> np.ndarray:
    """The rule's road likelihood from the cues' memberships: the gates multiply, the
    graded cues enter as a weighted geometric mean (a cue unknown in a cell is left out
    there)."""
    weights = dict(rule.weights)
    total = np.zeros(shape)
    weight = np.zeros(shape)
    gate = np.ones(shape)
    for name, member in memberships.items():
        known = np.isfinite(member)
        if name in rule.gates:
            gate[known] *= member[known]
        else:
            w = weights.get(name, 0.0)
            total[known] += w * np.log(np.maximum(member[known], 1e-6))
            weight[known] += w
    graded = np.exp(_ratio(total, weight))
    return np.where(np.isnan(graded), gate, gate * graded)


def _ground_intensity(cloud: PointCloud, ground: np.ndarray, cell: np.ndarray,
                      occupied: np.ndarray, references: EvidenceReferences | None,
                      ground_mean) -> tuple:
    """Mean intensity of the ground returns per cell over that of the bright ground.

    Split returns are first brought to the single-return scale. ``ground_mean(values)``
    averages values of the ground returns over each cell's neighbourhood.

    Returns
    -------
    relative : ndarray or None
        None when the file has no intensity or it has no contrast.
    text : str
        What was measured, or why nothing was.
    bright : float or None
        Intensity of the bright ground (the 90th percentile of the cells').
    share : float
        Intensity of a split return over a single one (1 when there are none).
    """
    if cloud.intensity is None:
        return None, "the file records no intensity", None, 1.0
    value = np.asarray(cloud.intensity, np.float64)
    single = np.asarray(cloud.number_of_returns) <= 1
    share, note = 1.0, ""
    if (~single).any() and single.any():
        share = references.split_share if references is not None else split_share(
            value, single, ground, cell)
        value = np.where(single, value, value / share)
        note = f", split returns / {share:.2f}"
    mean_intensity = ground_mean(value)
    has = np.isfinite(mean_intensity) & occupied
    if references is not None and references.bright_intensity is not None:
        dark, bright = 0.0, references.bright_intensity
    elif has.any():
        dark, bright = (float(v) for v in np.percentile(mean_intensity[has], [10, 90]))
    else:
        dark = bright = 0.0
    if not bright > 0 or dark >= 0.95 * bright:
        return None, ("the ground intensity has no contrast (10th and 90th percentiles "
                      "within 5 %)"), None, share
    return (mean_intensity / bright,
            f"ground intensity over the bright ground ({bright:.0f}{note})", bright, share)


def _class_membership(classes: np.ndarray, low_points: np.ndarray, count_near) -> tuple:
    """Share of the low returns near each cell in a class that is not road, the
    classification's membership, and what it used. ``count_near(mask)``: the returns of
    ``mask`` over each cell's neighbourhood."""
    n_low = count_near(low_points)
    bad = _ratio(count_near(low_points & np.isin(classes, NOT_ROAD_CLASSES)), n_low)
    member = 1.0 - bad
    note = "ground classes 2, 11, 17; low classes 3, 6, 9 are not road"
    road_points = low_points & (classes == ROAD_SURFACE_CLASS)
    if road_points.any():
        member = member * (0.3 + 0.7 * _ratio(count_near(road_points), n_low))
        note += "; road surface class 11"
    return bad, member, note


def _cell_grid(x: np.ndarray, y: np.ndarray, bounds, cell_m: float | None) -> tuple:
    """Transform, shape and cell side (metres) of the evidence grid over ``bounds`` (default:
    the points'); the cell side by default from the density of the points inside."""
    if bounds is None:
        bounds = (x.min(), y.min(), x.max(), y.max())
    if cell_m is None:
        area = max((bounds[2] - bounds[0]) * (bounds[3] - bounds[1]), 1.0)
        count = ((x >= bounds[0]) & (x <= bounds[2]) & (y >= bounds[1]) & (y <= bounds[3]))
        cell_m = auto_cell_m(int(count.sum()), area)
    transform, shape = image_grid(bounds, cell_m)
    return transform, shape, cell_m


def road_evidence(cloud: PointCloud, *, cell_m: float | None = None, bounds=None,
                  rule: EvidenceRule = EvidenceRule(), use_classification: bool = True,
                  ground_tolerance_m: float = 0.25,
                  references: EvidenceReferences | None = None,
                  progress: Progress = None) -> RoadEvidence:
    """Road likelihood per cell of the lowest surface of a point cloud.

    Cues, their memberships and the rule that combines them: see the module docstring.

    Parameters
    ----------
    cloud : PointCloud
        Metres (:func:`gisroads.io.las.read_las`).
    cell_m : float, optional
        Cell side, metres. Default: 0.5 m, or one mean point spacing for sparser clouds
        (:func:`gisroads.lidar.intensity.auto_cell_m`; 1.9 m on the thinned IGN tile).
    bounds : (xmin, ymin, xmax, ymax), optional
        Metres, snapped outward to the cell grid. Default: the cloud's bounds.
    rule : EvidenceRule
        Membership ramps and weights.
    use_classification : bool
        Use the file's classification when it has one (class 2 present).
    ground_tolerance_m : float
        Without a classification, returns within this of the terrain are ground, metres.
    references : EvidenceReferences, optional
        Normalise by these rather than by what this cloud measures (tiles of one file).
    progress : callable, optional
        ``progress(fraction, message)`` at each cue; may raise
        :class:`gisroads.progress.Cancelled`.

    Returns
    -------
    RoadEvidence
    """
    xyz = np.asarray(cloud.xyz, np.float64)
    if len(xyz) == 0:
        raise GisroadsError("the cloud holds no points")
    x, y, z = xyz.T
    classes = np.asarray(cloud.classification)
    classified = use_classification and bool((classes == GROUND_CLASS).any())
    transform, (rows, cols), cell_m = _cell_grid(x, y, bounds, cell_m)
    size = rows * cols
    col = np.floor((x - transform.c) / cell_m).astype(np.int64)
    row = np.floor((transform.f - y) / cell_m).astype(np.int64)
    inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
    if classified:
        inside &= ~np.isin(classes, NOISE_CLASSES)
    cell = np.where(inside, row * cols + col, 0)

    def grid(values, mask=inside):
        return np.bincount(cell[mask], weights=None if values is None else values[mask],
                           minlength=size).reshape(rows, cols).astype(np.float64)

    used, missing, measures, memberships = {}, {}, {}, {}

    report(progress, 0.0, "terrain")
    # Terrain and the returns of the lowest surface.
    if classified:
        deck = inside & (classes == BRIDGE_DECK_CLASS)
        deck_cell = grid(None, deck).ravel() > 0
        ground = inside & np.isin(classes, (GROUND_CLASS, ROAD_SURFACE_CLASS)) & ~deck_cell[cell]
        ground |= deck
        terrain = _fill_terrain(_cell_min(cell[ground], z[ground], size).reshape(rows, cols),
                                FILL_SIGMA_M / cell_m)
    else:
        lowest = _cell_min(cell[inside], z[inside], size).reshape(rows, cols)
        terrain = morphological_terrain(lowest, cell_m)
        ground = inside & (z - terrain.ravel()[cell] <= ground_tolerance_m)
    height = z - terrain.ravel()[cell]

    occupied = grid(None) > 0
    reach = max(1.5, 2.5 * cell_m) / cell_m
    footprint = ndimage.distance_transform_edt(~occupied) <= reach
    n_ground = grid(None, ground)
    ground_density = n_ground.sum() / max(occupied.sum(), 1) / cell_m ** 2
    sigma_local = max(0.5, np.sqrt(3.0 / (2 * np.pi * max(ground_density, 1e-6))) / cell_m)
    sigma_plane = np.clip(np.sqrt(12.0 / (2 * np.pi * max(ground_density, 1e-6))),
                          0.75, 2.5) / cell_m
    n_all_s = _smooth(grid(None), sigma_local)

    # height: lowest return above the terrain, per cell, then smoothed over the cells
    low = _cell_min(cell[inside], height[inside], size).reshape(rows, cols)
    h_member = ramp(low, *rule.height_m)
    measures["height"] = low
    memberships["height"] = _ratio(_smooth(np.nan_to_num(h_member), sigma_local),
                                   _smooth(np.isfinite(low).astype(float), sigma_local))
    used["height"] = "lowest return above the terrain (" + (
        "class-2 ground" if classified else "morphological filter") + ")"

    report(progress, 0.3, "height, density and pulses")
    # density of the ground returns, relative to the open ground
    density = _smooth(n_ground, sigma_plane) / cell_m ** 2
    open_density = (references.open_density if references is not None else
                    float(np.percentile(density[occupied], 75)))
    measures["density"] = density / max(open_density, 1e-9)
    memberships["density"] = ramp(measures["density"], *rule.density)
    used["density"] = f"ground returns per m2 over {open_density:.2f} (open ground)"

    # pulses: first returns per m2 of the footprint, relative to the cloud's typical density
    first = inside & (np.asarray(cloud.return_number) <= 1)
    n_first = grid(None, first)
    mean_pulses = n_first.sum() / max(occupied.sum(), 1) / cell_m ** 2
    sigma_pulse = np.clip(np.sqrt(12.0 / (2 * np.pi * max(mean_pulses, 1e-6))),
                          0.75, 2.5) / cell_m
    pulses = _ratio(_smooth(n_first, sigma_pulse),
                    _smooth(footprint.astype(float), sigma_pulse)) / cell_m ** 2
    if references is not None and references.pulse_density is not None:
        pulse_density = references.pulse_density
    else:
        pulse_density = float(np.nanmedian(pulses[occupied])) if occupied.any() else 0.0
    if pulse_density > 0:
        measures["pulses"] = pulses / pulse_density
        memberships["pulses"] = ramp(measures["pulses"], *rule.pulses)
        used["pulses"] = f"pulses per m2 over {pulse_density:.2f} (the cloud's median)"
    else:
        missing["pulses"] = "no pulse density"

    report(progress, 0.45, "ground planes")
    # roughness and slope: a plane fitted to the ground returns in the plane window
    residual, gradient = _ground_planes(
        xyz - [transform.c, transform.f, np.median(z[ground]) if ground.any() else 0.0],
        lambda values: _smooth(grid(values, ground), sigma_plane), sigma_plane, cell_m)
    enough = np.isfinite(residual)
    if references is not None:
        floor = references.noise_floor_m
    else:
        floor = max(float(np.nanpercentile(residual, 10)) if enough.any() else 0.0, 0.01)
    measures["roughness"], measures["slope"] = residual, gradient
    memberships["roughness"] = ramp(residual - floor, *rule.roughness_m,
                                    floor=rule.roughness_floor)
    memberships["slope"] = ramp(gradient, *rule.slope)
    used["roughness"] = f"plane residual above the noise floor {floor * 100:.1f} cm"
    used["slope"] = "plane gradient"

    report(progress, 0.7, "intensity, returns and classes")
    # intensity of the ground returns
    relative, text, bright, share = _ground_intensity(
        cloud, ground, cell, occupied, references,
        lambda values: _ratio(_smooth(grid(values, ground), sigma_local),
                              _smooth(n_ground, sigma_local)))
    if relative is None:
        missing["intensity"] = text
    else:
        measures["intensity"] = relative
        memberships["intensity"] = ramp(relative, *rule.intensity)
        used["intensity"] = text

    # returns: share of returns from multi-return pulses
    multi = np.asarray(cloud.number_of_returns) > 1
    if not multi.any():
        missing["returns"] = "every pulse has one return"
    else:
        measures["returns"] = _ratio(_smooth(grid(multi.astype(float)), sigma_local), n_all_s)
        memberships["returns"] = ramp(measures["returns"], *rule.returns,
                                      floor=rule.returns_floor)
        used["returns"] = "share of returns from multi-return pulses"

    # classification
    if not classified:
        missing["classification"] = ("not asked for" if not use_classification
                                     else "the file has no ground class (2)")
    else:
        measures["classification"], memberships["classification"], used["classification"] \
            = _class_membership(classes, inside & (height <= rule.height_m[1]),
                                lambda points: _smooth(grid(None, points), sigma_local))

    report(progress, 0.85, "kerbs and the rule")
    # kerbs: medians and islands between two carriageways, on the likelihood of the others
    if cell_m > 1.0:
        missing["kerbs"] = f"cells of {cell_m:.2f} m cannot resolve a kerb (at most 1 m)"
    else:
        ground_low = _cell_min(cell[ground], z[ground], size).reshape(rows, cols)
        steps = kerb_steps(ground_low, cell_m)
        measures["kerbs"] = steps
        used["kerbs"] = f"medians between carriageways (ground steps >= {KERB_GRADIENT})"
        if "intensity" in memberships:
            _lift_carriageways(memberships, measures, ground_low, ~occupied, cell_m)
            used["carriageway"] = ("troughs between kerbs (any surface): their intensity "
                                   "need not be asphalt's")

    likelihood = _combined_likelihood(memberships, rule, (rows, cols))
    if "kerbs" in measures:
        median = median_cells(likelihood >= PAVED_LIKELIHOOD,
                              np.nan_to_num(measures["kerbs"]) >= KERB_GRADIENT, cell_m)
        memberships["kerbs"] = np.where(median, 0.0, 1.0)
        likelihood[median] = 0.0
    likelihood[likelihood < 1e-5] = 0.0
    likelihood[~footprint] = np.nan

    def raster(array):
        return GeoRaster(np.asarray(array, np.float32), transform, cloud.crs, nodata=np.nan)

    report(progress, 1.0, "road evidence")
    return RoadEvidence(
        likelihood=raster(likelihood),
        memberships={k: raster(np.where(footprint, v, np.nan)) for k, v in memberships.items()},
        measures={k: raster(np.where(footprint, v, np.nan)) for k, v in measures.items()},
        used=used, missing=missing, references=EvidenceReferences(
            open_density=open_density, noise_floor_m=floor, bright_intensity=bright,
            split_share=share, pulse_density=pulse_density), cell_m=float(cell_m))


#: Lowest return above the terrain of an object of a vehicle's height (car 1.4-1.9 m, van
#: up to 2.5 m), metres: :func:`vehicle_cells`.
VEHICLE_HEIGHT_M = (0.8, 2.5)
#: A road's flank (:func:`flank_share`) starts this far past its edge and is this deep,
#: metres: a row of parked cars beside an aisle is about 5 m deep.
FLANK_GAP_M, FLANK_DEPTH_M = 0.5, 5.0
#: A road whose flanks are at least this share vehicle cells is a car-park aisle
#: (:func:`without_car_park_aisles`).
CAR_PARK_FLANK_SHARE = 0.15
#: A road whose flanks are at least this share pulse dropouts (:func:`dropout_cells`) is a
#: shore or the rim of a clearing around a pond (:func:`without_flanked_roads`).
SHORE_FLANK_SHARE = 0.1
#: The band around a road's edge where :func:`kerb_share` looks for its kerb, metres.
KERB_INSIDE_M = 1.5
KERB_OUTSIDE_M = 2.5
#: A road whose sides a kerb lines less than this share of their length has none
#: (:func:`kerb_share`); an area is kerbed where at least half its road length has them
#: (:func:`without_unkerbed_ways`). On synthetic kerbed streets (300 m scenes, 4.4 and 10
#: points/m2) the kerbed lines score 0.33-0.95, the same streets without kerbs 0, the lanes
#: of a car park (no kerbs) 0.16-0.24.
UNKERBED_SHARE = 0.3
KERBED_NETWORK_SHARE = 0.5
#: A road shorter than this is mostly the mouths at its ends, where kerbs stop: its sides
#: are not read (:func:`without_unkerbed_ways`), metres.
UNKERBED_MIN_LENGTH_M = 20.0
#: A carriageway's flank reaches 0.5 + 5 m past its edge (:func:`flank_share`): water that
#: near a kerbed carriageway is a canal beside a street, metres (:func:`dropout_cells`).
QUAY_M = 6.0


def vehicle_cells(evidence: RoadEvidence, *, height_m: tuple[float, float] = VEHICLE_HEIGHT_M,
                  max_multi_return: float = 0.3) -> GeoRaster:
    """Cells holding an object of a vehicle's height: a parked car, a van.

    The cell's lowest return stands ``height_m`` above the terrain (lower: a kerb, a low
    wall; higher: a roof), and few of its returns come from multi-return pulses (a car is
    opaque; a shrub or a tree crown of that height splits pulses). Closed over one cell,
    which bridges the scan-line gaps of a sparse cloud.

    Parameters
    ----------
    evidence : RoadEvidence
        Its ``height`` and (when the file has it) ``returns`` measures.
    height_m : (float, float)
        Lowest return above the terrain, metres.
    max_multi_return : float
        Largest share of returns from multi-return pulses.

    Returns
    -------
    GeoRaster
        float32 on the evidence's grid: 1 on vehicle cells, 0 elsewhere, NaN where the cell
        has no return (a scan gap).
    """
    low = np.asarray(evidence.measures["height"].data, np.float64)
    with np.errstate(invalid="ignore"):
        vehicle = (low >= height_m[0]) & (low <= height_m[1])
        if "returns" in evidence.measures:
            vehicle &= ~(np.asarray(evidence.measures["returns"].data) > max_multi_return)
    vehicle |= ndimage.binary_closing(vehicle)
    out = np.where(vehicle, 1.0, np.where(np.isfinite(low), 0.0, np.nan)).astype(np.float32)
    raster = evidence.likelihood
    return GeoRaster(out, raster.transform, raster.crs, nodata=np.nan)


def flank_share(centrelines, cells: GeoRaster, *, gap_m: float = FLANK_GAP_M,
                depth_m: float = FLANK_DEPTH_M) -> np.ndarray:
    """Per road, the share of its two flanks covered by marked cells (vehicles:
    :func:`vehicle_cells`; pulse dropouts: :func:`dropout_cells`).

    A flank is the band from ``width / 2 + gap_m`` to ``width / 2 + gap_m + depth_m`` on
    either side of the centre line, sampled every cell along offset lines; samples outside
    the raster or on cells without a return are left out. A car-park aisle is lined by rows
    of parked cars about 5 m deep; a road by kerbs, verges, footpaths and buildings (cars
    parked along its kerb stand inside its width).

    Parameters
    ----------
    centrelines : GeoDataFrame
        LineStrings with ``width_m`` (:func:`gisroads.network.rasters.raster_to_network`),
        in the raster's CRS.
    cells : GeoRaster
        1 marked, 0 not, NaN unknown.
    gap_m, depth_m : float
        Start of the flank past the road's edge, and its depth, metres.

    Returns
    -------
    ndarray of float
        One share in [0, 1] per road (0 for a road without a flank sample).
    """
    lines = np.asarray(centrelines.geometry.values, dtype=object)
    if len(lines) == 0:
        return np.zeros(0)
    cell = cells.pixel_size
    half = np.asarray(centrelines["width_m"], np.float64) / 2 + gap_m
    hits = np.zeros(len(lines))
    count = np.zeros(len(lines))
    data = np.asarray(cells.data)
    for offset in np.arange(cell / 2, depth_m, cell):
        for side in (-1.0, 1.0):
            curves = shapely.offset_curve(lines, side * (half + offset))
            points, owner = shapely.get_coordinates(shapely.segmentize(curves, cell),
                                                    return_index=True)
            rows, cols = cells.xy_to_rowcol(points[:, 0], points[:, 1])
            inside = (rows >= 0) & (rows < data.shape[0]) & (cols >= 0) & (cols < data.shape[1])
            value = np.full(len(points), np.nan)
            value[inside] = data[rows[inside], cols[inside]]
            seen = np.isfinite(value)
            count += np.bincount(owner[seen], minlength=len(lines))
            hits += np.bincount(owner[seen], weights=value[seen], minlength=len(lines))
    return hits / np.maximum(count, 1)


def vehicle_flank_share(centrelines, vehicles: GeoRaster, **options) -> np.ndarray:
    """Per road, the share of its two flanks covered by vehicles (:func:`vehicle_cells`):
    :func:`flank_share`."""
    return flank_share(centrelines, vehicles, **options)


def kerb_cells(evidence: RoadEvidence) -> GeoRaster:
    """Cells on a kerb: a step of the ground surface of at least :data:`KERB_GRADIENT`
    (:func:`gisroads.features.kerbs.kerb_steps`).

    Parameters
    ----------
    evidence : RoadEvidence
        Its ``kerbs`` measure (absent on cells over 1 m: every cell is then unknown).

    Returns
    -------
    GeoRaster
        float32 on the evidence's grid: 1 on a kerb, 0 elsewhere, NaN where the ground
        surface is unknown.
    """
    raster = evidence.likelihood
    steps = evidence.measures.get("kerbs")
    if steps is None:
        out = np.full(raster.data.shape, np.nan, np.float32)
    else:
        values = np.asarray(steps.data, np.float64)
        with np.errstate(invalid="ignore"):
            out = np.where(values >= KERB_GRADIENT, 1.0,
                           np.where(np.isfinite(values), 0.0, np.nan)).astype(np.float32)
    return GeoRaster(out, raster.transform, raster.crs, nodata=np.nan)


def kerb_share(centrelines, kerbs: GeoRaster, *, inside_m: float = KERB_INSIDE_M,
               outside_m: float = KERB_OUTSIDE_M) -> np.ndarray:
    """Per road, the share of its sides that a kerb lines (:func:`kerb_cells`).

    At stations every cell along the centre line, each side's band from ``inside_m`` inside
    to ``outside_m`` outside the road's edge (``width / 2`` from the centre line) is lined
    when one of its cells is a kerb; sides whose band has no known cell are left out. A
    kerbed street scores near 1, a way without kerbs (a drive across a footway, a paved
    path, an access strip) near 0.

    Parameters
    ----------
    centrelines : GeoDataFrame
        LineStrings with ``width_m``, in the raster's CRS.
    kerbs : GeoRaster
        1 kerb, 0 not, NaN unknown.
    inside_m, outside_m : float
        The band around the edge, metres: the extracted width is about a cell or two off.

    Returns
    -------
    ndarray of float
        One share in [0, 1] per road; NaN for a road without a known side.
    """
    lines = np.asarray(centrelines.geometry.values, dtype=object)
    if len(lines) == 0:
        return np.zeros(0)
    cell = kerbs.pixel_size
    length = shapely.length(lines)
    count = np.maximum(np.ceil(length / cell).astype(np.int64), 1) + 1
    owner = np.repeat(np.arange(len(lines)), count)
    start = np.repeat(np.cumsum(count) - count, count)
    along = (np.arange(owner.size) - start) / (count[owner] - 1) * length[owner]
    ahead = shapely.get_coordinates(shapely.line_interpolate_point(
        lines[owner], np.minimum(along + cell / 2, length[owner])))
    behind = shapely.get_coordinates(shapely.line_interpolate_point(
        lines[owner], np.maximum(along - cell / 2, 0.0)))
    centre = shapely.get_coordinates(shapely.line_interpolate_point(lines[owner], along))
    tangent = ahead - behind
    tangent /= np.maximum(np.hypot(tangent[:, 0], tangent[:, 1]), 1e-12)[:, None]
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    half = np.asarray(centrelines["width_m"], np.float64)[owner] / 2
    data = np.asarray(kerbs.data)
    lined = np.zeros(len(lines))
    seen_sides = np.zeros(len(lines))
    for side in (-1.0, 1.0):
        hit = np.zeros(owner.size, bool)
        seen = np.zeros(owner.size, bool)
        for offset in np.arange(-inside_m, outside_m + cell / 2, cell / 2):
            reach = np.maximum(half + offset, cell)
            points = centre + side * reach[:, None] * normal
            rows, cols = kerbs.xy_to_rowcol(points[:, 0], points[:, 1])
            inside = ((rows >= 0) & (rows < data.shape[0]) & (cols >= 0)
                      & (cols < data.shape[1]))
            value = np.full(owner.size, np.nan)
            value[inside] = data[rows[inside], cols[inside]]
            seen |= np.isfinite(value)
            hit |= value == 1.0
        lined += np.bincount(owner[seen], weights=hit[seen], minlength=len(lines))
        seen_sides += np.bincount(owner[seen], minlength=len(lines))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(seen_sides > 0, lined / seen_sides, np.nan)


def dropout_cells(evidence: RoadEvidence, *,
                  max_pulses: float = EvidenceRule().pulses[1],
                  quay_m: float = QUAY_M) -> GeoRaster:
    """Cells where most pulses came back with no return: water, a data gap.

    The ``pulses`` measure (first returns per m2 over the cloud's median) is at most
    ``max_pulses`` (the none end of the ``pulses`` ramp: under 15 % of the pulses). Water
    within ``quay_m`` (metres) of a carriageway between kerbs (the ``carriageway`` cue) is
    left out: a street along a canal is a street, the rim of a pond is not.

    Returns
    -------
    GeoRaster
        float32 on the evidence's grid: 1 dropout, 0 not, NaN where the measure has no value
        (outside the data; everywhere when the cloud gave no pulse density).
    """
    raster = evidence.likelihood
    measure = evidence.measures.get("pulses")
    if measure is None:
        out = np.full(raster.shape, np.nan, np.float32)
    else:
        m = np.asarray(measure.data, np.float64)
        with np.errstate(invalid="ignore"):
            out = np.where(np.isfinite(m), (m <= max_pulses).astype(float), np.nan)
        lanes = evidence.memberships.get("carriageway")
        if lanes is not None and (np.nan_to_num(lanes.data) >= 0.5).any():
            quay = ndimage.distance_transform_edt(~(np.nan_to_num(lanes.data) >= 0.5)) \
                * evidence.cell_m <= quay_m
            out[quay & np.isfinite(out)] = 0.0
    return GeoRaster(np.asarray(out, np.float32), raster.transform, raster.crs, nodata=np.nan)


def without_flanked_roads(likelihood: GeoRaster, centrelines, flanks: dict, *,
                          margin_m: float = 1.0) -> tuple[GeoRaster, object]:
    """The likelihood with the roads whose flanks are lined by what no road is lined by
    set to 0: run the network stage again on it (beyond the paper).

    Parameters
    ----------
    likelihood : GeoRaster
        The road likelihood (:attr:`RoadEvidence.likelihood`).
    centrelines : GeoDataFrame
        The roads of a network built on it (``width_m``), in its CRS.
    flanks : dict of str to (GeoRaster, float)
        A reason (``"car-park aisle"``, ``"shore"``) to the cells that mark it (1 marked, 0
        not, NaN unknown, on any grid in the likelihood's CRS) and the flank share
        (:func:`flank_share`) from which a road is taken for it. The first reason that
        applies is a road's.
    margin_m : float
        A taken road's band ``width / 2 + margin_m`` is set to 0, metres.

    Returns
    -------
    likelihood : GeoRaster
        A copy, the taken roads at 0.
    taken : GeoDataFrame
        The roads taken, with their ``reason`` and ``flank_share``.
    """
    reason = np.full(len(centrelines), "", dtype=object)
    share = np.zeros(len(centrelines))
    found = np.zeros(len(centrelines), bool)
    for name, (cells, max_share) in flanks.items():
        measured = flank_share(centrelines, cells)
        hit = ~found & (measured >= max_share)
        reason[hit], share[hit], found = name, measured[hit], found | hit
    taken = centrelines[found].assign(reason=reason[found], flank_share=share[found])
    return without_lines(likelihood, taken, margin_m=margin_m), taken


def without_unkerbed_ways(likelihood: GeoRaster, centrelines, kerbs: GeoRaster, *,
                          unkerbed_share: float = UNKERBED_SHARE,
                          kerbed_network: float = KERBED_NETWORK_SHARE,
                          min_length_m: float = UNKERBED_MIN_LENGTH_M
                          ) -> tuple[GeoRaster, object]:
    """The likelihood with the dead-end ways that no kerb lines set to 0, where the area's
    roads are kerbed (beyond the paper): run the network stage again on it.

    Where streets have kerbs, a paved way without them is a drive, an access strip across a
    footway, a path or a car park's lane, not a street (:func:`kerb_share`). Only ways with a
    dead end are taken: a through road stays a road whatever its edges. An area whose
    roads mostly lack kerbs (a village, a canal town's low kerbs, a cloud too sparse to show
    them) keeps every road.

    Parameters
    ----------
    likelihood : GeoRaster
        The road likelihood.
    centrelines : GeoDataFrame
        The roads of a network built on it (``width_m``), noded, in its CRS.
    kerbs : GeoRaster
        :func:`kerb_cells`.
    unkerbed_share : float
        A road whose :func:`kerb_share` is below this has no kerbs.
    kerbed_network : float
        The area's roads are kerbed when at least this share of their length (of the roads
        with a known side) is on roads with kerbs.
    min_length_m : float
        Shorter roads are not taken (:data:`UNKERBED_MIN_LENGTH_M`).

    Returns
    -------
    likelihood : GeoRaster
        A copy, the taken ways at 0 (the roads they join kept whole).
    taken : GeoDataFrame
        The ways taken, with ``reason`` "unkerbed way" and their ``kerb_share``.
    """
    share = kerb_share(centrelines, kerbs)
    length = shapely.length(np.asarray(centrelines.geometry.values, dtype=object))
    known = np.isfinite(share)
    found = np.zeros(len(centrelines), bool)
    if known.any():
        kerbed = length[known & (share >= unkerbed_share)].sum() / length[known].sum()
        if kerbed >= kerbed_network:
            found = (known & (share < unkerbed_share) & (length >= min_length_m)
                     & free_line_ends(centrelines.geometry.values).any(axis=1))
    taken = centrelines[found].assign(reason="unkerbed way", kerb_share=share[found])
    return (without_lines(likelihood, taken, keep=centrelines[~found],
                          spread_above=PAVED_LIKELIHOOD), taken)


def without_car_park_aisles(likelihood: GeoRaster, centrelines, vehicles: GeoRaster, *,
                            max_share: float = CAR_PARK_FLANK_SHARE, margin_m: float = 1.0
                            ) -> tuple[GeoRaster, object]:
    """The likelihood with the car-park aisles among a network's roads set to 0.

    Beyond the paper and the per-cell cues: the pavement of a car park is asphalt like a
    road's, and the aisles between its rows of cars are as wide and as long as streets, so
    no cue of a cell tells them apart; what does is what lines them. A road whose flanks
    are at least ``max_share`` vehicle cells (:func:`vehicle_flank_share`) is an aisle.
    Run the network stage again on the returned likelihood: the aisles are gone, and the
    roads they touched are joined and split as if they had never been there.

    ``max_share`` 0.15 (``bench/lidar_evidence_network.py``, network at threshold 0.8): the
    lines on the truth roads measure at most 0.128 on fusa, 0.098 on the IGN tile and 0.074
    on the synthetic scene with every feature; fusa's car-park aisles and the other lines
    taken 0.18-0.32. A full row of cars would cover about 0.7 of a flank; many of its cells
    have the ground between or beside the cars as their lowest return.

    Parameters
    ----------
    likelihood : GeoRaster
        The road likelihood (:attr:`RoadEvidence.likelihood`).
    centrelines : GeoDataFrame
        The roads of a network built on it (``width_m``), in its CRS.
    vehicles : GeoRaster
        :func:`vehicle_cells`, on the likelihood's grid.
    max_share : float
        Flank share of vehicles from which a road is an aisle.
    margin_m : float
        The aisle's band ``width / 2 + margin_m`` is set to 0, metres.

    Returns
    -------
    likelihood : GeoRaster
        A copy, aisles at 0.
    aisles : GeoDataFrame
        The roads taken for aisles, with their ``vehicle_share``.
    """
    cleared, taken = without_flanked_roads(likelihood, centrelines,
                                           {"car-park aisle": (vehicles, max_share)},
                                           margin_m=margin_m)
    return cleared, taken.drop(columns="reason").rename(
        columns={"flank_share": "vehicle_share"})
