"""A naive LiDAR road baseline, to measure the real method against: dark lowest points.

For every cell the lowest point is taken (a crude ground filter); cells whose lowest point is
close to the local ground and darker than an intensity threshold are road candidates; the
candidate mask is cleaned morphologically and skeletonised into centre lines with widths.
No planes, no shape model, no width selection.
"""
from __future__ import annotations

import numpy as np
from affine import Affine
from scipy import ndimage

from ..geo import RoadNetwork, network_from_centrelines
from ..io.las import PointCloud
from ..vectorize.skeleton import skeleton_lines


def lowest_point_grid(cloud: PointCloud, *, cell_m: float = 1.0):
    """Per cell: the height and intensity of its lowest point (NaN where the cell is empty).

    Returns
    -------
    z, intensity : ndarray (rows, cols)
    transform : affine.Affine
    """
    x, y, z = cloud.xyz.T
    x0, y1 = np.floor(x.min() / cell_m) * cell_m, np.ceil(y.max() / cell_m) * cell_m
    cols = int(np.ceil((x.max() - x0) / cell_m)) + 1
    rows = int(np.ceil((y1 - y.min()) / cell_m)) + 1
    cell = ((y1 - y) // cell_m).astype(np.int64) * cols + ((x - x0) // cell_m).astype(np.int64)
    order = np.lexsort((z, cell))
    first = order[np.r_[True, np.diff(cell[order]) != 0]]
    lowest_z = np.full(rows * cols, np.nan)
    lowest_i = np.full(rows * cols, np.nan)
    lowest_z[cell[first]] = z[first]
    intensity = cloud.intensity if cloud.intensity is not None else np.zeros(len(z))
    lowest_i[cell[first]] = intensity[first]
    transform = Affine(cell_m, 0.0, x0, 0.0, -cell_m, y1)
    return lowest_z.reshape(rows, cols), lowest_i.reshape(rows, cols), transform


def baseline_roads(cloud: PointCloud, *, cell_m: float = 1.0, dark_quantile: float = 0.35,
                   ground_window_m: float = 15.0, ground_tolerance_m: float = 0.5,
                   min_width_m: float = 3.0, min_length_m: float = 20.0) -> RoadNetwork:
    """Road centre lines from an intensity threshold on the lowest points, skeletonised.

    Parameters
    ----------
    cloud : PointCloud
    cell_m : float
        Grid cell, metres.
    dark_quantile : float
        Cells darker than this quantile of the ground cells' intensity are road candidates.
    ground_window_m : float
        Window of the local minimum that stands in for the terrain, metres.
    ground_tolerance_m : float
        A cell is ground when its lowest point is within this of the local minimum, metres.
    min_width_m : float
        Opening size that removes thinner candidate structures, metres.
    min_length_m : float
        Shorter skeleton lines are dropped, metres.
    """
    z, intensity, transform = lowest_point_grid(cloud, cell_m=cell_m)
    filled_z = np.where(np.isnan(z), np.nanmax(z), z)
    window = max(3, int(round(ground_window_m / cell_m)) | 1)
    ground = (filled_z - ndimage.minimum_filter(filled_z, size=window)) < ground_tolerance_m
    ground &= ~np.isnan(z)
    threshold = np.quantile(intensity[ground], dark_quantile) if ground.any() else 0.0
    candidates = ground & (intensity <= threshold)
    radius = max(1, int(round(min_width_m / cell_m / 2)))
    structure = ndimage.generate_binary_structure(2, 1)
    candidates = ndimage.binary_closing(candidates, structure, iterations=1)
    candidates = ndimage.binary_opening(candidates, structure, iterations=radius)
    lines = skeleton_lines(candidates, transform, cloud.crs, min_length_m=min_length_m,
                           simplify_m=cell_m)
    return network_from_centrelines(lines, method="baseline-dark-lowest-points")
