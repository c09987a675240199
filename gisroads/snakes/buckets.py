"""Grid buckets over a map's corridor: the points of a cloud near a road map, chunk by chunk.

The paper's out-of-core spatial index stores the points in blocks of a regular 2D grid;
here a chunk's points are hashed to the cells of such a grid, and only the cells near the
map's samples are kept, so a file of any size is streamed through a small working set.
"""
from __future__ import annotations

from pathlib import Path
from collections.abc import Iterator

import numpy as np
from scipy.spatial import cKDTree

from ..errors import GisroadsError
from ..io.las import DEFAULT_CHUNK, PointCloud, concatenate, iter_las_chunks, subset


def iter_source(source, *, chunk_size: int = DEFAULT_CHUNK) -> Iterator[tuple[int, PointCloud]]:
    """``(offset of the chunk's first point, chunk)`` of a PointCloud or a LAS/LAZ path."""
    if chunk_size <= 0:
        raise GisroadsError(f"chunk_size must be positive, got {chunk_size}")
    if isinstance(source, PointCloud):
        for start in range(0, len(source), chunk_size):
            yield start, subset(source, slice(start, start + chunk_size))
        return
    if not isinstance(source, (str, Path)):
        raise GisroadsError("source must be a PointCloud or a LAS/LAZ path, got "
                            f"{type(source)}")
    offset = 0
    for chunk in iter_las_chunks(source, chunk_size=chunk_size):
        yield offset, chunk
        offset += len(chunk)


def iter_indexed(source, *, chunk_size: int = DEFAULT_CHUNK, near=None
                 ) -> Iterator[tuple[np.ndarray, PointCloud]]:
    """``(position of each point in the source, chunk)`` of a PointCloud, a LAS/LAZ path or
    a :class:`gisroads.tiling.tilestore.TileStore` (the LiDAR pipeline's points bucketed by
    tile on disk: one stored cell at a time).

    ``near=(xy, reach_m)`` lets a tile store read only its cells within ``reach_m`` of the
    positions ``xy``; a file or a cloud is read whole (callers filter the points anyway).
    """
    from ..tiling.tilestore import TileStore

    if isinstance(source, TileStore):
        yield from source.iter_cells(None if near is None else source.cells_near(*near))
        return
    for offset, chunk in iter_source(source, chunk_size=chunk_size):
        yield np.arange(offset, offset + len(chunk), dtype=np.int64), chunk


def source_size(source) -> int:
    """Points of a PointCloud, a LAS/LAZ path or a tile store (1 when unknown)."""
    from ..io.las import las_info
    from ..tiling.tilestore import TileStore

    if isinstance(source, PointCloud):
        return max(len(source), 1)
    if isinstance(source, TileStore):
        return max(source.point_count, 1)
    if isinstance(source, (str, Path)):
        return max(las_info(source)["point_count"], 1)
    return 1


def _sorted_unique(values: np.ndarray) -> np.ndarray:
    """Distinct values, ascending (by a sort: numpy 2's hashing np.unique is far slower on
    millions of cell keys)."""
    values = np.sort(values)
    return values[np.concatenate([[True], values[1:] != values[:-1]])]


class GridBuckets:
    """Square grid cells around groups of sample points, to fetch a chunk's nearby points.

    Parameters
    ----------
    xy : ndarray, shape (n, 2)
        Sample positions (metres).
    group : ndarray of int, shape (n,)
        Group (road) of each sample.
    reach_m : float
        Points within this distance of a group's samples are in its cells: the cell side,
        and one ring of cells is added around each sample's cell.
    """

    def __init__(self, xy: np.ndarray, group: np.ndarray, reach_m: float):
        self.cell_m = float(reach_m)
        cells = np.floor(np.asarray(xy) / self.cell_m).astype(np.int64)
        ring = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)])
        near = (cells[:, None, :] + ring[None]).reshape(-1, 2)
        keys = self._key(near)
        groups = np.repeat(np.asarray(group), len(ring))
        order = np.lexsort((keys, groups))
        keys, groups = keys[order], groups[order]
        first = np.concatenate([[True], (keys[1:] != keys[:-1]) | (groups[1:] != groups[:-1])])
        keys, groups = keys[first], groups[first]
        bounds = np.flatnonzero(np.diff(groups)) + 1
        self.cells = {int(g[0]): k for g, k in zip(np.split(groups, bounds),
                                                    np.split(keys, bounds))}
        self.corridor = _sorted_unique(keys)

    @staticmethod
    def _key(cells: np.ndarray) -> np.ndarray:
        return (cells[:, 0] << 32) + (cells[:, 1] & 0xFFFFFFFF)

    def keys(self, xy: np.ndarray) -> np.ndarray:
        """Cell key of each point."""
        return self._key(np.floor(xy / self.cell_m).astype(np.int64))

    def in_corridor(self, xy: np.ndarray) -> np.ndarray:
        """Which points fall in any group's cells."""
        keys = self.keys(xy)
        order = np.argsort(keys)  # searching sorted keys is ten times faster
        at = np.minimum(np.searchsorted(self.corridor, keys[order]), len(self.corridor) - 1)
        inside = np.empty(len(keys), bool)
        inside[order] = self.corridor[at] == keys[order]
        return inside

    def members(self, sorted_keys: np.ndarray, group: int) -> np.ndarray:
        """Positions, in an array of point keys sorted ascending, of the group's points."""
        cells = self.cells[group]
        lo = np.searchsorted(sorted_keys, cells, "left")
        hi = np.searchsorted(sorted_keys, cells, "right")
        lengths = hi - lo
        starts = np.repeat(lo - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
        return starts + np.arange(int(lengths.sum()))


def read_corridor(source, xy: np.ndarray, radius_m: float, *,
                  chunk_size: int = DEFAULT_CHUNK) -> tuple[PointCloud, np.ndarray]:
    """The points of a source within ``radius_m`` (XY) of any of the positions ``xy``.

    Returns
    -------
    cloud : PointCloud
    point_index : ndarray of int64
        Position of each point in the source.
    """
    xy = np.asarray(xy, float)
    index = GridBuckets(xy, np.zeros(len(xy), np.int64), radius_m)
    tree = cKDTree(xy)
    parts, indices = [], []
    for position, chunk in iter_indexed(source, chunk_size=chunk_size, near=(xy, radius_m)):
        candidate = np.flatnonzero(index.in_corridor(chunk.xyz[:, :2]))
        distance, _ = tree.query(chunk.xyz[candidate, :2], distance_upper_bound=radius_m)
        keep = candidate[np.isfinite(distance)]
        parts.append(subset(chunk, keep))
        indices.append(position[keep])
    if not parts:  # a tile store without a cell near the positions
        empty = np.empty(0, np.uint8)
        crs = getattr(source, "crs", (None, None))
        return PointCloud(np.empty((0, 3)), np.empty(0, np.uint16), empty, empty, empty,
                          crs=crs[0], source_crs=crs[1]), np.empty(0, np.int64)
    cloud, indices = concatenate(parts), np.concatenate(indices).astype(np.int64)
    order = np.argsort(indices, kind="stable")  # the source's order
    return subset(cloud, order), indices[order]
