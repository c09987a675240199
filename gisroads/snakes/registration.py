"""Road map registration in 3D (Boyko & Funkhouser 2011, section 2.1).

A 2D road map (intersections joined by polylines) is lifted onto a point cloud: Cardinal
spline control vertices sit at every intersection and every 15 m along the roads, shared by
all roads meeting at an intersection; their elevations minimise the weighted squared
distance between the spline, sampled every metre, and the points within 15 cm of each
sample (weight: inverse variance of those elevations), every road of the map in one sparse
least-squares system. Each sample is then snapped to its closest point and inclines above
35 % are clamped.

Only heights are registered: the samples keep the map's horizontal positions, so a map
that is off by a few metres stays off by as much (the ribbon snakes correct that).
"""
from __future__ import annotations

from dataclasses import dataclass

import geopandas as gpd
import numpy as np
import scipy.sparse as sp
import shapely
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from ..errors import GisroadsError
from ..io.las import PointCloud
from ..progress import Progress, report
from .buckets import GridBuckets

SNAP_M = 2.0
"""Default snapping tolerance of the map's intersections (metres)."""
SUPPORT_RADIUS_M = 0.15
"""Radius of the points fitted by each sample (paper: 15 cm)."""
TENSION = 0.0
"""Cardinal spline tension c: tangents (1 - c)(z[i+1] - z[i-1]) / 2 (0: Catmull-Rom)."""
SIGMA_FLOOR_M = 0.05
"""Added to the standard deviation behind each sample's weight (metres), so that a sample
seeing one point, or two equal ones, gets a finite weight."""
LEVEL_LAYER_M = 0.3
"""Points at most this far above the lowest point near a sample make its first level
estimate (metres): returns from inside a tree crown or off a car roof lie higher."""
STEP_M = 0.25
"""Elevation step (metres) tolerated between neighbouring samples on top of the incline
limit: a 10-20 cm kerb, point noise."""
MAX_CURVATURE = 0.005
"""Sharpest bend of a road's elevation profile (1/metre, the inverse of the radius): a run
of samples between two kept ones may leave their chord by the sag of such an arc over the
gap, curvature x gap^2 / 8 (0.4 m over 25 m; a car roof rises 1.5 m within 5 m)."""
LEVEL_WINDOW_M = 0.5
"""Half height (metres) of the window around the spline in which points count for a
sample and may be snapped to: the paper's 1 m vertical window of a road's subcloud."""
REFITS = 2
"""Refits of the spline to the points within ``LEVEL_WINDOW_M`` of the previous one."""
GAP_STIFFNESS = 0.1
"""Weight of the second differences of consecutive control elevations along a road; small
next to the data (a sample weighs 10-20), it only decides controls no point constrains."""


@dataclass
class MapTopology:
    """A road map as a graph: intersections, and the roads between them.

    Attributes
    ----------
    intersections : GeoDataFrame
        Points; ``node_id``, ``degree`` (road ends meeting there; 1: a dead end).
    roads : GeoDataFrame
        LineStrings running from one intersection to another, in the map's CRS;
        ``road_id, start_node, end_node, source_row`` (position of the input line they come
        from) and the input's attributes (those named like a column of ours get ``map_``).
    """

    intersections: gpd.GeoDataFrame
    roads: gpd.GeoDataFrame


@dataclass
class RegisteredMap:
    """The map lifted onto the cloud: 3D lines and their 1 m samples.

    Attributes
    ----------
    lines : GeoDataFrame
        LineString Z per road (its samples); ``road_id, length_m, start_node, end_node,
        source_row, seen_fraction`` and the input's attributes.
    road_id : ndarray of int, shape (n,)
        Road of each sample; samples of a road are consecutive, in station order.
    station_m : ndarray, shape (n,)
        Distance of the sample along its road (metres).
    xyz : ndarray, shape (n, 3)
        Sample position (metres): the map's x, y and the registered elevation.
    tangent : ndarray, shape (n, 2)
        Unit direction of the road at the sample, in XY.
    seen : ndarray of bool, shape (n,)
        Points of the road's level lie within the support radius of the sample: its
        elevation is a snapped point's, not the spline's.
    intersections : GeoDataFrame
        The map's intersections (see :class:`MapTopology`).
    crs : pyproj.CRS or None
    """

    lines: gpd.GeoDataFrame
    road_id: np.ndarray
    station_m: np.ndarray
    xyz: np.ndarray
    tangent: np.ndarray
    seen: np.ndarray
    intersections: gpd.GeoDataFrame
    crs: object = None


# ---------------------------------------------------------------------------------------
# Topology


def _line_parts(lines: gpd.GeoDataFrame) -> tuple[list[np.ndarray], np.ndarray]:
    """2D vertex arrays of every non-degenerate LineString part, and the input row of each."""
    geoms = np.asarray(lines.geometry.values)
    if len(geoms) and not np.isin(shapely.get_type_id(geoms), (1, 5)).all():
        raise GisroadsError("the road map must hold LineString or MultiLineString geometries")
    parts, row = shapely.get_parts(geoms, return_index=True)
    coords = [shapely.get_coordinates(p) for p in parts]
    keep = [i for i, c in enumerate(coords) if len(c) >= 2 and shapely.length(parts[i]) > 0]
    return [coords[i] for i in keep], row[keep]


def _cluster(points: np.ndarray, radius_m: float) -> np.ndarray:
    """Label of each point: points chained within ``radius_m`` of each other share one."""
    pairs = cKDTree(points).query_pairs(radius_m, output_type="ndarray")
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                          shape=(len(points), len(points)))
    return connected_components(graph, directed=False)[1]


def map_topology(lines: gpd.GeoDataFrame, *, snap_m: float = SNAP_M) -> MapTopology:
    """Intersections and roads of a road map given as lines.

    Intersections are (a) line end points within ``snap_m`` of each other, merged at their
    mean position, (b) line ends within ``snap_m`` of the interior of another line (a T
    junction: the through line is split there and the ends move onto it), and (c) vertices
    two lines share exactly (within a millimetre), as crossing ways do in OpenStreetMap.
    Lines that merely cross, without a shared vertex, stay unconnected: a bridge over a
    road is no intersection. Roads are the lines split at every intersection.

    Parameters
    ----------
    lines : GeoDataFrame
        LineStrings or MultiLineStrings in a metre CRS; other columns are carried along.
    snap_m : float
        Snapping tolerance (metres) for (a) and (b).

    Returns
    -------
    MapTopology
    """
    if snap_m <= 0:
        raise GisroadsError(f"snap_m must be positive, got {snap_m}")
    parts, rows = _line_parts(lines)
    if not parts:
        raise GisroadsError("the road map holds no line")
    n = len(parts)
    ends = np.array([[c[0], c[-1]] for c in parts]).reshape(-1, 2)  # 2 per part
    label = _cluster(ends, snap_m)
    size = np.bincount(label)
    centres = np.column_stack([np.bincount(label, ends[:, 0]) / size,
                               np.bincount(label, ends[:, 1]) / size])

    # (b) T junctions: split positions per part, as (distance along, node).
    splits: list[list[tuple[float, int]]] = [[] for _ in range(n)]
    geoms = [shapely.linestrings(c) for c in parts]
    lengths = shapely.length(geoms)
    tree = shapely.STRtree(geoms)
    for k in range(len(centres)):
        point = shapely.points(centres[k])
        for j in tree.query(point, predicate="dwithin", distance=snap_m):
            at = float(shapely.line_locate_point(geoms[j], point))
            if min(at, lengths[j] - at) > snap_m:  # near an end: (a) decides
                centres[k] = shapely.get_coordinates(
                    shapely.line_interpolate_point(geoms[j], at))[0]
                splits[j].append((at, k))
    # (c) vertices shared exactly by interior vertices of two lines (ends went through b).
    interior = [c[1:-1] for c in parts]
    vertices = np.concatenate(interior)
    part_of = np.repeat(np.arange(n), [len(c) for c in interior])
    _, inverse, counts = np.unique(np.round(vertices / 1e-3).astype(np.int64), axis=0,
                                   return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    centres = list(centres)
    by_key = np.argsort(inverse, kind="stable")
    groups = np.split(by_key, np.cumsum(counts)[:-1])
    for members in (groups[key] for key in np.flatnonzero(counts > 1)):
        if len(np.unique(part_of[members])) < 2:
            continue
        at = [float(shapely.line_locate_point(geoms[part_of[v]], shapely.points(vertices[v])))
              for v in members]
        # A line end on the same vertex already made a node there (b): join it.
        known = [k for v, a in zip(members, at) for b, k in splits[part_of[v]]
                 if abs(a - b) < 1e-3]
        node = known[0] if known else len(centres)
        if not known:
            centres.append(vertices[members[0]])
        for v, a in zip(members, at):
            if not any(abs(a - b) < 1e-3 for b, _ in splits[part_of[v]]):
                splits[part_of[v]].append((a, node))
    centres = np.asarray(centres)

    pieces, start_node, end_node, source = [], [], [], []
    for j, coords in enumerate(parts):
        cuts = sorted(splits[j], key=lambda s: s[0])
        nodes = [label[2 * j]] + [k for _, k in cuts] + [label[2 * j + 1]]
        stations = [0.0] + [a for a, _ in cuts] + [lengths[j]]
        along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
        for a, b, na, nb in zip(stations[:-1], stations[1:], nodes[:-1], nodes[1:]):
            inside = coords[(along > a + 1e-9) & (along < b - 1e-9)]
            piece = shapely.linestrings(np.vstack([centres[na], inside, centres[nb]]))
            if shapely.length(piece) < 1e-6:
                continue
            pieces.append(piece)
            start_node.append(na)
            end_node.append(nb)
            source.append(rows[j])

    used, node_index = np.unique(np.concatenate([start_node, end_node]), return_inverse=True)
    start_node, end_node = np.split(node_index.ravel(), 2)
    degree = np.bincount(node_index.ravel(), minlength=len(used))
    intersections = gpd.GeoDataFrame(
        {"node_id": np.arange(len(used), dtype=np.int64), "degree": degree.astype(np.int64)},
        geometry=shapely.points(centres[used]), crs=lines.crs)
    attributes = lines.drop(columns=lines.geometry.name).iloc[source].reset_index(drop=True)
    ours = {"road_id", "start_node", "end_node", "source_row", "length_m", "seen_fraction"}
    attributes = attributes.rename(columns={c: f"map_{c}" for c in attributes if c in ours})
    roads = gpd.GeoDataFrame(
        {"road_id": np.arange(len(pieces), dtype=np.int64),
         "start_node": start_node.astype(np.int64), "end_node": end_node.astype(np.int64),
         "source_row": np.asarray(source, np.int64), **attributes.to_dict("series")},
        geometry=pieces, crs=lines.crs)
    return MapTopology(intersections, roads)


# ---------------------------------------------------------------------------------------
# Spline sampling


@dataclass
class _Samples:
    road_id: np.ndarray
    station_m: np.ndarray
    xy: np.ndarray
    tangent: np.ndarray
    basis: sp.csr_matrix       # samples x controls: the spline's value at each sample
    smoothness: sp.csr_matrix  # second differences of consecutive controls along each road


def _sample_roads(topology: MapTopology, control_spacing_m: float,
                  sample_spacing_m: float) -> _Samples:
    """Samples of every road and the Cardinal spline weights of the control elevations.

    Road r has k_r >= 2 evenly spaced controls, the first and last being its intersections'
    (shared with the other roads there), the others its own, numbered after the
    intersections. On the span between controls i and i + 1 the spline is the Hermite
    cubic h00 z_i + h10 m_i + h01 z_(i+1) + h11 m_(i+1), with the Cardinal tangents
    m_j = (1 - c)(z_(j+1) - z_(j-1)) / 2 per control step (one-sided at the road's ends).
    """
    roads = topology.roads
    geoms = np.asarray(roads.geometry.values)  # plain shapely objects: fast ufuncs
    start, end = roads["start_node"].to_numpy(), roads["end_node"].to_numpy()
    length = shapely.length(geoms)
    k = np.maximum(2, np.round(length / control_spacing_m).astype(np.int64) + 1)
    m = np.maximum(2, np.ceil(length / sample_spacing_m).astype(np.int64) + 1)
    first_interior = len(topology.intersections) + np.concatenate([[0], np.cumsum(k - 2)[:-1]])
    n_controls = int(len(topology.intersections) + (k - 2).sum())

    def control(r, j):
        """Global index of control ``j`` of road ``r``."""
        return np.where(j == 0, start[r], np.where(j == k[r] - 1, end[r],
                                                   first_interior[r] + j - 1))

    road = np.repeat(np.arange(len(roads)), m)
    local = np.arange(int(m.sum())) - np.repeat(np.cumsum(m) - m, m)
    station = local / (m[road] - 1) * length[road]
    xy = shapely.get_coordinates(shapely.line_interpolate_point(geoms[road], station))
    before = np.where(local == 0, 0, -1) + np.arange(len(road))
    after = np.where(local == m[road] - 1, 0, 1) + np.arange(len(road))
    direction = xy[after] - xy[before]
    tangent = direction / np.maximum(np.hypot(*direction.T), 1e-12)[:, None]

    kr = k[road]
    t = station / length[road] * (kr - 1)
    i = np.minimum(t.astype(np.int64), kr - 2)
    u = t - i
    h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
    h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
    columns, weights = [control(road, i), control(road, i + 1)], [h00, h01]
    for j, h in ((i, h10), (i + 1, h11)):
        lo, hi = np.maximum(j - 1, 0), np.minimum(j + 1, kr - 1)
        slope = (1.0 - TENSION) * h / (hi - lo)
        columns += [control(road, hi), control(road, lo)]
        weights += [slope, -slope]
    rows = np.tile(np.arange(len(road)), len(columns))
    basis = sp.csr_matrix((np.concatenate(weights), (rows, np.concatenate(columns))),
                          shape=(len(road), n_controls))

    bent = np.repeat(np.arange(len(roads)), k - 2)  # one row per interior control
    j = np.arange(int((k - 2).sum())) - np.repeat(np.cumsum(k - 2) - (k - 2), k - 2) + 1
    smooth_columns = np.concatenate([control(bent, j - 1), control(bent, j),
                                     control(bent, j + 1)])
    smooth_weights = np.repeat([1.0, -2.0, 1.0], len(bent))
    smoothness = sp.csr_matrix((smooth_weights, (np.tile(np.arange(len(bent)), 3),
                                                 smooth_columns)),
                               shape=(len(bent), n_controls))
    return _Samples(roads["road_id"].to_numpy()[road], station, xy, tangent, basis,
                    smoothness)


# ---------------------------------------------------------------------------------------
# Registration


def _neighbours(points_xy: np.ndarray, xy: np.ndarray,
                radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(sample, point) pairs with the point within ``radius_m`` of the sample in XY."""
    pairs = cKDTree(xy).sparse_distance_matrix(cKDTree(points_xy), radius_m,
                                               output_type="ndarray")
    return pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)


def _stats(sample: np.ndarray, z: np.ndarray, n: int):
    """Count, mean and variance of the elevations of each sample's points."""
    count = np.bincount(sample, minlength=n).astype(float)
    total = np.bincount(sample, z, minlength=n)
    mean = np.divide(total, count, out=np.full(n, np.nan), where=count > 0)
    square = np.bincount(sample, (z - np.nan_to_num(mean)[sample]) ** 2, minlength=n)
    var = np.divide(square, count, out=np.zeros(n), where=count > 0)
    return count, mean, var


def _continuous(road_id, station, z, max_incline: float) -> np.ndarray:
    """Which samples with a level estimate ``z`` (NaN: none) lie on their road's level.

    Along each road the samples fall into runs whose consecutive elevations change by at
    most ``max_incline`` per metre (plus ``STEP_M``). The longest run is the road; other
    runs are considered longest first: one between kept samples must follow their chord
    (within ``STEP_M`` plus the sag of a ``MAX_CURVATURE`` arc), one beyond them must
    continue them within the incline limit. A deck above a road, a car roof or a tree crown
    makes a short run that jumps up and down again: it is dropped.
    """
    keep = np.zeros(len(z), bool)
    for samples in np.split(np.arange(len(z)), np.flatnonzero(np.diff(road_id)) + 1):
        idx = samples[np.isfinite(z[samples])]  # the road's samples seeing points
        if len(idx) == 0:
            continue
        s, h = station[idx], z[idx]
        # A run breaks at any step the incline limit forbids over one metre, however long
        # the unseen gap: the tests below decide whether the pieces join again.
        breaks = np.abs(np.diff(h)) > max_incline * np.minimum(np.diff(s), 1.0) + STEP_M
        run = np.concatenate([[0], np.cumsum(breaks)])
        first = np.flatnonzero(np.concatenate([[True], breaks]))
        last = np.concatenate([first[1:] - 1, [len(idx) - 1]])
        kept: list[int] = []
        for r in np.argsort(-(s[last] - s[first]), kind="stable"):
            before = [last[q] for q in kept if last[q] < first[r]]
            after = [first[q] for q in kept if first[q] > last[r]]
            a, b = (max(before) if before else None), (min(after) if after else None)
            if a is not None and b is not None:
                # Between kept samples on both sides: the run must follow their chord.
                chord = np.interp(s[first[r]:last[r] + 1], [s[a], s[b]], [h[a], h[b]])
                fits = (np.abs(h[first[r]:last[r] + 1] - chord).max()
                        <= STEP_M + MAX_CURVATURE * (s[b] - s[a]) ** 2 / 8)
            elif a is not None:
                fits = abs(h[first[r]] - h[a]) <= max_incline * (s[first[r]] - s[a]) + STEP_M
            elif b is not None:
                fits = abs(h[b] - h[last[r]]) <= max_incline * (s[b] - s[last[r]]) + STEP_M
            else:
                fits = True
            if fits:
                kept.append(r)
        keep[idx[np.isin(run, kept)]] = True
    return keep


def _solve(samples: _Samples, count, mean, var) -> np.ndarray:
    """Control elevations minimising sum_s w(s) sum_p (s_z - p_z)^2 (eq. 1), w = 1/var."""
    used = count > 0
    reference = float(np.median(mean[used])) if used.any() else 0.0
    weight = np.sqrt(count[used] / (var[used] + SIGMA_FLOOR_M**2))
    data = sp.diags(weight) @ samples.basis[used]
    system = sp.vstack([data, GAP_STIFFNESS * samples.smoothness]).tocsr()
    rhs = np.concatenate([weight * (mean[used] - reference),
                          np.zeros(samples.smoothness.shape[0])])
    n = system.shape[1]
    normal = (system.T @ system + 1e-9 * sp.identity(n)).tocsc()
    return reference + spsolve(normal, system.T @ rhs)


def _clamp_inclines(road_id, station, z, max_incline: float) -> np.ndarray:
    """Visit the samples of each road in order and limit each step to ``max_incline``."""
    z = z.copy()
    # One pass over the samples (1 per metre of road), not over points.
    zs, ss, rs = z.tolist(), station.tolist(), road_id.tolist()
    for i in range(1, len(zs)):
        if rs[i] == rs[i - 1]:
            limit = max_incline * (ss[i] - ss[i - 1])
            zs[i] = min(max(zs[i], zs[i - 1] - limit), zs[i - 1] + limit)
    return np.asarray(zs)


def register_map(lines: gpd.GeoDataFrame, cloud: PointCloud, *, control_spacing_m: float = 15.0,
                 sample_spacing_m: float = 1.0, support_radius_m: float = SUPPORT_RADIUS_M,
                 max_incline: float = 0.35, snap_m: float = SNAP_M,
                 progress: Progress = None) -> RegisteredMap:
    """Register a 2D road map onto a point cloud: 3D centre lines on the road surface.

    Section 2.1 of Boyko & Funkhouser: Cardinal spline control vertices at the map's
    intersections (shared by the roads meeting there) and every ``control_spacing_m``
    along its roads; samples every ``sample_spacing_m``; the control elevations minimise
    E(V) = sum_s w(s) sum_{p in N(s)} (s_z - p_z)^2 (eq. 1), N(s) the points within
    ``support_radius_m`` of s in XY and w(s) the inverse variance of their elevations, all
    roads in one sparse least-squares system; each sample is snapped to the elevation of
    its closest point, then inclines above ``max_incline`` are clamped.

    Levels (a bridge deck over a road, tree crowns, car roofs): the points near a sample
    can belong to several levels, and the deck hides the road under it completely. As in
    the paper, spline and neighbour continuity decide. (1) Each sample first takes the
    lowest layer of its points (within 0.3 m of the lowest), which removes crown returns
    above a visible ground. (2) Along each road, runs of samples that follow each other
    within the incline limit are formed; the longest run is the road, and other runs are
    kept only if they continue it within the incline limit over the gap: the deck seen from
    the road under it rises 6-8 m within a metre and back, so its samples are dropped.
    (3) The spline is solved on the kept samples, then again with the points within
    +-0.5 m of it (the paper's subcloud window), and a sample is snapped only to a point
    in that window. Under the deck no point is in the window: those samples keep the
    spline's elevation, interpolated from the road on both sides, and are not ``seen``.
    The deck road itself climbs on ramps within the incline limit and stays one run.

    Departures from the paper, and why: the map's 2D polylines are kept as they are (the
    spline is fitted to elevations along them, so horizontal errors stay for the snakes to
    fix); a weak second-difference term between consecutive controls decides the controls
    no point constrains (a gap in the data; a road without any point near its samples takes
    the median elevation of the map's points); and the incline clamp limits the step to the
    incline instead of copying the preceding sample, so one stray point cannot flatten the
    rest of a ramp.

    Parameters
    ----------
    lines : GeoDataFrame
        Road map lines in the cloud's metre CRS (see :func:`map_topology`).
    cloud : PointCloud
        Points in metres.
    control_spacing_m : float
        Spacing of the spline control vertices along the roads (paper: 15 m).
    sample_spacing_m : float
        Spacing of the spline samples (paper: 1 m).
    support_radius_m : float
        Horizontal radius of N(s), the points fitted by each sample (paper: 15 cm).
        An airborne cloud of a few points per square metre sees one point in one sample
        out of two or three at 15 cm; the spline interpolates the rest.
    max_incline : float
        Largest incline (rise over run) of a road (paper: 35 %).
    snap_m : float
        Snapping tolerance of the map's intersections (see :func:`map_topology`).
    progress : callable, optional

    Returns
    -------
    RegisteredMap
    """
    for name, value in (("control_spacing_m", control_spacing_m),
                        ("sample_spacing_m", sample_spacing_m),
                        ("support_radius_m", support_radius_m), ("max_incline", max_incline)):
        if not value > 0:
            raise GisroadsError(f"{name} must be positive, got {value}")
    if len(cloud) == 0:
        raise GisroadsError("the point cloud holds no point")
    report(progress, 0.0, "building the map topology")
    topology = map_topology(lines, snap_m=snap_m)
    samples = _sample_roads(topology, control_spacing_m, sample_spacing_m)
    n = len(samples.station_m)
    report(progress, 0.1, f"finding the points near {n} samples")
    # Only the points in the grid cells around the samples go into the k-d tree.
    near = np.flatnonzero(GridBuckets(samples.xy, np.zeros(n, np.int64), support_radius_m)
                          .in_corridor(cloud.xyz[:, :2]))
    sample, point = _neighbours(cloud.xyz[near, :2], samples.xy, support_radius_m)
    point = near[point]
    if len(point) == 0:
        raise GisroadsError(f"no point lies within {support_radius_m} m of the map's samples; "
                            "does the map cover the cloud (same CRS)?")
    z = cloud.xyz[point, 2]

    report(progress, 0.4, "separating levels")
    lowest = np.full(n, np.inf)
    np.minimum.at(lowest, sample, z)
    layer = z <= lowest[sample] + LEVEL_LAYER_M
    count, mean, var = _stats(sample[layer], z[layer], n)
    level = np.where(count > 0, mean, np.nan)
    kept = _continuous(samples.road_id, samples.station_m, level, max_incline)

    report(progress, 0.6, "solving the control elevations")
    controls = _solve(samples, np.where(kept, count, 0), mean, var)
    spline_z = samples.basis @ controls
    for _ in range(REFITS):
        in_window = np.abs(z - spline_z[sample]) <= LEVEL_WINDOW_M
        count, mean, var = _stats(sample[in_window], z[in_window], n)
        if not (count > 0).any():
            break
        controls = _solve(samples, count, mean, var)
        spline_z = samples.basis @ controls

    report(progress, 0.85, "snapping the samples")
    gap = np.abs(z - spline_z[sample])
    in_window = gap <= LEVEL_WINDOW_M
    distance = np.hypot(np.hypot(*(cloud.xyz[point, :2] - samples.xy[sample]).T), gap)
    distance[~in_window] = np.inf
    order = np.lexsort((distance, sample))
    first = order[np.concatenate([[True], np.diff(sample[order]) != 0])] if len(order) else order
    first = first[np.isfinite(distance[first])]
    seen = np.zeros(n, bool)
    seen[sample[first]] = True
    elevation = spline_z.copy()
    elevation[sample[first]] = z[first]
    elevation = _clamp_inclines(samples.road_id, samples.station_m, elevation, max_incline)

    xyz = np.column_stack([samples.xy, elevation])
    bounds = np.flatnonzero(np.diff(samples.road_id)) + 1
    geoms = [shapely.linestrings(part) for part in np.split(xyz, bounds)]
    seen_fraction = np.array([s.mean() for s in np.split(seen, bounds)])
    roads = topology.roads
    out = gpd.GeoDataFrame(
        {"road_id": roads["road_id"].to_numpy(),
         "length_m": shapely.length(roads.geometry.values),
         "seen_fraction": seen_fraction,
         **roads.drop(columns=[roads.geometry.name, "road_id"]).to_dict("series")},
        geometry=geoms, crs=lines.crs)
    report(progress, 1.0, f"{len(out)} roads registered")
    return RegisteredMap(out, samples.road_id, samples.station_m, xyz, samples.tangent, seen,
                         topology.intersections, lines.crs)
