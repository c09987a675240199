"""Label images to polygons: one (Multi)Polygon per segment, traced along pixel edges."""
from __future__ import annotations

import numpy as np
import rasterio.features
import shapely
from affine import Affine


def segment_polygons(labels: np.ndarray, n: int, transform: Affine) -> np.ndarray:
    """One (Multi)Polygon per segment of a label image, from its pixel outlines.

    Parameters
    ----------
    labels : ndarray of int32, shape (rows, cols)
        Segments ``0..n-1``; negative = no segment.
    n : int
        Number of segments.
    transform : affine.Affine
        Pixel to map coordinates.

    Returns
    -------
    ndarray of shapely geometry, shape (n,)
        None for a label without pixels.
    """
    rings, owner, ring_polygon = [], [], []
    for index, (geometry, value) in enumerate(rasterio.features.shapes(
            labels, mask=labels >= 0, transform=transform, connectivity=4)):
        rings += geometry["coordinates"]  # the shell, then the holes
        ring_polygon += [index] * len(geometry["coordinates"])
        owner.append(int(value))
    # built in two vectorised calls: shapely.geometry.shape() per polygon costs more than
    # the tracing
    sizes = [len(ring) for ring in rings]
    ring_of = np.repeat(np.arange(len(rings)), sizes)
    rings = shapely.linearrings(np.concatenate(rings) if rings else np.empty((0, 2)),
                                indices=ring_of)
    parts = shapely.polygons(rings, indices=ring_polygon) if len(rings) else \
        np.empty(0, dtype=object)
    owner = np.array(owner, dtype=np.int64)
    order = np.argsort(owner, kind="stable")
    parts, owner = parts[order], owner[order]
    counts = np.bincount(owner, minlength=n)
    out = np.empty(n, dtype=object)
    single = counts[owner] == 1
    out[owner[single]] = parts[single]
    if (~single).any():
        multi = np.unique(owner[~single])
        out[multi] = shapely.multipolygons(parts[~single],
                                           indices=np.searchsorted(multi, owner[~single]))
    return out
