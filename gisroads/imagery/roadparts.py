"""Road-part extraction: shape and radiometric filtering of grouped segments.

Grote & Rottensteiner (2010), Section 2.1.3, with the parameters of Grote et al. (2009),
Table 1, and the criteria of Grote & Heipke (2008). A segment is a road part when it is

* elongated (squared perimeter / area high) and convex (area / convex-hull area high),
  where a very elongated part may be less convex, so curved roads pass;
* of a road's width (twice the mean distance from its centre line to its border) and of
  nearly constant width (mean / standard deviation of that width high);
* long enough, low in a normalised DSM (when given), not vegetation (low NDVI, when a NIR
  band is given; an RGB image without NIR uses its excess green instead, an addition to
  the paper, whose images were all CIR), neither very dark (shadow) nor very bright, of
  homogeneous intensity (low standard deviation) and, in RGB images, grey (low colour
  saturation, the RGB analogue of the NDVI test; another addition).

Adjacent road parts with similar directions are merged when the merged region still
passes. Each part gets a quality measure in [0, 1] from its elongation, width, width
constancy, length and NDVI (the subgraph stage starts from the best part).

Stages, each callable alone: :func:`measure_segments` (one polygon per segment with every
attribute and its centre line), :func:`filter_road_parts` (``passed``, ``reason``,
``quality`` and the ``road_parts`` line layer), :func:`merge_adjacent_parts`;
:func:`extract_road_parts` composes them. :func:`rasterize_segments` turns segment polygons
(e.g. edited in QGIS) back into the label image they all take.

Centre line
    The segments' interiors (segment pixels whose four neighbours belong to the same
    segment) are skeletonised, each in its own window; on each segment's skeleton the
    longest path (a double Dijkstra sweep over all skeletons at once) is its centre line. The
    tapering
    ends of that path, where it runs into the corners of the part, are trimmed (pixels
    whose distance to the border is below ``TAPER_FRACTION`` of the path's median, counted
    from each end), the rest is smoothed and extended at both ends by the local half width
    up to the part's end. Width and width constancy are measured on the trimmed path.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import NamedTuple

import geopandas as gpd
import numpy as np
import pandas as pd
import rasterio.features
import shapely
from affine import Affine
from pyproj import CRS
from scipy import ndimage, sparse
from scipy.sparse import csgraph
from skimage.morphology import skeletonize

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..progress import Progress, report, scaled
from ..vectorize.regions import segment_polygons
from ..features.edges import local_energy
from .cues import ImageCues, image_cues

MAX_WIDTH_M = 40.0
"""Segments wider than this get no centre line (see :func:`measure_segments`)."""
TAPER_FRACTION = 0.95
"""Path pixels at the ends whose border distance is below this share of the path's median
distance are the part's rounded or cornered ends, not its width."""
WIDTH_OFFSET_PX = 1.5
"""Width = 2 x distance to the nearest border pixel + this. The border pixel's outer edge is
half a pixel beyond its centre on each side (+1), and a discrete centre line of an
even-width part lies half a pixel off the true centre (-1 for even widths, 0 for odd:
+0.5 on average). On strips 3-16 m wide at 0.25 m pixels and angles 0-71 degrees the
error is -0.07 m on average, at most 0.38 m (at 45 degrees)."""
NDVI_SPAN = 0.2
"""The NDVI score of :func:`road_part_quality` rises from 0 to 1 over this much below
the NDVI threshold."""
_NEIGHBOURS = ((0, 1, 1.0), (1, -1, np.sqrt(2)), (1, 0, 1.0), (1, 1, np.sqrt(2)))

SEGMENT_COLUMNS = ["segment_id", "area_m2", "perimeter_m", "elongation", "convexity",
                   "width_m", "width_constancy", "length_m", "direction_rad",
                   "mean_intensity", "std_intensity", "edge_contrast", "ndvi", "excess_green",
                   "saturation", "height_m"]
"""Attributes of :func:`measure_segments` (then ``road_probability``, ``mean_b1``,
``mean_b2`` ...)."""


@dataclass(frozen=True)
class RoadPartCriteria:
    """The road-part criteria of :func:`filter_road_parts`.

    Defaults: Grote et al. (2009), Table 1, where it gives a value (width 3-16 m, minimum
    width constancy 1.7, minimum elongation 70), converted where the scale differs; the
    rest chosen here and stated below.

    Attributes
    ----------
    width_range_m : (min, max)
        Road widths in metres (Table 1: 3-16 m).
    min_length_m : float
        Shortest road part, metres (not in Table 1: 15 m keeps a short piece between two
        trees, drops car-sized blobs).
    elongation_min, convexity_min : float
        Every part needs ``elongation >= elongation_min`` (25: a 4:1 rectangle; 16 is a
        square); a part that elongated needs ``convexity >= convexity_min`` (0.75). Grote &
        Heipke (2008) let convex parts be less elongated than Table 1's 70, so short
        straight parts pass while ragged regions, elongated by their border alone, do not.
    elongation_curved_min, convexity_curved_min : float
        The relaxation for curved parts (2010: "the convexity can be lower than the
        threshold if the elongation is high"; the criteria are "balanced against each
        other"): the convexity needed falls linearly with the elongation, from
        ``convexity_min`` at ``elongation_min`` to ``convexity_curved_min`` (0.2) at
        ``elongation_curved_min`` (Table 1's minimum elongation, 70) and beyond. Setting
        ``convexity_curved_min = convexity_min`` turns the relaxation off.
    width_constancy_min : float
        Mean / std of the width (Table 1: 1.7).
    height_max_m : float
        Largest mean height above ground in the nDSM (2 m: a car on a lane lifts a
        segment's mean by centimetres, a roof by metres). Skipped without a DSM.
    ndvi_max : float
        Largest mean NDVI. Table 1 has 0 for scanned CIR film; the paper adapted this
        threshold per data set. 0.2 separates asphalt (about 0) from grass (0.4).
    excess_green_max : float
        Largest mean excess green (:func:`gisroads.imagery.cues.excess_green`), the
        vegetation test of RGB images without NIR, which the paper did not need (its images
        were CIR): 0.05 keeps grey and brown surfaces, lawns and trees are above 0.1. Skipped
        where the NDVI test applies and for panchromatic and CIR images.
    saturation_max : float
        Largest mean saturation (HSV ``(max - min) / max`` of the stretched bands 1-3) of
        RGB images without NIR; skipped for CIR and panchromatic images. The RGB analogue
        of the NDVI test (Sec. 2.1.3 asks for road parts that are not vegetation and have
        the radiometry of a road surface): asphalt, concrete and gravel are grey, while
        what else forms elongated regions in RGB images (vegetation and its shadow, brown
        soil, red tiles, coloured roofs) is not; the excess-green test catches only green.
        Computed on the raw values of every pixel (:func:`gisroads.imagery.cues.saturation`),
        so it is independent of the image's stretch. 0.18: on the grouped segments of the
        13 real benchmark images, passing segments lying on roads have a median saturation
        of 0.11-0.17 (Massachusetts, Paris, ETH, DeepGlobe), passing off-road segments
        (leaf-off forest and its shadow stripes, soil, tiled roofs) 0.16-0.23; the whole
        pipeline's mean completeness / correctness / quality went 0.325 / 0.189 / 0.136
        without the test to 0.309 / 0.316 / 0.183 (0.15: 0.270 / 0.359 / 0.174; 0.22:
        0.322 / 0.252 / 0.164). Tested after the intensity tests, so a noisy dark shadow,
        whose pixel saturation is unstable, fails as "too dark".
    intensity_range : (min, max)
        Mean intensity bounds in [0, 1] (see :func:`gisroads.imagery.cues.intensity`):
        Table 1's minimum 40 of 255 is 0.1 after a typical 1-99 % stretch (0.15 dropped 5 %
        of the false road-part length on six real crops but lost roads in building shadows
        of the synthetic scenes: whole-pipeline completeness 0.81 -> 0.77); above 0.9 are
        white roofs and paint.
    intensity_std_max : float
        Largest intensity standard deviation (Table 1: 50 of 255 for colour, 0.2 here).
    edge_contrast_min : float
        Smallest ``edge_contrast`` (border over inner edge strength), an addition to the
        papers' criteria: their segmentation puts segment borders on edges, so a road part
        is a homogeneous region bounded by edges, while NCut regions cut out of texture
        (forest, fields, leaf-off tree shadows) are as elongated but have no stronger
        edges on their border than inside. Off (0) by default: over the passing parts of
        five real images 1.2 kept 65 % of the on-road length and 28 % of the off-road
        length, but on the 13 scored benchmark images the whole pipeline's mean
        completeness / correctness / quality went 0.325 / 0.189 / 0.136 -> 0.262 / 0.216 /
        0.133 (1.1: 0.295 / 0.205 / 0.138), no gain; raise it on textured scenes.
    road_width_m : float
        The typical road width the quality measure rewards (:func:`road_part_quality`).
    probability_min : float
        Smallest mean learned road probability (``road_probability``, measured when the
        cues hold a model's probability, :mod:`gisroads.learn`; beyond the papers). Where a
        segment has one, it replaces the colour tests of RGB images (the excess-green
        vegetation test and the saturation test; the NDVI test of a NIR band stays) and
        joins the quality measure; segments without one take the colour tests.
    """

    width_range_m: tuple = (3.0, 16.0)
    min_length_m: float = 15.0
    elongation_min: float = 25.0
    convexity_min: float = 0.75
    elongation_curved_min: float = 70.0
    convexity_curved_min: float = 0.2
    width_constancy_min: float = 1.7
    height_max_m: float = 2.0
    ndvi_max: float = 0.2
    excess_green_max: float = 0.05
    saturation_max: float = 0.18
    intensity_range: tuple = (0.1, 0.9)
    intensity_std_max: float = 0.2
    edge_contrast_min: float = 0.0
    road_width_m: float = 7.0
    probability_min: float = 0.3


CRITERIA = asdict(RoadPartCriteria())
"""The defaults of :class:`RoadPartCriteria` by name."""

TESTS = ("not elongated", "not convex", "too narrow", "too wide", "irregular width",
         "too short", "too high", "vegetation", "too dark", "too bright", "textured",
         "coloured", "no border edges", "low road probability")
"""Failure reasons in the order they are tested; ``reason`` names the first that fails."""


def _metric_pixel(image: GeoRaster) -> float:
    t = image.transform
    if t.b or t.d or not np.isclose(abs(t.a), abs(t.e)):
        raise GisroadsError("road parts need square, north-up pixels; warp the image first")
    crs = None if image.crs is None else CRS.from_user_input(image.crs)
    if crs is not None and not crs.is_projected:
        raise GisroadsError(f"road parts are measured in metres; {crs.name} is not a "
                            "projected CRS (warp the image to one, e.g. its UTM zone)")
    return image.pixel_size


def _check_labels(labels, shape) -> np.ndarray:
    labels = np.asarray(labels)
    if labels.ndim != 2 or not np.issubdtype(labels.dtype, np.integer):
        raise GisroadsError(f"labels must be a 2-D integer array, got {labels.dtype} "
                            f"{labels.shape}")
    if labels.shape != tuple(shape):
        raise GisroadsError(f"labels {labels.shape} and image {tuple(shape)} differ in shape")
    if labels.size and labels.min() < -1:
        raise GisroadsError("labels must be >= 0 (segments) or -1 (no data)")
    return labels


def _group_stats(index: np.ndarray, values: np.ndarray, n: int, *, std: bool = True):
    """Per-group mean (and standard deviation) of the finite ``values``; NaN for empty
    groups."""
    ok = np.isfinite(values)
    if not ok.all():
        index, values = index[ok], values[ok]
    count = np.bincount(index, minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(index, weights=values, minlength=n) / count
        if not std:
            return mean
        square = np.bincount(index, weights=values * values, minlength=n)
        return mean, np.sqrt(np.maximum(square / count - mean ** 2, 0.0))


def _last_per_group(groups: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Index of the element with the largest key in each group (groups as sorted ids)."""
    order = np.lexsort((keys, groups))
    last = np.r_[groups[order][1:] != groups[order][:-1], True]
    return order[last]


def _interior(compact: np.ndarray) -> np.ndarray:
    """Segment pixels whose four neighbours lie in the same segment (not at the image edge)."""
    padded = np.pad(compact, 1, constant_values=-2)
    centre = padded[1:-1, 1:-1]
    inside = centre >= 0
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        inside &= padded[1 + dr:padded.shape[0] - 1 + dr, 1 + dc:padded.shape[1] - 1 + dc] \
            == centre
    return inside


class _Paths(NamedTuple):
    """Longest skeleton paths, one per segment that has a skeleton, concatenated."""

    segment: np.ndarray   # per path: compact segment index
    start: np.ndarray     # per path: first row in the node arrays
    rows: np.ndarray      # per node, ordered along each path
    cols: np.ndarray
    border_px: np.ndarray  # per node: distance to the segment's nearest border pixel


def _skeleton(compact: np.ndarray, interior: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Skeleton of the interiors of the given segments, each thinned in its own window (the
    thinning passes scale with a region's width: a whole-image pass over a wide background
    segment would cost seconds)."""
    skeleton = np.zeros(compact.shape, bool)
    windows = ndimage.find_objects(compact + 1)
    for segment in segments:
        window = windows[segment]
        skeleton[window] |= skeletonize(interior[window] & (compact[window] == segment))
    return skeleton


def _longest_paths(compact: np.ndarray, skeleton: np.ndarray,
                   border: np.ndarray) -> _Paths:
    """The longest path of each segment's skeleton, for all segments at once."""
    rows, cols = np.nonzero(skeleton)
    n_nodes = len(rows)
    empty = np.empty(0, np.int64)
    if n_nodes == 0:
        return _Paths(empty, empty, empty, empty, np.empty(0))
    node = np.full(skeleton.shape, -1, np.int64)
    node[rows, cols] = np.arange(n_nodes)
    padded = np.pad(node, 1, constant_values=-1)
    heads, tails, weights = [], [], []
    for dr, dc, length in _NEIGHBOURS:
        other = padded[rows + 1 + dr, cols + 1 + dc]
        linked = other >= 0
        heads.append(np.flatnonzero(linked))
        tails.append(other[linked])
        weights.append(np.full(int(linked.sum()), length))
    graph = sparse.coo_matrix((np.concatenate(weights),
                               (np.concatenate(heads), np.concatenate(tails))),
                              shape=(n_nodes, n_nodes)).tocsr()
    _, component = csgraph.connected_components(graph, directed=False)
    # double sweep: the farthest node from any node is one end of the longest path, the
    # farthest node from that end is the other (exact on trees, near it on skeletons)
    _, first = np.unique(component, return_index=True)
    reach = csgraph.dijkstra(graph, directed=False, indices=first, min_only=True)
    ends = _last_per_group(component, reach)
    reach, predecessor = csgraph.dijkstra(graph, directed=False, indices=ends, min_only=True,
                                          return_predecessors=True)[:2]
    far = _last_per_group(component, reach)  # one per component: the path's other end
    segment = compact[rows[far], cols[far]]
    far = far[_last_per_group(segment, reach[far])]  # the longest component per segment
    walk, path_of = [], []
    current, path = far, np.arange(len(far))
    while len(current):
        walk.append(current)
        path_of.append(path)
        current = predecessor[current]
        alive = current >= 0
        current, path = current[alive], path[alive]
    walk, path_of = np.concatenate(walk), np.concatenate(path_of)
    order = np.lexsort((reach[walk], path_of))  # each path from its start (reach 0) on
    walk, path_of = walk[order], path_of[order]
    start = np.searchsorted(path_of, np.arange(len(far)))
    return _Paths(compact[rows[far], cols[far]], start, rows[walk], cols[walk],
                  border[rows[walk], cols[walk]])


def _trim(paths: _Paths, path: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and last node of each path between its tapering ends (``TAPER_FRACTION``)."""
    n = len(paths.segment)
    median = pd.Series(paths.border_px).groupby(path).median().to_numpy()
    full = paths.border_px >= TAPER_FRACTION * median[path]
    position = np.arange(len(path))
    first = np.full(n, len(path))
    last = np.full(n, -1)
    np.minimum.at(first, path[full], position[full])
    np.maximum.at(last, path[full], position[full])
    return first, last


def _smooth(points: np.ndarray, window: int) -> np.ndarray:
    """Moving average that keeps the end points and straight runs where they are: the path
    is continued past each end by its point reflection."""
    reach = min(window // 2, len(points) - 1)
    if reach < 1:
        return points
    padded = np.vstack([2 * points[0] - points[reach:0:-1], points,
                        2 * points[-1] - points[-2:-reach - 2:-1]])
    return ndimage.uniform_filter1d(padded, 2 * reach + 1, axis=0)[reach:-reach]


def _extend(points: np.ndarray, extend_px: float, at_start: bool) -> np.ndarray:
    """The end point moved ``extend_px`` outwards along the direction of the last half
    width of the path (not of its last, noisy pixel step)."""
    reach = int(min(len(points) - 1, max(1, round(extend_px))))
    tip, inner = (points[0], points[reach]) if at_start else (points[-1], points[-1 - reach])
    step = tip - inner
    norm = np.hypot(*step)
    return tip + step / norm * extend_px if norm > 0 else tip


def _centreline(rows, cols, half_px_start, half_px_end, transform: Affine, smooth_px: int):
    """Ordered path pixels -> smoothed LineString extended at both ends, in map units."""
    points = _smooth(np.column_stack([cols, rows]).astype(float) + 0.5, smooth_px)
    points = np.vstack([_extend(points, half_px_start, True), points,
                        _extend(points, half_px_end, False)])
    x = transform.a * points[:, 0] + transform.b * points[:, 1] + transform.c
    y = transform.d * points[:, 0] + transform.e * points[:, 1] + transform.f
    return shapely.linestrings(x, y)


def _edge_contrast(index: np.ndarray, border: np.ndarray, edges: np.ndarray,
                   n: int) -> np.ndarray:
    """Mean edge strength of each segment's border pixels over that of its other pixels
    (``index``: segment of every valid pixel; ``border``, ``edges``: at those pixels)."""
    border_mean = _group_stats(index[border], edges[border], n, std=False)
    inner_mean = _group_stats(index[~border], edges[~border], n, std=False)
    with np.errstate(invalid="ignore", divide="ignore"):
        return border_mean / inner_mean


def _measure(labels: np.ndarray, cues: ImageCues, edges: np.ndarray, transform: Affine, crs,
             pixel_m: float, max_width_m: float, progress: Progress = None
             ) -> gpd.GeoDataFrame:
    valid = labels >= 0
    index = labels[valid]
    if index.size and index.max() < 4 * labels.size:  # ids dense enough for a lookup table
        present = np.bincount(index) > 0
        ids = np.flatnonzero(present)
        index = (np.cumsum(present) - 1)[index]
    else:
        ids, index = np.unique(index, return_inverse=True)
    n = len(ids)
    compact = np.full(labels.shape, -1, np.int32)
    compact[valid] = index
    count = np.bincount(index, minlength=n).astype(float)
    frame = {"segment_id": ids.astype(np.int64), "area_m2": count * pixel_m ** 2}

    report(progress, 0.05, "segment outlines")
    polygons = segment_polygons(compact, n, transform)
    # the pixel staircase would overstate oblique and curved borders: simplify by a pixel
    perimeter = shapely.length(shapely.simplify(polygons, pixel_m, preserve_topology=False))
    hull = shapely.area(shapely.convex_hull(polygons))
    with np.errstate(invalid="ignore", divide="ignore"):
        frame["perimeter_m"] = perimeter
        frame["elongation"] = perimeter ** 2 / frame["area_m2"]
        frame["convexity"] = np.minimum(frame["area_m2"] / hull, 1.0)

    report(progress, 0.25, "centre lines")
    interior = _interior(compact)
    border = ndimage.distance_transform_edt(interior)
    radius = np.zeros(n)
    inner = compact[interior]
    radius[:] = pd.Series(border[interior]).groupby(inner).max().reindex(
        np.arange(n), fill_value=0.0).to_numpy()
    # wider segments are no road; they keep the width of their largest inscribed disc
    narrow = np.flatnonzero(radius * pixel_m <= max_width_m / 2)
    paths = _longest_paths(compact, _skeleton(compact, interior, narrow), border)
    path = np.repeat(np.arange(len(paths.segment)),
                     np.diff(np.r_[paths.start, len(paths.rows)]))
    first, last = _trim(paths, path)
    kept = (np.arange(len(path)) >= first[path]) & (np.arange(len(path)) <= last[path])
    width_px = 2 * paths.border_px + WIDTH_OFFSET_PX
    mean_px, std_px = _group_stats(path[kept], width_px[kept], len(paths.segment))
    half_start = paths.border_px[first] + 0.5  # to the outline beyond the border pixel
    half_end = paths.border_px[last] + 0.5
    frame["width_m"] = np.where(radius > 0, (2 * radius + WIDTH_OFFSET_PX) * pixel_m, np.nan)
    frame["width_m"][paths.segment] = mean_px * pixel_m
    frame["width_constancy"] = np.full(n, np.nan)
    # a straight part's width varies only by pixel rounding: its std is floored at half a
    # pixel so the ratio stays finite
    frame["width_constancy"][paths.segment] = mean_px / np.maximum(std_px, 0.5)

    report(progress, 0.6, "direction and radiometry")
    rows, cols = np.nonzero(valid)
    mean_r = _group_stats(index, rows.astype(float), n, std=False)
    mean_c = _group_stats(index, cols.astype(float), n, std=False)
    dr, dc = rows - mean_r[index], cols - mean_c[index]
    srr = np.bincount(index, weights=dr * dr, minlength=n)
    scc = np.bincount(index, weights=dc * dc, minlength=n)
    src = np.bincount(index, weights=dr * dc, minlength=n)
    angle_px = 0.5 * np.arctan2(2 * src, scc - srr)  # main axis, (cols, rows) space
    t = transform
    frame["direction_rad"] = np.mod(np.arctan2(t.d * np.cos(angle_px) + t.e * np.sin(angle_px),
                                               t.a * np.cos(angle_px) + t.b * np.sin(angle_px)),
                                    np.pi)
    frame["mean_intensity"], frame["std_intensity"] = _group_stats(
        index, cues.intensity[valid].astype(float), n)
    frame["edge_contrast"] = _edge_contrast(index, ~interior[valid],
                                            edges[valid].astype(float), n)
    for name, cue in (("ndvi", cues.ndvi), ("excess_green", cues.exg),
                      ("saturation", cues.saturation), ("height_m", cues.ndsm)):
        frame[name] = np.full(n, np.nan) if cue is None else \
            _group_stats(index, cue[valid].astype(float), n, std=False)
    frame["road_probability"] = np.full(n, np.nan) if cues.probability is None else \
        _group_stats(index, cues.probability[valid].astype(float), n, std=False)
    for band, values in enumerate(cues.bands, start=1):
        frame[f"mean_b{band}"] = _group_stats(index, values[valid].astype(float), n,
                                              std=False)

    report(progress, 0.75, "centre line geometry")
    centrelines = np.full(n, None, dtype=object)
    for p, segment in enumerate(paths.segment):
        take = slice(first[p], last[p] + 1)
        centrelines[segment] = _centreline(
            paths.rows[take], paths.cols[take], half_start[p], half_end[p], transform,
            smooth_px=int(round(mean_px[p] / 2)))
    centrelines = shapely.simplify(centrelines, 0.5 * pixel_m)
    # the smoothed line, not the 8-connected pixel path (7 % too long at 30 degrees)
    frame["length_m"] = shapely.length(centrelines)
    columns = (SEGMENT_COLUMNS + ["road_probability"]
               + [f"mean_b{band}" for band in range(1, len(cues.bands) + 1)])
    out = gpd.GeoDataFrame({c: frame[c] for c in columns},
                           geometry=gpd.GeoSeries(polygons, crs=crs), crs=crs)
    out["centreline"] = gpd.GeoSeries(centrelines, crs=crs)
    report(progress, 1.0, f"{n} segments measured")
    return out


def measure_segments(labels, image: GeoRaster, *, ndvi=None, ndsm=None,
                     nir_band: int | None = None, cues: ImageCues | None = None,
                     edge_magnitude=None, max_width_m: float = MAX_WIDTH_M,
                     progress: Progress = None) -> gpd.GeoDataFrame:
    """Shape and radiometric attributes of every segment of a label image.

    Parameters
    ----------
    labels : ndarray of int, shape (rows, cols)
        Segment ids ``>= 0``; ``-1`` = no data. A segment may be in several pieces.
    image : GeoRaster
        The image the segments cut (its grid, CRS and bands), in a metric CRS.
    ndvi, ndsm : ndarray, optional
        NDVI and height above ground (metres) on the image grid (see
        :mod:`gisroads.imagery.cues`); their columns are NaN when absent.
    nir_band : int, optional
        1-based NIR band, left out of the intensity.
    cues : ImageCues, optional
        Precomputed cues of ``image`` (then ``ndvi``, ``ndsm`` and ``nir_band`` are
        ignored).
    edge_magnitude : array_like, shape (rows, cols), optional
        Edge strength on the image grid; default: the local energy of the intensity
        (:func:`gisroads.features.edges.local_energy`, as
        :func:`gisroads.imagery.segments.edge_strength`; pass that to compute it once).
    max_width_m : float
        Segments whose largest inscribed disc is wider get no centre line (their
        ``width_m`` is that disc's, ``width_constancy`` and ``length_m`` NaN): far beyond
        any road width, it bounds the cost of the skeletons.
    progress : callable, optional

    Returns
    -------
    GeoDataFrame
        One (Multi)Polygon per segment, sorted by ``segment_id``, with ``segment_id``,
        ``area_m2``, ``perimeter_m``, ``elongation`` (squared perimeter / area; 16 for a
        square, 68 for an 8 x 120 m strip), ``convexity`` (area / convex-hull area),
        ``width_m`` (twice the mean distance from the trimmed centre line to the border),
        ``width_constancy`` (mean / std of that width), ``length_m`` (centre line),
        ``direction_rad`` (main axis, [0, pi) counter-clockwise from east),
        ``mean_intensity``, ``std_intensity`` ([0, 1]), ``edge_contrast`` (mean edge
        strength on the segment's border pixels over that on its other pixels: above 1
        where edges bound a homogeneous region), ``ndvi`` (mean), ``excess_green``
        (mean, RGB images), ``height_m`` (mean nDSM), ``mean_b1`` ... (each band scaled to
        [0, 1]) and ``centreline`` (a second GeoSeries, not the active geometry: the
        LineString the road-part layer takes; None for segments at most two pixels wide,
        whose width and length are NaN).
    """
    pixel_m = _metric_pixel(image)
    labels = _check_labels(labels, image.shape)
    if cues is None:
        base = image_cues(image, nir_band=nir_band)
        cues = ImageCues(base.bands, base.intensity, ndvi, ndsm, base.kind, nir_band, base.exg,
                         base.saturation)
    for name, cue in (("ndvi", cues.ndvi), ("ndsm", cues.ndsm)):
        if cue is not None and np.shape(cue) != labels.shape:
            raise GisroadsError(f"{name} {np.shape(cue)} is not on the image grid "
                                f"{labels.shape}")
    if edge_magnitude is None:
        edge_magnitude = local_energy(cues.intensity)[0]
    elif np.shape(edge_magnitude) != labels.shape:
        raise GisroadsError(f"edge_magnitude {np.shape(edge_magnitude)} is not on the image "
                            f"grid {labels.shape}")
    return _measure(labels, cues, np.asarray(edge_magnitude), image.transform, image.crs,
                    pixel_m, max_width_m, progress)


def road_part_quality(segments: pd.DataFrame, *, road_width_m: float = 7.0,
                      width_range_m=(3.0, 16.0), ndvi_max: float = 0.2,
                      elongation_full: float = 140.0, constancy_full: float = 10.0,
                      length_full_m: float = 100.0, probability=None) -> np.ndarray:
    """Quality of road parts in [0, 1]: the mean of five scores in [0, 1].

    Grote & Rottensteiner (2010, end of Section 2.1.3) compute it "from the elongation,
    width, width constancy, length and NDVI"; the scores here are linear ramps:

    * elongation: 0 for a square (16), 1 from ``elongation_full`` (twice the paper's
      minimum, 70) on;
    * width: 1 at ``road_width_m``, 0 at the nearer end of ``width_range_m``;
    * width constancy: 0 at 1 (the std as large as the mean), 1 from ``constancy_full`` on;
    * length: ``length_m / length_full_m``, at most 1;
    * NDVI: 0 at ``ndvi_max``, 1 from ``NDVI_SPAN`` below it on; left out where NDVI is
      NaN (no NIR band);
    * learned road probability (``probability``, per segment, beyond the papers): its
      value; left out where NaN or not given.
    """
    low, high = width_range_m
    width = segments["width_m"].to_numpy(float)
    span = np.where(width < road_width_m, road_width_m - low, high - road_width_m)
    scores = [
        (segments["elongation"].to_numpy(float) - 16.0) / (elongation_full - 16.0),
        1.0 - np.abs(width - road_width_m) / np.maximum(span, 1e-9),
        (segments["width_constancy"].to_numpy(float) - 1.0) / (constancy_full - 1.0),
        segments["length_m"].to_numpy(float) / length_full_m,
        (ndvi_max - segments["ndvi"].to_numpy(float)) / NDVI_SPAN,
    ]
    shape = np.clip(np.nan_to_num(np.vstack(scores[:4]), nan=0.0), 0.0, 1.0)
    vegetation = np.clip(scores[4], 0.0, 1.0)  # stays NaN without NIR: left out of the mean
    rows = [shape, vegetation[None]]
    if probability is not None:
        rows.append(np.clip(np.asarray(probability, float), 0.0, 1.0)[None])
    with np.errstate(invalid="ignore"):
        return np.nanmean(np.vstack(rows), axis=0)


def filter_road_parts(segments: gpd.GeoDataFrame,
                      criteria: RoadPartCriteria = RoadPartCriteria(), **changes):
    """Test every measured segment against the road-part criteria.

    Parameters
    ----------
    segments : GeoDataFrame
        From :func:`measure_segments`.
    criteria : RoadPartCriteria
        The criteria; defaults from Grote et al. (2009), Table 1.
    **changes
        Fields of ``criteria`` to change for this call.

    Returns
    -------
    segments : GeoDataFrame
        A copy with ``passed`` (bool), ``reason`` ("" or the first failing test of
        :data:`TESTS`), ``failures`` (every failing test, comma-separated) and ``quality``.
    road_parts : GeoDataFrame
        One LineString per passing segment, its centre line: ``part_id``, ``segment_id``,
        ``width_m``, ``length_m``, ``quality``, ``mean_b1`` ..., ``mean_intensity``.
    """
    criteria = replace(criteria, **changes)
    out = segments.assign(**_verdict(segments, asdict(criteria)))
    return out, _road_part_layer(out)


def _verdict(segments: pd.DataFrame, criteria: dict) -> dict:
    """``passed``, ``reason``, ``failures`` and ``quality`` of measured segments under a
    full set of criteria (the keys of :data:`CRITERIA`)."""
    c = criteria
    (low_w, high_w), (low_i, high_i) = c["width_range_m"], c["intensity_range"]
    if not (0 < low_w < high_w and low_i < high_i):
        raise GisroadsError("width_range_m and intensity_range must be (min, max) with "
                            "min < max, widths positive")
    if not c["elongation_min"] < c["elongation_curved_min"]:
        raise GisroadsError("elongation_curved_min must exceed elongation_min")
    if c["min_length_m"] <= 0:
        raise GisroadsError("min_length_m must be positive")
    s = {name: segments[name].to_numpy(float) for name in SEGMENT_COLUMNS[1:]}
    probability = (segments["road_probability"].to_numpy(float)
                   if "road_probability" in segments else np.full(len(segments), np.nan))
    learned = np.isfinite(probability)  # a model's probability replaces the colour tests
    width = s["width_m"]
    needed = np.interp(s["elongation"], [c["elongation_min"], c["elongation_curved_min"]],
                       [c["convexity_min"], c["convexity_curved_min"]])
    failing = {
        "not elongated": s["elongation"] < c["elongation_min"],
        "not convex": s["convexity"] < needed,
        "too narrow": np.isnan(width) | (width < low_w),
        "too wide": width > high_w,
        "irregular width": s["width_constancy"] < c["width_constancy_min"],
        "too short": np.isnan(s["length_m"]) | (s["length_m"] < c["min_length_m"]),
        "too high": s["height_m"] > c["height_max_m"],
        # NDVI when there is NIR, else the excess green of RGB
        "vegetation": np.where(np.isnan(s["ndvi"]),
                               ~learned & (s["excess_green"] > c["excess_green_max"]),
                               s["ndvi"] > c["ndvi_max"]),
        "coloured": ~learned & (s["saturation"] > c["saturation_max"]),
        "too dark": s["mean_intensity"] < low_i,
        "too bright": s["mean_intensity"] > high_i,
        "textured": s["std_intensity"] > c["intensity_std_max"],
        "no border edges": s["edge_contrast"] < c["edge_contrast_min"],
        "low road probability": learned & (probability < c.get("probability_min", 0.0)),
    }
    fails = np.column_stack([failing[name] for name in TESTS]).reshape(-1, len(TESTS))
    names = np.array(TESTS, dtype=object)
    passed = ~fails.any(axis=1)
    return {"passed": passed,
            "reason": np.where(passed, "", names[np.argmax(fails, axis=1)]).astype(object),
            "failures": np.array([", ".join(names[row]) for row in fails], dtype=object),
            "quality": road_part_quality(segments, road_width_m=c["road_width_m"],
                                         probability=probability,
                                         width_range_m=c["width_range_m"],
                                         ndvi_max=c["ndvi_max"])}


def _road_part_layer(segments: gpd.GeoDataFrame) -> gpd.GeoDataFrame:
    parts = segments[segments["passed"].to_numpy(bool)]
    bands = sorted((c for c in segments.columns if c.startswith("mean_b")),
                   key=lambda c: int(c[6:]))
    frame = {"part_id": np.arange(len(parts), dtype=np.int64),
             "segment_id": parts["segment_id"].to_numpy(np.int64)}
    for column in ["width_m", "length_m", "quality", *bands, "mean_intensity"]:
        frame[column] = parts[column].to_numpy(float)
    if "road_probability" in parts:
        frame["road_probability"] = parts["road_probability"].to_numpy(float)
    return gpd.GeoDataFrame(frame, geometry=gpd.GeoSeries(parts["centreline"].to_numpy(),
                                                         crs=segments.crs),
                            crs=segments.crs)


def rasterize_segments(segments: gpd.GeoDataFrame, like: GeoRaster, *,
                       id_column: str = "segment_id") -> np.ndarray:
    """Segment polygons (from the segmentation stage or edited by hand) as a label image.

    Parameters
    ----------
    segments : GeoDataFrame
        Polygons with non-negative integer ids in ``id_column``, in ``like``'s CRS; where
        polygons overlap, the later one wins.
    like : GeoRaster
        The grid to burn into.
    id_column : str

    Returns
    -------
    ndarray of int32, ``like.shape``; -1 outside every polygon.
    """
    if id_column not in segments:
        raise GisroadsError(f"the segments have no {id_column!r} field")
    ids = pd.to_numeric(segments[id_column], errors="coerce").to_numpy(float)
    if len(ids) and (np.isnan(ids).any() or (ids < 0).any() or (ids != np.round(ids)).any()
                     or ids.max() >= np.iinfo(np.int32).max):
        raise GisroadsError(f"{id_column} must hold non-negative integers")
    crs = None if like.crs is None else CRS.from_user_input(like.crs)
    if segments.crs is not None and crs is not None and CRS.from_user_input(segments.crs) != crs:
        raise GisroadsError("the segments are in another CRS than the image; reproject them")
    shapes = [(g, int(i)) for g, i in zip(segments.geometry.values, ids)
              if g is not None and not g.is_empty]
    if not shapes:
        return np.full(like.shape, -1, np.int32)
    return rasterio.features.rasterize(shapes, out_shape=like.shape, transform=like.transform,
                                       fill=-1, dtype="int32")


def _adjacent_pairs(labels: np.ndarray) -> np.ndarray:
    """Pairs ``(a, b)``, ``a < b``, of 4-adjacent segment ids, shape ``(n, 2)``."""
    low, high = [], []
    for a, b in ((labels[:, :-1], labels[:, 1:]), (labels[:-1], labels[1:])):
        touch = (a != b) & (a >= 0) & (b >= 0)
        low.append(np.minimum(a[touch], b[touch]))
        high.append(np.maximum(a[touch], b[touch]))
    low, high = np.concatenate(low).astype(np.int64), np.concatenate(high).astype(np.int64)
    span = int(high.max()) + 1 if len(high) else 1
    keys = np.unique(low * span + high)  # one sortable key per pair
    return np.column_stack([keys // span, keys % span])


def _relabel(labels: np.ndarray, source: np.ndarray, target: np.ndarray, *,
             others: int | None = None) -> np.ndarray:
    """``labels`` with ids ``source`` replaced by ``target``; every other pixel keeps its
    id, or becomes ``others`` when given."""
    order = np.argsort(source)
    source, target = np.asarray(source)[order], np.asarray(target)[order]
    if not len(source):
        return labels.copy() if others is None else np.full_like(labels, others)
    where = np.clip(np.searchsorted(source, labels), 0, len(source) - 1)
    hit = source[where] == labels
    rest = labels if others is None else others
    return np.where(hit, target[where], rest).astype(labels.dtype)


def _window(mask: np.ndarray):
    """The bounding rows and columns of a mask's pixels as a pair of slices."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


def _crop(cues: ImageCues, window) -> ImageCues:
    rows, cols = window
    def crop(cue):
        return None if cue is None else cue[..., rows, cols]
    return ImageCues(crop(cues.bands), crop(cues.intensity), crop(cues.ndvi), crop(cues.ndsm),
                     cues.kind, cues.nir_band, crop(cues.exg),
                     crop(cues.saturation), crop(cues.probability))


def merge_adjacent_parts(segments: gpd.GeoDataFrame, labels, image: GeoRaster,
                         cues: ImageCues, *, edge_magnitude=None,
                         max_direction_diff_rad: float = np.radians(20.0),
                         criteria: RoadPartCriteria = RoadPartCriteria()):
    """Merge adjacent road parts of similar direction when the merged region still passes.

    Pairs of passing parts that share a border and whose main directions differ by at most
    ``max_direction_diff_rad`` are tried, most similar first; a merge is kept when the
    union, measured afresh, passes :func:`filter_road_parts` (Grote & Rottensteiner 2010,
    Section 2.1.3). Each round tries a set of disjoint pairs, all measured together;
    rounds repeat until no pair merges, so chains of parts merge too.

    Parameters
    ----------
    segments : GeoDataFrame
        From :func:`filter_road_parts`.
    labels : ndarray of int
        The label image ``segments`` were measured on.
    image : GeoRaster
        Its grid and CRS.
    cues : ImageCues
        The cues ``segments`` were measured with.
    edge_magnitude : array_like, optional
        The edge strength they were measured with (default as :func:`measure_segments`).
    max_direction_diff_rad : float
        Largest difference of main directions (radians; 20 degrees by default).
    criteria : RoadPartCriteria
        The criteria a merged region must pass (:func:`filter_road_parts`).

    Returns
    -------
    segments : GeoDataFrame
        Merged parts replace their pieces, keeping the smallest ``segment_id``;
        ``merged_from`` lists the pieces' ids ("" for unmerged segments).
    labels : ndarray
        The label image with the merges applied.
    """
    criteria = asdict(criteria)
    pixel_m = _metric_pixel(image)
    labels = _check_labels(labels, image.shape).copy()
    edges = local_energy(cues.intensity)[0] if edge_magnitude is None else \
        np.asarray(edge_magnitude)
    segments = segments.copy()
    if "merged_from" not in segments:
        segments["merged_from"] = ""
    refused = set()  # pairs whose union failed; retried only once one of them has grown
    while True:
        by_id = segments.set_index("segment_id")
        passing = by_id.index.to_numpy()[by_id["passed"].to_numpy(bool)]
        pairs = _adjacent_pairs(labels)
        pairs = pairs[np.isin(pairs, passing).all(axis=1)]
        diff = np.abs(by_id.loc[pairs[:, 0], "direction_rad"].to_numpy()
                      - by_id.loc[pairs[:, 1], "direction_rad"].to_numpy())
        diff = np.minimum(diff, np.pi - diff)
        order = np.argsort(diff, kind="stable")
        chosen, used = [], set()
        for a, b in pairs[order][diff[order] <= max_direction_diff_rad].tolist():
            if a not in used and b not in used and (a, b) not in refused:
                chosen.append((a, b))
                used.update((a, b))
        if not chosen:
            return segments.reset_index(drop=True), labels
        first, second = np.array(chosen).T
        unions = _relabel(labels, np.r_[first, second], np.r_[first, first], others=-1)
        window = _window(unions >= 0)
        t, r0, c0 = image.transform, window[0].start, window[1].start
        origin = Affine(t.a, t.b, t.c + t.a * c0 + t.b * r0,
                        t.d, t.e, t.f + t.d * c0 + t.e * r0)
        rows = _measure(unions[window], _crop(cues, window), edges[window], origin,
                        image.crs, pixel_m, MAX_WIDTH_M)
        rows = rows.assign(**_verdict(rows, criteria))
        partner = dict(chosen)
        refused.update((a, partner[a]) for a in rows["segment_id"][~rows["passed"]])
        rows = rows[rows["passed"].to_numpy()]
        if not len(rows):
            return segments.reset_index(drop=True), labels
        kept = rows["segment_id"].to_numpy()
        grown = set(kept.tolist()) | {partner[a] for a in kept.tolist()}
        refused = {pair for pair in refused if grown.isdisjoint(pair)}
        rows = rows.assign(merged_from=[",".join(sorted(
            ",".join(by_id.loc[k, "merged_from"] or str(k) for k in (a, partner[a])).split(","),
            key=int)) for a in kept.tolist()])
        labels = _relabel(labels, np.array([partner[a] for a in kept.tolist()]), kept)
        segments = pd.concat([segments[~segments["segment_id"].isin(grown).to_numpy()],
                              rows[segments.columns]],
                             ignore_index=True).sort_values("segment_id")


class RoadParts(NamedTuple):
    """Result of :func:`extract_road_parts`."""

    segments: gpd.GeoDataFrame
    """Every segment with its attributes, ``passed``, ``reason``, ``failures``, ``quality``,
    ``merged_from`` (polygons; the ``centreline`` column dropped)."""
    road_parts: gpd.GeoDataFrame
    """Centre lines of the passing parts (see :func:`filter_road_parts`)."""
    labels: np.ndarray
    """The label image after merging."""
    cues: dict
    """:meth:`ImageCues.record` of the cues used."""


def extract_road_parts(labels, image: GeoRaster, *, nir_band: int | None = None,
                       red_band: int | None = None, dsm: GeoRaster | None = None,
                       cues: ImageCues | None = None, edge_magnitude=None,
                       merge: bool = True,
                       max_direction_diff_rad: float = np.radians(20.0),
                       criteria: RoadPartCriteria = RoadPartCriteria(),
                       progress: Progress = None, **changes) -> RoadParts:
    """Road parts of a segmentation: measure, filter, merge adjacent parts, filter.

    Parameters
    ----------
    labels : ndarray of int
        Segments (``-1`` = no data) on the image grid, e.g. from the grouping stage.
    image : GeoRaster
    nir_band, red_band : int, optional
        1-based; a NIR band adds the NDVI test.
    dsm : GeoRaster, optional
        Adds the height test (normalised DSM, :func:`gisroads.imagery.cues.normalised_dsm`).
    cues : ImageCues, optional
        Precomputed cues (then ``nir_band``, ``red_band`` and ``dsm`` are ignored).
    edge_magnitude : array_like, optional
        See :func:`measure_segments`.
    merge : bool
        Run :func:`merge_adjacent_parts`.
    max_direction_diff_rad : float
        See :func:`merge_adjacent_parts`.
    criteria : RoadPartCriteria
        The criteria of :func:`filter_road_parts`.
    progress : callable, optional
    **changes
        Fields of ``criteria`` to change for this call.

    Returns
    -------
    RoadParts
    """
    unknown = set(changes) - set(CRITERIA)
    if unknown:
        raise GisroadsError(f"unknown road-part criteria {sorted(unknown)}; "
                            f"choose from {sorted(CRITERIA)}")
    criteria = replace(criteria, **changes)
    report(progress, 0.0, "image cues")
    if cues is None:
        cues = image_cues(image, nir_band=nir_band, red_band=red_band, dsm=dsm)
    if edge_magnitude is None:
        edge_magnitude = local_energy(cues.intensity)[0]
    segments = measure_segments(labels, image, cues=cues, edge_magnitude=edge_magnitude,
                                progress=scaled(progress, 0.1, 0.8))
    segments, road_parts = filter_road_parts(segments, criteria)
    labels = np.asarray(labels)
    if merge:
        report(progress, 0.8, "merging adjacent parts")
        segments, labels = merge_adjacent_parts(
            segments, labels, image, cues, edge_magnitude=edge_magnitude,
            max_direction_diff_rad=max_direction_diff_rad,
            criteria=criteria)
        road_parts = _road_part_layer(segments)
    else:
        segments["merged_from"] = ""
    report(progress, 1.0, f"{len(road_parts)} road parts of {len(segments)} segments")
    return RoadParts(segments.drop(columns="centreline"), road_parts, labels, cues.record())
