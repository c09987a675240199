"""Raster skeletons to centre lines with widths (for masks: baselines, imagery road parts)."""
from __future__ import annotations

import geopandas as gpd
import numpy as np
import shapely
from scipy import ndimage
from skimage.morphology import skeletonize


# 8-neighbour offsets that pair every two adjacent pixels exactly once
_FORWARD = ((0, 1), (1, -1), (1, 0), (1, 1))


def skeleton_lines(mask: np.ndarray, transform, crs, *, min_length_m: float = 0.0,
                   simplify_m: float = 0.0) -> gpd.GeoDataFrame:
    """Centre lines of a binary mask: its skeleton as LineStrings with a width each.

    Each pair of 8-adjacent skeleton pixels becomes a segment between pixel centres; the
    segments are merged into lines between junctions and ends. The width of a line is twice
    the mean distance from its skeleton pixels to the mask border.

    Parameters
    ----------
    mask : ndarray of bool, shape (rows, cols)
    transform : affine.Affine
        Pixel to map coordinates (pixel corners).
    crs : pyproj.CRS or None
    min_length_m : float
        Lines shorter than this (metres) are dropped.
    simplify_m : float
        Douglas-Peucker tolerance (metres) applied to the merged lines.

    Returns
    -------
    GeoDataFrame
        LineStrings with ``width_m``.
    """
    mask = np.asarray(mask, bool)
    skeleton = skeletonize(mask)
    distance = ndimage.distance_transform_edt(mask) * abs(transform.a)
    rows, cols = np.nonzero(skeleton)
    segments, widths = [], []
    padded = np.pad(skeleton, 1)
    for dr, dc in _FORWARD:
        r2, c2 = rows + dr, cols + dc
        linked = padded[r2 + 1, c2 + 1]
        if dr and dc:
            # a diagonal pair already joined through a straight neighbour would close a
            # small triangle: skip it
            linked &= ~(padded[rows + 1, c2 + 1] | padded[r2 + 1, cols + 1])
        a = np.column_stack([rows[linked], cols[linked]])
        b = np.column_stack([r2[linked], c2[linked]])
        segments.append(np.stack([a, b], axis=1))
        widths.append(distance[a[:, 0], a[:, 1]] + distance[b[:, 0], b[:, 1]])
    segments = np.concatenate(segments).astype(float) + 0.5  # pixel centres
    if len(segments) == 0:
        return gpd.GeoDataFrame({"width_m": np.empty(0)}, geometry=[], crs=crs)
    t = transform
    x = t.a * segments[..., 1] + t.b * segments[..., 0] + t.c
    y = t.d * segments[..., 1] + t.e * segments[..., 0] + t.f
    pieces = shapely.linestrings(np.stack([x, y], axis=-1))
    merged = shapely.get_parts(shapely.line_merge(shapely.union_all(pieces)))
    if simplify_m > 0:
        merged = shapely.simplify(merged, simplify_m)
    # each piece's width (sum of its two end distances = twice their mean) goes to the line
    # that holds its midpoint
    owner = shapely.STRtree(merged).query_nearest(shapely.centroid(pieces), all_matches=False,
                                                  return_distance=False)[1]
    width = np.bincount(owner, weights=np.concatenate(widths), minlength=len(merged)) / \
        np.maximum(np.bincount(owner, minlength=len(merged)), 1)
    lines = gpd.GeoDataFrame({"width_m": width}, geometry=merged, crs=crs)
    return lines[lines.length >= min_length_m].reset_index(drop=True)

