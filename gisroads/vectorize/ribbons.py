"""Road pieces (rectangles, ribbons) to the road-network output contract.

The ribbon snakes (centre lines with widths, :func:`ribbons_to_network`) go through the four
steps below; the LiDAR minimum cover's rectangles (Zhu & Mordohai) through the first
(:func:`chain_lines` of :func:`rectangle_centrelines`), then the network stage every method
ends in (:mod:`gisroads.lidar.roads`):

1. **Chain.** Pieces of similar direction that continue each other are stitched into longer
   centre lines. An end is *near* another piece when it lies within ``join_gap_m`` of that
   piece's centre line, or within half the wider piece's width (on its surface), whichever
   reaches farther. Two pieces continue each other when an end of each is near the other (head to
   tail, overlapping or abutting), or when one runs alongside the other, near it over at
   least half the shorter one's length; and when their directions where they come closest
   differ by at most ``angle_tol_deg``. Where the pieces overlap, the stitched line switches
   from one to the other where they cross, or, where they do not cross (pieces offset
   sideways), cross-fades from one to the other over the overlap with smoothstep weights,
   so it has no kink. Collinear overlapping pieces give a straight line as long as their
   union. A stitch is refused when a vertex of either piece would end up farther than twice
   the nearness distance from the result (a fork, not a continuation). Width and score of a
   chain are means weighted by piece length. Chains shorter than ``min_length_m`` are
   dropped.
2. **Snap.** A chain end near another chain of clearly different direction (more than
   ``angle_tol_deg``), within that chain's half width plus ``join_gap_m``, is a T-junction:
   the end is extended to the nearest point of the other line and that point is inserted
   into the other line as a vertex, so both share it exactly. An end that already crosses
   the other line is left alone: noding cuts it there.
3. **Node.** Lines are split at every crossing and shared vertex
   (:func:`gisroads.geo.node_lines`). A dangling piece hanging off a junction and no longer
   than the half width of the other roads there plus ``join_gap_m`` is an overshoot across
   the other road's surface and is removed. Lines meeting at nodes of degree 2 are merged
   into one road, whatever the angle (an L-shaped bend is one road); junctions are nodes of
   degree 3 or more. So a crossing of two chains gives four roads and one junction of
   degree 4. Isolated roads shorter than ``min_length_m`` are dropped.
4. **Polygons.** The union of the pieces' areas is closed (``buffer(+smooth_m)`` then
   ``buffer(-smooth_m)``, which fills the notches between pieces at an angle and leaves
   convex corners sharp) and divided between the roads by nearest centre line (a Voronoi
   partition of the centre lines' vertices, densified to 2 m), so the road polygons tile
   the road surface without overlapping, one or more polygons per road.

Widths are one number per piece (a ribbon's per-vertex widths are averaged over its length
first), so a road's width is the length-weighted mean of the pieces it was made of.
"""
from __future__ import annotations

import geopandas as gpd
import numpy as np
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..geo import RoadNetwork, line_graph, network_from_centrelines

#: Defaults of the shared steps (the papers give none): ends within 5 m, about half a
#: two-lane road, continue each other; 20 degrees separates continuing pieces from branches
#: (close to the 15 degrees of Zhu & Mordohai's edge-orientation tolerance, Sec. 4.2);
#: a 2 m closing removes the notches of pieces meeting at an angle; chains shorter than 10 m
#: are noise (the paper's hypotheses are at least 40 m long, Sec. 4.3).
JOIN_GAP_M = 5.0
ANGLE_TOL_DEG = 20.0
SMOOTH_M = 2.0
MIN_LENGTH_M = 10.0

_TANGENT_STEP_M = 0.5    # half the baseline of a tangent estimate
_BLEND_STEP_M = 1.0      # vertex spacing of a cross-fade
_PARTITION_STEP_M = 2.0  # spacing of the Voronoi generators along the centre lines
_ALONGSIDE_PROBES = 21   # points along the shorter piece that test "runs alongside"
_SIMPLIFY_M = 0.01       # removes the collinear vertices a stitch leaves, far below a pixel
_EPS_M = 1e-6            # "the same place"


# --- pieces -------------------------------------------------------------------------------

def rectangle_centrelines(rectangles: gpd.GeoDataFrame) -> np.ndarray:
    """Mid-lines of rectangles along their long axis.

    Parameters
    ----------
    rectangles : GeoDataFrame
        Polygons with ``theta_rad``, the road direction (radians, counter-clockwise from
        east). The centre line runs through the middle of the polygon's extent across
        ``theta_rad``, from its least to its greatest extent along ``theta_rad``, so it does
        not depend on which corner a rectangle was anchored at.

    Returns
    -------
    ndarray of LineString, one per rectangle, pointing along ``theta_rad``.
    """
    geoms = rectangles.geometry.values
    if len(geoms) == 0:
        return np.empty(0, dtype=object)
    theta = rectangles["theta_rad"].to_numpy(float)
    along_dir = np.column_stack([np.cos(theta), np.sin(theta)])
    across_dir = np.column_stack([-along_dir[:, 1], along_dir[:, 0]])
    xy, owner = shapely.get_coordinates(geoms, return_index=True)
    starts = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
    origin = xy[starts]     # local origins keep map coordinates' digits
    local = xy - origin[owner]
    along = np.einsum("ij,ij->i", local, along_dir[owner])
    across = np.einsum("ij,ij->i", local, across_dir[owner])
    a0, a1 = np.minimum.reduceat(along, starts), np.maximum.reduceat(along, starts)
    mid = (np.minimum.reduceat(across, starts) + np.maximum.reduceat(across, starts)) / 2
    ends = origin[:, None] + np.stack([a0[:, None] * along_dir + mid[:, None] * across_dir,
                                       a1[:, None] * along_dir + mid[:, None] * across_dir],
                                      axis=1)
    return shapely.linestrings(ends)


def _vertex_widths(lines, widths_m):
    """Vertices of lines, the line of each, and a width per vertex.

    ``widths_m`` holds per line either one width per vertex or a scalar for all of them.
    """
    xy, owner = shapely.get_coordinates(lines, return_index=True)
    counts = np.bincount(owner, minlength=len(lines))
    width = np.concatenate([np.broadcast_to(np.asarray(w, float), (c,))
                            for w, c in zip(widths_m, counts)] or [np.empty(0)])
    return xy, owner, width


def ribbon_areas(lines, widths_m) -> np.ndarray:
    """Surface of ribbons: a trapezoid per segment plus a disc at every inner vertex.

    Parameters
    ----------
    lines : array_like of LineString
    widths_m : sequence
        Per line, an array of one width per vertex or one scalar width (metres, CRS units).

    Returns
    -------
    ndarray of (Multi)Polygon, one per line.
    """
    lines = np.asarray(lines, dtype=object)
    xy, owner, half = _vertex_widths(lines, widths_m)
    half = half / 2.0
    same_line = owner[1:] == owner[:-1]
    step = np.diff(xy, axis=0)
    length = np.hypot(step[:, 0], step[:, 1])
    segment = same_line & (length > 0)
    a, b = xy[:-1][segment], xy[1:][segment]
    ha, hb = half[:-1][segment, None], half[1:][segment, None]
    normal = np.column_stack([-step[segment, 1], step[segment, 0]]) / length[segment, None]
    quads = shapely.polygons(np.stack([a + ha * normal, b + hb * normal, b - hb * normal,
                                       a - ha * normal, a + ha * normal], axis=1))
    inner = np.r_[False, same_line] & np.r_[same_line, False]
    discs = shapely.buffer(shapely.points(xy[inner]), half[inner])
    parts = np.concatenate([quads, discs])
    part_owner = np.concatenate([owner[1:][segment], owner[inner]])
    return np.array([shapely.union_all(parts[part_owner == k]) for k in range(len(lines))],
                    dtype=object)


# --- geometry helpers ---------------------------------------------------------------------

def tangents(lines, along_m) -> np.ndarray:
    """Unit direction of lines at distances ``along_m`` along them, shape (n, 2)."""
    length = shapely.length(lines)
    back = shapely.line_interpolate_point(lines, np.clip(along_m - _TANGENT_STEP_M, 0, length))
    ahead = shapely.line_interpolate_point(lines, np.clip(along_m + _TANGENT_STEP_M, 0, length))
    d = shapely.get_coordinates(ahead) - shapely.get_coordinates(back)
    norm = np.hypot(d[:, 0], d[:, 1])
    return d / np.where(norm > 0, norm, 1.0)[:, None]


def _clean(xy: np.ndarray) -> np.ndarray:
    """Vertices without consecutive duplicates."""
    step = np.hypot(*np.diff(xy, axis=0).T)
    return xy[np.r_[True, step > _EPS_M]]


def _stations(xy: np.ndarray) -> np.ndarray:
    return np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]


def _points_at(xy: np.ndarray, stations: np.ndarray, along_m) -> np.ndarray:
    along_m = np.asarray(along_m, float)
    return np.column_stack([np.interp(along_m, stations, xy[:, 0]),
                            np.interp(along_m, stations, xy[:, 1])])


def _cut(xy: np.ndarray, start_m: float, stop_m: float) -> np.ndarray:
    """Vertices of a polyline between two distances along it (inclusive)."""
    st = _stations(xy)
    inner = xy[(st > start_m) & (st < stop_m)]
    return np.vstack([_points_at(xy, st, [start_m]), inner, _points_at(xy, st, [stop_m])])


def _blend(x_xy, x_from, x_to, y_xy, y_from, y_to) -> np.ndarray:
    """Cross-fade from polyline X to polyline Y over their overlap: points moving from X's
    part ``[x_from, x_to]`` to Y's part ``[y_from, y_to]`` with smoothstep weights, which
    leave X and reach Y along their own directions."""
    span = max(x_to - x_from, y_to - y_from)
    s = np.linspace(0.0, 1.0, max(2, int(np.ceil(span / _BLEND_STEP_M)) + 1))
    px = _points_at(x_xy, _stations(x_xy), x_from + s * (x_to - x_from))
    py = _points_at(y_xy, _stations(y_xy), y_from + s * (y_to - y_from))
    weight = (s * s * (3 - 2 * s))[:, None]
    return (1 - weight) * px + weight * py


def _head_to_tail(x, y) -> np.ndarray:
    """X followed by Y, where Y's start lies along X's end region and Y's end past it.

    Over their overlap the result switches from X to Y where they cross, or, when they do
    not cross, cross-fades from one to the other (:func:`_blend`).
    """
    x_xy, y_xy = shapely.get_coordinates(x), shapely.get_coordinates(y)
    x_length, y_length = float(shapely.length(x)), float(shapely.length(y))
    x_from = float(shapely.line_locate_point(x, shapely.get_point(y, 0)))
    y_to = float(shapely.line_locate_point(y, shapely.get_point(x, -1)))
    x_part, y_part = _clean(_cut(x_xy, x_from, x_length)), _clean(_cut(y_xy, 0.0, y_to))
    x_part = shapely.linestrings(x_part) if len(x_part) > 1 else None
    y_part = shapely.linestrings(y_part) if len(y_part) > 1 else None
    # intersects() first: GEOS 3.11 flags the NaN z of an empty intersection as invalid
    if x_part is not None and y_part is not None and shapely.intersects(x_part, y_part):
        crossing = shapely.points(shapely.get_coordinates(shapely.intersection(x_part, y_part)))
        first = int(np.argmin(shapely.line_locate_point(x, crossing)))
        switch_x = float(shapely.line_locate_point(x, crossing[first]))
        switch_y = float(shapely.line_locate_point(y, crossing[first]))
        return np.vstack([_cut(x_xy, 0.0, switch_x), _cut(y_xy, switch_y, y_length)])
    return np.vstack([_cut(x_xy, 0.0, x_from), _blend(x_xy, x_from, x_length, y_xy, 0.0, y_to),
                      _cut(y_xy, y_to, y_length)])


def _stitch(a, b, tolerance_m: float):
    """One line continuing ``a`` with ``b`` (see the module docstring), or None when a vertex
    of either would lie farther than twice ``tolerance_m`` from it (a fork)."""
    if shapely.length(b) > shapely.length(a):
        a, b = b, a
    closest = shapely.get_coordinates(shapely.shortest_line(a, b))
    ta = tangents(np.array([a]), shapely.line_locate_point(a, shapely.points(closest[0])))
    tb = tangents(np.array([b]), shapely.line_locate_point(b, shapely.points(closest[1])))
    if float(np.sum(ta * tb)) < 0:
        b = shapely.reverse(b)
    la, lb = float(shapely.length(a)), float(shapely.length(b))
    b_start_on_a = float(shapely.line_locate_point(a, shapely.get_point(b, 0)))
    b_end_on_a = float(shapely.line_locate_point(a, shapely.get_point(b, -1)))
    a_start_on_b = float(shapely.line_locate_point(b, shapely.get_point(a, 0)))
    a_end_on_b = float(shapely.line_locate_point(b, shapely.get_point(a, -1)))
    b_before = b_start_on_a <= _EPS_M and a_start_on_b > _EPS_M
    b_after = b_end_on_a >= la - _EPS_M and a_end_on_b < lb - _EPS_M
    if b_before and b_after:
        merged = b
    elif b_after:
        merged = shapely.linestrings(_clean(_head_to_tail(a, b)))
    elif b_before:
        merged = shapely.linestrings(_clean(_head_to_tail(b, a)))
    else:
        merged = a
    merged = shapely.simplify(merged, _SIMPLIFY_M)
    probes = shapely.points(shapely.get_coordinates(
        shapely.segmentize(np.array([a, b]), _BLEND_STEP_M)))
    if shapely.distance(probes, merged).max() > 2 * tolerance_m:
        return None
    return merged


# --- 1. chain -----------------------------------------------------------------------------

def _continuation_pairs(lines, widths_m, join_gap_m: float, angle_tol_deg: float):
    """Pairs ``(i, j)`` of lines that continue each other, closest pairs first, and the
    distance within which their ends count as near (see :func:`_near_m`)."""
    reach = max(join_gap_m, float(np.max(widths_m)) / 2)
    i, j = shapely.STRtree(lines).query(lines, predicate="dwithin", distance=reach)
    keep = i < j
    i, j = i[keep], j[keep]
    tolerance = _near_m(widths_m[i], widths_m[j], join_gap_m)
    starts, ends = shapely.get_point(lines, 0), shapely.get_point(lines, -1)
    i_start = shapely.distance(starts[i], lines[j]) <= tolerance
    i_end = shapely.distance(ends[i], lines[j]) <= tolerance
    j_start = shapely.distance(starts[j], lines[i]) <= tolerance
    j_end = shapely.distance(ends[j], lines[i]) <= tolerance
    i_shorter = shapely.length(lines[i]) <= shapely.length(lines[j])
    shorter, longer = np.where(i_shorter, lines[i], lines[j]), np.where(i_shorter, lines[j],
                                                                         lines[i])
    probes = shapely.line_interpolate_point(np.repeat(shorter, _ALONGSIDE_PROBES),
                                            np.tile(np.linspace(0, 1, _ALONGSIDE_PROBES),
                                                    len(i)), normalized=True)
    near_longer = (shapely.distance(probes, np.repeat(longer, _ALONGSIDE_PROBES))
                   <= np.repeat(tolerance, _ALONGSIDE_PROBES))
    alongside = near_longer.reshape(-1, _ALONGSIDE_PROBES).mean(axis=1) >= 0.5
    contact = ((i_start | i_end) & (j_start | j_end)) | alongside
    i, j, tolerance = i[contact], j[contact], tolerance[contact]
    closest = shapely.get_coordinates(shapely.shortest_line(lines[i], lines[j])).reshape(-1, 2, 2)
    ti = tangents(lines[i], shapely.line_locate_point(lines[i], shapely.points(closest[:, 0])))
    tj = tangents(lines[j], shapely.line_locate_point(lines[j], shapely.points(closest[:, 1])))
    aligned = np.abs(np.einsum("ij,ij->i", ti, tj)) >= np.cos(np.radians(angle_tol_deg))
    i, j, tolerance = i[aligned], j[aligned], tolerance[aligned]
    order = np.argsort(shapely.distance(lines[i], lines[j]), kind="stable")
    return i[order], j[order], tolerance[order]


def _near_m(width_a, width_b, join_gap_m: float):
    """How near an end must be to another piece's centre line to continue it: within
    ``join_gap_m``, or on the wider piece's surface (half its width), whichever is farther,
    so pieces of one wide road offset sideways still chain."""
    return np.maximum(join_gap_m, np.maximum(width_a, width_b) / 2)


def _chain(lines, widths_m, *, join_gap_m: float, angle_tol_deg: float):
    """Stitch continuing lines; returns (chain lines, chain label of every input line)."""
    parent = np.arange(len(lines))
    geometry = dict(enumerate(lines))

    def root(k):
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for i, j, tolerance in zip(*_continuation_pairs(lines, widths_m, join_gap_m,
                                                     angle_tol_deg)):
        ri, rj = root(i), root(j)
        if ri == rj:
            continue
        merged = _stitch(geometry[ri], geometry[rj], tolerance)
        if merged is not None:
            parent[rj] = ri
            geometry[ri] = merged
            del geometry[rj]
    roots = np.array([root(k) for k in range(len(lines))], dtype=np.int64)
    unique_roots, labels = np.unique(roots, return_inverse=True)
    return np.array([geometry[r] for r in unique_roots], dtype=object), labels.ravel()


def _weighted_mean(values, weights, labels, count) -> np.ndarray:
    total = np.bincount(labels, weights=weights, minlength=count)
    return np.bincount(labels, weights=values * weights, minlength=count) / total


def _chained(lines, widths_m, scores, *, join_gap_m: float, angle_tol_deg: float):
    """Step 1: (chain lines, their widths and scores as length-weighted means of their
    pieces, chain label of every piece)."""
    chains, labels = _chain(lines, widths_m, join_gap_m=join_gap_m,
                            angle_tol_deg=angle_tol_deg)
    piece_length = shapely.length(lines)
    return (chains, _weighted_mean(widths_m, piece_length, labels, len(chains)),
            _weighted_mean(scores, piece_length, labels, len(chains)), labels)


def chain_lines(pieces: gpd.GeoDataFrame, *, join_gap_m: float = JOIN_GAP_M,
                angle_tol_deg: float = ANGLE_TOL_DEG,
                min_length_m: float = MIN_LENGTH_M) -> gpd.GeoDataFrame:
    """Step 1 alone: pieces that continue each other stitched into centre lines.

    Parameters
    ----------
    pieces : GeoDataFrame
        LineStrings in a metre CRS with ``width_m`` (metres) and ``score``.
    join_gap_m, angle_tol_deg, min_length_m : float
        As in :func:`ribbons_to_network`.

    Returns
    -------
    GeoDataFrame
        One LineString per chain at least ``min_length_m`` long, with ``width_m`` and
        ``score`` (means of its pieces weighted by their length); not noded: crossing
        chains are left for the network stage (:mod:`gisroads.network`).
    """
    lines = np.asarray(pieces.geometry.values, dtype=object)
    usable = shapely.length(lines) > 0
    if not usable.any():
        return gpd.GeoDataFrame({"width_m": np.empty(0), "score": np.empty(0)},
                                geometry=gpd.GeoSeries([], crs=pieces.crs), crs=pieces.crs)
    chains, width, score, _ = _chained(
        lines[usable], pieces["width_m"].to_numpy(float)[usable],
        pieces["score"].to_numpy(float)[usable], join_gap_m=join_gap_m,
        angle_tol_deg=angle_tol_deg)
    kept = shapely.length(chains) >= min_length_m
    return gpd.GeoDataFrame({"width_m": width[kept], "score": score[kept]},
                            geometry=gpd.GeoSeries(chains[kept], crs=pieces.crs),
                            crs=pieces.crs)


# --- 2. snap ------------------------------------------------------------------------------

def _insert_vertex(xy: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Polyline vertices with ``point`` (lying on it) inserted in place."""
    if np.any(np.hypot(*(xy - point).T) <= _EPS_M):
        return xy
    along = shapely.line_locate_point(shapely.linestrings(xy), shapely.points(point))
    position = int(np.searchsorted(_stations(xy), along, side="right"))
    return np.insert(xy, min(max(position, 1), len(xy) - 1), point, axis=0)


def _snap_ends(lines, widths_m, *, join_gap_m: float, angle_tol_deg: float) -> np.ndarray:
    """T-junctions: ends near a line of another direction are extended onto it, sharing an
    exact vertex with it (step 2 of the module docstring)."""
    n = len(lines)
    ends = np.concatenate([shapely.get_point(lines, 0), shapely.get_point(lines, -1)])
    end_line, at_start = np.tile(np.arange(n), 2), np.arange(2 * n) < n
    reach = float(np.max(widths_m)) / 2 + join_gap_m
    e, t = shapely.STRtree(lines).query(ends, predicate="dwithin", distance=reach)
    other = end_line[e] != t
    e, t = e[other], t[other]
    distance = shapely.distance(ends[e], lines[t])
    along_target = shapely.line_locate_point(lines[t], ends[e])
    along_source = np.where(at_start[e], 0.0, shapely.length(lines[end_line[e]]))
    crossing = (np.abs(np.einsum("ij,ij->i", tangents(lines[end_line[e]], along_source),
                                 tangents(lines[t], along_target)))
                < np.cos(np.radians(angle_tol_deg)))
    ok = crossing & (distance <= widths_m[t] / 2 + join_gap_m)
    e, t, distance = e[ok], t[ok], distance[ok]
    order = np.lexsort((distance, e))
    nearest_target = order[np.r_[True, e[order][1:] != e[order][:-1]]] if len(e) else order
    coords = [shapely.get_coordinates(line) for line in lines]
    for k in nearest_target:
        source, target, start = end_line[e[k]], t[k], at_start[e[k]]
        # the target as it is now: an earlier snap may have extended it
        along = shapely.line_locate_point(shapely.linestrings(coords[target]), ends[e[k]])
        point = _points_at(coords[target], _stations(coords[target]), [along])[0]
        if np.hypot(*(point - coords[source][0 if start else -1])) > _EPS_M:
            forward = coords[source][::-1] if start else coords[source]
            length = _stations(forward)[-1]
            tail = shapely.linestrings(_cut(forward, max(0.0, length - reach), length))
            if shapely.intersects(tail, shapely.linestrings(coords[target])):
                continue  # it crosses the other line already: noding cuts it there
            coords[source] = (np.vstack([point, coords[source]]) if start
                              else np.vstack([coords[source], point]))
        else:
            coords[source][0 if start else -1] = point
        coords[target] = _insert_vertex(coords[target], point)
    return np.array([shapely.linestrings(_clean(xy)) for xy in coords], dtype=object)


# --- 3. node ------------------------------------------------------------------------------

def node_roads(lines, widths_m, scores, *, join_gap_m: float, min_length_m: float):
    """Noded roads (step 3 of the module docstring): roads split at crossings and T ends,
    overshooting spurs trimmed, roads merged through degree-2 nodes.

    Parameters
    ----------
    lines : ndarray of shapely LineString
    widths_m, scores : ndarray of float
        Per line; carried to the roads as length-weighted means.
    join_gap_m : float
        How far past the half width of a road a spur may overshoot and still be trimmed.
    min_length_m : float
        Shorter isolated roads are dropped.

    Returns
    -------
    (lines, width_m, score)
    """
    tree = shapely.STRtree(lines)
    graph = line_graph(lines)
    edges, pieces = graph.edges, graph.lines
    midpoints = shapely.line_interpolate_point(pieces, 0.5, normalized=True)
    source = tree.query_nearest(midpoints, all_matches=False)[1]
    keep = np.ones(len(pieces), dtype=bool)
    while True:
        degree = np.bincount(edges[keep].ravel(), minlength=len(graph.nodes))
        half_width = widths_m[source] / 2
        # a spur overshoots the widest road at its junction by at most that road's half width
        node_half = np.zeros(len(graph.nodes))
        np.maximum.at(node_half, edges[keep].ravel(), np.repeat(half_width[keep], 2))
        end_degree = degree[edges]
        dangling = (end_degree.min(axis=1) == 1) & (end_degree.max(axis=1) >= 3)
        hub = np.where(end_degree[:, 0] >= 3, edges[:, 0], edges[:, 1])
        spur = keep & dangling & (graph.lengths <= node_half[hub] + join_gap_m)
        if not spur.any():
            break
        keep &= ~spur
    pieces, edges, source = pieces[keep], edges[keep], source[keep]
    lengths = graph.lengths[keep]
    degree = np.bincount(edges.ravel(), minlength=len(graph.nodes))
    # edges meeting at a degree-2 node belong to one road
    ends = edges.ravel()
    edge_of_end = np.repeat(np.arange(len(pieces)), 2)
    through = degree[ends] == 2
    order = np.argsort(ends[through], kind="stable")
    pairs = edge_of_end[through][order].reshape(-1, 2)
    count, road_of_piece = connected_components(
        coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                   shape=(len(pieces), len(pieces))), directed=False)
    roads = np.array([shapely.line_merge(shapely.multilinestrings(pieces[road_of_piece == r]))
                      for r in range(count)], dtype=object)
    width = _weighted_mean(widths_m[source], lengths, road_of_piece, count)
    score = _weighted_mean(scores[source], lengths, road_of_piece, count)
    road_degree = np.bincount(road_of_piece, weights=(degree[edges] >= 3).sum(axis=1),
                              minlength=count)
    # line_merge leaves a MultiLineString only where pieces fail to share exact end points
    roads, part_of = shapely.get_parts(roads, return_index=True)
    long_enough = (road_degree[part_of] > 0) | (shapely.length(roads) >= min_length_m)
    part_of = part_of[long_enough]
    return roads[long_enough], width[part_of], score[part_of]


# --- 4. polygons --------------------------------------------------------------------------

def _partition(surface, roads) -> list:
    """The surface divided between roads by nearest centre line; one geometry per road."""
    if len(roads) == 1:
        return [surface]
    xy, owner = shapely.get_coordinates(shapely.segmentize(roads, _PARTITION_STEP_M),
                                        return_index=True)
    _, first = np.unique(np.round(xy / _EPS_M).astype(np.int64), axis=0, return_index=True)
    # Evenly spaced points on straight lines are cocircular by the dozen, and GEOS (3.14)
    # then returns self-intersecting Voronoi cells; a fixed millimetre jitter avoids that.
    jitter = np.random.default_rng(0).uniform(-1e-3, 1e-3, (len(first), 2))
    xy, owner = xy[first] + jitter, owner[first]
    cells = shapely.get_parts(shapely.get_parts(shapely.voronoi_polygons(
        shapely.multipoints(xy), extend_to=shapely.envelope(surface).buffer(1.0))))
    # GEOS may return a cell as a collection of its polygon and a degenerate line
    cells = cells[shapely.get_type_id(cells) == shapely.GeometryType.POLYGON]
    cell, point = shapely.STRtree(shapely.points(xy)).query(cells, predicate="contains")
    regions = np.array([shapely.union_all(cells[cell[owner[point] == r]])
                        for r in range(len(roads))], dtype=object)
    return list(shapely.intersection(regions, surface))


# --- the pipeline -------------------------------------------------------------------------

def _empty_network(crs, method: str, qa: dict | None) -> RoadNetwork:
    return network_from_centrelines(gpd.GeoDataFrame(
        {"width_m": []}, geometry=gpd.GeoSeries([], crs=crs), crs=crs), method=method, qa=qa)


def _pieces_to_network(lines, widths_m, scores, areas, crs, *, method: str, join_gap_m: float,
                       angle_tol_deg: float, smooth_m: float, min_length_m: float,
                       qa: dict | None) -> RoadNetwork:
    """Steps 1-4 of the module docstring on pieces with one width, score and area each."""
    lines = np.asarray(lines, dtype=object)
    areas = np.asarray(areas, dtype=object)
    usable = shapely.length(lines) > 0
    lines, widths_m, scores, areas = lines[usable], widths_m[usable], scores[usable], areas[usable]
    if len(lines) == 0:
        return _empty_network(crs, method, qa)
    chains, chain_width, chain_score, labels = _chained(
        lines, widths_m, scores, join_gap_m=join_gap_m, angle_tol_deg=angle_tol_deg)
    kept = shapely.length(chains) >= min_length_m
    if not kept.any():
        return _empty_network(crs, method, qa)
    snapped = _snap_ends(chains[kept], chain_width[kept], join_gap_m=join_gap_m,
                         angle_tol_deg=angle_tol_deg)
    roads, width, score = node_roads(snapped, chain_width[kept], chain_score[kept],
                                join_gap_m=join_gap_m, min_length_m=min_length_m)
    if len(roads) == 0:
        return _empty_network(crs, method, qa)
    road_id = np.arange(len(roads), dtype=np.int64)
    network = network_from_centrelines(gpd.GeoDataFrame(
        {"road_id": road_id, "width_m": width, "score": score, "method": method},
        geometry=gpd.GeoSeries(roads, crs=crs), crs=crs), method=method, qa=qa)
    surface = shapely.union_all(areas[kept[labels]])
    if smooth_m > 0:
        surface = shapely.buffer(shapely.buffer(surface, smooth_m), -smooth_m)
    polygons = gpd.GeoDataFrame(
        {"road_id": road_id, "width_m": width},
        geometry=gpd.GeoSeries(_partition(surface, roads), crs=crs),
        crs=crs).explode(index_parts=False)
    polygons = polygons[polygons.geom_type == "Polygon"].reset_index(drop=True)
    polygons["area_m2"] = shapely.area(polygons.geometry.values)
    network.polygons = polygons
    return network


def _no_roads(crs, method: str, qa: dict | None) -> RoadNetwork:
    """The contract layers, empty, for input without a single road piece."""
    empty = gpd.GeoDataFrame({"width_m": np.empty(0)}, geometry=gpd.GeoSeries([], crs=crs),
                             crs=crs)
    return network_from_centrelines(empty, method=method, qa=qa)


def ribbons_to_network(centrelines: gpd.GeoDataFrame, *, method: str,
                       join_gap_m: float = JOIN_GAP_M, angle_tol_deg: float = ANGLE_TOL_DEG,
                       smooth_m: float = SMOOTH_M, min_length_m: float = MIN_LENGTH_M,
                       qa: dict | None = None) -> RoadNetwork:
    """Road network from ribbons given as centre lines with widths (e.g. ribbon snakes).

    Follows the four steps of the module docstring; a ribbon's surface is a trapezoid per
    segment between its vertex widths plus a disc at each inner vertex
    (:func:`ribbon_areas`).

    Parameters
    ----------
    centrelines : GeoDataFrame
        LineStrings in a metre CRS with either ``widths_m`` (per row an array, one width per
        vertex, metres) or ``width_m`` (one width per row); ``score`` is carried to the
        roads when present. A road's width is the length-weighted mean of its ribbons'
        segment widths.
    method : str
        The ``method`` of every centre line.
    join_gap_m : float
        Metres; ends this close to another piece's centre line continue it; T-junction ends
        reach this far beyond a road's half width.
    angle_tol_deg : float
        Degrees; pieces this close in direction may continue each other, lines farther
        apart form junctions.
    smooth_m : float
        Metres; radius of the closing applied to the union of the pieces' areas.
    min_length_m : float
        Metres; shorter chains, and shorter isolated roads, are dropped.
    qa : dict of GeoDataFrame, optional
        QA layers stored beside the contract layers.

    Returns
    -------
    RoadNetwork
    """
    if len(centrelines) == 0:
        return _no_roads(centrelines.crs, method, qa)
    lines = np.asarray(centrelines.geometry.values, dtype=object)
    per_vertex = (list(centrelines["widths_m"]) if "widths_m" in centrelines
                  else list(centrelines["width_m"].to_numpy(float)))
    xy, owner, vertex_width = _vertex_widths(lines, per_vertex)
    same_line = owner[1:] == owner[:-1]
    segment_length = np.hypot(*np.diff(xy, axis=0).T)[same_line]
    segment_width = ((vertex_width[:-1] + vertex_width[1:]) / 2)[same_line]
    segment_owner = owner[1:][same_line]
    width = _weighted_mean(segment_width, segment_length, segment_owner, len(lines))
    score = (centrelines["score"].to_numpy(float) if "score" in centrelines
             else np.full(len(lines), np.nan))
    network = _pieces_to_network(lines, width, score, ribbon_areas(lines, per_vertex),
                                 centrelines.crs, method=method, join_gap_m=join_gap_m,
                                 angle_tol_deg=angle_tol_deg, smooth_m=smooth_m,
                                 min_length_m=min_length_m, qa=qa)
    if "widths_m" in centrelines:
        network.centrelines["vertex_widths_m"] = vertex_widths_text(
            network.centrelines.geometry.values, xy, vertex_width)
    return network


def vertex_widths_text(roads, ribbon_xy: np.ndarray, ribbon_width_m: np.ndarray) -> np.ndarray:
    """Per road, the width at each of its vertices as text (``"7.21,7.30,..."``, metres,
    one per vertex in order): that of the nearest ribbon vertex. A GeoPackage field holds
    one value, so a road's varying width travels as this list beside its mean ``width_m``.
    """
    if len(roads) == 0:
        return np.empty(0, dtype=object)
    xy, owner = shapely.get_coordinates(roads, return_index=True)
    _, nearest = cKDTree(ribbon_xy).query(xy)
    text = np.char.mod("%.2f", ribbon_width_m[nearest])
    starts = np.r_[0, np.flatnonzero(np.diff(owner)) + 1]
    return np.array([",".join(part) for part in np.split(text, starts[1:])], dtype=object)
