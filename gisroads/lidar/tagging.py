"""Back to 3D (Zhu & Mordohai, Algorithm 1 step 7): classify the road points of the cloud.

A point is road when it lies inside a road polygon of ground level k and within a height
tolerance of level k's ground surface at its cell. The level surfaces are rasters of the mean
ground height per level, so the input file is streamed chunk by chunk; on a bridge the deck
points tag the deck's road and the points of the road underneath tag that road, never each
other.
"""
from __future__ import annotations

import geopandas as gpd
import numpy as np
import shapely
from affine import Affine
from scipy import ndimage

from ..geo import GeoRaster
from ..io.las import ROAD_SURFACE_CLASS, PointCloud, write_classified
from .ground import ground_planes
from .intensity import auto_cell_m, image_grid

def level_heights(xyz: np.ndarray, level: np.ndarray, n_levels: int, *, transform: Affine,
                  shape: tuple[int, int], crs=None, fill_cells: int = 4) -> GeoRaster:
    """Mean ground height per cell of each level, small holes filled from the nearest cell.

    Parameters
    ----------
    xyz : ndarray (n, 3)
        Metres.
    level : ndarray of int (n,)
        Ground level of each point, -1 for non-ground points.
    n_levels : int
    transform, shape
        The grid (north-up, square cells).
    fill_cells : int
        Empty cells take the height of the nearest filled cell of the level up to this many
        cells away (scan gaps); farther ones stay NaN.

    Returns
    -------
    GeoRaster
        ``(n_levels, rows, cols)`` float32 metres, NaN where a level has no surface.
    """
    rows, cols = shape
    ground = level >= 0
    col = np.floor((xyz[ground, 0] - transform.c) / transform.a).astype(np.int64)
    row = np.floor((xyz[ground, 1] - transform.f) / transform.e).astype(np.int64)
    inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
    flat = (level[ground][inside].astype(np.int64) * rows + row[inside]) * cols + col[inside]
    size = n_levels * rows * cols
    total = np.bincount(flat, weights=xyz[ground, 2][inside], minlength=size)
    count = np.bincount(flat, minlength=size)
    heights = (total / np.maximum(count, 1)).reshape(n_levels, rows, cols)
    empty = (count == 0).reshape(n_levels, rows, cols)
    for k in range(n_levels):  # a few levels
        if empty[k].all():
            heights[k] = np.nan
            continue
        distance, (near_r, near_c) = ndimage.distance_transform_edt(empty[k],
                                                                    return_indices=True)
        heights[k] = np.where(distance <= fill_cells, heights[k][near_r, near_c], np.nan)
    return GeoRaster(heights.astype(np.float32), transform, crs)


def ground_level_heights(cloud: PointCloud, *, cell_m: float | None = None,
                         **ground_options) -> GeoRaster:
    """Per-level ground heights of a whole cloud from its own ground planes.

    What :func:`road_point_mask` needs for road polygons that come without the LiDAR
    pipeline's height raster (ribbon-snake polygons, hand-drawn ones): the same ground
    levels (:func:`gisroads.lidar.ground.ground_planes`, ``ground_options``) and heights,
    on one grid over the cloud, which is held in memory.

    Parameters
    ----------
    cloud : PointCloud
        Metres.
    cell_m : float, optional
        Grid cell; default :func:`gisroads.lidar.intensity.auto_cell_m` of the cloud.
    """
    bounds = (*cloud.xyz[:, :2].min(axis=0), *cloud.xyz[:, :2].max(axis=0))
    if cell_m is None:
        cell_m = auto_cell_m(len(cloud), (bounds[2] - bounds[0]) * (bounds[3] - bounds[1]))
    planes = ground_planes(cloud.xyz, **ground_options)
    transform, shape = image_grid(bounds, cell_m)
    return level_heights(cloud.xyz, planes.level, planes.n_levels, transform=transform,
                         shape=shape, crs=cloud.crs)


def road_point_mask(xyz: np.ndarray, road_polygons: gpd.GeoDataFrame, heights: GeoRaster, *,
                    tolerance_m: float = 0.3) -> np.ndarray:
    """Which points lie on a road surface.

    Parameters
    ----------
    xyz : ndarray (n, 3)
        Metres, in the polygons' CRS.
    road_polygons : GeoDataFrame
        Road polygons with a ``level`` column (level 0 where it is missing).
    heights : GeoRaster
        Output of :func:`level_heights`.
    tolerance_m : float
        Largest height difference (metres) between a point and its level's surface.
    """
    road = np.zeros(len(xyz), bool)
    if len(road_polygons) == 0 or len(xyz) == 0:
        return road
    levels = (road_polygons["level"].to_numpy(int) if "level" in road_polygons
              else np.zeros(len(road_polygons), int))
    row, col = heights.xy_to_rowcol(xyz[:, 0], xyz[:, 1])
    n_levels, rows, cols = heights.data.shape
    inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
    for k in np.unique(levels):  # a few levels
        if k >= n_levels:
            continue
        area = shapely.union_all(road_polygons.geometry.values[levels == k])
        shapely.prepare(area)
        surface = np.full(len(xyz), np.nan)
        surface[inside] = heights.data[k][row[inside], col[inside]]
        near = np.abs(xyz[:, 2] - surface) <= tolerance_m
        candidates = np.flatnonzero(near & ~road)
        road[candidates] = shapely.contains_xy(area, xyz[candidates, 0], xyz[candidates, 1])
    return road


def tag_road_points(source, target, road_polygons: gpd.GeoDataFrame, heights: GeoRaster, *,
                    road_class: int = ROAD_SURFACE_CLASS, tolerance_m: float = 0.3) -> int:
    """Copy a LAS/LAZ file with its road points classified ``road_class``, streamed.

    Parameters
    ----------
    source, target : str or Path
    road_polygons : GeoDataFrame
        In the cloud's (metre) working CRS, with ``level``.
    heights : GeoRaster
        Per-level ground heights (:func:`level_heights`).

    Returns
    -------
    int
        Number of points classified as road.
    """
    tagged = 0

    def classify(chunk: PointCloud) -> np.ndarray:
        nonlocal tagged
        road = road_point_mask(chunk.xyz, road_polygons, heights, tolerance_m=tolerance_m)
        tagged += int(road.sum())
        return np.where(road, road_class, chunk.classification)

    write_classified(source, target, classify)
    return tagged
