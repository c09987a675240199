"""Road subgraphs: gap hypotheses between road parts, their weights, and the integer program
that keeps one connection per road-part end (Grote & Rottensteiner 2010, Sec. 2.2;
Grote et al. 2009).

Stages, each callable alone
---------------------------
:func:`gap_edges`
    Subgraph generation (Sec. 2.2.1): every pair of road-part ends that passes the link
    criteria (distance absolute and relative to the parts' lengths, direction difference,
    continuation smoothness) becomes a gap edge; competing branches are all kept.
:func:`gap_context`
    What lies in each gap (Sec. 2.2.2): buildings, vehicles, trees, vegetated areas, shadow
    and asphalt-like surface inside the gap's road-part hypothesis, and the occluded share.
:func:`edge_weights`
    Relation weight (product of six linear weight functions), context weight and their
    combination into the weight ``w_i`` of Eq. 1.
:func:`select_gap_edges`
    Eq. 1 as a 0/1 integer program solved with PuLP: at most one connection per part end.
:func:`road_strings`
    Parts chained through the selected gap edges into road strings, the input of network
    generation.

:func:`link_road_parts` composes them.

What the papers leave open, and what we chose
---------------------------------------------
The excerpt of Grote et al. (2009) in this project stops before the subgraph evaluation and
the 2010 paper gives the method without numbers, so every threshold and weight range below is
ours (module constants, all parameters):

- Links are end to end only: a subgraph follows roads "in a more or less straight
  continuation" and junctions are left to network generation (Sec. 2.2.1, 2.3).
- A part's direction at an end is the direction of its last ``end_window_m`` (at most half
  the part), so curved parts continue along their ends rather than along their chords.
  Direction difference is the angle between one end's outward direction and the reverse of
  the other's (0 for a straight continuation). Continuation smoothness is the lateral offset:
  the mean distance of each end from the other part's extension line, in metres. Both ends
  must lie ahead of each other, up to a small overlap (no backward links).
- Relative distance is the gap over the sum of both parts' lengths.
- The generation is greedy as in the paper: subgraphs grow from the best-quality part not yet
  used, always extending the best-quality part reached; an edge's ``from`` side is the part it
  was found from. As the link criteria are symmetric, the edges found are all pairs that pass
  them, and a subgraph is a connected component of them; the greedy order fixes
  ``subgraph_id`` (best subgraph first) and the edge directions.
- The "qualities of the connected road parts" are one feature of the six, their mean.
- Context relation categories (the paper has 14, defined in Grote et al. 2009, not given
  here) are those we can detect inside the gap from the rasters at hand:
  :data:`RELATION_VALUES`. A building on the road is -10 as in the paper; a vegetated
  (low, nDSM given) area on the road -0.5; a vehicle or asphalt-like surface on the road
  +0.5; trees and shadow 0, as they support a link through the occlusion share instead.
  Without an nDSM vegetation cannot be split into trees and lawns and counts as trees, the
  usual cause of a road part missing between two others.
- A raised road (bridge deck, ramp) reads as a building in the nDSM. With a DSM the
  road-part stage keeps only parts low in the nDSM, so no such parts reach this stage.
"""
from __future__ import annotations

import heapq
import re
from dataclasses import dataclass, replace

import geopandas as gpd
import numpy as np
import pandas as pd
import pulp
import shapely
from affine import Affine
from scipy import ndimage

from ..errors import GisroadsError
from ..optimize import solver, variable
from ..progress import Progress, report, scaled

#: Largest gap between two linked part ends, metres.
MAX_GAP_M = 40.0
#: Largest gap relative to the sum of both parts' lengths.
MAX_GAP_RELATIVE = 1.0
#: Largest direction difference of a link, radians (30 degrees).
MAX_DIRECTION_DIFF_RAD = np.pi / 6
#: Largest lateral offset (continuation smoothness) of a link, metres.
MAX_LATERAL_OFFSET_M = 4.0
#: Length of a part's end section that gives its direction at that end, metres.
END_WINDOW_M = 10.0
#: How far two linked ends may reach past each other, metres: centre lines extended to
#: their segments' borders overlap by a pixel or two where two segments touch.
MAX_OVERLAP_M = 2.0

#: Linear weight functions ``w_R(f)``: feature -> (value of weight 1, value of weight 0);
#: in between the weight is linear, outside it is clipped to [0, 1]. The "bad" ends lie
#: beyond the generation limits, so a link at a limit keeps a small positive weight.
WEIGHT_RANGES = {
    "smoothness": (0.0, 6.0),                  # lateral offset, metres
    "distance_m": (0.0, 60.0),
    "direction_diff_rad": (0.0, np.pi / 4),
    "quality": (1.0, 0.0),                     # mean quality of the two parts
    "colour_diff": (0.0, 0.25),                # RMS difference of band means (0..1)
    "width_diff_m": (0.0, 5.0),
}

#: Context relation values ``v_k`` (Eq. 2) of the categories found in a gap.
RELATION_VALUES = {
    "building": -10.0,
    "vegetated_area": -0.5,
    "tree": 0.0,
    "shadow": 0.0,
    "vehicle": 0.5,
    "asphalt": 0.5,
}
#: Gaps shorter than this ignore their context (too short to judge), metres.
SMALL_GAP_M = 3.0
#: Context weight a link needs when its relation weight is 0.
GOOD_CONTEXT = 0.75

_BAND = re.compile(r"mean_b\d+$")
_GAP_COLUMNS = {"gap_id": "int64", "subgraph_id": "int64", "from_part": "int64",
                "from_end": "int64", "to_part": "int64", "to_end": "int64",
                "smoothness": "float64", "distance_m": "float64",
                "direction_diff_rad": "float64", "quality_from": "float64",
                "quality_to": "float64", "colour_diff": "float64", "width_diff_m": "float64",
                "width_m": "float64"}
_STRING_COLUMNS = {"string_id": "int64", "part_ids": "object", "width_m": "float64",
                   "quality": "float64", "length_m": "float64", "n_parts": "int64"}


def _check_parts(road_parts: gpd.GeoDataFrame) -> None:
    missing = [c for c in ("part_id", "width_m", "quality") if c not in road_parts]
    if missing:
        raise GisroadsError(f"road_parts lacks columns {missing}")
    if road_parts.crs is not None and road_parts.crs.is_geographic:
        raise GisroadsError("road_parts must be in a projected CRS in metres, not "
                            f"{road_parts.crs.name}")
    kinds = set(road_parts.geom_type.dropna()) - {"LineString"}
    if kinds or road_parts.geometry.isna().any():
        raise GisroadsError("road_parts must be LineString centre lines, found "
                            f"{sorted(kinds)} or empty geometries")
    if road_parts["part_id"].duplicated().any():
        raise GisroadsError("road_parts has duplicate part_id values")
    for column in ("width_m", "quality"):
        if not np.isfinite(road_parts[column].to_numpy(float)).all():
            raise GisroadsError(f"road_parts has missing or infinite {column}")
    if (shapely.length(road_parts.geometry.values) <= 0).any():
        raise GisroadsError("road_parts has a zero-length centre line")


def _empty(columns: dict, crs) -> gpd.GeoDataFrame:
    return gpd.GeoDataFrame({c: pd.Series(dtype=t) for c, t in columns.items()},
                            geometry=gpd.GeoSeries([], crs=crs), crs=crs)


def _part_ends(lines, end_window_m: float):
    """End points and outward unit directions, ends ordered part0 start, part0 end, ...

    Returns ``xy (2n, 2)`` and ``outward (2n, 2)``.
    """
    length = shapely.length(lines)
    window = np.minimum(end_window_m, length / 2.0)
    start = shapely.get_coordinates(shapely.get_point(lines, 0))
    end = shapely.get_coordinates(shapely.get_point(lines, -1))
    inner_start = shapely.get_coordinates(shapely.line_interpolate_point(lines, window))
    inner_end = shapely.get_coordinates(shapely.line_interpolate_point(lines, length - window))
    xy = np.stack([start, end], axis=1).reshape(-1, 2)
    outward = np.stack([start - inner_start, end - inner_end], axis=1).reshape(-1, 2)
    norm = np.linalg.norm(outward, axis=1, keepdims=True)
    if (norm == 0).any():   # a closed part: its ends coincide with their windows' ends
        raise GisroadsError("road_parts has a centre line whose end has no direction (closed?)")
    return xy, outward / norm


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """z of the cross products of 2-D vectors (numpy 2 deprecates 2-D ``np.cross``)."""
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def _colour_diff(road_parts: gpd.GeoDataFrame, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """RMS difference of the band means of parts ``a`` and ``b`` (``mean_intensity`` when
    there are no ``mean_b*`` columns, NaN when neither)."""
    bands = [c for c in road_parts.columns if _BAND.match(c)] or (
        ["mean_intensity"] if "mean_intensity" in road_parts else [])
    if not bands:
        return np.full(len(a), np.nan)
    means = road_parts[bands].to_numpy(float)
    return np.sqrt(np.mean((means[a] - means[b]) ** 2, axis=1))


def _greedy_order(n_parts: int, quality: np.ndarray, pair_parts: np.ndarray):
    """Grow subgraphs from the best-quality unused part, extending the best-quality part
    reached first. Returns the subgraph of every pair and, per pair, whether its second
    end's part was the one it was found from."""
    touching = [[] for _ in range(n_parts)]
    for k, (p, q) in enumerate(pair_parts):
        touching[p].append(k)
        touching[q].append(k)
    subgraph = np.full(len(pair_parts), -1, dtype=np.int64)
    swapped = np.zeros(len(pair_parts), dtype=bool)
    used = np.zeros(n_parts, dtype=bool)
    next_id = 0
    for seed in np.lexsort((np.arange(n_parts), -quality)):
        if used[seed]:
            continue
        used[seed] = True
        heap = [(-quality[seed], seed)]
        while heap:
            _, part = heapq.heappop(heap)
            for k in touching[part]:
                if subgraph[k] >= 0:
                    continue
                subgraph[k] = next_id
                swapped[k] = pair_parts[k, 1] == part
                other = pair_parts[k, 0] if swapped[k] else pair_parts[k, 1]
                if not used[other]:
                    used[other] = True
                    heapq.heappush(heap, (-quality[other], other))
        next_id += 1
    return subgraph, swapped


@dataclass(frozen=True)
class GapOptions:
    """The options of :func:`gap_edges`: how far apart, how differently directed and how
    offset two road-part ends may be to become a gap edge (Sec. 2.2.1).

    Attributes
    ----------
    max_gap_m, max_gap_relative, max_direction_diff_rad, max_lateral_offset_m : float
        Link criteria (metres, ratio, radians, metres).
    max_overlap_m : float
        Metres.
    end_window_m : float
        Length of the end section giving a part's direction at an end, metres.
    """

    max_gap_m: float = MAX_GAP_M
    max_gap_relative: float = MAX_GAP_RELATIVE
    max_direction_diff_rad: float = MAX_DIRECTION_DIFF_RAD
    max_lateral_offset_m: float = MAX_LATERAL_OFFSET_M
    max_overlap_m: float = MAX_OVERLAP_M
    end_window_m: float = END_WINDOW_M


def gap_edges(road_parts: gpd.GeoDataFrame, options: GapOptions = GapOptions(),
              **changes) -> gpd.GeoDataFrame:
    """Gap edges: hypotheses linking road-part ends (subgraph generation, Sec. 2.2.1).

    Two part ends are linked when the gap between them is at most ``max_gap_m`` and at most
    ``max_gap_relative`` times the sum of both parts' lengths, their direction difference is
    at most ``max_direction_diff_rad``, their lateral offset at most ``max_lateral_offset_m``,
    and each end lies ahead of the other or at most ``max_overlap_m`` behind it (see the
    module docstring for the definitions).
    One end may be linked to several others: the competing branches are kept for
    :func:`select_gap_edges`.

    Parameters
    ----------
    road_parts : GeoDataFrame
        One LineString centre line per road part, projected CRS in metres, with
        ``part_id``, ``width_m``, ``quality`` (0..1) and band means ``mean_b1``, ``mean_b2``,
        ... (0..1; or ``mean_intensity``) for the colour difference.
    options : GapOptions
        The limits of a gap edge (:class:`GapOptions`).
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    GeoDataFrame
        One LineString per gap edge from end point to end point, with ``gap_id``,
        ``subgraph_id``, ``from_part``, ``from_end``, ``to_part``, ``to_end`` (part ids;
        end 0 = start, 1 = end of the part's line), the features ``smoothness`` (lateral
        offset, metres), ``distance_m``, ``direction_diff_rad``, ``quality_from``,
        ``quality_to``, ``colour_diff``, ``width_diff_m``, and ``width_m`` (mean width of
        the two parts: the width of the gap's road-part hypothesis).

    Raises
    ------
    ValueError
        Missing columns, non-line or zero-length geometries, duplicate ids, geographic CRS.
    """
    options = replace(options, **changes)
    _check_parts(road_parts)
    n = len(road_parts)
    if n < 2:
        return _empty(_GAP_COLUMNS, road_parts.crs)
    lines = road_parts.geometry.values
    xy, outward = _part_ends(lines, options.end_window_m)
    length = shapely.length(lines)
    points = shapely.points(xy)
    i, j = shapely.STRtree(points).query(points, predicate="dwithin", distance=options.max_gap_m)
    i, j = i[(i < j) & (i // 2 != j // 2)], j[(i < j) & (i // 2 != j // 2)]
    d = xy[j] - xy[i]
    distance = np.hypot(d[:, 0], d[:, 1])
    ahead_i = np.einsum("ij,ij->i", d, outward[i])
    ahead_j = -np.einsum("ij,ij->i", d, outward[j])
    lateral = (np.abs(_cross(outward[i], d)) + np.abs(_cross(outward[j], d))) / 2.0
    direction = np.arccos(np.clip(-np.einsum("ij,ij->i", outward[i], outward[j]), -1, 1))
    keep = ((distance <= options.max_gap_m)
            & (distance <= options.max_gap_relative * (length[i // 2] + length[j // 2]))
            & (ahead_i >= -options.max_overlap_m) & (ahead_j >= -options.max_overlap_m)
            & (direction <= options.max_direction_diff_rad)
            & (lateral <= options.max_lateral_offset_m))
    i, j, distance, lateral, direction = (a[keep] for a in (i, j, distance, lateral, direction))
    if len(i) == 0:
        return _empty(_GAP_COLUMNS, road_parts.crs)
    quality = road_parts["quality"].to_numpy(float)
    subgraph, swapped = _greedy_order(n, quality, np.stack([i // 2, j // 2], axis=1))
    i, j = np.where(swapped, j, i), np.where(swapped, i, j)
    order = np.lexsort((j, i, subgraph))
    i, j, subgraph, distance, lateral, direction = (
        a[order] for a in (i, j, subgraph, distance, lateral, direction))
    a, b = i // 2, j // 2
    ids = road_parts["part_id"].to_numpy()
    width = road_parts["width_m"].to_numpy(float)
    return gpd.GeoDataFrame(
        {"gap_id": np.arange(len(i), dtype=np.int64), "subgraph_id": subgraph,
         "from_part": ids[a].astype(np.int64), "from_end": (i % 2).astype(np.int64),
         "to_part": ids[b].astype(np.int64), "to_end": (j % 2).astype(np.int64),
         "smoothness": lateral, "distance_m": distance, "direction_diff_rad": direction,
         "quality_from": quality[a], "quality_to": quality[b],
         "colour_diff": _colour_diff(road_parts, a, b),
         "width_diff_m": np.abs(width[a] - width[b]), "width_m": (width[a] + width[b]) / 2},
        geometry=shapely.linestrings(np.stack([xy[i], xy[j]], axis=1)), crs=road_parts.crs)


def _object_masks(ndvi, ndsm, intensity, rgb, *, ndvi_vegetation, exg_vegetation,
                  tree_height_m, vehicle_height_m, shadow_intensity, bright_intensity,
                  grey_saturation):
    """Per-pixel context classes of one window: vegetation, tree, vegetated_area, raised
    (vehicles and buildings, split later by object size and height), shadow, asphalt."""
    shape = next(a.shape[-2:] for a in (ndvi, ndsm, intensity, rgb) if a is not None)
    none = np.zeros(shape, dtype=bool)
    if ndvi is not None:
        vegetation = ndvi >= ndvi_vegetation
    elif rgb is not None:
        total = rgb.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            vegetation = (2 * rgb[1] - rgb[0] - rgb[2]) / total >= exg_vegetation
    else:
        vegetation = none
    raised = (~vegetation & (ndsm >= vehicle_height_m)) if ndsm is not None else none
    tree = vegetation & (ndsm >= tree_height_m) if ndsm is not None else vegetation
    vegetated_area = vegetation & (ndsm < tree_height_m) if ndsm is not None else none
    if intensity is None and rgb is not None:
        intensity = rgb.mean(axis=0)
    if intensity is None:
        return {"tree": tree, "vegetated_area": vegetated_area, "raised": raised,
                "shadow": none, "asphalt": none}
    shadow = (intensity < shadow_intensity) & ~vegetation & ~raised
    asphalt = ((intensity >= shadow_intensity) & (intensity <= bright_intensity)
               & ~vegetation & ~raised)
    if ndsm is not None:
        asphalt &= ndsm < vehicle_height_m
    if rgb is not None:
        brightest = rgb.max(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            asphalt &= (brightest - rgb.min(axis=0)) / brightest <= grey_saturation
    return {"tree": tree, "vegetated_area": vegetated_area, "raised": raised,
            "shadow": shadow, "asphalt": asphalt}


def _majority(mask: np.ndarray, size_px: int) -> np.ndarray:
    """Pixels where most of the ``size_px`` square around them is in ``mask``: single noisy
    pixels go, objects keep their outline."""
    if size_px <= 1:
        return mask
    return ndimage.uniform_filter(mask.astype(np.float32), size_px, mode="nearest") > 0.5


def _appearances(mask, corridor, min_pixels) -> int:
    """Objects (8-connected) of ``mask`` with at least ``min_pixels`` inside ``corridor``."""
    labels, count = ndimage.label(mask & corridor, structure=np.ones((3, 3)))
    if count == 0:
        return 0
    return int((np.bincount(labels.ravel(), minlength=count + 1)[1:] >= min_pixels).sum())


def _raised_appearances(raised, height, corridor, min_pixels, pixel_m2, *,
                        building_height_m, max_vehicle_m2):
    """Buildings and vehicles among the raised objects reaching into the corridor: an
    object is a building when it reaches ``building_height_m`` or exceeds
    ``max_vehicle_m2`` in the window, a vehicle otherwise."""
    labels, count = ndimage.label(raised, structure=np.ones((3, 3)))
    if count == 0:
        return 0, 0, np.zeros_like(raised)
    index = np.arange(1, count + 1)
    inside = np.bincount(labels[corridor], minlength=count + 1)[1:]
    area = np.bincount(labels.ravel(), minlength=count + 1)[1:] * pixel_m2
    top = ndimage.maximum(height, labels, index)
    building = (top >= building_height_m) | (area > max_vehicle_m2)
    present = inside >= min_pixels
    vehicle_mask = np.isin(labels, index[~building])
    return int((present & building).sum()), int((present & ~building).sum()), vehicle_mask


def _pixel_window(polygon, transform: Affine, shape):
    """Row and column slices of the raster covering ``polygon`` (clipped), or None."""
    x0, y0, x1, y1 = polygon.bounds
    inverse = ~transform
    corners = np.array([[x0, y0], [x0, y1], [x1, y0], [x1, y1]])
    cols = inverse.a * corners[:, 0] + inverse.b * corners[:, 1] + inverse.c
    rows = inverse.d * corners[:, 0] + inverse.e * corners[:, 1] + inverse.f
    r0, r1 = max(0, int(np.floor(rows.min()))), min(shape[0], int(np.ceil(rows.max())))
    c0, c1 = max(0, int(np.floor(cols.min()))), min(shape[1], int(np.ceil(cols.max())))
    if r0 >= r1 or c0 >= c1:
        return None
    return slice(r0, r1), slice(c0, c1)


@dataclass(frozen=True)
class ContextOptions:
    """The thresholds of :func:`gap_context`, which tell its context classes apart (its
    docstring says how each is used): NDVI and excess green of vegetation, heights above
    ground (metres), the largest vehicle (square metres), intensity of shadow and of bright
    surfaces (0..1), the greyness of asphalt (HSV saturation), the majority-vote square and
    the least object (metres, square metres).
    """

    ndvi_vegetation: float = 0.3
    exg_vegetation: float = 0.1
    tree_height_m: float = 2.0
    vehicle_height_m: float = 1.0
    building_height_m: float = 2.5
    max_vehicle_m2: float = 15.0
    shadow_intensity: float = 0.15
    bright_intensity: float = 0.85
    grey_saturation: float = 0.35
    smooth_m: float = 1.0
    min_object_m2: float = 1.0


def gap_context(gaps: gpd.GeoDataFrame, options: ContextOptions = ContextOptions(), *,
                transform: Affine, ndvi=None, ndsm=None, intensity=None, rgb=None,
                progress: Progress = None, **changes) -> gpd.GeoDataFrame:
    """Context objects in each gap's road-part hypothesis and its occluded share (Sec. 2.2.2).

    The hypothesis is the gap line buffered by half its ``width_m`` (flat caps). Inside it,
    per pixel: vegetation (``ndvi >= ndvi_vegetation``, or without NIR the excess green
    ``(2G - R - B) / (R + G + B) >= exg_vegetation``), split by the nDSM into trees
    (``>= tree_height_m``) and vegetated areas; raised non-vegetation (nDSM ``>=
    vehicle_height_m``) split into buildings (reaching ``building_height_m`` or larger than
    ``max_vehicle_m2``) and vehicles; shadow (``intensity < shadow_intensity``); and
    asphalt-like surface (neither of those, intensity up to ``bright_intensity``, low above
    ground, grey: HSV saturation up to ``grey_saturation`` when ``rgb`` is given). Each class
    is cleaned by a majority vote over ``smooth_m`` squares (pixel noise would otherwise
    split one asphalt area into many); objects are then 8-connected regions with at least
    ``min_object_m2`` inside the hypothesis, each one appearance of its relation category
    in Eq. 2. Vehicles need an nDSM; trees and vegetated areas are told apart only with one
    (without, vegetation counts as trees).

    Parameters
    ----------
    gaps : GeoDataFrame
        From :func:`gap_edges` (needs ``width_m``).
    transform : affine.Affine
        Pixel (col, row) to map (x, y) of the upper-left corner, shared by all rasters.
    ndvi, ndsm, intensity : ndarray (rows, cols), optional
        NDVI (-1..1), normalised DSM (height above ground, metres), intensity (0..1).
        NaN marks no data.
    rgb : ndarray (3, rows, cols), optional
        Red, green, blue (0..1): vegetation without NIR, greyness, and the intensity when
        ``intensity`` is not given.
    options : ContextOptions
        The thresholds of the context classes (:class:`ContextOptions`).
    progress : callable, optional
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    GeoDataFrame
        ``gaps`` with ``n_building``, ``n_vehicle``, ``n_tree``, ``n_vegetated_area``,
        ``n_shadow``, ``n_asphalt`` (appearances), ``occlusion`` (share of the hypothesis
        covered by trees, vehicles and shadow, 0..1) and ``context_cues`` (the rasters
        used). All NaN where the hypothesis has no valid pixel (off the rasters, zero
        length).
    """
    options = replace(options, **changes)
    rasters = {"ndvi": ndvi, "ndsm": ndsm, "intensity": intensity, "rgb": rgb}
    given = {k: np.asarray(v) for k, v in rasters.items() if v is not None}
    if not given:
        raise GisroadsError("gap_context needs at least one raster (ndvi, ndsm, intensity, "
                            "rgb)")
    if "rgb" in given and (given["rgb"].ndim != 3 or given["rgb"].shape[0] != 3):
        raise GisroadsError(f"rgb must have shape (3, rows, cols), not {given['rgb'].shape}")
    shapes = {k: v.shape[-2:] for k, v in given.items()}
    if len(set(shapes.values())) > 1 or any(v.ndim != 2 for k, v in given.items()
                                              if k != "rgb"):
        raise GisroadsError(f"context rasters must be 2-D on one grid, got shapes {shapes}")
    if "width_m" not in gaps:
        raise GisroadsError("gaps lacks the width_m column (use gap_edges)")
    shape = next(iter(shapes.values()))
    pixel_m2 = abs(transform.a * transform.e - transform.b * transform.d)
    min_pixels = max(1, int(np.ceil(options.min_object_m2 / pixel_m2)))
    smooth_px = 2 * int(round(options.smooth_m / np.sqrt(pixel_m2) / 2)) + 1
    kinds = ("building", "vehicle", "tree", "vegetated_area", "shadow", "asphalt")
    counts = np.full((len(gaps), len(kinds)), np.nan)
    occlusion = np.full(len(gaps), np.nan)
    corridors = shapely.buffer(gaps.geometry.values, gaps["width_m"].to_numpy(float) / 2,
                               cap_style="flat")
    for k, corridor in enumerate(corridors):
        report(progress, k / max(1, len(gaps)), "context in the gaps")
        window = None if corridor.is_empty else _pixel_window(corridor, transform, shape)
        if window is None:
            continue
        rows, cols = np.mgrid[window[0], window[1]] + 0.5
        x = transform.a * cols + transform.b * rows + transform.c
        y = transform.d * cols + transform.e * rows + transform.f
        cut = {name: raster[..., window[0], window[1]].astype(float)
               for name, raster in given.items()}
        valid = np.all([np.isfinite(v).all(axis=0) if v.ndim == 3 else np.isfinite(v)
                        for v in cut.values()], axis=0)
        inside = shapely.contains_xy(corridor, x, y) & valid
        if not inside.any():
            continue
        masks = _object_masks(
            cut.get("ndvi"), cut.get("ndsm"), cut.get("intensity"), cut.get("rgb"),
            ndvi_vegetation=options.ndvi_vegetation, exg_vegetation=options.exg_vegetation,
            tree_height_m=options.tree_height_m, vehicle_height_m=options.vehicle_height_m,
            shadow_intensity=options.shadow_intensity, bright_intensity=options.bright_intensity,
            grey_saturation=options.grey_saturation)
        masks = {name: _majority(mask & valid, smooth_px) & valid
                 for name, mask in masks.items()}
        buildings, vehicles, vehicle_mask = _raised_appearances(
            masks["raised"], cut.get("ndsm"), inside, min_pixels, pixel_m2,
            building_height_m=options.building_height_m, max_vehicle_m2=options.max_vehicle_m2)
        counts[k] = [buildings, vehicles] + [_appearances(masks[name], inside, min_pixels)
                                             for name in kinds[2:]]
        occluded = masks["tree"] | masks["shadow"] | vehicle_mask
        occlusion[k] = occluded[inside].mean()
    report(progress, 1.0, "context in the gaps")
    out = gaps.copy()
    for column, kind in enumerate(kinds):
        out[f"n_{kind}"] = counts[:, column]
    out["occlusion"] = occlusion
    out["context_cues"] = ",".join(given)
    return out


def linear_weight(values, good: float, bad: float) -> np.ndarray:
    """``w_R(f)``: 1 at ``good``, 0 at ``bad``, linear between and clipped to [0, 1]
    outside; a missing (NaN) feature weighs 1, as it holds no evidence against the link."""
    values = np.asarray(values, float)
    weight = np.clip((values - bad) / (good - bad), 0.0, 1.0)
    return np.where(np.isnan(values), 1.0, weight)


@dataclass(frozen=True)
class WeightOptions:
    """The options of :func:`edge_weights`: the ranges of the relation weight's linear
    weight functions, the context relation values, and how the two weights combine.

    Attributes
    ----------
    weight_ranges : dict, optional
        Feature name -> ``(good, bad)``, in the feature's unit (metres, radians, 0..1),
        updating :data:`WEIGHT_RANGES` (None: those).
    relation_values : dict, optional
        Relation category -> ``v_k`` (Eq. 2), updating :data:`RELATION_VALUES` (None:
        those).
    small_gap_m : float
        Gaps shorter than this take their relation weight alone (context too short to
        judge), metres.
    good_context : float
        The context weight a link of relation weight 0 needs to be kept.
    """

    weight_ranges: dict | None = None
    relation_values: dict | None = None
    small_gap_m: float = SMALL_GAP_M
    good_context: float = GOOD_CONTEXT


def edge_weights(gaps: gpd.GeoDataFrame, options: WeightOptions = WeightOptions(),
                 **changes) -> gpd.GeoDataFrame:
    """Weights ``w_i`` of the gap edges (Sec. 2.2.2).

    - Relation weight ``w_R``: the product of :func:`linear_weight` of the six features
      (``smoothness``, ``distance_m``, ``direction_diff_rad``, the mean of ``quality_from``
      and ``quality_to``, ``colour_diff``, ``width_diff_m``) over ``weight_ranges``.
    - Context weight ``w_C = w_CR + w_CO``: the relation part ``w_CR = sum_k sum_{m=1..a_k}
      v_k / m`` (Eq. 2) over the categories' appearances ``a_k`` (``n_<category>`` columns
      of :func:`gap_context`) with values ``relation_values``, plus the occlusion share.
    - Total: gaps shorter than ``small_gap_m``, and gaps without context (no
      :func:`gap_context`, or off the rasters), take ``w_R``; otherwise a negative ``w_C``
      (a building on the road, -10) gives 0; ``w_R = 0`` keeps the link only when ``w_C >=
      good_context``; else the mean of ``w_R`` and ``w_C``.

    Parameters
    ----------
    gaps : GeoDataFrame
        From :func:`gap_edges`, optionally through :func:`gap_context`.
    options : WeightOptions
        Weight ranges, relation values, ``small_gap_m`` and ``good_context``
        (:class:`WeightOptions`).
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    GeoDataFrame
        ``gaps`` with ``relation_weight``, ``context_weight`` (NaN without context) and
        ``weight``.
    """
    options = replace(options, **changes)
    ranges = {**WEIGHT_RANGES, **(options.weight_ranges or {})}
    values = {**RELATION_VALUES, **(options.relation_values or {})}
    unknown = (set(ranges) - set(WEIGHT_RANGES)) | (set(values) - set(RELATION_VALUES))
    if unknown:
        raise GisroadsError(f"unknown features or relation categories {sorted(unknown)}")
    features = {name: gaps[name].to_numpy(float) for name in ranges if name != "quality"}
    features["quality"] = (gaps["quality_from"].to_numpy(float)
                           + gaps["quality_to"].to_numpy(float)) / 2
    relation = np.ones(len(gaps))
    for name, (good, bad) in ranges.items():
        relation *= linear_weight(features[name], good, bad)
    if "occlusion" in gaps:
        context = gaps["occlusion"].to_numpy(float).copy()
        appearances = np.nan_to_num(
            gaps[[f"n_{kind}" for kind in values]].to_numpy(float)).astype(np.int64)
        # sum_{m=1..a} 1 / m, the harmonic number of a (0 for no appearance)
        harmonic = np.concatenate([[0.0], np.cumsum(1.0 / np.arange(1, appearances.max(
            initial=0) + 1))])[appearances]
        context += harmonic @ np.array(list(values.values()))
    else:
        context = np.full(len(gaps), np.nan)
    ignored = np.isnan(context) | (gaps["distance_m"].to_numpy(float) < options.small_gap_m)
    mean = (relation + context) / 2
    weight = np.where(ignored, relation,
                      np.where(context < 0, 0.0,
                               np.where(relation == 0,
                                        np.where(context >= options.good_context, mean,
                                                 0.0),
                                        mean)))
    out = gaps.copy()
    out["relation_weight"] = relation
    out["context_weight"] = context
    out["weight"] = weight
    return out


def _end_keys(gaps: gpd.GeoDataFrame):
    """Per edge, the two part-end keys ``(part_id, end)`` it occupies."""
    return (list(zip(gaps["from_part"].tolist(), gaps["from_end"].tolist())),
            list(zip(gaps["to_part"].tolist(), gaps["to_end"].tolist())))


def select_gap_edges(gaps: gpd.GeoDataFrame, *, time_limit_s: float = 60.0
                     ) -> gpd.GeoDataFrame:
    """Keep the connections maximising ``sum w_i x_i`` (Eq. 1), at most one per part end.

    A 0/1 variable per gap edge of positive weight (edges of weight <= 0 are never kept),
    one constraint ``sum x_i <= 1`` per road-part end, solved with PuLP's CBC
    (:func:`gisroads.lidar.mincover.solver`). The result reduces every subgraph to road
    strings without branches.

    Parameters
    ----------
    gaps : GeoDataFrame
        With ``weight`` (:func:`edge_weights`).
    time_limit_s : float
        Solver time limit; past it the best solution found is kept.

    Returns
    -------
    GeoDataFrame
        ``gaps`` with ``selected`` (bool); ``attrs["objective"]`` the summed weight kept and
        ``attrs["optimal"]`` whether the solver proved it optimal.
    """
    if "weight" not in gaps:
        raise GisroadsError("gaps lacks the weight column (use edge_weights)")
    weight = gaps["weight"].to_numpy(float)
    candidates = np.flatnonzero(weight > 0)
    selected = np.zeros(len(gaps), dtype=bool)
    out = gaps.copy()
    out.attrs.update(objective=0.0, optimal=True)
    if len(candidates):
        model = pulp.LpProblem("subgraph_evaluation", pulp.LpMaximize)
        x = {k: variable(model, f"x{k}", cat=pulp.LpBinary) for k in candidates}
        model += pulp.lpDot([float(weight[k]) for k in candidates], list(x.values()))
        ends: dict = {}
        for k, (a, b) in enumerate(zip(*_end_keys(gaps))):
            if k in x:
                ends.setdefault(a, []).append(x[k])
                ends.setdefault(b, []).append(x[k])
        for variables in ends.values():
            if len(variables) > 1:
                model += pulp.lpSum(variables) <= 1
        model.solve(solver(time_limit_s=time_limit_s))
        selected[candidates] = [(x[k].varValue or 0) > 0.5 for k in candidates]
        out.attrs.update(objective=float(weight[selected].sum()),
                         optimal=model.sol_status == pulp.LpSolutionOptimal)
    out["selected"] = selected
    return out


def road_strings(road_parts: gpd.GeoDataFrame, gaps: gpd.GeoDataFrame) -> gpd.GeoDataFrame:
    """Chain road parts through the selected gap edges into road strings.

    Every part belongs to exactly one string (an unlinked part is a string of its own).
    Parts are walked from a free end and reversed where needed, so a string's line runs
    continuously through its parts and gaps; a closed chain (a ring of links) gives a
    closed line.

    Parameters
    ----------
    road_parts : GeoDataFrame
        As for :func:`gap_edges`.
    gaps : GeoDataFrame
        With ``from_part``, ``from_end``, ``to_part``, ``to_end``, ``selected`` (missing
        counts as False), e.g. from :func:`select_gap_edges` or edited by hand.

    Returns
    -------
    GeoDataFrame
        LineStrings with ``string_id``, ``part_ids`` (text "3,7,9" in chain order),
        ``width_m`` and ``quality`` (length-weighted means over the parts), ``length_m``
        (whole line, gaps included) and ``n_parts``.

    Raises
    ------
    ValueError
        A part end with more than one selected gap edge, or a gap naming an unknown part.
    """
    _check_parts(road_parts)
    if len(road_parts) == 0:
        return _empty(_STRING_COLUMNS, road_parts.crs)
    ids = road_parts["part_id"].to_numpy()
    row = {pid: r for r, pid in enumerate(ids.tolist())}
    chosen = gaps[gaps["selected"].fillna(False).astype(bool)] if len(gaps) else gaps
    link: dict = {}
    for ends in zip(*_end_keys(chosen)):
        for part, end in ends:
            if part not in row:
                raise GisroadsError(f"a selected gap edge links unknown part_id {part}")
            if (row[part], end) in link:
                raise GisroadsError(f"part {part} end {end} has more than one selected gap "
                                    "edge")
        a, b = ((row[part], end) for part, end in ends)
        link[a], link[b] = b, a
    lines = road_parts.geometry.values
    part_length = shapely.length(lines)
    width = road_parts["width_m"].to_numpy(float)
    quality = road_parts["quality"].to_numpy(float)
    visited = np.zeros(len(ids), dtype=bool)

    def walk(part: int, entry: int) -> list[tuple[int, int]]:
        chain = []
        while True:
            chain.append((part, entry))
            visited[part] = True
            following = link.get((part, 1 - entry))
            if following is None or visited[following[0]]:
                return chain
            part, entry = following

    chains = []
    for part in range(len(ids)):
        if not visited[part] and ((part, 0) not in link or (part, 1) not in link):
            chains.append(walk(part, 0 if (part, 0) not in link else 1))
    for part in range(len(ids)):   # what is left lies on rings
        if not visited[part]:
            chains.append(walk(part, 0))
    geometries, records = [], []
    for string_id, chain in enumerate(chains):
        parts = np.array([p for p, _ in chain])
        pieces = [shapely.get_coordinates(lines[p])[::1 if entry == 0 else -1]
                  for p, entry in chain]
        first, last = chain[0], chain[-1]
        if len(chain) > 1 and link.get((last[0], 1 - last[1])) == first:
            pieces.append(pieces[0][:1])
        coords = np.concatenate(pieces)
        coords = coords[np.r_[True, np.any(np.diff(coords, axis=0) != 0, axis=1)]]
        geometries.append(shapely.linestrings(coords))
        weights = part_length[parts]
        records.append({
            "string_id": string_id, "part_ids": ",".join(str(i) for i in ids[parts]),
            "width_m": float(np.average(width[parts], weights=weights)),
            "quality": float(np.average(quality[parts], weights=weights)),
            "length_m": float(shapely.length(geometries[-1])), "n_parts": len(chain)})
    frame = pd.DataFrame.from_records(records).astype(_STRING_COLUMNS)
    return gpd.GeoDataFrame(frame, geometry=geometries, crs=road_parts.crs)


def mean_along(values: np.ndarray, transform: Affine, lines, step_m: float) -> np.ndarray:
    """Per line, the mean of a raster at points every ``step_m`` along it (NaN and points
    off the raster count 0)."""
    points, owner = shapely.get_coordinates(shapely.segmentize(lines, step_m),
                                            return_index=True)
    inverse = ~transform
    cols = inverse.a * points[:, 0] + inverse.b * points[:, 1] + inverse.c
    rows = inverse.d * points[:, 0] + inverse.e * points[:, 1] + inverse.f
    rows, cols = np.floor(rows).astype(np.int64), np.floor(cols).astype(np.int64)
    inside = (rows >= 0) & (rows < values.shape[0]) & (cols >= 0) & (cols < values.shape[1])
    sampled = np.zeros(len(points))
    sampled[inside] = np.nan_to_num(values[rows[inside], cols[inside]])
    return (np.bincount(owner, weights=sampled, minlength=len(lines))
            / np.maximum(np.bincount(owner, minlength=len(lines)), 1))


def _probability_context(gaps, transform, probability, ndsm, context_options: ContextOptions,
                         progress):
    """Gap context from a learned road probability (and buildings, vehicles from an nDSM)."""
    if ndsm is not None:
        gaps = gap_context(gaps, context_options, transform=transform, ndsm=ndsm,
                           progress=progress)
        gaps["context_cues"] = "ndsm,probability"
    else:
        gaps = gaps.copy()
        gaps["context_cues"] = "probability"
    for kind in ("building", "vehicle", "tree", "vegetated_area", "shadow", "asphalt"):
        if ndsm is None or kind not in ("building", "vehicle"):
            gaps[f"n_{kind}"] = 0.0
    gaps["occlusion"] = (mean_along(probability, transform, gaps.geometry.values,
                                    abs(transform.a)) if len(gaps) else np.empty(0))
    return gaps


def link_road_parts(road_parts: gpd.GeoDataFrame, *, transform: Affine | None = None,
                    ndvi=None, ndsm=None, intensity=None, rgb=None, probability=None,
                    gap_options: GapOptions = GapOptions(),
                    context_options: ContextOptions = ContextOptions(),
                    weight_options: WeightOptions = WeightOptions(), progress: Progress = None):
    """Subgraph generation and evaluation in one call: :func:`gap_edges`, :func:`gap_context`
    (when a raster and its ``transform`` are given), :func:`edge_weights`,
    :func:`select_gap_edges`, :func:`road_strings`.

    Parameters
    ----------
    road_parts : GeoDataFrame
        As for :func:`gap_edges`.
    transform, ndvi, ndsm, intensity, rgb
        Context rasters, as for :func:`gap_context`.
    probability : array_like, optional
        A learned road probability on the same grid (beyond the papers): a gap's
        ``occlusion`` becomes the mean probability along it (as
        :func:`gisroads.network.rasters.link_gaps` does) and the radiometric categories
        (trees, vegetated areas, shadow, asphalt) are left out; buildings and vehicles
        still come from the nDSM when given.
    gap_options : GapOptions
        The limits of a gap edge (:func:`gap_edges`).
    context_options : ContextOptions
        The thresholds of the context classes (:func:`gap_context`).
    weight_options : WeightOptions
        The weights of the gap edges (:func:`edge_weights`).
    progress : callable, optional

    Returns
    -------
    gaps : GeoDataFrame
        Every gap hypothesis with its features, context, weights and ``selected``.
    strings : GeoDataFrame
        The road strings.
    """
    report(progress, 0.0, "linking road parts")
    gaps = gap_edges(road_parts, gap_options)
    if probability is not None:
        if transform is None:
            raise GisroadsError("the probability raster needs its transform")
        gaps = _probability_context(gaps, transform, np.asarray(probability, float), ndsm,
                                    context_options, scaled(progress, 0.1, 0.8))
    elif any(r is not None for r in (ndvi, ndsm, intensity, rgb)):
        if transform is None:
            raise GisroadsError("context rasters need their transform")
        gaps = gap_context(gaps, context_options, transform=transform, ndvi=ndvi, ndsm=ndsm,
                           intensity=intensity, rgb=rgb, progress=scaled(progress, 0.1, 0.8))
    gaps = select_gap_edges(edge_weights(gaps, weight_options))
    report(progress, 0.9, "chaining road strings")
    strings = road_strings(road_parts, gaps)
    report(progress, 1.0, "road strings done")
    return gaps, strings
