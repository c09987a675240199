"""Multi-level ground planes of an airborne point cloud (Zhu & Mordohai, section 4.1).

The paper clusters the points by x, y, z with Felzenszwalb & Huttenlocher's graph-based
segmentation [7], keeps the clusters that are planar and horizontal, groups adjacent ones into
ground surfaces and drops the small surfaces. Several surfaces may lie one above another (a
bridge deck over a road, a road on a cliff top above another): each goes on its own *level*,
and each level is projected to its own intensity image (:mod:`gisroads.lidar.intensity`).

What :func:`ground_planes` does, every step over whole arrays:

1. **Graph.** The points of every ``cell_m`` column (1 m) are sorted by height and split into
   *runs* where one point is more than ``max_step_m`` above the next. Each run is a node,
   joined to the runs just below and just above its mean height in each of the 8
   neighbouring columns (a binary search in the runs sorted by column and height) by an
   edge weighted with the difference of the mean heights. A run more than two steps tall (a
   wall, a hedge, a crown seen through) is no surface and gets no edge, so that walls and
   bushes do not chain roofs and crowns to the ground.
2. **Clusters (in the spirit of FH).** FH merges two components when the lightest edge
   between them is no heavier than the internal variation of each (plus ``k/|C|``). On the
   2.5-D surfaces of an airborne survey the internal variation of ground is point noise,
   slope and kerbs, which ``max_step_m`` bounds, so the adaptive predicate is replaced by
   that fixed one; the merge order then no longer matters and the segmentation is the
   connected components of the edges no heavier than ``max_step_m`` (one
   :func:`scipy.sparse.csgraph.connected_components` call over the runs). FH's size term
   keeps segments local; here edges are also cut at the borders of ``block_m`` blocks, which
   bounds every cluster to a block, so that planarity is judged locally (the paper gets
   "typically several thousand" clusters per 300 m tile: 5 m blocks give 3600). Cars, roofs
   and the face of a cliff are cut from the ground by their steps; crowns fall apart into
   scattered pieces.
3. **Ground clusters** (paper, section 4.1): PCA of each cluster's points, from their moments
   summed per run (:func:`numpy.add.reduceat`) and per cluster (:func:`numpy.bincount`),
   and a stacked :func:`numpy.linalg.eigh`; a cluster is ground when
   ``lambda3 / (lambda1 + lambda2 + lambda3) < t_planar``, ``|u3 . z| > t_vert`` and it
   has ``min_cluster_points`` points.
4. **Surfaces**: ground clusters joined by edges no heavier than ``max_step_m`` across
   block borders; a surface whose footprint (occupied ``cell_m`` columns) is under
   ``min_surface_area_m2`` is dropped (car roofs, building roofs, stray crown pieces).
5. **Levels.** A bridge deck is joined to the road network by its ramps, so the surfaces of
   step 4 can lie over themselves. Each surface is therefore cut into *pieces*: the ground
   that *spans* lower ground (ground at least ``min_clearance_m`` lower lies within
   ``level_radius_m`` on both sides of it along its row or its column: a deck over a road,
   the top of a ramp's embankment) and the rest, each connected. A spanning piece stands on
   another where, in two neighbouring columns (a 2 x 2 window of columns), ground of the two
   pieces lies more than ``min_clearance_m`` apart in height: at the edge of a deck, ground
   of the road below comes within a column of ground of the deck. The level of a piece is the
   length of the longest chain of pieces stacked under it (0: nothing under it), and the
   final surfaces are the connected ground within one level: the deck with the upper parts
   of its ramps is level 1, the roads under it and the lower parts of the ramps level 0.
   A cliff top or a terrace has lower ground on one side only, so it spans nothing and
   stays on level 0, even behind a vertical wall. (Nor does anything span at the border of
   the data, where one side is missing: tiles need their overlap margins.)

So ``level`` answers "which ground raster does this point go to": overlapping ground gets
different levels, and ground that overlaps nothing (a cliff top, however high) is level 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import GisroadsError
from ..progress import Progress, report

@dataclass(frozen=True)
class GroundPlanes:
    """Ground surfaces and levels of a point cloud (see the module docstring).

    Attributes
    ----------
    cluster : ndarray of int32, shape (n,)
        Graph-based cluster of every point (step 2), 0..n_clusters-1.
    surface : ndarray of int32, shape (n,)
        Ground surface of every point, -1 for points that are not ground. Surfaces are
        numbered by decreasing point count.
    level : ndarray of int16, shape (n,)
        Ground level of every point, 0..n_levels-1 (0: nothing under it), -1 off the ground.
    n_levels : int
    surfaces : pandas.DataFrame
        One row per surface, in surface order: ``surface_id``, ``level``, ``n_points``,
        ``area_m2`` (occupied ``cell_m`` columns), ``mean_z_m``.
    """

    cluster: np.ndarray
    surface: np.ndarray
    level: np.ndarray
    n_levels: int
    surfaces: pd.DataFrame


T_PLANAR = 0.01
"""Planarity threshold of a ground cell's points (Zhu & Mordohai, Table 1)."""
T_VERT = 0.98
"""Verticality threshold of a ground plane's normal (Zhu & Mordohai, Table 1)."""


def ground_planes(xyz, *, t_planar: float = T_PLANAR, t_vert: float = T_VERT,
                  max_step_m: float = 0.3, cell_m: float | None = None, block_m: float = 5.0,
                  min_cluster_points: int = 10, min_surface_area_m2: float = 1000.0,
                  min_clearance_m: float = 2.5, level_radius_m: float = 10.0,
                  progress: Progress = None) -> GroundPlanes:
    """Ground points of a cloud, grouped into surfaces on one or more levels.

    Works on the points of one tile in memory (with its overlap margin); a 500 m x 500 m tile
    at 20 points/m2 (5 M points) takes a few seconds. Steps and definitions: see the module
    docstring.

    Parameters
    ----------
    xyz : ndarray, shape (n, 3)
        Metres (x, y in a projected CRS, z up).
    t_planar : float
        A cluster is planar when ``lambda3 / (lambda1 + lambda2 + lambda3)`` is under this
        (paper section 4.1: T_planar = 0.01).
    t_vert : float
        A cluster is horizontal when ``|u3 . (0, 0, 1)|`` exceeds this (paper: T_vert = 0.98,
        slopes up to 11.5 degrees).
    max_step_m : float
        Largest height step (metres) within a surface: over a kerb (10-20 cm), not onto a car
        roof (1.4 m). Also the gap that splits a column into runs. Columns wider than 1 m
        allow the rise of a ``t_vert`` slope over a column's diagonal if that is more (at
        1 m the two agree: 1.41 m x tan 11.5 degrees = 0.29 m).
    cell_m : float, optional
        Column side, metres. By default 1 m, or more where the cloud is so sparse that a 1 m
        column holds fewer than 4 points on average.
    block_m : float
        Clusters do not reach across the borders of blocks of this side (metres; at least 3
        columns), so that planarity is judged locally.
    min_cluster_points : int
        Smaller clusters are not ground (too few points to judge).
    min_surface_area_m2 : float
        Ground surfaces with a smaller footprint (square metres) are dropped: car roofs,
        flat building roofs, stray pieces of crowns.
    min_clearance_m : float
        Height (metres) from one level to the next: ground that spans lower ground and lies
        this much above other ground in a neighbouring column stands on it.
    level_radius_m : float
        Ground spans lower ground found within this distance (metres) on both sides of it;
        decks up to twice as wide are found throughout.
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    GroundPlanes
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise GisroadsError(f"xyz must have shape (n, 3), not {xyz.shape}")
    if len(xyz) == 0:
        empty = np.empty(0, np.int32)
        return GroundPlanes(empty, empty, empty.astype(np.int16), 0,
                            _surface_table(*np.empty((4, 0))))
    if cell_m is None:
        cell_m = _default_cell_m(xyz)
    if min(max_step_m, cell_m, block_m) <= 0:
        raise GisroadsError("max_step_m, cell_m and block_m must be positive")
    step_m = max(max_step_m, np.sqrt(2.0) * cell_m * np.tan(np.arccos(t_vert)))
    report(progress, 0.0, "ground planes: column runs")
    runs = _Runs(xyz, cell_m=cell_m, step_m=step_m)
    near, far, weight = runs.edges()
    # A run taller than two steps is a wall, a hedge or a crown seen through: no surface.
    flat = runs.height_m <= 2 * step_m
    light = (weight <= step_m) & flat[near] & flat[far]

    report(progress, 0.3, "ground planes: clusters")
    block_cols = max(3, int(round(block_m / cell_m)))
    same_block = ((runs.global_col[near] // block_cols == runs.global_col[far] // block_cols)
                  & (runs.global_row[near] // block_cols == runs.global_row[far] // block_cols))
    run_cluster = _components(runs.n_runs, near[light & same_block], far[light & same_block])
    cluster = run_cluster[runs.run]

    report(progress, 0.5, "ground planes: planarity")
    ground = _planar_horizontal(runs, run_cluster, t_planar=t_planar, t_vert=t_vert,
                                min_points=min_cluster_points)[run_cluster] & flat
    joined = light & ground[near] & ground[far]
    surface = _components(runs.n_runs, near[joined], far[joined], nodes=ground)
    large = runs.footprint(surface) * cell_m ** 2 >= min_surface_area_m2
    ground[ground] = large[surface[ground]]
    joined &= ground[near] & ground[far]

    report(progress, 0.7, "ground planes: levels")
    run_level = _levels(runs, near[joined], far[joined], ground,
                        min_clearance_m=min_clearance_m,
                        radius_cells=max(1, int(np.ceil(level_radius_m / cell_m))))
    same_level = joined & (run_level[near] == run_level[far])
    run_surface = _components(runs.n_runs, near[same_level], far[same_level], nodes=ground)
    run_surface = _by_size(run_surface, runs.count)

    report(progress, 0.9, "ground planes: surfaces")
    on = run_surface >= 0
    n_surfaces = int(run_surface.max()) + 1
    n_points = np.bincount(run_surface[on], weights=runs.count[on], minlength=n_surfaces)
    surface_level = np.zeros(n_surfaces, np.int64)
    surface_level[run_surface[on]] = run_level[on]
    table = _surface_table(
        surface_level, n_points, runs.footprint(run_surface) * cell_m ** 2,
        np.bincount(run_surface[on], weights=(runs.z * runs.count)[on], minlength=n_surfaces)
        / np.maximum(n_points, 1))
    point_surface = run_surface[runs.run]
    point_level = run_level[runs.run].astype(np.int16)
    n_levels = int(point_level.max()) + 1
    report(progress, 1.0, f"ground planes: {len(table)} surfaces on {n_levels} levels")
    return GroundPlanes(cluster.astype(np.int32), point_surface.astype(np.int32), point_level,
                        n_levels, table)


def _default_cell_m(xyz: np.ndarray, *, points_per_cell: float = 4.0) -> float:
    """1 m, or the side of a square holding ``points_per_cell`` points at the cloud's mean
    density over the 10 m cells it covers, if that is more."""
    every = max(1, len(xyz) // 500_000)  # a regular sample is plenty to count 10 m cells
    coarse = np.floor((xyz[::every, :2] - xyz[:, :2].min(axis=0)) / 10.0).astype(np.int64)
    occupied = np.count_nonzero(np.bincount(coarse[:, 1] * (coarse[:, 0].max() + 1)
                                            + coarse[:, 0]))
    density_per_m2 = len(xyz) / (occupied * 100.0)
    return float(max(1.0, np.sqrt(points_per_cell / density_per_m2)))


class _Runs:
    """Points in vertical runs: in every ``cell_m`` column of a grid aligned to multiples of
    ``cell_m`` (so that tiles agree), the points sorted by height and split where one is more
    than ``step_m`` above the next. Runs are numbered in (column, height) order.

    Each run also keeps the moments of its points (count, sums of coordinates and of their
    products) about its own reference point (column corner, lowest height), from which the
    PCA of any union of runs follows without going back to the points.
    """

    def __init__(self, xyz: np.ndarray, *, cell_m: float, step_m: float):
        x, y, z = (np.ascontiguousarray(xyz[:, i]) for i in range(3))
        origin_col, origin_row = np.floor(x.min() / cell_m), np.floor(y.min() / cell_m)
        col = ((x - origin_col * cell_m) / cell_m).astype(np.int64)
        row = ((y - origin_row * cell_m) / cell_m).astype(np.int64)
        # A spare row and column, so that a neighbour's index never wraps onto another column.
        self.shape = (int(row.max()) + 2, int(col.max()) + 2)
        self.z0 = z.min()
        self.z_span = float(z.max() - self.z0) + 1.0
        column = row * self.shape[1] + col
        order = np.argsort(column * self.z_span + (z - self.z0))
        column, x, y, z = column[order], x[order], y[order], z[order]
        starts = np.ones(len(z), bool)
        starts[1:] = (column[1:] != column[:-1]) | (z[1:] - z[:-1] > step_m)
        first = np.flatnonzero(starts)
        last = np.append(first[1:], len(z)) - 1
        self.n_runs = len(first)
        self.run = np.empty(len(z), np.int64)
        self.run[order] = np.cumsum(starts) - 1
        self.count = last - first + 1
        self.column = column[first]
        row, self.col = np.divmod(self.column, self.shape[1])
        self.global_row = row + int(origin_row)
        self.global_col = self.col + int(origin_col)
        self.height_m = z[last] - z[first]
        self.reference = np.column_stack([self.global_col * cell_m, self.global_row * cell_m,
                                          z[first]])
        local = [v - np.repeat(self.reference[:, i], self.count) for i, v in enumerate((x, y, z))]
        self.sum = np.column_stack([np.add.reduceat(v, first) for v in local])
        self.z = self.reference[:, 2] + self.sum[:, 2] / self.count
        self.sum_products = np.empty((self.n_runs, 3, 3))
        for i in range(3):
            for j in range(i, 3):
                self.sum_products[:, i, j] = self.sum_products[:, j, i] = np.add.reduceat(
                    local[i] * local[j], first)

    def edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pairs of runs in 8-neighbour columns with the difference of their mean heights:
        in each neighbour column, the runs just below and just above the run's mean."""
        keys = self.column * self.z_span + (self.z - self.z0)
        near, far = [], []
        for dx, dy in ((1, 0), (-1, 1), (0, 1), (1, 1)):  # with their opposites: 8 columns
            source = np.flatnonzero(self.col + dx >= 0)
            target = self.column[source] + dy * self.shape[1] + dx
            above = np.searchsorted(keys, target * self.z_span + (self.z[source] - self.z0))
            for position in (above - 1, np.minimum(above, self.n_runs - 1)):
                found = self.column[position] == target
                near.append(source[found])
                far.append(position[found])
        near, far = np.concatenate(near), np.concatenate(far)
        return near, far, np.abs(self.z[near] - self.z[far])

    def footprint(self, label: np.ndarray) -> np.ndarray:
        """Number of distinct columns covered by each label's runs (label -1 ignored)."""
        labelled = label >= 0
        n_labels = int(label.max()) + 1 if labelled.any() else 0
        n_columns = self.shape[0] * self.shape[1]
        pairs = np.unique(label[labelled] * n_columns + self.column[labelled])
        return np.bincount(pairs // n_columns, minlength=n_labels)


def _unique_inverse(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique values and the index of each value among them (1-D on numpy 1 and 2)."""
    unique, inverse = np.unique(values, return_inverse=True)
    return unique, inverse.ravel()


def _components(n_nodes: int, a: np.ndarray, b: np.ndarray, nodes=None) -> np.ndarray:
    """Connected components of an undirected graph, numbered 0.. over ``nodes`` (a mask;
    every node by default); nodes outside the mask get -1."""
    graph = coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n_nodes, n_nodes)).tocsr()
    _, label = connected_components(graph, directed=False)
    if nodes is None:
        return label
    _, compact = _unique_inverse(label[nodes])
    out = np.full(n_nodes, -1, np.int64)
    out[nodes] = compact
    return out


def _by_size(label: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Labels renumbered by decreasing total weight (ties by old label); -1 stays -1."""
    labelled = label >= 0
    if not labelled.any():
        return label
    total = np.bincount(label[labelled], weights=weight[labelled])
    rank = np.empty(len(total), np.int64)
    rank[np.argsort(-total, kind="stable")] = np.arange(len(total))
    return np.where(labelled, rank[np.maximum(label, 0)], -1)


def _planar_horizontal(runs: _Runs, run_cluster: np.ndarray, *, t_planar: float,
                       t_vert: float, min_points: int) -> np.ndarray:
    """Which clusters pass the paper's planarity and vertical-normal tests (section 4.1)."""
    n_clusters = int(run_cluster.max()) + 1
    # Moments about one reference point per cluster (that of one of its runs), so that the
    # covariance of centimetres of noise does not drown in the squares of map coordinates.
    reference = np.empty((n_clusters, 3))
    reference[run_cluster] = runs.reference
    shift = runs.reference - reference[run_cluster]
    n = runs.count[:, None]
    run_sum = runs.sum + n * shift
    run_products = (runs.sum_products + shift[:, :, None] * runs.sum[:, None, :]
                    + runs.sum[:, :, None] * shift[:, None, :]
                    + n[:, :, None] * shift[:, :, None] * shift[:, None, :])
    count = np.bincount(run_cluster, weights=runs.count, minlength=n_clusters)
    total = np.stack([np.bincount(run_cluster, weights=run_sum[:, i], minlength=n_clusters)
                      for i in range(3)], axis=1)
    products = np.stack([np.bincount(run_cluster, weights=run_products[:, i, j],
                                     minlength=n_clusters)
                         for i in range(3) for j in range(3)], axis=1).reshape(-1, 3, 3)
    mean = total / count[:, None]
    covariance = products / count[:, None, None] - mean[:, :, None] * mean[:, None, :]
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)  # ascending: lambda3 first
    with np.errstate(invalid="ignore", divide="ignore"):
        planar = eigenvalues[:, 0] / eigenvalues.sum(axis=1) < t_planar
    vertical = np.abs(eigenvectors[:, 2, 0]) > t_vert
    return planar & vertical & (count >= max(min_points, 3))


def _levels(runs: _Runs, a: np.ndarray, b: np.ndarray, ground: np.ndarray, *,
            min_clearance_m: float, radius_cells: int) -> np.ndarray:
    """Level of every ground run (step 5 of the module docstring); -1 off the ground."""
    rows, cols = runs.shape[:2]
    level = np.full(runs.n_runs, -1, np.int64)
    if not ground.any():
        return level
    # Does each run lie min_clearance_m above the lowest ground of some column within
    # radius_cells on both sides of it, along its row or its column?
    bottom = np.full(rows * cols, np.inf)
    np.minimum.at(bottom, runs.column[ground], runs.z[ground])
    bottom = bottom.reshape(rows, cols)
    row, col = np.divmod(runs.column, cols)
    spans = np.zeros(runs.n_runs, bool)
    for axis in (0, 1):
        ahead = _min_ahead(bottom, axis, radius_cells)[row, col]
        behind = np.flip(_min_ahead(np.flip(bottom, axis), axis, radius_cells), axis)[row, col]
        spans |= (runs.z - ahead > min_clearance_m) & (runs.z - behind > min_clearance_m)
    same = spans[a] == spans[b]
    piece = _components(runs.n_runs, a[same], b[same], nodes=ground)
    n_pieces = int(piece.max()) + 1

    # Every ground run enters the four 2 x 2 windows that hold its column; in each window,
    # consecutive runs by height, of different pieces, far enough apart and the upper one
    # spanning, stack the pieces.
    members = np.flatnonzero(ground)
    window = np.concatenate([runs.column[members] - shift for shift in (0, 1, cols, cols + 1)])
    member = np.tile(members, 4)
    order = np.lexsort((runs.z[member], window))
    window, member = window[order], member[order]
    lower, upper = member[:-1], member[1:]
    stacked = ((window[:-1] == window[1:]) & (piece[lower] != piece[upper]) & spans[upper]
               & (runs.z[upper] - runs.z[lower] > min_clearance_m))
    pairs = np.unique(piece[lower[stacked]] * n_pieces + piece[upper[stacked]])
    below, above = np.divmod(pairs, n_pieces)
    # Two pieces each seen over the other (noise, or a spiral ramp) get no order.
    mutual = np.isin(above * n_pieces + below, pairs)
    below, above = below[~mutual], above[~mutual]

    piece_level = np.zeros(n_pieces, np.int64)
    for _ in range(n_pieces):  # longest chain under each piece; a handful of rounds
        raised_level = piece_level.copy()
        np.maximum.at(raised_level, above, piece_level[below] + 1)
        if np.array_equal(raised_level, piece_level):
            break
        piece_level = raised_level
    _, piece_level = _unique_inverse(piece_level)  # no empty level left by a cycle
    level[ground] = piece_level[piece[ground]]
    return level


def _min_ahead(grid: np.ndarray, axis: int, reach: int) -> np.ndarray:
    """Minimum of ``grid`` over the ``reach`` cells after each cell along ``axis`` (cells
    beyond the edge count as +inf)."""
    window = ndimage.minimum_filter1d(grid, size=reach, axis=axis, origin=-(reach // 2),
                                      mode="constant", cval=np.inf)  # cells i .. i+reach-1
    ahead = np.full_like(grid, np.inf)
    target, source = [slice(None)] * 2, [slice(None)] * 2
    target[axis], source[axis] = slice(0, -1), slice(1, None)
    ahead[tuple(target)] = window[tuple(source)]
    return ahead


def _surface_table(level, n_points, area_m2, mean_z_m) -> pd.DataFrame:
    return pd.DataFrame({"surface_id": np.arange(len(level), dtype=np.int64),
                         "level": np.asarray(level, np.int64),
                         "n_points": np.asarray(n_points, np.int64),
                         "area_m2": np.asarray(area_m2, float),
                         "mean_z_m": np.asarray(mean_z_m, float)})
