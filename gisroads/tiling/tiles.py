"""Overlapping tiles as independent units of work, and stitching their roads back together.

Zhu & Mordohai (section 3) process 300 m x 300 m tiles that overlap their neighbours by 100 m
and trust only each tile's centre. Here a tile's *core* is the tile shrunk by half the overlap
on every side, so the cores of neighbouring tiles meet exactly and partition the extent
(at the extent's border a core reaches the border). Each tile is processed alone, with all of
its context; only what lies in its core is kept; the pieces are then joined across the seams.
"""
from __future__ import annotations

from dataclasses import dataclass

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely

from ..errors import GisroadsError

TILE_M = 300.0
"""Side of a tile, metres (Zhu & Mordohai, section 3)."""
OVERLAP_M = 100.0
"""Overlap of a tile with each neighbour, metres (Zhu & Mordohai, section 3)."""


@dataclass(frozen=True)
class Tile:
    """One unit of work.

    Attributes
    ----------
    row, col : int
        Position in the tile grid (row 0 is the southernmost).
    bounds : (xmin, ymin, xmax, ymax)
        What the tile reads and processes, metres.
    core : (xmin, ymin, xmax, ymax)
        Where its results are kept, metres.
    """

    row: int
    col: int
    bounds: tuple[float, float, float, float]
    core: tuple[float, float, float, float]


def _counts(lo: float, hi: float, tile_m: float, stride_m: float) -> int:
    return max(1, int(np.ceil((hi - lo - tile_m) / stride_m)) + 1)


def tile_grid(extent, *, tile_m: float = TILE_M, overlap_m: float = OVERLAP_M,
              points_xy=None) -> list[Tile]:
    """Tiles of ``tile_m`` overlapping their neighbours by ``overlap_m`` over an extent.

    Parameters
    ----------
    extent : (xmin, ymin, xmax, ymax)
        Metres.
    tile_m : float
        Tile side, metres (paper: 300 m).
    overlap_m : float
        Overlap with each neighbour, metres (paper: 100 m); must be below ``tile_m``.
    points_xy : iterable of ndarray (n, 2), optional
        The points (e.g. chunk by chunk): only tiles holding one are made, so a cloud with
        a few stray points far from the rest (a bad GPS fix, two surveys in one file) gets
        tiles where its points are, not over its whole bounding box.

    Returns
    -------
    list of Tile
        Row by row from the south-west; cores partition the extent (the occupied part of
        it with ``points_xy``).
    """
    if not 0 <= overlap_m < tile_m:
        raise GisroadsError(f"overlap_m ({overlap_m}) must be in [0, tile_m={tile_m})")
    xmin, ymin, xmax, ymax = map(float, extent)
    stride = tile_m - overlap_m
    nx, ny = _counts(xmin, xmax, tile_m, stride), _counts(ymin, ymax, tile_m, stride)
    if points_xy is None:
        rows, cols = np.divmod(np.arange(nx * ny), nx)
    else:
        rows, cols = _occupied(points_xy, (xmin, ymin), stride, tile_m, nx, ny)
    half = overlap_m / 2.0
    x0, y0 = xmin + stride * cols, ymin + stride * rows
    # cores meet halfway through the overlaps and reach the extent at its border
    cx0 = np.where(cols == 0, xmin, x0 + half)
    cx1 = np.where(cols == nx - 1, xmax, x0 + stride + half)
    cy0 = np.where(rows == 0, ymin, y0 + half)
    cy1 = np.where(rows == ny - 1, ymax, y0 + stride + half)
    return [Tile(int(r), int(c), (float(a), float(b), float(a) + tile_m, float(b) + tile_m),
                 (float(e), float(f), float(g), float(h)))
            for r, c, a, b, e, f, g, h in zip(rows, cols, x0, y0, cx0, cy0, cx1, cy1)]


def _occupied(points_xy, origin, stride: float, tile_m: float, nx: int, ny: int):
    """Rows and columns (sorted row by row) of the tiles holding at least one point."""
    reach = int(np.ceil(tile_m / stride))   # strides a tile spans
    cells = set()
    for xy in points_xy:
        xy = np.asarray(xy, float)
        cell = np.floor((xy - origin) / stride).astype(np.int64)
        cells.update(map(tuple, np.unique(cell, axis=0)))
    if not cells:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    cells = np.array(sorted(cells))
    # a tile starting at stride cell (r, c) spans cells r .. r + reach - 1 (same for c)
    shifts = np.stack(np.meshgrid(np.arange(reach), np.arange(reach)), -1).reshape(-1, 2)
    tiles = (cells[:, None, ::-1] - shifts[None]).reshape(-1, 2)
    tiles = tiles[(tiles[:, 0] >= 0) & (tiles[:, 0] < ny) & (tiles[:, 1] >= 0)
                  & (tiles[:, 1] < nx)]
    tiles = np.unique(tiles, axis=0)
    return tiles[:, 0], tiles[:, 1]


def clip_to_core(lines: gpd.GeoDataFrame, tile: Tile) -> gpd.GeoDataFrame:
    """The parts of a tile's centre lines inside its core (half-open seams: no duplicates)."""
    if len(lines) == 0:
        return lines
    clipped = lines.copy()
    clipped[lines.geometry.name] = shapely.intersection(lines.geometry.values,
                                                        shapely.box(*tile.core))
    clipped = clipped[~clipped.geometry.is_empty].explode(index_parts=False)
    return clipped[clipped.geom_type == "LineString"].reset_index(drop=True)


def _snap_seam_ends(lines: np.ndarray, seams, snap_m: float) -> np.ndarray:
    """Move line ends that lie on a seam and have a partner end across it within ``snap_m``
    to their common midpoint, so the two pieces of one road join exactly."""
    starts = shapely.get_coordinates(shapely.get_point(lines, 0))
    ends = shapely.get_coordinates(shapely.get_point(lines, -1))
    points = np.concatenate([starts, ends])
    on_seam = shapely.distance(shapely.points(points), seams) < 1e-6
    candidates = np.flatnonzero(on_seam)
    if len(candidates) < 2:
        return lines
    from scipy.spatial import cKDTree
    tree = cKDTree(points[candidates])
    pairs = tree.query_pairs(snap_m, output_type="ndarray")
    if len(pairs) == 0:
        return lines
    # keep each end in at most one pair, closest pairs first
    gap = np.hypot(*(points[candidates[pairs[:, 0]]] - points[candidates[pairs[:, 1]]]).T)
    pairs = pairs[np.argsort(gap, kind="stable")]
    used = np.zeros(len(candidates), bool)
    keep = []
    for a, b in pairs:  # a handful of seam crossings per tile
        if not (used[a] or used[b]):
            used[a] = used[b] = True
            keep.append((a, b))
    keep = np.asarray(keep)
    ia, ib = candidates[keep[:, 0]], candidates[keep[:, 1]]
    middle = (points[ia] + points[ib]) / 2.0
    points[ia], points[ib] = middle, middle
    n = len(lines)
    coords, index = shapely.get_coordinates(lines, return_index=True)
    first = np.r_[0, np.flatnonzero(np.diff(index)) + 1]
    last = np.r_[first[1:] - 1, len(index) - 1]
    coords[first], coords[last] = points[:n], points[n:]
    return shapely.set_coordinates(lines.copy(), coords)


def stitch_tiles(pieces: list[tuple[Tile, gpd.GeoDataFrame]], *, snap_m: float = 3.0
                 ) -> gpd.GeoDataFrame:
    """Join the tiles' centre lines into one layer without breaks or duplicates at seams.

    Parameters
    ----------
    pieces : list of (Tile, GeoDataFrame)
        Each tile's centre lines (``width_m``, ``score`` and any other columns), in one CRS.
    snap_m : float
        Ends of two pieces on a seam closer than this (metres) are the same road.

    Returns
    -------
    GeoDataFrame
        Centre lines clipped to their tiles' cores, seam ends joined, and pieces of one road
        merged across seams (width and score length-weighted).
    """
    clipped = [clip_to_core(lines, tile) for tile, lines in pieces]
    clipped = [c for c in clipped if len(c)]
    if not clipped:
        return pieces[0][1].iloc[:0].copy() if pieces else gpd.GeoDataFrame()
    frame = gpd.GeoDataFrame(pd.concat(clipped, ignore_index=True), crs=clipped[0].crs)
    tiles = [tile for tile, _ in pieces]
    seams = shapely.union_all([shapely.boundary(shapely.box(*t.core)) for t in tiles])
    outer = shapely.boundary(shapely.box(min(t.core[0] for t in tiles),
                                         min(t.core[1] for t in tiles),
                                         max(t.core[2] for t in tiles),
                                         max(t.core[3] for t in tiles)))
    seams = shapely.difference(seams, outer)
    geoms = _snap_seam_ends(frame.geometry.values, seams, snap_m)
    return merge_pieces(frame.set_geometry(geoms, crs=frame.crs))


def merge_pieces(lines: gpd.GeoDataFrame) -> gpd.GeoDataFrame:
    """Merge lines that continue each other end to end (at nodes where exactly two ends
    meet) into single lines; float attributes become means weighted by the length each
    piece shares with the merged line, others are taken from the piece that shares the
    most (the union splits pieces where they cross, so a piece can feed several lines)."""
    geoms = lines.geometry.values
    merged = shapely.get_parts(shapely.line_merge(shapely.union_all(geoms)))
    if len(merged) == 0:
        return lines.iloc[:0]
    line, piece = shapely.STRtree(geoms).query(merged, predicate="intersects")
    shared = shapely.length(shapely.intersection(merged[line], geoms[piece]))
    weights = np.bincount(line, weights=shared, minlength=len(merged))
    best = pd.DataFrame({"line": line, "piece": piece, "shared": shared}).sort_values(
        ["line", "shared"], ascending=[True, False], kind="stable").groupby("line").first()
    source = np.zeros(len(merged), dtype=np.int64)
    source[best.index.to_numpy()] = best["piece"].to_numpy()
    columns = {}
    for c in lines.columns:
        if c == lines.geometry.name:
            continue
        columns[c] = lines[c].to_numpy()[source]
        if pd.api.types.is_float_dtype(lines[c]):
            columns[c] = np.where(
                weights > 0,
                np.bincount(line, weights=lines[c].to_numpy(float)[piece] * shared,
                            minlength=len(merged)) / np.maximum(weights, 1e-12),
                columns[c])
    return gpd.GeoDataFrame(columns, geometry=merged, crs=lines.crs)
