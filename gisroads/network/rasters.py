"""Any road raster to a clean, connected road network.

A road raster is a binary mask or a road probability (0-1, or 0-255 for 8-bit images): a
deep-learning segmentation, a classified land-cover map, a thresholded index, the LiDAR
road evidence or the imagery road cue of this project. The stages, each callable alone:

:func:`road_probability`
    The raster as a probability in [0, 1], NaN where there is no data.
:func:`road_mask`
    Smoothed, thresholded and cleaned: holes up to ``max_hole_m2`` filled (a car, a tree
    crown, salt noise inside a road), components under ``min_area_m2`` dropped (salt
    noise and small blobs outside the roads).
:func:`skeleton_parts`
    Tile by tile (``tile_px`` with ``overlap_px`` of context, the cores stitched exactly
    as the LiDAR tiles are), cuts across roads closed in the mask (two road ends of the
    same width facing each other across open ground, up to ``max_cut_m``:
    :func:`gisroads.network.cuts.bridge_cuts`; a piece between two cuts of a wide road is
    shorter than wide and its own skeleton would run across the road), the mask's
    skeleton with the width at every skeleton pixel from the distance transform; then, on
    the whole network of vectors: spurs pruned
    (end branches shorter than the local half width plus ``spur_m``: the skeleton's twigs
    towards corners and bumps of the border), junction pixel clusters contracted into one
    node (junctions joined by less than ``junction_merge_m``), the last ``straighten``
    half widths of every branch at a junction replaced by a straight segment to the node
    (the skeleton bends towards the junction's centre of mass), lines split at junctions
    and merged through nodes of degree 2, then simplified (Douglas-Peucker,
    ``simplify_m``). Every part carries its mean width and its mean probability
    (``quality``).
:func:`link_gaps`
    The gap edges of :mod:`gisroads.network.subgraph` between dead ends only (an end
    already at a junction is connected), weighted by the geometry of the gap and by the
    raster's own road probability along it (sub-threshold evidence plays the part of the
    paper's occlusion share), and chosen by the integer program: a road cut by a tree, a
    car or a bridge shadow is bridged when its continuation is smooth.
:func:`parts_to_network`
    Road parts of any cue (these skeleton parts, the LiDAR rectangles' chained centre
    lines) through :func:`link_gaps` and the network generation below.
:func:`raster_to_network`
    The composition, ending in the network generation of
    :mod:`gisroads.network.junctions`: junctions built from the remaining dead ends (T
    junctions across a cut next to the crossing road), duplicates removed, insignificant
    components (false blobs) dropped, lines split at junctions with a shared vertex at every
    T. QA layers: ``gap_edges`` (weights and ``selected``), ``junction_connections`` and
    ``rejected`` (pieces dropped, with a ``reason``).

Every distance is in metres, so one set of defaults serves 0.3-1 m pixels.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from affine import Affine
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import GisroadsError
from ..geo import GeoRaster, RoadNetwork, _apply, free_line_ends
from ..progress import Progress, report, scaled
from ..vectorize.regions import segment_polygons
from ..vectorize.ribbons import node_roads
from ..vectorize.skeleton import skeleton_lines
from .areas import WIDE_AREA_M, lines_in_wide_areas, wide_paved_areas
from .cuts import MAX_CUT_M, bridge_cuts
from .junctions import NetworkOptions, merge_close_junctions, strings_to_network
from .subgraph import (GapOptions, WeightOptions, edge_weights, gap_edges, road_strings,
                       select_gap_edges)

METHOD = "road-raster"
#: Pixels at or above this probability are road.
THRESHOLD = 0.5
#: Gaussian smoothing of the probability before the threshold (sigma, metres): ragged
#: borders of a classifier's output would grow spurs.
SMOOTH_M = 1.0
#: Holes of the mask up to this area are filled (cars, tree crowns, noise), square metres.
MAX_HOLE_M2 = 50.0
#: Components of the mask under this area are noise, square metres.
MIN_AREA_M2 = 40.0
#: An end branch shorter than the half width of the widest road at its junction plus this
#: is a spur, metres (as the reference centre lines of mask datasets are pruned).
SPUR_M = 5.0
#: Junctions joined by a line shorter than this are one junction, metres.
JUNCTION_MERGE_M = 4.0
#: Branches at a junction are straight over this many half widths of the widest road there.
STRAIGHTEN = 1.5
#: Douglas-Peucker tolerance of the centre lines, metres.
SIMPLIFY_M = 0.5
#: Parts wider than this are no road: a six-lane arterial with its median is about 35 m.
MAX_WIDTH_M = WIDE_AREA_M
#: Isolated lines shorter than this are dropped, metres.
MIN_LENGTH_M = 10.0
#: An isolated string shorter than this many times its width is a blob, not a road.
MIN_ELONGATION = 2.0
#: Tiles of this many pixels a side, with this much context on each side.
TILE_PX = 2048
OVERLAP_PX = 128
#: Gap edges between dead ends (:func:`link_gaps`): as the imagery's subgraph generation,
#: with directions within 35 degrees and a lateral offset allowed up to a road's width (a
#: cut road's two ends are skeletonised independently), metres.
RASTER_GAPS = GapOptions(max_gap_m=40.0, max_direction_diff_rad=np.radians(35.0),
                         max_lateral_offset_m=5.0)

#: Weights of the gap edges (:func:`link_gaps`): widths measured on a raster vary more along
#: a road than a road part's (a part's mean width falls where it ends at a cut or bends), so
#: a width difference weighs 0 only at 10 m.
RASTER_WEIGHTS = WeightOptions(weight_ranges={"width_diff_m": (0.0, 10.0)})

#: The network generation of a raster's roads (:func:`parts_to_network`): junction search
#: radii of roads of quality 0 and 1 wider than the imagery's defaults (15 and 45 m), since
#: a raster's road ends retreat from a cut by half the road's width; a junction connection
#: running over more than 20 m off the road is refused.
RASTER_NETWORK = NetworkOptions(min_search_radius_m=15.0, max_search_radius_m=45.0,
                                max_unsupported_m=20.0)

#: :func:`with_missing_roads`: another network's line is missing from a network where it runs
#: farther than this beyond the half width of the network's roads, over pieces at least
#: MISSING_MIN_M long, metres.
MISSING_MARGIN_M = 1.0
MISSING_MIN_M = 5.0

_SEAM_SNAP_PX = 1.5


def road_probability(raster: GeoRaster, *, band: int = 1) -> GeoRaster:
    """The road probability of a raster, in [0, 1], NaN where there is no data.

    Parameters
    ----------
    raster : GeoRaster
        2-D, or ``(bands, rows, cols)``. Values 0-1 (a probability or a 0/1 mask), or 0-255
        (an 8-bit mask or probability; read whenever a value exceeds 1). ``nodata`` and NaN
        mark no data.
    band : int
        1-based band of a multi-band raster.

    Raises
    ------
    ValueError
        A band that does not exist, values below 0 or above 255, no valid pixel, or a
        geographic CRS (reproject to metres first).
    """
    if raster.crs is not None and not raster.crs.is_projected:
        raise GisroadsError("the road raster must be in a projected CRS in metres (reproject "
                            "it, e.g. to its UTM zone)")
    data = np.asarray(raster.data)
    if data.ndim == 3:
        if not 1 <= band <= data.shape[0]:
            raise GisroadsError(f"band {band} does not exist: the raster has {data.shape[0]}")
        data = data[band - 1]
    elif data.ndim != 2 or band != 1:
        raise GisroadsError(f"band {band} does not exist: the raster has one band")
    values = data.astype(np.float32)
    invalid = ~np.isfinite(values)
    if raster.nodata is not None and np.isfinite(raster.nodata):
        invalid |= data == raster.nodata
    values[invalid] = np.nan
    if invalid.all():
        raise GisroadsError("the road raster holds no valid pixel (all no-data or NaN)")
    low, high = np.nanmin(values), np.nanmax(values)
    if low < 0 or high > 255:
        raise GisroadsError(f"road raster values must lie in 0-1 or 0-255, found {low:g} to "
                            f"{high:g}")
    if high > 1:
        values /= 255.0
    return GeoRaster(values, raster.transform, raster.crs)


def road_mask(probability: np.ndarray, pixel_m: float, *, threshold: float = THRESHOLD,
              smooth_m: float = SMOOTH_M, max_hole_m2: float = MAX_HOLE_M2,
              min_area_m2: float = MIN_AREA_M2, low_threshold: float | None = None
              ) -> np.ndarray:
    """Road pixels of a probability raster, cleaned.

    Parameters
    ----------
    probability : ndarray, shape (rows, cols)
        0-1, NaN = no data (never road).
    pixel_m : float
        Pixel size, metres.
    threshold : float
        Road where the smoothed probability is at least this.
    smooth_m : float
        Gaussian sigma, metres (0: none). No-data pixels do not pull the road down: the
        smoothing is normalised by the smoothed validity.
    max_hole_m2, min_area_m2 : float
        Holes up to this area are filled; components under it dropped, square metres.
    low_threshold : float, optional
        Hysteresis (as Canny's edges): pixels at or above this (and below ``threshold``)
        are road too when their 8-connected component of such pixels holds a component
        of ``min_area_m2`` or more at or above ``threshold`` (salt noise seeds nothing). A
        road whose probability sags along a stretch (a grey surface, a shadow, sparse
        points) stays whole, and weak blobs on their own stay out. Off by default (None).

    Returns
    -------
    ndarray of bool
    """
    valid = np.isfinite(probability)
    values = np.where(valid, probability, 0).astype(np.float32)
    if smooth_m > 0:
        sigma = smooth_m / pixel_m
        weight = ndimage.gaussian_filter(valid.astype(np.float32), sigma)
        values = ndimage.gaussian_filter(values, sigma) / np.maximum(weight, 1e-6)
    road = (values >= threshold) & valid
    pixel_m2 = pixel_m ** 2
    if low_threshold is not None and low_threshold < threshold:
        strong, count = ndimage.label(road, structure=np.ones((3, 3)))
        seed = np.bincount(strong.ravel(), minlength=count + 1) * pixel_m2 >= min_area_m2
        seed[0] = False
        weak, count = ndimage.label((values >= low_threshold) & valid, structure=np.ones((3, 3)))
        seeded = np.zeros(count + 1, bool)
        seeded[weak[seed[strong]]] = True
        seeded[0] = False
        road = seeded[weak]
    background, count = ndimage.label(~road)
    touching_border = np.unique(np.concatenate([background[0], background[-1],
                                                background[:, 0], background[:, -1]]))
    small = np.bincount(background.ravel(), minlength=count + 1) * pixel_m2 <= max_hole_m2
    small[touching_border] = False
    small[0] = False
    road |= small[background]
    labels, count = ndimage.label(road, structure=np.ones((3, 3)))
    large = np.bincount(labels.ravel(), minlength=count + 1) * pixel_m2 >= min_area_m2
    large[0] = False
    return large[labels]


def _tiles(shape, tile_px: int, overlap_px: int):
    """Per tile: the window with context and the core (row and column slices)."""
    rows, cols = shape
    for r0 in range(0, rows, tile_px):
        for c0 in range(0, cols, tile_px):
            core = (slice(r0, min(rows, r0 + tile_px)), slice(c0, min(cols, c0 + tile_px)))
            window = (slice(max(0, r0 - overlap_px), min(rows, r0 + tile_px + overlap_px)),
                      slice(max(0, c0 - overlap_px), min(cols, c0 + tile_px + overlap_px)))
            yield window, core


def _box(transform, rows: slice, cols: slice):
    x0, y0 = _apply(transform, cols.start, rows.start)
    x1, y1 = _apply(transform, cols.stop, rows.stop)
    return shapely.box(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1))


def _sample(raster: GeoRaster, lines, step_m: float):
    """Per line, the mean of the raster at points every ``step_m`` along it (NaN counts 0)."""
    points, owner = shapely.get_coordinates(shapely.segmentize(lines, step_m),
                                            return_index=True)
    rows, cols = raster.xy_to_rowcol(points[:, 0], points[:, 1])
    inside = (rows >= 0) & (rows < raster.shape[0]) & (cols >= 0) & (cols < raster.shape[1])
    values = np.zeros(len(points))
    values[inside] = np.nan_to_num(raster.data[rows[inside], cols[inside]])
    return (np.bincount(owner, weights=values, minlength=len(lines))
            / np.maximum(np.bincount(owner, minlength=len(lines)), 1))


def _off_road_length(raster: GeoRaster, threshold: float):
    """``measure(lines) -> metres`` of each line where ``raster`` is below ``threshold``
    (sampled every pixel; no data and outside count as off road)."""
    def measure(lines):
        length = shapely.length(lines)
        # GEOS cannot segmentize a line of length 0; it has nothing off road either
        points, owner = shapely.get_coordinates(
            shapely.segmentize(np.where(length > 0, lines, None), raster.pixel_size),
            return_index=True)
        rows, cols = raster.xy_to_rowcol(points[:, 0], points[:, 1])
        inside = ((rows >= 0) & (rows < raster.shape[0]) & (cols >= 0)
                  & (cols < raster.shape[1]))
        on_road = np.zeros(len(points), dtype=bool)
        on_road[inside] = np.nan_to_num(raster.data[rows[inside], cols[inside]]) >= threshold
        off_share = 1.0 - (np.bincount(owner, weights=on_road, minlength=len(lines))
                           / np.maximum(np.bincount(owner, minlength=len(lines)), 1))
        return off_share * length
    return measure


def _stitch_seams(lines, seams, tolerance_m: float):
    """Ends of tile cores that meet on a seam within ``tolerance_m`` become one point."""
    if len(lines) == 0 or seams.is_empty:
        return lines
    ends = np.concatenate([shapely.get_coordinates(shapely.get_point(lines, 0)),
                           shapely.get_coordinates(shapely.get_point(lines, -1))])
    on_seam = np.flatnonzero(shapely.distance(shapely.points(ends), seams) <= 1e-6)
    if len(on_seam) < 2:
        return lines
    pairs = shapely.STRtree(shapely.points(ends[on_seam])).query(
        shapely.points(ends[on_seam]), predicate="dwithin", distance=tolerance_m)
    count, group = connected_components(coo_matrix(
        (np.ones(pairs.shape[1]), (pairs[0], pairs[1])), shape=(len(on_seam),) * 2))
    centre = np.column_stack([np.bincount(group, weights=ends[on_seam, k]) / np.bincount(group)
                              for k in (0, 1)])
    ends[on_seam] = centre[group]
    n = len(lines)
    coords, owner = shapely.get_coordinates(lines, return_index=True)
    first = np.r_[0, np.flatnonzero(np.diff(owner)) + 1]
    last = np.r_[first[1:] - 1, len(coords) - 1]
    coords[first], coords[last] = ends[:n], ends[n:]
    return shapely.linestrings(coords, indices=owner)


def _raw_skeleton(probability: GeoRaster, *, tile_px: int, overlap_px: int, mask_options,
                  max_cut_m: float, progress: Progress):
    """Skeleton lines with widths of the whole raster, tile by tile, cores stitched."""
    pixel_m = probability.pixel_size
    transform = probability.transform
    pieces, widths, cores = [], [], []
    tiles = list(_tiles(probability.shape, tile_px, overlap_px))
    for k, (window, core) in enumerate(tiles):
        report(progress, k / len(tiles), f"skeleton, tile {k + 1} of {len(tiles)}")
        mask = road_mask(probability.data[window], pixel_m, **mask_options)
        if not mask.any():
            continue
        if max_cut_m > 0:
            mask = bridge_cuts(mask, pixel_m, max_cut_m=max_cut_m)
        x0, y0 = _apply(transform, window[1].start, window[0].start)
        local = Affine(transform.a, transform.b, x0, transform.d, transform.e, y0)
        lines = skeleton_lines(mask, local, probability.crs)
        core_box = _box(transform, *core)
        cores.append(core_box)
        if len(tiles) > 1:
            lines = lines.assign(geometry=shapely.intersection(lines.geometry.values,
                                                               core_box))
            lines = lines.explode(index_parts=False)
            lines = lines[(lines.geom_type == "LineString") & ~lines.is_empty]
        pieces.append(lines.geometry.values)
        widths.append(lines["width_m"].to_numpy(float))
    if not pieces:
        return np.empty(0, dtype=object), np.empty(0)
    lines, width = np.concatenate(pieces), np.concatenate(widths)
    if len(tiles) > 1:
        extent = _box(transform, slice(0, probability.shape[0]), slice(0, probability.shape[1]))
        seams = shapely.difference(shapely.union_all(shapely.boundary(np.array(cores))),
                                   extent.exterior.buffer(1e-6))
        lines = _stitch_seams(lines, seams, _SEAM_SNAP_PX * pixel_m)
    return lines, width


def _straighten(lines, reach_m):
    """Ends of skeleton lines made straight over ``reach_m`` (one value per line).

    At a junction (three or more ends meeting) the skeleton bends towards the crossing's
    centre: the line's last ``reach_m`` (the most of its lines there) becomes a straight
    segment to the junction. At a dead end it forks towards the corners of the road's end:
    the last ``reach_m`` is replaced by the continuation of the stretch before it, so the
    line ends where the road does.
    """
    ends = np.stack([shapely.get_coordinates(shapely.get_point(lines, 0)),
                     shapely.get_coordinates(shapely.get_point(lines, -1))], axis=1)
    keys = np.round(ends.reshape(-1, 2) / 1e-6).astype(np.int64)
    _, node, degree = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    node = node.ravel()
    reach = np.zeros(len(degree))
    np.maximum.at(reach, node, np.repeat(reach_m, 2))
    end_degree = degree[node].reshape(-1, 2)
    length = shapely.length(lines)
    # never more than a third of a line from either end, and loops are left alone
    cut = np.minimum(np.where(end_degree >= 3, reach[node].reshape(-1, 2),
                              np.where(end_degree == 1, np.asarray(reach_m)[:, None], 0.0)),
                     length[:, None] / 3)
    out = np.array(lines, dtype=object)
    for k in np.flatnonzero(cut.any(axis=1)):
        xy = shapely.get_coordinates(lines[k])
        along = np.r_[0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
        inner = xy[(along > cut[k, 0]) & (along < length[k] - cut[k, 1])]
        if len(inner) == 0:
            continue
        first, last = xy[:1], xy[-1:]
        if end_degree[k, 0] == 1:
            first = inner[:1] + _heading(inner[::-1], cut[k, 0]) * cut[k, 0]
        if end_degree[k, 1] == 1:
            last = inner[-1:] + _heading(inner, cut[k, 1]) * cut[k, 1]
        out[k] = shapely.linestrings(np.vstack([first, inner, last]))
    return out


def _heading(xy: np.ndarray, window_m: float) -> np.ndarray:
    """Unit direction at the last vertex of ``xy``, over about ``window_m`` before it."""
    back = np.hypot(*(xy - xy[-1]).T)
    far = np.flatnonzero(back >= window_m)
    start = xy[far[-1]] if len(far) else xy[0]
    d = xy[-1] - start
    norm = np.hypot(*d)
    return d / norm if norm > 0 else np.zeros(2)


@dataclass(frozen=True)
class PartOptions:
    """The options of :func:`skeleton_parts`: cleaning the road mask, pruning and
    straightening its skeleton, and the tiles it is computed in.

    Attributes
    ----------
    smooth_m, max_hole_m2, min_area_m2, low_threshold : float
        See :func:`road_mask` (the hysteresis of ``low_threshold`` connects within a tile
        and its overlap).
    spur_m : float
        End branches shorter than the half width of the widest road at their junction plus
        this are pruned, metres.
    junction_merge_m : float
        Junctions joined by a shorter line are contracted into one, metres.
    straighten : float
        The stretch of a branch within this many half widths of the widest road at its
        junction becomes straight.
    simplify_m : float
        Douglas-Peucker tolerance, metres.
    max_width_m : float
        Parts wider than this (mean width, metres) are no road: the middle of a field, a
        lawn or a square.
    tile_px, overlap_px : int
        Tile side and context on each side, pixels.
    max_cut_m : float
        Cuts across roads up to this long are closed in the mask before the skeleton
        (:func:`gisroads.network.cuts.bridge_cuts`), metres; 0: none.
    """

    smooth_m: float = SMOOTH_M
    max_hole_m2: float = MAX_HOLE_M2
    min_area_m2: float = MIN_AREA_M2
    spur_m: float = SPUR_M
    junction_merge_m: float = JUNCTION_MERGE_M
    straighten: float = STRAIGHTEN
    simplify_m: float = SIMPLIFY_M
    max_width_m: float = MAX_WIDTH_M
    tile_px: int = TILE_PX
    overlap_px: int = OVERLAP_PX
    low_threshold: float | None = None
    max_cut_m: float = MAX_CUT_M


def skeleton_parts(probability: GeoRaster, options: PartOptions = PartOptions(), *,
                   threshold: float = THRESHOLD, progress: Progress = None,
                   **changes) -> gpd.GeoDataFrame:
    """Road parts of a probability raster: clean centre lines split at junctions.

    Parameters
    ----------
    probability : GeoRaster
        2-D, 0-1, NaN = no data (see :func:`road_probability`), projected CRS in metres.
    threshold : float
        See :func:`road_mask`.
    options : PartOptions
        Mask cleaning, skeleton pruning and tiles (:class:`PartOptions`).
    progress : callable, optional
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    GeoDataFrame
        LineStrings with ``part_id``, ``width_m`` (mean of twice the distance to the mask
        border along the line, metres) and ``quality`` (mean probability along the line).
    """
    options = replace(options, **changes)
    if options.tile_px < 64 or options.overlap_px < 0:
        raise GisroadsError("tile_px must be at least 64 and overlap_px at least 0")
    mask_options = dict(threshold=threshold, smooth_m=options.smooth_m,
                        max_hole_m2=options.max_hole_m2, min_area_m2=options.min_area_m2,
                        low_threshold=options.low_threshold)
    lines, width = _raw_skeleton(probability, tile_px=options.tile_px,
                                 overlap_px=options.overlap_px,
                                 mask_options=mask_options, max_cut_m=options.max_cut_m,
                                 progress=scaled(progress, 0.0, 0.8))
    report(progress, 0.8, "pruning spurs, contracting junctions")
    crs = probability.crs
    if len(lines):
        score = np.zeros(len(lines))
        lines, width, score = node_roads(lines, width, score, join_gap_m=options.spur_m,
                                         min_length_m=0.0)
        lines, width, score = merge_close_junctions(lines, width, score,
                                                    junction_merge_m=options.junction_merge_m)
        lines, width, score = node_roads(lines, width, score, join_gap_m=options.spur_m,
                                         min_length_m=0.0)
        lines = _straighten(lines, options.straighten * width / 2)
        lines = shapely.simplify(lines, options.simplify_m, preserve_topology=False)
        usable = (shapely.length(lines) > 0) & (width <= options.max_width_m)
        lines, width = lines[usable], width[usable]
    quality = _sample(probability, lines, probability.pixel_size) if len(lines) else []
    report(progress, 1.0, f"{len(lines)} road parts")
    return gpd.GeoDataFrame(
        {"part_id": np.arange(len(lines), dtype=np.int64), "width_m": np.asarray(width, float),
         "quality": np.clip(np.asarray(quality, float), 0, 1)},
        geometry=gpd.GeoSeries(lines, crs=crs), crs=crs)


def link_gaps(parts: gpd.GeoDataFrame, probability: GeoRaster | None = None, *,
              gap_options: GapOptions = RASTER_GAPS, weight_options: WeightOptions = RASTER_WEIGHTS
              ) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame]:
    """Bridge gaps between dead ends (see the module docstring).

    Parameters
    ----------
    parts : GeoDataFrame
        From :func:`skeleton_parts`.
    probability : GeoRaster, optional
        The road probability; its mean along a gap is the gap's context (``occlusion``).
    gap_options : GapOptions
        The limits of a gap edge (:func:`gisroads.network.subgraph.gap_edges`); default
        :data:`RASTER_GAPS`.
    weight_options : WeightOptions
        The weights of the gap edges (:func:`gisroads.network.subgraph.edge_weights`);
        default :data:`RASTER_WEIGHTS`.

    Returns
    -------
    gaps : GeoDataFrame
        The gap edges between dead ends, with their weights and ``selected``.
    strings : GeoDataFrame
        Parts chained through the selected gaps (:func:`gisroads.network.subgraph.road_strings`).
    """
    gaps = gap_edges(parts, gap_options)
    if len(gaps):
        free = free_line_ends(parts.geometry.values)
        row = pd.Series(np.arange(len(parts)), index=parts["part_id"].to_numpy())
        keep = (free[row[gaps["from_part"]].to_numpy(), gaps["from_end"].to_numpy()]
                & free[row[gaps["to_part"]].to_numpy(), gaps["to_end"].to_numpy()])
        gaps = gaps[keep].reset_index(drop=True)
        gaps["gap_id"] = np.arange(len(gaps), dtype=np.int64)
    if probability is not None:
        gaps["occlusion"] = (_sample(probability, gaps.geometry.values, probability.pixel_size)
                             if len(gaps) else np.empty(0))
        for kind in ("building", "vehicle", "tree", "vegetated_area", "shadow", "asphalt"):
            gaps[f"n_{kind}"] = 0.0
    gaps = select_gap_edges(edge_weights(gaps, weight_options))
    return gaps, road_strings(parts, gaps)


def drop_blobs(strings: gpd.GeoDataFrame, *, min_elongation: float = MIN_ELONGATION,
               min_length_m: float = MIN_LENGTH_M
               ) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame]:
    """Road strings that touch no other string and are short for their width, or short,
    are blobs (a roof, a car park, a false patch of the raster, noise), not roads. Short
    pieces of road between two cuts are kept when the gap linking chained them into a
    longer string.

    Parameters
    ----------
    strings : GeoDataFrame
        From :func:`link_gaps` (``width_m``).
    min_elongation : float
        An isolated string shorter than this many times its width is a blob.
    min_length_m : float
        An isolated string shorter than this is a blob, metres.

    Returns
    -------
    kept, blobs : GeoDataFrame
    """
    lines = strings.geometry.values
    if len(lines) == 0:
        return strings, strings.iloc[:0]
    a, b = shapely.STRtree(lines).query(lines, predicate="intersects")
    touching = np.bincount(a[a != b], minlength=len(lines)) > 0
    shortest = np.maximum(min_length_m, min_elongation * strings["width_m"].to_numpy(float))
    blob = ~touching & (shapely.length(lines) < shortest)
    return strings[~blob], strings[blob]


def _rejected(raw_lines, kept_lines, crs) -> gpd.GeoDataFrame:
    """Stretches of the raw skeleton that no road keeps (spurs, noise), with a reason."""
    if len(raw_lines) == 0:
        return gpd.GeoDataFrame({"reason": pd.Series(dtype=object)},
                                geometry=gpd.GeoSeries([], crs=crs), crs=crs)
    covered = shapely.buffer(shapely.union_all(kept_lines), 1.0) if len(kept_lines) else None
    lost = (shapely.difference(raw_lines, covered) if covered is not None
            else np.asarray(raw_lines, dtype=object))
    lost = shapely.get_parts(lost)
    lost = lost[shapely.length(lost) > 1.0]
    return gpd.GeoDataFrame({"reason": np.full(len(lost), "spur or isolated", dtype=object),
                             "length_m": shapely.length(lost)},
                            geometry=gpd.GeoSeries(lost, crs=crs), crs=crs)


def _observed(probability: GeoRaster):
    """The area of a raster's valid (finite) pixels, grown by a pixel so that a line along
    a staircase border (a reprojected raster's edge) is not cut into pieces; None when all
    pixels are valid."""
    valid = np.isfinite(probability.data)
    if valid.all():
        return None
    area = segment_polygons(np.where(valid, 0, -1).astype(np.int32), 1,
                            probability.transform)[0]
    return shapely.buffer(area if area is not None else shapely.Polygon(),
                          probability.pixel_size, join_style="mitre")


def _clip_to_extent(network: RoadNetwork, extent) -> None:
    """Keep the network inside the raster (or the area it has data in): a dead end
    extended to where its road ends, or a junction built through the extensions of two
    ends, can reach past the border."""
    lines = network.centrelines
    if len(lines) == 0 or shapely.covers(extent, shapely.union_all(lines.geometry.values)):
        return
    clipped = shapely.intersection(lines.geometry.values, extent)
    lines = lines.assign(geometry=clipped).explode(index_parts=False)
    lines = lines[(lines.geom_type == "LineString") & ~lines.is_empty].reset_index(drop=True)
    lines["length_m"] = shapely.length(lines.geometry.values)
    network.centrelines = lines
    polygons = network.polygons.assign(geometry=shapely.intersection(
        network.polygons.geometry.values, extent)).explode(index_parts=False)
    polygons = polygons[polygons.geom_type == "Polygon"].reset_index(drop=True)
    polygons["area_m2"] = shapely.area(polygons.geometry.values)
    network.polygons = polygons
    network.junctions = network.junctions[shapely.covers(
        extent, network.junctions.geometry.values)].reset_index(drop=True)


def parts_to_network(parts: gpd.GeoDataFrame, *, extent, crs, method: str = METHOD,
                     observed=None, probability: GeoRaster | None = None, unsupported=None,
                     gap_options: GapOptions = RASTER_GAPS,
                     weight_options: WeightOptions = RASTER_WEIGHTS,
                     network_options: NetworkOptions = RASTER_NETWORK,
                     progress: Progress = None) -> RoadNetwork:
    """Road parts (centre lines of road pieces, from a raster or from any other cue) to
    the road-network contract: the network stage every method ends in.

    Gaps between dead ends bridged by the integer program (:func:`link_gaps`), isolated
    short pieces dropped (:func:`drop_blobs`), then junctions built, duplicates removed,
    insignificant components dropped and lines split at junctions
    (:func:`gisroads.network.junctions.strings_to_network`), and the result clipped to
    ``extent``.

    Parameters
    ----------
    parts : GeoDataFrame
        LineStrings in a metre CRS with ``part_id``, ``width_m`` (metres) and ``quality``
        (0-1).
    extent : (xmin, ymin, xmax, ymax)
        Where the cue was observed, metres: the border rule of the significance check, and
        the network is clipped to it.
    crs
        The parts' CRS.
    method : str
        The ``method`` of every centre line.
    observed : shapely geometry, optional
        The part of ``extent`` the cue has data in (an image's valid pixels): the network
        is clipped to it instead, so that a road ending at a no-data border stops there.
    probability : GeoRaster, optional
        A road probability raster: the context of the gap edges (see :func:`link_gaps`).
    unsupported : callable, optional
        ``unsupported(lines) -> metres`` of each candidate junction connection that the cue
        does not show as road (see :func:`gisroads.network.junctions.find_junctions`); in
        place of ``network_options.unsupported`` when given.
    gap_options : GapOptions
        See :func:`link_gaps`; default :data:`RASTER_GAPS`.
    weight_options : WeightOptions
        See :func:`link_gaps`; default :data:`RASTER_WEIGHTS`.
    network_options : NetworkOptions
        Junctions, duplicates and significance
        (:func:`gisroads.network.junctions.strings_to_network`); default
        :data:`RASTER_NETWORK` (change it with :func:`dataclasses.replace`, e.g.
        ``replace(RASTER_NETWORK, max_unsupported_m=np.inf)``).
    progress : callable, optional

    Returns
    -------
    RoadNetwork
        QA layers ``gap_edges`` and ``junction_connections``.
    """
    report(progress, 0.0, "linking gaps")
    gaps, strings = link_gaps(parts, probability, gap_options=gap_options,
                              weight_options=weight_options)
    strings, blobs = drop_blobs(strings)
    if unsupported is not None:
        network_options = replace(network_options, unsupported=unsupported)
    network, _ = strings_to_network(strings, network_options, extent=extent, crs=crs,
                                    method=method, progress=scaled(progress, 0.25, 0.95))
    _clip_to_extent(network, shapely.box(*extent) if observed is None else observed)
    network.qa["gap_edges"] = gaps
    report(progress, 1.0, f"{len(network.centrelines)} roads, "
                          f"{len(network.junctions)} junctions")
    return network


def with_missing_roads(network: RoadNetwork, other: gpd.GeoDataFrame,
                       probability: GeoRaster, *, method: str = METHOD,
                       margin_m: float = MISSING_MARGIN_M,
                       min_length_m: float = MISSING_MIN_M,
                       progress: Progress = None) -> RoadNetwork:
    """``network`` with the roads of another network of the same raster's area that it
    lacks, joined to its roads by the network stage.

    The pieces of ``other``'s lines farther than ``margin_m`` beyond the half width of
    ``network``'s roads, at least ``min_length_m`` long, and ``network``'s roads are the
    road parts of :func:`parts_to_network` (gaps bridged, junctions built, lines split at
    them), on ``probability``'s extent and valid pixels.

    Parameters
    ----------
    network : RoadNetwork
        Centre lines with ``width_m`` (metres) and ``score`` (0-1).
    other : GeoDataFrame
        Centre lines with ``width_m`` and ``score`` in the same CRS, e.g. another cue's.
    probability : GeoRaster
        The raster ``network`` was built on: its extent, CRS and valid pixels.
    method : str
        The ``method`` of every centre line.
    margin_m, min_length_m : float
        Metres.
    progress : callable, optional

    Returns
    -------
    RoadNetwork
        ``network`` itself when ``other`` adds nothing; else a new network with the QA
        layers of this run and ``rejected`` kept from ``network``.

    Examples
    --------
    A T of two 8 m roads at 0.5 m cells, and the same raster without the T's stem:

    >>> import numpy as np
    >>> from affine import Affine
    >>> from pyproj import CRS
    >>> from gisroads.geo import GeoRaster
    >>> from gisroads.network import raster_to_network, with_missing_roads
    >>> mask = np.zeros((400, 400), np.uint8)
    >>> mask[192:208, :] = 1
    >>> mask[200:, 192:208] = 1
    >>> grid, utm = Affine(0.5, 0.0, 500000.0, 0.0, -0.5, 5000000.0), CRS.from_epsg(32633)
    >>> t = GeoRaster(mask, grid, utm)
    >>> road = GeoRaster(np.where(np.arange(400)[:, None] < 208, mask, 0), grid, utm)
    >>> lacking = raster_to_network(road)
    >>> len(lacking.centrelines), len(lacking.junctions)
    (1, 0)
    >>> merged = with_missing_roads(lacking, raster_to_network(t).centrelines, t)
    >>> len(merged.centrelines), merged.junctions.degree.tolist()
    (3, [3])
    """
    roads = network.centrelines
    pieces = other
    if len(roads) and len(other):
        cover = shapely.union_all(shapely.buffer(
            roads.geometry.values, roads["width_m"].to_numpy(float) / 2 + margin_m))
        pieces = other.assign(geometry=shapely.difference(other.geometry.values, cover))
        pieces = pieces.explode(index_parts=False)
    pieces = pieces[(pieces.geom_type == "LineString")
                    & (shapely.length(pieces.geometry.values) >= min_length_m)]
    if not len(pieces):
        return network
    both = pd.concat([roads[["width_m", "score", "geometry"]],
                      pieces[["width_m", "score", "geometry"]]], ignore_index=True)
    parts = gpd.GeoDataFrame(
        {"part_id": np.arange(len(both), dtype=np.int64),
         "width_m": both["width_m"].to_numpy(float), "quality": both["score"].to_numpy(float)},
        geometry=both.geometry.values, crs=probability.crs)
    merged = parts_to_network(parts, extent=probability.bounds, crs=probability.crs,
                              method=method, observed=_observed(probability),
                              progress=progress)
    merged.qa["rejected"] = network.qa.get("rejected", _rejected([], [], probability.crs))
    return merged


def without_lines(raster: GeoRaster, lines, *, margin_m: float = 1.0,
                  area=None, keep=None, spread_above: float | None = None) -> GeoRaster:
    """A copy of a road raster with the band ``width / 2 + margin_m`` (metres) of each of
    ``lines`` (LineStrings with ``width_m``, in its CRS) set to 0, and ``area`` (a shapely
    geometry, optional) too, NaN cells kept: run the network stage again on it and the
    lines are gone, the roads they touched joined and split as if they had never been
    there. The bands ``width / 2`` of ``keep`` (lines with ``width_m``, optional) are left
    as they are, so a way taken off a road does not cut the road where it joins it. With
    ``spread_above``, the cells at least that likely that connect to the erased band
    (outside ``keep``) within one more width of each line go too: a paved area beside the
    line goes whole, not as a slot cut through it that leaves its sides to be drawn again,
    and the fringes of the kept roads beyond are left alone."""
    from rasterio import features

    data = np.array(raster.data, dtype=np.float32, copy=True)
    shapes = list(shapely.buffer(lines.geometry.values,
                                 lines["width_m"].to_numpy(float) / 2 + margin_m))
    if area is not None and not area.is_empty:
        shapes.append(area)
    if shapes:
        erase = features.rasterize(shapes, out_shape=data.shape,
                                   transform=raster.transform).astype(bool)
        kept = np.zeros(data.shape, bool)
        if keep is not None and len(keep):
            kept = features.rasterize(
                shapely.buffer(keep.geometry.values, keep["width_m"].to_numpy(float) / 2),
                out_shape=data.shape, transform=raster.transform).astype(bool)
        erase &= ~kept
        if spread_above is not None:
            near = features.rasterize(
                shapely.buffer(lines.geometry.values,
                               lines["width_m"].to_numpy(float) * 1.5 + margin_m),
                out_shape=data.shape, transform=raster.transform).astype(bool)
            labels, _ = ndimage.label((np.nan_to_num(data) >= spread_above) & ~kept & near)
            erase |= np.isin(labels, np.unique(labels[erase & (labels > 0)]))
        data[erase & np.isfinite(data)] = 0.0
    return GeoRaster(data, raster.transform, raster.crs, nodata=raster.nodata)


def raster_to_network(raster: GeoRaster, *, band: int = 1, threshold: float = THRESHOLD,
                      method: str = METHOD, part_options: PartOptions = PartOptions(),
                      gap_options: GapOptions = RASTER_GAPS,
                      weight_options: WeightOptions = RASTER_WEIGHTS,
                      network_options: NetworkOptions = RASTER_NETWORK,
                      wide_areas: bool = False, progress: Progress = None) -> RoadNetwork:
    """A road raster (mask or probability) to the road-network contract.

    Parameters
    ----------
    raster : GeoRaster
        See :func:`road_probability`; projected CRS in metres.
    band : int
        1-based band.
    threshold : float
        Road probability threshold (0-1; a 0-255 raster is scaled to 0-1 first).
    method : str
        The ``method`` of every centre line.
    part_options : PartOptions
        Mask cleaning, skeleton pruning and tiles (:func:`skeleton_parts`); its
        ``low_threshold`` (when set) also bounds the road of the junction connections and
        of the wide paved areas.
    gap_options, weight_options, network_options : GapOptions, WeightOptions, NetworkOptions
        See :func:`parts_to_network` (defaults :data:`RASTER_GAPS`, :data:`RASTER_WEIGHTS`,
        :data:`RASTER_NETWORK`).
    wide_areas : bool
        Take out the lines drawn in wide paved areas (car parks, plazas: their outlines,
        aisles and accesses, :mod:`gisroads.network.areas`) and build the network again
        without them; they go to ``rejected`` with the reason "wide paved area".
    progress : callable, optional
        ``progress(fraction, message)``; may raise :class:`gisroads.progress.Cancelled`.

    Returns
    -------
    RoadNetwork
        ``score`` is the mean road probability along each road; QA layers ``gap_edges``,
        ``junction_connections`` and ``rejected``. Empty (valid, typed layers) when the
        raster holds no road.

    Examples
    --------
    A synthetic scene's road areas as a segmentation would give them, cut in ten places
    and sprinkled with false blobs and noise, back to a connected network:

    >>> from affine import Affine
    >>> from rasterio.features import rasterize
    >>> from gisroads.evaluate import buffer_metrics
    >>> from gisroads.geo import GeoRaster
    >>> from gisroads.network import raster_to_network
    >>> from gisroads.synthetic import degrade_mask, make_scene
    >>> scene = make_scene(seed=0, size_m=(300, 300))
    >>> truth = scene.truth
    >>> x0, y0, x1, y1 = scene.extent
    >>> transform = Affine(0.5, 0.0, x0, 0.0, -0.5, y1)        # 0.5 m cells, north up
    >>> mask = rasterize(truth.polygons.geometry, out_shape=(600, 600), transform=transform)
    >>> segmentation = degrade_mask(mask, truth.centrelines, transform, cuts=10, seed=0)
    >>> raster = GeoRaster(segmentation.astype("float32"), transform, scene.crs)
    >>> network = raster_to_network(raster)
    >>> sorted(network.qa)
    ['gap_edges', 'junction_connections', 'rejected']
    >>> int(network.qa["gap_edges"].selected.sum()) > 0       # gaps bridged
    True
    >>> scores = buffer_metrics(network.centrelines, truth.centrelines, buffer_m=3.0)
    >>> scores.completeness > 0.9, scores.correctness > 0.9
    (True, True)
    """
    probability = road_probability(raster, band=band)
    options = dict(threshold=threshold, method=method, part_options=part_options,
                   gap_options=gap_options, weight_options=weight_options,
                   network_options=network_options)
    end = 0.7 if wide_areas else 1.0
    parts = skeleton_parts(probability, part_options, threshold=threshold,
                           progress=scaled(progress, 0.0, 0.6 * end))
    low = part_options.low_threshold
    network = parts_to_network(
        parts, extent=probability.bounds, crs=probability.crs, method=method,
        observed=_observed(probability), probability=probability,
        unsupported=_off_road_length(probability, threshold if low is None else low),
        gap_options=gap_options, weight_options=weight_options,
        network_options=network_options, progress=scaled(progress, 0.6 * end, end))
    network.qa["rejected"] = _rejected(parts.geometry.values,
                                       network.centrelines.geometry.values, probability.crs)
    if wide_areas and len(network.centrelines):
        area = wide_paved_areas(probability, threshold if low is None else low)
        taken = lines_in_wide_areas(network.centrelines.geometry.values, area,
                                    extent=shapely.box(*probability.bounds))
        if taken.any():
            paved, roads = network.centrelines[taken], network.centrelines[~taken]
            # the rest of the area too, or its remnants beside the roads through it draw
            # their own lines
            rest = shapely.difference(area, shapely.union_all(shapely.buffer(
                roads.geometry.values, roads["width_m"].to_numpy(float) / 2 + 1.0)))
            network = raster_to_network(without_lines(probability, paved, area=rest),
                                        **options, progress=scaled(progress, end, 1.0))
            network.qa["rejected"] = pd.concat([network.qa["rejected"], gpd.GeoDataFrame(
                {"reason": np.full(len(paved), "wide paved area", dtype=object),
                 "length_m": shapely.length(paved.geometry.values)},
                geometry=paved.geometry.values, crs=probability.crs)], ignore_index=True)
    return network
