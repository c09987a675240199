"""Subclouds per road patch (Boyko & Funkhouser 2011, section 2.2).

Every road of a registered map (the spline between two intersections) gets the points of
its own level around it: a support plane is fitted at each 1 m sample to the points within
4 m, and the subcloud keeps the points within 0.5 m of that plane and 22 m of the sample.
Points on a bridge deck and on the road under it lie metres apart vertically, so they fall
into different subclouds.

The cloud is read chunk by chunk through a grid of buckets over the map's corridor (the
paper's out-of-core 2D grid index), so a file larger than memory works: only the
subclouds are held.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import GisroadsError
from ..io.las import DEFAULT_CHUNK
from ..progress import Progress, report
from .buckets import GridBuckets, iter_indexed, read_corridor, source_size
from .registration import RegisteredMap

__all__ = ["RoadPatch", "road_patches", "read_corridor"]

MIN_PLANE_POINTS = 10
"""Fewest points a support plane is fitted to; with fewer the prior plane stands."""
MIN_PLANE_SPREAD_M = 0.5
"""Smallest horizontal spread (standard deviation across the points' main axis, metres)
of the points a plane is fitted to: points along a line do not fix a plane."""


@dataclass
class RoadPatch:
    """One road of the map and the points of its subcloud.

    Attributes
    ----------
    road_id : int
        ``road_id`` of the registered map's line.
    samples_xyz : ndarray, shape (k, 3)
        The road's registered samples (metres).
    tangent : ndarray, shape (k, 2)
        Unit XY direction of the road at each sample.
    plane_normal : ndarray, shape (k, 3)
        Unit upward normal of the support plane at each sample.
    plane_z : ndarray, shape (k,)
        Elevation of the support plane at the sample's XY (metres).
    points : ndarray, shape (m, 3)
        The subcloud (metres).
    intensity : ndarray of uint16, shape (m,)
        Zero where the source records none.
    sample_index : ndarray of int, shape (m,)
        Nearest sample of each point (index into ``samples_xyz``).
    point_index : ndarray of int64, shape (m,)
        Position of each point in the source (the cloud's order, or the file's point
        order), so that a later stage can classify them.
    """

    road_id: int
    samples_xyz: np.ndarray
    tangent: np.ndarray
    plane_normal: np.ndarray
    plane_z: np.ndarray
    points: np.ndarray
    intensity: np.ndarray
    sample_index: np.ndarray
    point_index: np.ndarray


def _grades(registered: RegisteredMap) -> np.ndarray:
    """Along-road grade (rise over run) at each sample, from the registered elevations."""
    grade = np.zeros(len(registered.station_m))
    bounds = np.flatnonzero(np.diff(registered.road_id)) + 1
    for idx in np.split(np.arange(len(grade)), bounds):
        if len(idx) >= 2:
            grade[idx] = np.gradient(registered.xyz[idx, 2], registered.station_m[idx])
    return grade


def _fit_planes(moments: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """Least-squares planes dz = a + b dx + c dy from summed moments (n, 9) per sample;
    the prior (a, b, c) where the points are too few or too narrow."""
    n, sx, sy, sxx, sxy, syy, sz, sxz, syz = moments.T
    normal = np.stack([np.stack([n, sx, sy], -1), np.stack([sx, sxx, sxy], -1),
                       np.stack([sy, sxy, syy], -1)], -2)
    with np.errstate(invalid="ignore", divide="ignore"):
        vx, vy = sxx / n - (sx / n) ** 2, syy / n - (sy / n) ** 2
        cxy = sxy / n - sx * sy / n**2
        spread = (vx + vy) / 2 - np.sqrt(((vx - vy) / 2) ** 2 + cxy**2)
    good = (n >= MIN_PLANE_POINTS) & (spread >= MIN_PLANE_SPREAD_M**2)
    planes = prior.copy()
    if good.any():
        rhs = np.stack([sz, sxz, syz], -1)[good][..., None]
        planes[good] = np.linalg.solve(normal[good], rhs)[..., 0]
    return planes


def road_patches(registered: RegisteredMap, source, *, plane_radius_m: float = 4.0,
                 plane_tolerance_m: float = 0.5, reach_m: float = 22.0,
                 chunk_size: int = DEFAULT_CHUNK, progress: Progress = None
                 ) -> list[RoadPatch]:
    """Subclouds of the roads of a registered map (section 2.2 of Boyko & Funkhouser).

    1. At each sample s, a support plane P(s) is fitted by least squares to the points
       within ``plane_radius_m`` of s (XY) that lie within ``plane_tolerance_m`` of the
       prior plane through s rising with the road's registered grade: the prior keeps the
       deck out of the plane of the road under it, and the road out of the deck's.
       Where fewer than ten points, or points along a line only, are found, the prior
       stands.
    2. A point joins the subcloud of a road when it lies within ``reach_m`` of the
       road's nearest sample s and within ``plane_tolerance_m`` of P(s). The paper merges
       the working sets of all the samples within reach; testing the nearest sample's
       plane only keeps a point under a deck out of the deck road's subcloud even where
       a ramp sample farther away passes at the point's height.

    The source is read twice (planes, then subclouds), chunk by chunk; a chunk's points
    are looked up through a grid of ``reach_m`` buckets over the roads' corridors.

    Parameters
    ----------
    registered : RegisteredMap
        From :func:`gisroads.snakes.registration.register_map`, in the source's CRS.
    source : PointCloud, path or TileStore
        The cloud, a LAS/LAZ file read through :func:`gisroads.io.las.iter_las_chunks`, or
        the tile store of the LiDAR pipeline (:func:`gisroads.tiling.tilestore.open_store`),
        of which only the cells along the map are read.
    plane_radius_m : float
        Radius of the support plane's points (paper: 4 m).
    plane_tolerance_m : float
        Half height of the subcloud's window around the plane (paper: 0.5 m).
    reach_m : float
        Horizontal reach of a sample (paper: 22 m, six 3.66 m lanes).
    chunk_size : int
        Points read at a time.
    progress : callable, optional

    Returns
    -------
    list of RoadPatch
        One per road, in the order of ``registered.lines``.
    """
    for name, value in (("plane_radius_m", plane_radius_m),
                        ("plane_tolerance_m", plane_tolerance_m), ("reach_m", reach_m)):
        if not value > 0:
            raise GisroadsError(f"{name} must be positive, got {value}")
    xyz, tangent, road_of = registered.xyz, registered.tangent, registered.road_id
    n = len(xyz)
    total = source_size(source)
    grade = _grades(registered)
    prior = np.column_stack([np.zeros(n), grade * tangent[:, 0], grade * tangent[:, 1]])
    index = GridBuckets(xyz[:, :2], road_of, reach_m)
    plane_index = GridBuckets(xyz[:, :2], np.zeros(n, np.int64), plane_radius_m)
    sample_tree = cKDTree(xyz[:, :2])

    report(progress, 0.0, "fitting the support planes")
    moments = np.zeros((n, 9))
    read = 0
    for _, chunk in iter_indexed(source, chunk_size=chunk_size,
                                 near=(xyz[:, :2], plane_radius_m)):
        read += len(chunk)
        report(progress, 0.5 * read / total, f"support planes: {read} of {total} points read")
        candidate = chunk.xyz[plane_index.in_corridor(chunk.xyz[:, :2])]
        if len(candidate) == 0:
            continue
        pairs = sample_tree.sparse_distance_matrix(cKDTree(candidate[:, :2]), plane_radius_m,
                                                   output_type="ndarray")
        s, p = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
        dx, dy = (candidate[p, :2] - xyz[s, :2]).T
        dz = candidate[p, 2] - xyz[s, 2]
        near = np.abs(dz - prior[s, 1] * dx - prior[s, 2] * dy) <= plane_tolerance_m
        s, dx, dy, dz = s[near], dx[near], dy[near], dz[near]
        for k, w in enumerate((None, dx, dy, dx * dx, dx * dy, dy * dy, dz, dx * dz, dy * dz)):
            moments[:, k] += np.bincount(s, w, minlength=n)
    planes = _fit_planes(moments, prior)
    normal = np.column_stack([-planes[:, 1], -planes[:, 2], np.ones(n)])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)

    report(progress, 0.5, "extracting the subclouds")
    roads = registered.lines["road_id"].to_numpy()
    bounds = np.flatnonzero(np.diff(road_of)) + 1
    spans = dict(zip(road_of[np.concatenate([[0], bounds])].tolist(),
                     np.split(np.arange(n), bounds)))  # each road's samples
    trees = {r: cKDTree(xyz[span, :2]) for r, span in spans.items()}
    found: dict[int, list] = {int(r): [] for r in roads}
    read = 0
    for position, chunk in iter_indexed(source, chunk_size=chunk_size, near=(xyz[:, :2], reach_m)):
        read += len(chunk)
        report(progress, 0.5 + 0.5 * read / total, f"subclouds: {read} of {total} points read")
        keys = index.keys(chunk.xyz[:, :2])
        order = np.argsort(keys, kind="stable")
        sorted_keys = keys[order]
        intensity = (chunk.intensity if chunk.intensity is not None
                     else np.zeros(len(chunk), np.uint16))
        for r in found:
            local = order[index.members(sorted_keys, r)]
            if len(local) == 0:
                continue
            distance, nearest = trees[r].query(chunk.xyz[local, :2], distance_upper_bound=reach_m)
            hit = np.isfinite(distance)
            local, nearest = local[hit], nearest[hit]
            s = spans[r][nearest]
            dx, dy = (chunk.xyz[local, :2] - xyz[s, :2]).T
            residual = chunk.xyz[local, 2] - xyz[s, 2] - (planes[s, 0] + planes[s, 1] * dx
                                                          + planes[s, 2] * dy)
            keep = np.abs(residual) <= plane_tolerance_m
            local, nearest = local[keep], nearest[keep]
            found[r].append((chunk.xyz[local], intensity[local], nearest, position[local]))

    none = (np.empty((0, 3)), np.empty(0, np.uint16), np.empty(0, np.int64),
            np.empty(0, np.int64))
    patches = []
    for r in roads:
        points, intensity, nearest, point_index = (
            np.concatenate(column) for column in zip(*(found[int(r)] or [none])))
        order = np.argsort(point_index, kind="stable")  # the source's order
        s = spans[int(r)]
        patches.append(RoadPatch(
            road_id=int(r), samples_xyz=xyz[s], tangent=tangent[s], plane_normal=normal[s],
            plane_z=xyz[s, 2] + planes[s, 0], points=points[order],
            intensity=intensity[order].astype(np.uint16),
            sample_index=nearest[order].astype(np.int64),
            point_index=point_index[order].astype(np.int64)))
    report(progress, 1.0, f"{len(patches)} subclouds, "
                          f"{sum(len(p.points) for p in patches)} points")
    return patches
