"""Grouping of an over-segmentation into larger segments (Grote & Rottensteiner 2010, 2.1.2).

The normalized-cut over-segmentation (:func:`gisroads.imagery.segments.segment_image`)
puts most road borders on segment borders but cuts roads into many pieces. Adjacent
segments are merged iteratively with the paper's criteria:

- colour-histogram difference (roads are homogeneous in sections),
- edge strength along the shared border,
- convexity of the merged region (area / convex-hull area),
- shared border length, absolute (metres) and relative to the shorter segment perimeter,
- mean height difference from a DSM, when given (and mean NDVI difference, when given),
- beyond the paper, the mean learned road probability difference, when a probability is
  given (:mod:`gisroads.learn`): a road does not merge into a dark neighbour of its colour
  that the model does not take for road.

Each criterion value is mapped linearly to a goodness in [0, 1] between a "poor" and a
"very good" limit (:data:`CRITERIA`); fuzzy sets on it are *good* (goodness >= 0.5 fully)
and *very good* (goodness 1). Fuzzy rules (AND = min, OR = max) decide whether a pair is a
merge candidate, so that segments can be merged not only when every criterion is good but
also when one is poor and others are very good:

1. every criterion is good;
2. at least two of edge, colour and convexity are very good and the third is good: the
   relative border length is disregarded (the paper's example);
3. edge, colour and convexity are all very good: either border-length criterion may be
   poor.

Height, NDVI and road-probability differences are never disregarded: a roof is not a road
however similar its colour. Pairs whose rule strength is at least 0.5 are candidates; they
are sorted by the sum of their goodness values and, in each iteration, the best
``merge_fraction`` (the paper's 10 %) are merged; pairs that share a segment merge into one
segment.

Everything per pixel is computed once (histograms, border pixel pairs, row runs for the
convex hulls) with ``bincount`` and array shifts; the iterations then work on per-segment
and per-pair arrays only: merged statistics are sums, merged borders are re-aggregated
pair sums, and merged hulls are hulls of the two hulls' vertices.

:func:`split_branching_segments` then cuts segments whose skeleton has several long
branches: they span road junctions.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import shapely
from scipy import ndimage, sparse
from scipy.sparse.csgraph import connected_components
from skimage.measure import label as connected_regions
from skimage.morphology import skeletonize

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..progress import report
from ..segmentation.ncut import typical_scale
from .cues import ndvi as compute_ndvi, resample_to, scale_bands
from .segments import edge_strength, pixel_size_m

HISTOGRAM_BINS = 16
"""Bins per band over the stretched [0, 1] range; values are shared linearly between the
two nearest bin centres, so a colour on a bin edge does not flip between bins."""

CRITERIA = {
    # name: (poor, very good) in the criterion's units
    "colour": (0.5, 0.15),        # histogram difference, 0 (same) .. 1 (disjoint)
    "edge": (6.0, 2.0),           # mean edge along the border / the typical border edge
    "convexity": (0.5, 0.85),     # merged area / merged convex-hull area
    "border_m": (0.5, 3.0),       # shared border length, metres
    "border_rel": (0.05, 0.3),    # shared border / shorter perimeter
    "height_m": (1.5, 0.5),       # |mean DSM difference|, metres
    "ndvi": (0.25, 0.1),          # |mean NDVI difference|
    "probability": (0.5, 0.2),    # |mean learned road probability difference|
}
"""``(poor, very_good)`` limits of each criterion; goodness is linear in between."""

CANDIDATE_STRENGTH = 0.5
"""Smallest rule strength of a merge candidate."""

MIN_BRANCH_M = 10.0
"""Default length a skeleton branch must reach beyond the junction's inscribed circle to
count as a road arm (more than a road width)."""


def _goodness(value: np.ndarray, limits: tuple[float, float]) -> np.ndarray:
    poor, very_good = limits
    return np.clip((value - poor) / (very_good - poor), 0.0, 1.0)


def _compact(labels: np.ndarray) -> tuple[np.ndarray, int]:
    out = np.full(labels.shape, -1, np.int64)
    ids, inverse = np.unique(labels[labels >= 0], return_inverse=True)
    out[labels >= 0] = inverse.ravel()
    return out, len(ids)


def _pixel_pairs(labels: np.ndarray):
    """Flat indices of the two pixels of every 4-neighbour pair in different segments."""
    cols = labels.shape[1]
    firsts, seconds = [], []
    for here, there, step in ((labels[:, :-1], labels[:, 1:], 1),
                              (labels[:-1], labels[1:], cols)):
        r, c = np.nonzero((here != there) & (here >= 0) & (there >= 0))
        firsts.append(r * cols + c)
        seconds.append(r * cols + c + step)
    return np.concatenate(firsts), np.concatenate(seconds)


def _perimeters(labels: np.ndarray, n: int) -> np.ndarray:
    """Pixel edges on each segment's outline (to other segments, no data or the image
    border)."""
    padded = np.pad(labels, 1, constant_values=-1)
    centre = padded[1:-1, 1:-1]
    exposed = sum((centre != padded[1 + dr:padded.shape[0] - 1 + dr,
                                    1 + dc:padded.shape[1] - 1 + dc]).astype(np.int64)
                  for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)))
    inside = centre >= 0
    return np.bincount(centre[inside], exposed[inside], minlength=n)


def _hulls(labels: np.ndarray, n: int) -> np.ndarray:
    """Convex hull of every segment's pixel squares, from the ends of its row runs."""
    rows, cols = labels.shape
    start = np.ones(labels.shape, bool)
    start[:, 1:] = labels[:, 1:] != labels[:, :-1]
    stop = np.ones(labels.shape, bool)
    stop[:, :-1] = labels[:, :-1] != labels[:, 1:]
    r0, c0 = np.nonzero(start & (labels >= 0))
    r1, c1 = np.nonzero(stop & (labels >= 0))  # the same runs in the same order
    owner = labels[r0, c0]
    x = np.concatenate([c0, c0, c1 + 1, c1 + 1]).astype(float)
    y = np.concatenate([r0, r0 + 1, r0, r0 + 1]).astype(float)
    owner = np.tile(owner, 4)
    order = np.argsort(owner, kind="stable")
    # a line through the corners builds one coordinate sequence per segment, no point
    # objects; its hull is the hull of the corners
    corners = shapely.linestrings(np.column_stack([x[order], y[order]]), indices=owner[order])
    return shapely.convex_hull(corners)


def _merged_hull_areas(hulls: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Areas of the convex hulls of the unions of segments ``a[i]`` and ``b[i]``."""
    if len(a) == 0:
        return np.empty(0)
    pairs = shapely.geometrycollections(np.column_stack([hulls[a], hulls[b]]).ravel(),
                                        indices=np.repeat(np.arange(len(a)), 2))
    return shapely.area(shapely.convex_hull(pairs))


def _soft_histograms(bands: np.ndarray, labels: np.ndarray, n: int) -> np.ndarray:
    """``(n, bands * HISTOGRAM_BINS)`` pixel counts with linear bin sharing."""
    inside = labels >= 0
    ids = labels[inside]
    out = np.zeros((n, len(bands) * HISTOGRAM_BINS))
    for b, band in enumerate(bands):
        value = np.nan_to_num(band[inside], nan=0.0)
        position = np.clip(value * HISTOGRAM_BINS - 0.5, 0, HISTOGRAM_BINS - 1)
        low = np.floor(position).astype(np.int64)
        high = np.minimum(low + 1, HISTOGRAM_BINS - 1)
        share = position - low
        for bins, weight in ((low, 1 - share), (high, share)):
            out[:, b * HISTOGRAM_BINS:(b + 1) * HISTOGRAM_BINS] += np.bincount(
                ids * HISTOGRAM_BINS + bins, weight,
                minlength=n * HISTOGRAM_BINS).reshape(n, HISTOGRAM_BINS)
    return out


class _State:
    """Per-segment sums and per-pair border sums of the current grouping."""

    def __init__(self, labels, bands, edges, height, vegetation, probability, n):
        inside = labels >= 0
        ids = labels[inside]
        self.n = n
        self.parent = np.arange(n)
        self.area = np.bincount(ids, minlength=n).astype(float)
        self.histogram = _soft_histograms(bands, labels, n)
        self.n_bands = len(bands)
        self.perimeter = _perimeters(labels, n).astype(float)
        self.hull = _hulls(labels, n)
        self.means = {}
        for name, values in (("height_m", height), ("ndvi", vegetation),
                             ("probability", probability)):
            if values is not None:
                finite = np.isfinite(values[inside])
                self.means[name] = [np.bincount(ids[finite], values[inside][finite],
                                                minlength=n),
                                    np.bincount(ids[finite], minlength=n).astype(float)]
        first, second = _pixel_pairs(labels)
        flat = labels.ravel()
        a, b = flat[first], flat[second]
        across = np.maximum(edges.ravel()[first], edges.ravel()[second])
        self.edge_scale = typical_scale(across)
        self._set_pairs(np.minimum(a, b), np.maximum(a, b), np.ones(len(a)), across,
                        changed=np.ones(n, bool))

    def _set_pairs(self, lo, hi, length, edge_sum, changed, convexity=None):
        keep = lo != hi
        keys, inverse = np.unique(lo[keep] * self.n + hi[keep], return_inverse=True)
        inverse = inverse.ravel()
        self.lo, self.hi = keys // self.n, keys % self.n
        self.length = np.bincount(inverse, length[keep], minlength=len(keys))
        self.edge_sum = np.bincount(inverse, edge_sum[keep], minlength=len(keys))
        redo = changed[self.lo] | changed[self.hi]
        self.convexity = np.empty(len(keys))
        if convexity is not None:
            self.convexity[inverse] = convexity[keep]
        areas = _merged_hull_areas(self.hull, self.lo[redo], self.hi[redo])
        total = self.area[self.lo[redo]] + self.area[self.hi[redo]]
        self.convexity[redo] = np.minimum(total / np.maximum(areas, 1.0), 1.0)

    def criteria(self, pixel_m: float) -> dict[str, np.ndarray]:
        lo, hi = self.lo, self.hi
        share = self.histogram / np.maximum(self.area, 1)[:, None]
        colour = 0.5 * np.abs(share[lo] - share[hi]).sum(axis=1) / self.n_bands
        values = {
            "colour": colour,
            "edge": self.edge_sum / self.length / self.edge_scale,
            "convexity": self.convexity,
            "border_m": self.length * pixel_m,
            "border_rel": self.length / np.minimum(self.perimeter[lo], self.perimeter[hi]),
        }
        for name, (total, count) in self.means.items():
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = total / count
            difference = np.abs(mean[lo] - mean[hi])
            values[name] = np.where(np.isfinite(difference), difference, 0.0)
        return values

    def merge(self, pair_index: np.ndarray) -> None:
        """Merge the segments of the given pairs, groups of linked pairs as one segment."""
        lo, hi = self.lo[pair_index], self.hi[pair_index]
        graph = sparse.csr_matrix((np.ones(len(lo)), (lo, hi)), shape=(self.n, self.n))
        _, group = connected_components(graph, directed=False)
        # every group is represented by its smallest id
        smallest = np.full(self.n, self.n)
        np.minimum.at(smallest, group, np.arange(self.n))
        root = smallest[group]
        members = np.flatnonzero(root != np.arange(self.n))
        targets = root[members]
        internal = root[self.lo] == root[self.hi]
        self.parent[members] = targets
        np.add.at(self.area, targets, self.area[members])
        np.add.at(self.histogram, targets, self.histogram[members])
        np.add.at(self.perimeter, targets, self.perimeter[members])
        np.add.at(self.perimeter, root[self.lo[internal]], -2 * self.length[internal])
        for sums in self.means.values():
            for array in sums:
                np.add.at(array, targets, array[members])
        changed = np.zeros(self.n, bool)
        changed[targets] = True
        grown = np.flatnonzero(changed)
        in_group = np.flatnonzero(changed[root])  # the grown segments and their members
        order = np.argsort(root[in_group], kind="stable")
        collections = shapely.geometrycollections(
            self.hull[in_group[order]],
            indices=np.searchsorted(grown, root[in_group[order]]))
        self.hull[grown] = shapely.convex_hull(collections)
        self._set_pairs(np.minimum(root[self.lo], root[self.hi]),
                        np.maximum(root[self.lo], root[self.hi]), self.length, self.edge_sum,
                        changed, self.convexity)

    def roots(self) -> np.ndarray:
        root = self.parent.copy()
        while True:
            up = root[root]
            if np.array_equal(up, root):
                return root
            root = up


def merge_strength(goodness: dict[str, np.ndarray]) -> np.ndarray:
    """Rule strength of the fuzzy rules (module docstring) from per-criterion goodness.

    Parameters
    ----------
    goodness : dict of ndarray
        Goodness in [0, 1] of every criterion in :data:`CRITERIA` that is in use
        (``height_m``, ``ndvi`` and ``probability`` may be absent).

    Returns
    -------
    ndarray
        Strength in [0, 1]; pairs with at least :data:`CANDIDATE_STRENGTH` are candidates.
    """
    good = {k: np.clip(2 * g, 0, 1) for k, g in goodness.items()}
    very_good = {k: np.clip(2 * g - 1, 0, 1) for k, g in goodness.items()}
    ones = np.ones_like(goodness["colour"])
    physical = ones.copy()
    for name in ("height_m", "ndvi", "probability"):
        if name in good:
            physical = np.minimum(physical, good[name])
    appearance = ("edge", "colour", "convexity")
    every_good = np.minimum.reduce([good[k] for k in good])
    appearance_good = np.minimum.reduce([good[k] for k in appearance])
    two_very_good = np.sort(np.stack([very_good[k] for k in appearance]), axis=0)[1]
    rule_two = np.minimum.reduce([two_very_good, appearance_good, good["border_m"], physical])
    all_very_good = np.minimum.reduce([very_good[k] for k in appearance])
    rule_three = np.minimum.reduce([all_very_good, physical,
                                    np.maximum(good["border_m"], good["border_rel"])])
    return np.maximum.reduce([every_good, rule_two, rule_three])


def _merge_iteratively(state: _State, limits: dict, pixel_m: float, merge_fraction: float,
                       max_iterations: int, progress) -> None:
    """The paper's iterations: evaluate every pair, merge the best share of candidates."""
    for iteration in range(max_iterations):
        if len(state.lo) == 0:
            break
        values = state.criteria(pixel_m)
        goodness = {name: _goodness(value, limits[name]) for name, value in values.items()}
        candidates = np.flatnonzero(merge_strength(goodness) >= CANDIDATE_STRENGTH)
        if len(candidates) == 0:
            break
        score = sum(goodness.values())[candidates]
        ranked = candidates[np.argsort(-score, kind="stable")]
        ranked = ranked[:max(1, int(np.ceil(merge_fraction * len(candidates))))]
        state.merge(ranked)
        report(progress, 0.9 * (iteration + 1) / max_iterations,
               f"grouping: iteration {iteration + 1}, {len(ranked)} pairs merged")


@dataclass(frozen=True)
class GroupingOptions:
    """The options of :func:`group_segments`: how fast and how long segments are merged,
    the criteria limits and the splitting of branching segments.

    Attributes
    ----------
    merge_fraction : float
        Share of the candidate pairs merged per iteration (paper: 10 %); at least one.
    max_iterations : int
        Iterations at most; the grouping usually stops earlier, when no pair is a candidate.
    criteria : dict, optional
        Overrides of :data:`CRITERIA` limits, ``{name: (poor, very_good)}``.
    split_branches : bool
        Run :func:`split_branching_segments` on the result.
    min_branch_m : float
        See :func:`split_branching_segments`.
    """

    merge_fraction: float = 0.1
    max_iterations: int = 200
    criteria: dict | None = None
    split_branches: bool = True
    min_branch_m: float = MIN_BRANCH_M


def group_segments(labels, image: GeoRaster, options: GroupingOptions = GroupingOptions(), *,
                   dsm: GeoRaster | None = None, ndvi=None, nir_band: int | None = None,
                   edge_magnitude=None, probability=None, progress=None,
                   **changes) -> np.ndarray:
    """Merge adjacent segments iteratively with the paper's criteria and fuzzy rules.

    Parameters
    ----------
    labels : array_like of int, shape (rows, cols)
        Segments ``>= 0`` (any ids), -1 for no data, e.g. from
        :func:`gisroads.imagery.segments.segment_image` or
        :func:`gisroads.imagery.segments.frame_to_labels`.
    image : GeoRaster
        The image the segments cover (same grid); its bands give the colour histograms and
        the intensity edges.
    dsm : GeoRaster, optional
        Surface heights (metres), resampled to the image grid when on another grid; enables
        the mean-height-difference criterion.
    ndvi : array_like, shape (rows, cols), optional
        NDVI on the image grid; enables the mean-NDVI-difference criterion. With
        ``nir_band`` instead, it is computed from the image.
    nir_band : int, optional
        1-based NIR band number: left out of the intensity edges and used for the NDVI.
    edge_magnitude : array_like, shape (rows, cols), optional
        Edge strength on the image grid; default:
        :func:`gisroads.imagery.segments.edge_strength`, as the segmentation uses.
    probability : array_like, shape (rows, cols), optional
        A learned road probability in [0, 1] on the image grid (beyond the paper; NaN: no
        value); enables the mean-probability-difference criterion.
    options : GroupingOptions
        Merging, criteria and branch splitting (:class:`GroupingOptions`).
    progress : callable, optional
        ``progress(fraction, message)``; may raise :class:`gisroads.progress.Cancelled`.
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    labels : ndarray of int32, shape (rows, cols)
        Grouped segments ``0..m-1`` numbered in raster order, -1 where ``labels`` was -1.

    Raises
    ------
    ValueError
        Labels of another shape than the image, non-integer labels, a ``merge_fraction``
        outside (0, 1], or an unknown criterion.
    """
    options = replace(options, **changes)
    labels = np.asarray(labels)
    if labels.ndim != 2 or not np.issubdtype(labels.dtype, np.integer):
        raise GisroadsError(f"labels must be a 2-D integer array, got {labels.dtype} "
                            f"{labels.shape}")
    if labels.shape != image.shape:
        raise GisroadsError(f"labels {labels.shape} and image {image.shape} differ in shape")
    if not 0 < options.merge_fraction <= 1:
        raise GisroadsError(f"merge_fraction must lie in (0, 1], got {options.merge_fraction}")
    limits = dict(CRITERIA)
    for name, value in (options.criteria or {}).items():
        if name not in CRITERIA:
            raise GisroadsError(f"unknown criterion {name!r}; known: {sorted(CRITERIA)}")
        limits[name] = tuple(value)
    compact, n = _compact(labels)
    report(progress, 0.0, "grouping: segment statistics")
    pixel_m = pixel_size_m(image)
    if ndvi is None and nir_band is not None:
        ndvi = compute_ndvi(image, nir_band)
    if ndvi is not None:
        ndvi = np.asarray(ndvi, dtype=float)
        if ndvi.shape != labels.shape:
            raise GisroadsError(f"ndvi {ndvi.shape} and image {labels.shape} differ in shape")
    if probability is not None:
        probability = np.asarray(probability, dtype=float)
        if probability.shape != labels.shape:
            raise GisroadsError(f"probability {probability.shape} and image {labels.shape} "
                                "differ in shape")
    grouped = compact
    if n >= 2:
        bands = scale_bands(image)
        edges = (edge_strength(image, nir_band=nir_band, bands=bands)
                 if edge_magnitude is None else np.asarray(edge_magnitude, dtype=float))
        if edges.shape != labels.shape:
            raise GisroadsError(f"edge_magnitude {edges.shape} and image {labels.shape} differ "
                                "in shape")
        state = _State(compact, bands, edges,
                       None if dsm is None else resample_to(dsm, image), ndvi, probability, n)
        _merge_iteratively(state, limits, pixel_m, options.merge_fraction,
                           options.max_iterations, progress)
        grouped = np.where(compact >= 0, state.roots()[np.maximum(compact, 0)], -1)
    grouped = (connected_regions(grouped, background=-1, connectivity=1) - 1).astype(np.int32)
    if options.split_branches:
        grouped = split_branching_segments(grouped, pixel_m=pixel_m,
                                           min_branch_m=options.min_branch_m)
    report(progress, 1.0, "grouping done")
    return grouped


def split_branching_segments(labels, *, pixel_m: float, min_branch_m: float = MIN_BRANCH_M,
                             min_branches: int = 3) -> np.ndarray:
    """Split segments whose skeleton has several long branches: they span junctions.

    The skeleton of every segment large enough to hold ``min_branches`` arms is cut at its
    branch points (pixels with three or more skeleton neighbours). A branch is long when
    its length minus the largest distance to the segment border along it (the radius of
    the junction's inscribed circle, which a compact blob's corner branches do not
    outgrow) reaches ``min_branch_m``. Segments with at least ``min_branches`` long
    branches are split: each of their pixels goes to its nearest long branch, so a
    cross-shaped segment becomes its four arms, meeting on the diagonals of the junction.

    Parameters
    ----------
    labels : array_like of int, shape (rows, cols)
        Segments ``>= 0``, -1 for no data.
    pixel_m : float
        Pixel side, metres.
    min_branch_m : float
        Length a branch must exceed beyond the junction's inscribed circle, metres.
    min_branches : int
        Long branches that make a segment a junction (3: a T).

    Returns
    -------
    labels : ndarray of int32
        ``0..m-1`` in raster order, -1 where ``labels`` was -1.
    """
    labels = np.asarray(labels)
    if pixel_m <= 0 or min_branch_m < 0:
        raise GisroadsError("pixel_m must be positive and min_branch_m non-negative")
    out = labels.astype(np.int64).copy()
    fresh = int(labels.max()) + 1
    # a segment with min_branches arms spans at least two of them end to end
    span_px = 2 * min_branch_m / pixel_m
    for segment, box in enumerate(ndimage.find_objects(labels + 1)):
        if box is None or max(s.stop - s.start for s in box) < span_px:
            continue
        arms = _arms(np.pad(labels[box] == segment, 1), pixel_m, min_branch_m,
                     min_branches)
        if arms is not None:
            arms = arms[1:-1, 1:-1]
            window = out[box]
            window[arms > 0] = fresh + arms[arms > 0]
            fresh += int(arms.max()) + 1
    return (connected_regions(out, background=-1, connectivity=1) - 1).astype(np.int32)


def _arms(mask: np.ndarray, pixel_m: float, min_branch_m: float, min_branches: int):
    """Each pixel of ``mask`` labelled with its nearest long skeleton branch (1..), or None
    when the skeleton has fewer than ``min_branches`` long branches."""
    distance = ndimage.distance_transform_edt(mask)
    skeleton = skeletonize(mask)
    neighbours = ndimage.convolve(skeleton.astype(np.int32), np.ones((3, 3), np.int32),
                                  mode="constant") - 1
    branch_point = skeleton & (neighbours >= 3)
    if not branch_point.any():
        return None
    branch_pixels = skeleton & ~ndimage.binary_dilation(branch_point,
                                                        structure=np.ones((3, 3), bool))
    branches, n_branches = ndimage.label(branch_pixels, structure=np.ones((3, 3), int))
    on = branches > 0
    length_px = np.bincount(branches[on], minlength=n_branches + 1)
    radius_px = np.zeros(n_branches + 1)
    np.maximum.at(radius_px, branches[on], distance[on])
    long = (length_px - radius_px) * pixel_m >= min_branch_m
    long[0] = False
    if long.sum() < min_branches:
        return None
    seeds = np.where(long[branches], branches, 0)
    _, (rows, cols) = ndimage.distance_transform_edt(seeds == 0, return_indices=True)
    return np.where(mask, seeds[rows, cols], 0)
