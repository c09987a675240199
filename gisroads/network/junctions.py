"""Network generation: road strings to a road network (Grote & Rottensteiner 2010, Sec. 2.3).

The last stage of every road network, whatever the evidence (the image pipeline, any road
raster through :mod:`gisroads.network.rasters`, the LiDAR pipeline). Its input are the road strings
of the subgraph
evaluation (one LineString per string, ``width_m``, ``quality``), its output the road-network
contract (:class:`gisroads.geo.RoadNetwork`) plus the QA layer ``junction_connections``.

1. **Approximation** (:func:`approximate_strings`). Each string's centre line is approximated
   by a polygon: starting from the straight line between its end points, the vertex farthest
   from the approximation is added until every vertex lies within ``tolerance_m``. This is
   the Douglas-Peucker algorithm, which ``shapely.simplify(..., preserve_topology=False)``
   (GEOS ``DouglasPeuckerSimplifier``) implements exactly; it is used as is. A road's width
   is the string's average width; its region the centre line buffered by half the width
   with flat caps (:func:`road_regions`).
2. **Duplicates** (:func:`remove_duplicates`). Of two parallel roads lying close together,
   the one of better quality is kept; then roads whose region is mostly covered by the
   regions of other roads are deleted.
3. **Junctions** (:func:`find_junctions`). A semicircle ahead of each road end (in the
   direction of the road's last ``end_window_m``), its radius growing with the road's
   quality, is searched for other roads. Collinear roads (pointing
   at each other) are joined end to end when the other end lies in the semicircle; otherwise
   the end is extended to the point where its extension hits the other road (end-road), or
   joined to the other road's end by the short polygon through the intersection of both
   extensions. Roads that cross, or whose end overshoots another road by less than that
   road's half width, meet at their intersection (crossing). An end lying on another
   road's surface (within its half width plus ``overshoot_m``) whose extension misses that
   road, as a lane running into a bend of the crossing road does, meets it where it comes
   closest (end-road). Each road end receives at most
   one junction connection, the shortest; we accept the collinear (end-end) connections
   before the others, each kind shortest first, and after each acceptance the ends near the
   new connection search again. So a road interrupted at a junction is closed first and the
   side road then meets the closing connection in a T (end-road onto a connection), where
   the shortest connection alone would bend the side road into one half of the interrupted
   road. Every meeting point is a vertex shared exactly by both lines. Junctions that end up
   less than ``junction_merge_m`` apart are merged (:func:`merge_close_junctions`).
4. **Significance** (:func:`significant_components`). Roads and accepted connections form
   connected components; a component is kept when its roads are longer than its junction
   connections and its total length reaches a minimum, the minimum being waived when at
   least two of its open ends lie near the image border (the network may continue beyond).
5. **Network** (:func:`strings_to_network`). Roads and connections are noded (split at every
   junction), overshoots of a crossing end are trimmed, lines meeting at degree-2 nodes are
   merged into one road whose width and score are length-weighted means
   (:func:`gisroads.vectorize.ribbons` step 3, shared with the LiDAR pipeline), and the
   contract layers are built by :func:`gisroads.geo.network_from_centrelines` (flat-capped
   road polygons, junctions by exact noding).

The paper gives no numbers for this stage; the defaults below are chosen for suburban roads
of 4-12 m in images of 0.1-0.5 m pixels, and are all in metres.
"""
from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass, replace

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from shapely.ops import substring

from ..errors import GisroadsError
from ..geo import RoadNetwork, network_from_centrelines
from ..progress import Progress, report
# the shared noding and tangent steps of the LiDAR and snake vectorisers (private there)
from ..vectorize.ribbons import node_roads, tangents

METHOD = "grote-rottensteiner"
#: Polygon approximation tolerance: a tenth to a fifth of a suburban road's width.
TOLERANCE_M = 1.0
#: Search radius of a road of quality 0 and of quality 1 (linear in between): gaps of a
#: few metres at every junction, up to a road width and more for good roads.
MIN_SEARCH_RADIUS_M = 10.0
MAX_SEARCH_RADIUS_M = 30.0
#: Largest direction difference of collinear roads, as the LiDAR chaining's tolerance.
COLLINEAR_DEG = 20.0
#: Length of the end section whose chord gives a road's direction at that end (as the
#: subgraph stage's ``END_WINDOW_M``).
END_WINDOW_M = 10.0
#: Parallel roads are duplicates when their centre lines stay within the wider road's half
#: width plus this margin over at least ``PARALLEL_SHARE`` of each road's length.
PARALLEL_MARGIN_M = 1.0
PARALLEL_SHARE = 0.5
#: A road whose region is covered by other roads' regions for more than this share goes.
OVERLAP_SHARE = 0.6
#: A component shorter than this (roads and connections) is insignificant, unless two open
#: ends lie within ``BORDER_M`` of the image border.
MIN_TOTAL_LENGTH_M = 50.0
BORDER_M = 15.0
#: An end that passes a crossing road by at most that road's half width plus this margin
#: ends at the crossing (the overshoot is trimmed).
OVERSHOOT_M = 2.0
#: Width and quality of lines that carry none (:func:`road_strings_from_lines`): a
#: two-lane suburban road, a middling string.
DEFAULT_WIDTH_M = 6.0
DEFAULT_QUALITY = 0.5
#: Junctions joined by a road shorter than this are one junction: two ends extended onto
#: each other's connections at a crossroads meet the crossing road at nearby points.
JUNCTION_MERGE_M = 3.0

_EPS_M = 1e-9
_SAMPLE_STEP_M = 1.0     # spacing of the points that test "runs alongside"
_ARC_POINTS = 33         # vertices of a search semicircle's arc


# --- 1. approximation -----------------------------------------------------------------------

def _check_frame(frame, required) -> None:
    if not isinstance(frame, gpd.GeoDataFrame):
        raise GisroadsError(f"expected a GeoDataFrame, got {type(frame).__name__}")
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise GisroadsError(f"road strings lack the column(s) {missing}")
    if frame.crs is not None and not frame.crs.is_projected:
        raise GisroadsError(f"road strings must be in a projected CRS in metres, not "
                            f"{frame.crs.name}")


def approximate_strings(road_strings: gpd.GeoDataFrame, *,
                        tolerance_m: float = TOLERANCE_M) -> gpd.GeoDataFrame:
    """Centre lines of road strings by iterative polygon approximation (Sec. 2.3, first
    paragraph), with their average widths.

    Parameters
    ----------
    road_strings : GeoDataFrame
        LineStrings (MultiLineStrings are merged, and split into one road per part where
        they do not join) in a projected metre CRS, with ``width_m`` (average width,
        metres, > 0) and ``quality`` (0..1); ``string_id`` is kept when present, otherwise
        the row number is used. Empty geometries are skipped.
    tolerance_m : float
        Largest distance (metres) of a string's vertices from its approximation: the
        Douglas-Peucker algorithm, ``shapely.simplify(preserve_topology=False)``.

    Returns
    -------
    GeoDataFrame
        One row per road: ``road_id`` (0..n-1), ``string_id``, ``width_m``, ``quality``,
        ``length_m`` and the approximated centre line.

    Raises
    ------
    ValueError
        For a missing column, a geographic CRS, non-line geometries, widths that are not
        positive or qualities outside [0, 1].
    """
    _check_frame(road_strings, ("width_m", "quality"))
    if tolerance_m < 0:
        raise GisroadsError(f"tolerance_m must be >= 0, got {tolerance_m}")
    frame = road_strings[~(road_strings.geometry.isna() | road_strings.geometry.is_empty)]
    kinds = set(frame.geom_type) - {"LineString", "MultiLineString"}
    if kinds:
        raise GisroadsError(f"road strings must be lines, got {sorted(kinds)}")
    width = frame["width_m"].to_numpy(float)
    quality = frame["quality"].to_numpy(float)
    if not np.all(np.isfinite(width) & (width > 0)):
        raise GisroadsError("road strings need a positive width_m (metres) on every row")
    if not np.all((quality >= 0) & (quality <= 1)):
        raise GisroadsError("road string quality must lie in [0, 1] on every row")
    string_id = (frame["string_id"].to_numpy() if "string_id" in frame
                 else np.arange(len(frame), dtype=np.int64))
    merged = shapely.line_merge(frame.geometry.values)
    lines, row = shapely.get_parts(merged, return_index=True)
    lines = shapely.simplify(lines, tolerance_m, preserve_topology=False)
    usable = shapely.length(lines) > 0
    lines, row = lines[usable], row[usable]
    return gpd.GeoDataFrame(
        {"road_id": np.arange(len(lines), dtype=np.int64), "string_id": string_id[row],
         "width_m": width[row], "quality": quality[row], "length_m": shapely.length(lines)},
        geometry=gpd.GeoSeries(lines, crs=road_strings.crs), crs=road_strings.crs)


def road_strings_from_lines(lines: gpd.GeoDataFrame, *, width_m: float = DEFAULT_WIDTH_M,
                            quality: float = DEFAULT_QUALITY) -> gpd.GeoDataFrame:
    """Any line layer as road strings: ``width_m`` and ``quality`` filled in where the
    layer has no such column or a row has no value (e.g. centre lines digitised by hand).

    Parameters
    ----------
    lines : GeoDataFrame
        Lines; ``width_m`` (metres) and ``quality`` (0..1) are used where present.
    width_m : float
        Metres, for rows without a width.
    quality : float
        0..1, for rows without a quality.
    """
    frame = lines.copy()
    for column, default in (("width_m", width_m), ("quality", quality)):
        values = (pd.to_numeric(frame[column], errors="coerce") if column in frame
                  else pd.Series(np.nan, index=frame.index))
        frame[column] = values.fillna(default).astype(float)
    return frame


def road_regions(roads: gpd.GeoDataFrame) -> np.ndarray:
    """Road regions: centre lines buffered by half their ``width_m``, flat caps, round
    joins (as :func:`gisroads.geo.network_from_centrelines` builds the road polygons)."""
    return shapely.buffer(roads.geometry.values, roads["width_m"].to_numpy(float) / 2,
                          cap_style="flat", join_style="round")


# --- 2. duplicates --------------------------------------------------------------------------

def _alongside_share(lines, a, b, near_m, cos_tol) -> np.ndarray:
    """Share of the length of ``lines[a]`` running alongside ``lines[b]``: within ``near_m``
    of it and in a direction differing by less than the angle of ``cos_tol``."""
    length = shapely.length(lines[a])
    count = np.maximum(3, np.ceil(length / _SAMPLE_STEP_M).astype(int) + 1)
    pair = np.repeat(np.arange(len(a)), count)
    fraction = np.concatenate([np.linspace(0, 1, c) for c in count] or [np.empty(0)])
    along = fraction * length[pair]
    probes = shapely.line_interpolate_point(lines[a][pair], along)
    other = lines[b][pair]
    close = shapely.distance(probes, other) <= near_m[pair]
    own = tangents(lines[a][pair], along)
    theirs = tangents(other, shapely.line_locate_point(other, probes))
    aligned = np.abs(np.einsum("ij,ij->i", own, theirs)) >= cos_tol
    return np.bincount(pair, weights=close & aligned, minlength=len(a)) / count


def _length_inside(lines, areas) -> np.ndarray:
    """Length of each line inside its area (pairwise)."""
    inside = np.zeros(len(lines))
    # intersects() first: GEOS 3.11 flags the NaN z of an empty intersection as invalid
    hit = shapely.intersects(lines, areas)
    inside[hit] = shapely.length(shapely.intersection(lines[hit], areas[hit]))
    return inside


def remove_duplicates(roads: gpd.GeoDataFrame, *, parallel_margin_m: float = PARALLEL_MARGIN_M,
                      parallel_share: float = PARALLEL_SHARE, collinear_deg: float = COLLINEAR_DEG,
                      overlap_share: float = OVERLAP_SHARE) -> gpd.GeoDataFrame:
    """Remove close parallel duplicates and roads mostly overlapped by others (Sec. 2.3,
    second paragraph).

    Parameters
    ----------
    roads : GeoDataFrame
        As returned by :func:`approximate_strings`.
    parallel_margin_m : float
        Two roads are close where their centre lines are within the wider road's half width
        plus this margin (metres).
    parallel_share : float
        Two roads are a parallel pair when each is close to the other, in a direction
        differing by less than ``collinear_deg``, over at least this share of its length;
        of a pair, the road of better quality (then the longer) is kept.
    collinear_deg : float
        Degrees.
    overlap_share : float
        Then, while some road's region (:func:`road_regions`) is covered by the regions of
        the other remaining roads for more than this share of its area, the most covered
        one (of equal cover, the worse one) is deleted.

    Returns
    -------
    GeoDataFrame
        The remaining rows of ``roads``.
    """
    if len(roads) < 2:
        return roads.copy()
    lines = np.asarray(roads.geometry.values, dtype=object)
    width = roads["width_m"].to_numpy(float)
    # rank 0 is the best road: higher quality first, then the longer
    rank = np.empty(len(roads), dtype=np.int64)
    rank[np.lexsort((-shapely.length(lines), -roads["quality"].to_numpy(float)))] = \
        np.arange(len(roads))
    cos_tol = np.cos(np.radians(collinear_deg))
    i, j = shapely.STRtree(lines).query(lines, predicate="dwithin",
                                        distance=width.max() / 2 + parallel_margin_m)
    keep = i < j
    i, j = i[keep], j[keep]
    near = np.maximum(width[i], width[j]) / 2 + parallel_margin_m
    # closeness alone, measured exactly, rules out most pairs (crossings, T junctions)
    close_i = _length_inside(lines[i], shapely.buffer(lines[j], near))
    close_j = _length_inside(lines[j], shapely.buffer(lines[i], near))
    maybe = ((close_i >= parallel_share * shapely.length(lines[i]))
             & (close_j >= parallel_share * shapely.length(lines[j])))
    i, j, near = i[maybe], j[maybe], near[maybe]
    parallel = ((_alongside_share(lines, i, j, near, cos_tol) >= parallel_share)
                & (_alongside_share(lines, j, i, near, cos_tol) >= parallel_share))
    worse = np.where(rank[i[parallel]] > rank[j[parallel]], i[parallel], j[parallel])
    better = np.where(rank[i[parallel]] > rank[j[parallel]], j[parallel], i[parallel])
    alive = np.ones(len(roads), dtype=bool)
    for road in np.argsort(rank):  # the better partner's fate is settled first
        if np.any(alive[better[worse == road]]):
            alive[road] = False

    regions = road_regions(roads)
    area = shapely.area(regions)
    a, b = shapely.STRtree(regions).query(regions, predicate="intersects")
    neighbours = [b[(a == k) & (b != k)] for k in range(len(roads))]

    def covered(k):
        others = neighbours[k][alive[neighbours[k]]]
        if len(others) == 0 or area[k] == 0:
            return 0.0
        return float(shapely.area(shapely.intersection(regions[k], shapely.union_all(
            regions[others]))) / area[k])

    share = np.array([covered(k) if alive[k] else 0.0 for k in range(len(roads))])
    while True:
        candidates = np.flatnonzero(alive & (share > overlap_share))
        if len(candidates) == 0:
            break
        gone = candidates[np.lexsort((-rank[candidates], -share[candidates]))[0]]
        alive[gone] = False
        share[gone] = 0.0
        for k in neighbours[gone]:
            if alive[k]:
                share[k] = covered(k)
    return roads[alive].copy()


# --- 3. junctions ---------------------------------------------------------------------------

def _insert_vertex(xy: np.ndarray, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polyline vertices with ``point`` (on it) inserted in place, and the vertex used: an
    existing vertex within a nanometre is reused, so the meeting point is exactly shared."""
    distance = np.hypot(*(xy - point).T)
    nearest = int(np.argmin(distance))
    if distance[nearest] <= _EPS_M:
        return xy, xy[nearest].copy()
    # the segment holding the point: where it is closest to the point
    a, b = xy[:-1], xy[1:]
    step = b - a
    t = np.clip(np.einsum("ij,ij->i", point - a, step)
                / np.maximum(np.einsum("ij,ij->i", step, step), _EPS_M), 0, 1)
    gap = np.hypot(*(a + t[:, None] * step - point).T)
    segment = int(np.argmin(gap))
    return np.insert(xy, segment + 1, point, axis=0), point


def _semicircles(points: np.ndarray, directions: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Half discs ahead of points: centre, direction and radius per row."""
    heading = np.arctan2(directions[:, 1], directions[:, 0])
    angle = heading[:, None] + np.linspace(-np.pi / 2, np.pi / 2, _ARC_POINTS)[None, :]
    arc = points[:, None, :] + radius[:, None, None] * np.stack([np.cos(angle),
                                                                  np.sin(angle)], axis=-1)
    ring = np.concatenate([points[:, None, :], arc, points[:, None, :]], axis=1)
    return shapely.polygons(ring)


def _first_hit(ray, line, origin: np.ndarray):
    """Point of ``line`` met first along ``ray`` (a segment from ``origin``), or None."""
    if not shapely.intersects(ray, line):
        return None
    xy = shapely.get_coordinates(shapely.intersection(ray, line))
    if len(xy) == 0:
        return None
    return xy[int(np.argmin(np.hypot(*(xy - origin).T)))]


class _JunctionSearch:
    """The state of the junction search of :func:`find_junctions`: current line vertices,
    free ends and constructed connections."""

    def __init__(self, roads, *, min_search_radius_m, max_search_radius_m, collinear_deg,
                 end_window_m, overshoot_m, unsupported=None, max_unsupported_m=np.inf):
        self.n = len(roads)
        self.unsupported = unsupported
        self.max_unsupported_m = max_unsupported_m
        self.lines = np.asarray(roads.geometry.values, dtype=object)
        self.tree = shapely.STRtree(self.lines)
        self.coords = [shapely.get_coordinates(line) for line in self.lines]
        self.width = roads["width_m"].to_numpy(float)
        self.quality = roads["quality"].to_numpy(float)
        self.string_id = roads["string_id"].to_numpy()
        self.cos_collinear = np.cos(np.radians(collinear_deg))
        self.overshoot_m = overshoot_m
        # end e belongs to road e // 2, at its start when e is even
        first = np.array([c[0] for c in self.coords]).reshape(-1, 2)
        last = np.array([c[-1] for c in self.coords]).reshape(-1, 2)
        length = shapely.length(self.lines)
        window = np.minimum(end_window_m, length / 2)
        inner_first = shapely.get_coordinates(shapely.line_interpolate_point(self.lines, window))
        inner_last = shapely.get_coordinates(shapely.line_interpolate_point(self.lines,
                                                                            length - window))
        self.point = np.stack([first, last], axis=1).reshape(-1, 2)
        outward = np.stack([first - inner_first, last - inner_last], axis=1).reshape(-1, 2)
        self.direction = outward / np.hypot(*outward.T)[:, None]
        self.radius = np.repeat(min_search_radius_m + self.quality
                                * (max_search_radius_m - min_search_radius_m), 2)
        self.region = _semicircles(self.point, self.direction, self.radius)
        loop = np.hypot(*(first - last).T) <= _EPS_M
        self.free = ~np.repeat(loop, 2)
        self.version = np.zeros(2 * self.n, dtype=np.int64)
        self.connections = []   # dicts: kind, from, to, coords, verified, width, quality
        self.seen = {}          # candidate key -> index in connections (for the QA layer)
        self.built = {}         # index in connections -> line, of the accepted ones

    # -- crossings ---------------------------------------------------------------------------

    def crossings(self) -> None:
        """Record crossing roads; ends at or just past a crossing road end there."""
        a, b = self.tree.query(self.lines, predicate="intersects")
        keep = a < b
        for i, j in zip(a[keep], b[keep]):
            points = shapely.get_coordinates(shapely.intersection(self.lines[i],
                                                                  self.lines[j]))
            points = np.unique(np.round(points, 9), axis=0)
            for road, other in ((i, j), (j, i)):
                line, length = self.lines[road], shapely.length(self.lines[road])
                along = shapely.line_locate_point(line, shapely.points(points))
                reach = self.width[other] / 2 + self.overshoot_m
                for end, distance in ((2 * road, along), (2 * road + 1, length - along)):
                    if np.any(distance <= reach):
                        self.free[end] = False
            for point, along in zip(points, shapely.line_locate_point(
                    self.lines[i], shapely.points(points))):
                half = self.width[j] / 2
                piece = substring(self.lines[i], max(0.0, along - half),
                                  min(shapely.length(self.lines[i]), along + half))
                self._record(("crossing", i, j, *np.round(point, 6)), "crossing", i, j,
                             shapely.get_coordinates(piece), verified=True, length_m=0.0)

    # -- candidates --------------------------------------------------------------------------

    def _record(self, key, kind, source, target, xy, *, verified, length_m=None,
                target_is_connection=False):
        if key in self.seen:
            return self.seen[key]
        if target_is_connection:
            target_connection = self.connections[target]
            to_string = target_connection["from_string"]
            width = (self.width[source] + target_connection["width_m"]) / 2
            quality = (self.quality[source] + target_connection["quality"]) / 2
        else:
            to_string = self.string_id[target]
            width = (self.width[source] + self.width[target]) / 2
            quality = (self.quality[source] + self.quality[target]) / 2
        self.connections.append({
            "kind": kind, "from_string": self.string_id[source], "to_string": to_string,
            "xy": np.asarray(xy, float), "verified": verified, "width_m": width,
            "quality": quality,
            "length_m": float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
            if length_m is None else length_m})
        self.seen[key] = len(self.connections) - 1
        return self.seen[key]

    def candidates(self, end: int) -> list[tuple]:
        """Junction connections for a free end: (length, kind rank, key, kind, target,
        vertices, other end or -1, target is a connection)."""
        road = end // 2
        p, d, r = self.point[end], self.direction[end], self.radius[end]
        found = []
        region = self.region[end]
        ray = shapely.linestrings([p, p + r * d])
        for target in self.tree.query(region, predicate="intersects"):
            if target == road:
                continue
            line = shapely.linestrings(self.coords[target])
            for other in (2 * target, 2 * target + 1):
                if not self.free[other]:
                    continue
                q, dq, rq = self.point[other], self.direction[other], self.radius[other]
                v = q - p
                gap = float(np.hypot(*v))
                facing = -float(d @ dq) >= self.cos_collinear
                if facing:
                    lateral = abs(d[0] * v[1] - d[1] * v[0])
                    if (gap <= r and float(v @ d) >= 0
                            and lateral <= max(self.width[road], self.width[target])):
                        found.append((gap, 0, ("end-end", *sorted((end, other))), "end-end",
                                      target, np.array([p, q]), other, False))
                    continue
                if abs(float(d @ dq)) >= self.cos_collinear:
                    continue  # parallel, side by side: no junction between them
                # p + t d = q + s dq, solved by cross products (d and dq are not parallel)
                det = d[0] * dq[1] - d[1] * dq[0]
                t = (v[0] * dq[1] - v[1] * dq[0]) / det
                s = (v[0] * d[1] - v[1] * d[0]) / det
                if _EPS_M < t <= r and _EPS_M < s <= rq:
                    x = p + t * d
                    found.append((t + s, 2, ("intersection-polygon", *sorted((end, other))),
                                  "intersection-polygon", target, np.array([p, x, q]), other,
                                  False))
            hit = _first_hit(ray, line, p)
            if hit is not None and self._crosses(d, line, hit):
                found.append(self._end_road(end, target, hit, False))
            elif shapely.distance(shapely.points(p), line) <= (self.width[target] / 2
                                                               + self.overshoot_m):
                # the end lies on the other road's surface but points along it (a lane
                # running into a bend of the crossing road): it meets the road where the
                # road comes closest
                nearest = shapely.get_coordinates(
                    shapely.shortest_line(shapely.points(p), line))[-1]
                # not a road running beside it: two parallel roads are no junction
                if (np.hypot(*(nearest - p)) > _EPS_M
                        and self._crosses(d, line, nearest)):
                    found.append(self._end_road(end, target, nearest, False))
        built = np.fromiter(self.built, dtype=np.int64, count=len(self.built))
        built_lines = np.array(list(self.built.values()), dtype=object)
        reached = shapely.intersects(built_lines, region) if len(built) else []
        for index, line in zip(built[reached], built_lines[reached]):
            hit = _first_hit(ray, line, p)
            if hit is not None and self._crosses(d, line, hit):
                found.append(self._end_road(end, index, hit, True))
        return found

    def _crosses(self, d, line, hit) -> bool:
        """The end's direction and the line's at ``hit`` differ by more than collinear."""
        along = shapely.line_locate_point(line, shapely.points(hit))
        tangent = tangents(np.array([line]), np.array([along]))[0]
        return abs(float(d @ tangent)) < self.cos_collinear

    def _end_road(self, end, target, hit, is_connection):
        p = self.point[end]
        length = float(np.hypot(*(hit - p)))
        key = ("end-road", end, "connection" if is_connection else "road", target,
               *np.round(hit, 6))
        return (length, 1, key, "end-road", target, np.array([p, hit]), -1, is_connection)

    # -- acceptance --------------------------------------------------------------------------

    def _push(self, heap, end, counter):
        found = self.candidates(end)
        if self.unsupported is not None and found:
            xy = [c[5] for c in found]
            off_road = self.unsupported(shapely.linestrings(
                np.concatenate(xy), indices=np.repeat(np.arange(len(xy)), [len(v) for v in xy])))
            found = [c for c, metres in zip(found, off_road) if metres <= self.max_unsupported_m]
        for candidate in found:
            length, rank, key, kind, target, xy, other, is_connection = candidate
            if key not in self.seen:
                self._record(key, kind, end // 2, target, xy, verified=False,
                             target_is_connection=is_connection)
            # collinear continuations first, then junctions through an intersection
            heapq.heappush(heap, (kind != "end-end", length, rank, next(counter), end,
                                  self.version[end], candidate))

    def run(self) -> None:
        """Accept junction connections, one per road end: collinear continuations first,
        then the others, each shortest first."""
        counter = itertools.count()
        heap = []
        for end in np.flatnonzero(self.free):
            self._push(heap, int(end), counter)
        while heap:
            *_, end, version, candidate = heapq.heappop(heap)
            length, rank, key, kind, target, xy, other, is_connection = candidate
            if not self.free[end] or version != self.version[end]:
                continue
            if other >= 0 and not self.free[other]:
                continue
            xy = xy.copy()
            if kind == "end-road":
                holder = (self.connections[target]["xy"] if is_connection
                          else self.coords[target])
                updated, xy[-1] = _insert_vertex(holder, xy[-1])
                if is_connection:
                    self.connections[target]["xy"] = updated
                    self.built[target] = shapely.linestrings(updated)
                else:
                    self.coords[target] = updated
            index = self.seen[key]
            connection = self.connections[index]
            connection.update(xy=xy, verified=True)
            self.built[index] = shapely.linestrings(xy)
            if not is_connection:  # found from either end: name the roads in its direction
                connection.update(from_string=self.string_id[end // 2],
                                  to_string=self.string_id[target])
            self.free[end] = False
            if other >= 0:
                self.free[other] = False
            # ends that reach the new connection may now end on it
            new_line = shapely.linestrings(xy)
            waiting = np.flatnonzero(self.free)
            reach = shapely.distance(shapely.points(self.point[waiting]), new_line)
            for nearby in waiting[reach <= self.radius[waiting]]:
                self.version[nearby] += 1
                self._push(heap, int(nearby), counter)


def find_junctions(roads: gpd.GeoDataFrame, *,
                   min_search_radius_m: float = MIN_SEARCH_RADIUS_M,
                   max_search_radius_m: float = MAX_SEARCH_RADIUS_M,
                   collinear_deg: float = COLLINEAR_DEG,
                   end_window_m: float = END_WINDOW_M,
                   overshoot_m: float = OVERSHOOT_M, unsupported=None,
                   max_unsupported_m: float = np.inf) -> tuple[gpd.GeoDataFrame,
                                                               gpd.GeoDataFrame]:
    """Junction connections between roads (Sec. 2.3, second paragraph).

    Parameters
    ----------
    roads : GeoDataFrame
        As returned by :func:`approximate_strings` (``string_id``, ``width_m``,
        ``quality``).
    min_search_radius_m, max_search_radius_m : float
        Radius (metres) of the semicircle searched ahead of an end of a road of quality 0
        and 1; linear in between. The semicircle is centred on the end point and points
        in the road's direction at that end.
    collinear_deg : float
        Roads whose directions differ by at most this (degrees) are collinear: joined end to
        end when pointing at each other, the other end inside the semicircle and within the
        wider road's width sideways; never joined when side by side. Other roads are joined
        through the intersection of the end's extension with the other road (end-road) or
        with the other road's extension (intersection-polygon, through both end points);
        each extension reaches at most its end's search radius.
    end_window_m : float
        A road's direction at an end is that of the chord from the point this far (metres;
        at most half the road) along it to the end: the last approximation segment alone
        can be a short, noisy one.
    overshoot_m : float
        An end within a crossing road's half width plus this margin (metres) past it ends
        at the crossing.
    unsupported : callable, optional
        ``unsupported(lines) -> metres``: how much of each candidate connection (a
        LineString array) the evidence does not show as road, e.g. the raster's
        sub-threshold stretch (:func:`gisroads.network.rasters.raster_to_network`). Not in
        the paper, which has no evidence left at this stage.
    max_unsupported_m : float
        Candidates with more than this unsupported, metres, are no connection: a false
        blob of the raster would otherwise reach out its full search radius across a block.

    Returns
    -------
    roads : GeoDataFrame
        ``roads`` with the meeting points inserted as vertices, so connections and the roads
        they end on share them exactly.
    junction_connections : GeoDataFrame
        Every connection hypothesis, LineStrings: ``kind`` (``end-end``, ``end-road``,
        ``intersection-polygon``, ``crossing``), ``from_road`` and ``to_road`` (the
        ``string_id`` of the roads; an end-road connection onto another connection names
        that connection's ``from_road``), ``length_m`` (centre line it adds; 0 for a
        crossing, drawn as the stretch of ``from_road`` across ``to_road``), ``verified``
        (accepted: the shortest at its road ends), ``width_m`` and ``quality`` (means of the
        two roads').
    """
    if min_search_radius_m <= 0 or max_search_radius_m < min_search_radius_m:
        raise GisroadsError("search radii must satisfy 0 < min_search_radius_m <= "
                            "max_search_radius_m")
    if not 0 <= collinear_deg < 90:
        raise GisroadsError(f"collinear_deg must lie in [0, 90), got {collinear_deg}")
    crs = roads.crs
    if len(roads) == 0:
        return roads.copy(), _connection_frame([], roads["string_id"].dtype
                                               if "string_id" in roads else np.int64, crs)
    search = _JunctionSearch(roads, min_search_radius_m=min_search_radius_m,
                             max_search_radius_m=max_search_radius_m,
                             collinear_deg=collinear_deg, end_window_m=end_window_m,
                             overshoot_m=overshoot_m, unsupported=unsupported,
                             max_unsupported_m=max_unsupported_m)
    search.crossings()
    search.run()
    edited = roads.copy()
    edited.geometry = gpd.GeoSeries([shapely.linestrings(xy) for xy in search.coords],
                                    index=roads.index, crs=crs)
    return edited, _connection_frame(search.connections, roads["string_id"].dtype, crs)


def _connection_frame(connections, id_dtype, crs) -> gpd.GeoDataFrame:
    columns = {
        "kind": pd.Series([c["kind"] for c in connections], dtype=object),
        "from_road": pd.Series([c["from_string"] for c in connections], dtype=id_dtype),
        "to_road": pd.Series([c["to_string"] for c in connections], dtype=id_dtype),
        "length_m": pd.Series([c["length_m"] for c in connections], dtype=float),
        "verified": pd.Series([bool(c["verified"]) for c in connections], dtype=bool),
        "width_m": pd.Series([c["width_m"] for c in connections], dtype=float),
        "quality": pd.Series([c["quality"] for c in connections], dtype=float),
    }
    geometry = gpd.GeoSeries([shapely.linestrings(c["xy"]) for c in connections], crs=crs)
    return gpd.GeoDataFrame(columns, geometry=geometry, crs=crs)


# --- 4. significance ------------------------------------------------------------------------

def significant_components(roads: gpd.GeoDataFrame, connections: gpd.GeoDataFrame, *,
                           min_total_length_m: float = MIN_TOTAL_LENGTH_M, extent=None,
                           border_m: float = BORDER_M) -> tuple[gpd.GeoDataFrame,
                                                                gpd.GeoDataFrame]:
    """Connected components and their significance (Sec. 2.3, last paragraph).

    A component is the set of roads and verified junction connections that touch each
    other. It is significant when the length of its roads exceeds the length of
    its junction connections, and its total length is at least ``min_total_length_m`` or
    at least two of its open ends (line ends touching no other line) lie within
    ``border_m`` of the border of ``extent``.

    Parameters
    ----------
    roads, connections : GeoDataFrame
        As returned by :func:`find_junctions` (lines meeting at exactly shared points).
    min_total_length_m : float
        Metres.
    extent : (xmin, ymin, xmax, ymax), optional
        The image extent in the roads' CRS; without it no component is kept for its border
        ends.
    border_m : float
        Metres.

    Returns
    -------
    roads, connections : GeoDataFrame
        Copies with ``component`` (int; -1 for unverified connections) and ``significant``
        (bool).
    """
    roads, connections = roads.copy(), connections.copy()
    if len(roads) == 0:
        roads["component"], roads["significant"] = np.empty(0, np.int64), np.empty(0, bool)
        connections["component"] = np.full(len(connections), -1, dtype=np.int64)
        connections["significant"] = np.zeros(len(connections), dtype=bool)
        return roads, connections
    in_network = connections["verified"].to_numpy(bool)
    lines = np.concatenate([roads.geometry.values,
                            connections.geometry.values[in_network]]).astype(object)
    is_road = np.arange(len(lines)) < len(roads)
    # a crossing's line lies on both roads: it joins them and adds no length
    lengths = np.concatenate([shapely.length(roads.geometry.values),
                              connections["length_m"].to_numpy(float)[in_network]])
    a, b = shapely.STRtree(lines).query(lines, predicate="intersects")
    count, label = connected_components(
        coo_matrix((np.ones(len(a)), (a, b)), shape=(len(lines), len(lines))), directed=False)
    road_length = np.bincount(label[is_road], weights=lengths[is_road], minlength=count)
    link_length = np.bincount(label[~is_road], weights=lengths[~is_road], minlength=count)
    border_ends = np.zeros(count, dtype=np.int64)
    if extent is not None:
        ends = np.concatenate([shapely.get_point(lines, 0), shapely.get_point(lines, -1)])
        owner = np.tile(np.arange(len(lines)), 2)
        hit_end, hit_line = shapely.STRtree(lines).query(ends, predicate="intersects")
        touches = np.bincount(hit_end[hit_line != owner[hit_end]], minlength=len(ends))
        near_border = shapely.distance(ends, shapely.box(*extent).exterior) <= border_m
        open_near = (touches == 0) & near_border
        border_ends = np.bincount(label[owner[open_near]], minlength=count)
    significant = (road_length > link_length) & (
        (road_length + link_length >= min_total_length_m) | (border_ends >= 2))
    roads["component"] = label[is_road].astype(np.int64)
    roads["significant"] = significant[label[is_road]]
    component = np.full(len(connections), -1, dtype=np.int64)
    component[in_network] = label[~is_road]
    connections["component"] = component
    connections["significant"] = np.where(component >= 0,
                                          significant[np.maximum(component, 0)], False)
    return roads, connections


def merge_close_junctions(lines, width_m, score, *,
                          junction_merge_m: float = JUNCTION_MERGE_M):
    """Contract roads shorter than ``junction_merge_m`` that join two junctions.

    Junctions built one end at a time around the same crossing can land a little apart;
    each short road between two junctions (nodes where three or more road ends meet) is
    removed and the junctions it joined become one, at the mean of their positions; the
    roads ending there are moved to it.

    Parameters
    ----------
    lines : ndarray of LineString
        Noded roads (they meet only at their end points).
    width_m, score : ndarray
        One value per road, kept for the remaining roads.
    junction_merge_m : float
        Metres.

    Returns
    -------
    lines, width_m, score : ndarray
    """
    lines = np.asarray(lines, dtype=object)
    if len(lines) == 0 or junction_merge_m <= 0:
        return lines, width_m, score
    ends = np.concatenate([shapely.get_coordinates(shapely.get_point(lines, 0)),
                           shapely.get_coordinates(shapely.get_point(lines, -1))])
    keys = np.round(ends / _EPS_M).astype(np.int64)
    _, first, end_node = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    end_node = end_node.ravel()           # numpy 2.0 returns a column, others a flat array
    node = end_node.reshape(2, -1).T
    degree = np.bincount(end_node)
    short = ((shapely.length(lines) < junction_merge_m) & (node[:, 0] != node[:, 1])
             & (degree[node].min(axis=1) >= 3))
    if not short.any():
        return lines, width_m, score
    count, cluster = connected_components(coo_matrix(
        (np.ones(int(short.sum())), (node[short, 0], node[short, 1])),
        shape=(len(degree), len(degree))), directed=False)
    position = np.column_stack([
        np.bincount(cluster, weights=ends[first, axis], minlength=count)
        / np.bincount(cluster, minlength=count) for axis in (0, 1)])
    kept = []
    for k in np.flatnonzero(~short):
        xy = shapely.get_coordinates(lines[k])
        xy[0], xy[-1] = position[cluster[node[k, 0]]], position[cluster[node[k, 1]]]
        kept.append(shapely.linestrings(xy))
    return np.array(kept, dtype=object), width_m[~short], score[~short]


# --- 5. the stage ---------------------------------------------------------------------------

@dataclass(frozen=True)
class NetworkOptions:
    """The options of :func:`strings_to_network`: approximation, duplicates, junctions and
    significance (steps 1-5 of the module docstring).

    Attributes
    ----------
    tolerance_m : float
        See :func:`approximate_strings`.
    min_search_radius_m, max_search_radius_m, collinear_deg, end_window_m, overshoot_m : float
        See :func:`find_junctions`.
    unsupported, max_unsupported_m : callable, float
        See :func:`find_junctions`.
    parallel_margin_m, parallel_share, overlap_share : float
        See :func:`remove_duplicates`.
    min_total_length_m, border_m : float
        See :func:`significant_components`.
    junction_merge_m : float
        See :func:`merge_close_junctions`.
    """

    tolerance_m: float = TOLERANCE_M
    min_search_radius_m: float = MIN_SEARCH_RADIUS_M
    max_search_radius_m: float = MAX_SEARCH_RADIUS_M
    collinear_deg: float = COLLINEAR_DEG
    end_window_m: float = END_WINDOW_M
    parallel_margin_m: float = PARALLEL_MARGIN_M
    parallel_share: float = PARALLEL_SHARE
    overlap_share: float = OVERLAP_SHARE
    min_total_length_m: float = MIN_TOTAL_LENGTH_M
    border_m: float = BORDER_M
    overshoot_m: float = OVERSHOOT_M
    junction_merge_m: float = JUNCTION_MERGE_M
    unsupported: object = None
    max_unsupported_m: float = np.inf


def strings_to_network(road_strings: gpd.GeoDataFrame,
                       options: NetworkOptions = NetworkOptions(), *, extent=None, crs=None,
                       method: str = METHOD, progress: Progress = None,
                       **changes) -> tuple[RoadNetwork, gpd.GeoDataFrame]:
    """Road strings to the road-network contract (steps 1-5 of the module docstring).

    Parameters
    ----------
    road_strings : GeoDataFrame
        One LineString per road string with ``width_m`` and ``quality`` (see
        :func:`approximate_strings`).
    extent : (xmin, ymin, xmax, ymax), optional
        The image extent, for the border rule of :func:`significant_components`.
    crs : optional
        CRS of strings that carry none; must agree with theirs otherwise.
    options : NetworkOptions
        Approximation, duplicates, junctions and significance (:class:`NetworkOptions`).
    method : str
        The ``method`` of every centre line.
    progress : callable, optional
        ``progress(fraction, message)``; may raise :class:`gisroads.progress.Cancelled`.
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    network : RoadNetwork
        Roads split at junctions and merged through degree-2 nodes (``score`` = quality,
        ``width_m`` = length-weighted means), flat-capped road polygons, junctions of degree
        >= 3; ``qa["junction_connections"]`` holds the connections.
    junction_connections : GeoDataFrame
        Every hypothesis of :func:`find_junctions` plus ``component`` and ``significant``
        from :func:`significant_components`.
    """
    options = replace(options, **changes)
    _check_frame(road_strings, ("width_m", "quality"))
    if crs is not None and road_strings.crs is not None and road_strings.crs != crs:
        raise GisroadsError(f"road strings are in {road_strings.crs.name}, not in the given "
                            "crs")
    if road_strings.crs is None and crs is not None:
        road_strings = road_strings.set_crs(crs)
    report(progress, 0.0, "approximating road strings")
    roads = approximate_strings(road_strings, tolerance_m=options.tolerance_m)
    report(progress, 0.15, "removing duplicate roads")
    roads = remove_duplicates(roads, parallel_margin_m=options.parallel_margin_m,
                              parallel_share=options.parallel_share,
                              collinear_deg=options.collinear_deg,
                              overlap_share=options.overlap_share)
    report(progress, 0.3, "searching junctions")
    roads, connections = find_junctions(
        roads, min_search_radius_m=options.min_search_radius_m,
        max_search_radius_m=options.max_search_radius_m, collinear_deg=options.collinear_deg,
        end_window_m=options.end_window_m, overshoot_m=options.overshoot_m,
        unsupported=options.unsupported, max_unsupported_m=options.max_unsupported_m)
    report(progress, 0.7, "checking connected components")
    roads, connections = significant_components(roads, connections,
                                                min_total_length_m=options.min_total_length_m,
                                                extent=extent, border_m=options.border_m)
    report(progress, 0.8, "building the network")
    kept_roads = roads[roads["significant"].to_numpy(bool)]
    kept_links = connections[connections["significant"].to_numpy(bool)
                             & (connections["kind"].to_numpy(object) != "crossing")]
    lines = np.concatenate([kept_roads.geometry.values, kept_links.geometry.values])
    width = np.concatenate([kept_roads["width_m"].to_numpy(float),
                            kept_links["width_m"].to_numpy(float)])
    score = np.concatenate([kept_roads["quality"].to_numpy(float),
                            kept_links["quality"].to_numpy(float)])
    qa = {"junction_connections": connections}
    if len(lines) == 0:
        network = network_from_centrelines(gpd.GeoDataFrame(
            {"width_m": np.empty(0)}, geometry=gpd.GeoSeries([], crs=roads.crs),
            crs=roads.crs), method=method, qa=qa)
    else:
        merged, width, score = node_roads(lines.astype(object), width, score,
                                          join_gap_m=options.overshoot_m, min_length_m=0.0)
        merged, width, score = merge_close_junctions(merged, width, score,
                                                     junction_merge_m=options.junction_merge_m)
        network = network_from_centrelines(gpd.GeoDataFrame(
            {"road_id": np.arange(len(merged), dtype=np.int64), "width_m": width,
             "score": score, "method": method},
            geometry=gpd.GeoSeries(merged, crs=roads.crs), crs=roads.crs), method=method,
            qa=qa)
    report(progress, 1.0, "network built")
    return network, connections
