"""Degrade a road network the way real extractions and old maps are degraded.

Used to make stand-in inputs with known error: a road map shifted and jittered for the
map-guided snakes, or an "extraction" with missing and false roads for the evaluation demo.
"""
from __future__ import annotations

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely


def perturb_lines(lines: gpd.GeoDataFrame, *, shift_m: float = 0.0, jitter_m: float = 0.0,
                  vertex_spacing_m: float = 10.0, drop_fraction: float = 0.0,
                  false_roads: int = 0, false_length_m: float = 60.0,
                  seed: int = 0) -> gpd.GeoDataFrame:
    """Shift, jitter, drop and add centre lines.

    Parameters
    ----------
    lines : GeoDataFrame
        Centre lines in a metre CRS; other columns are kept.
    shift_m : float
        Every line is moved by this distance (metres) in one random direction per line.
    jitter_m : float
        Standard deviation (metres) of independent Gaussian noise added to each vertex after
        densifying to ``vertex_spacing_m``.
    vertex_spacing_m : float
        Densification step before jittering (metres).
    drop_fraction : float
        Share of lines removed at random (missed roads).
    false_roads : int
        Number of straight lines of ``false_length_m`` added at random inside the bounds of
        ``lines`` (false roads); they copy the first line's attributes.
    seed : int

    Returns
    -------
    GeoDataFrame

    Examples
    --------
    An old road map of a scene: every line 2.5 m off, and each road left off it with a
    chance of one in five:

    >>> from gisroads.evaluate import buffer_metrics
    >>> from gisroads.synthetic import make_scene, perturb_lines
    >>> truth = make_scene(seed=0, size_m=(300, 300)).truth.centrelines
    >>> old_map = perturb_lines(truth, shift_m=2.5, drop_fraction=0.2, seed=1)
    >>> len(truth), len(old_map)
    (9, 8)
    >>> scores = buffer_metrics(old_map, truth, buffer_m=3.0)
    >>> round(scores.correctness, 2), round(scores.completeness, 1)
    (1.0, 0.9)
    """
    rng = np.random.default_rng(seed)
    keep = rng.random(len(lines)) >= drop_fraction
    out = lines[keep].copy()
    geoms = shapely.segmentize(out.geometry.values, vertex_spacing_m)
    angle = rng.uniform(0, 2 * np.pi, len(geoms))
    coords, index = shapely.get_coordinates(geoms, return_index=True)
    coords = coords + shift_m * np.column_stack([np.cos(angle), np.sin(angle)])[index]
    coords = coords + rng.normal(0.0, jitter_m, coords.shape) if jitter_m > 0 else coords
    out[out.geometry.name] = gpd.GeoSeries(shapely.set_coordinates(geoms.copy(), coords),
                                           index=out.index, crs=lines.crs)
    if false_roads:
        xmin, ymin, xmax, ymax = lines.total_bounds
        start = rng.uniform([xmin, ymin], [xmax, ymax], (false_roads, 2))
        heading = rng.uniform(0, 2 * np.pi, false_roads)
        end = start + false_length_m * np.column_stack([np.cos(heading), np.sin(heading)])
        template = lines.iloc[[0] * false_roads].reset_index(drop=True)
        template[template.geometry.name] = gpd.GeoSeries(
            shapely.linestrings(np.stack([start, end], 1)), crs=lines.crs)
        extra = template
        out = pd.concat([out, extra[out.columns]], ignore_index=True)
    return out.reset_index(drop=True)


def degrade_mask(mask: np.ndarray, centrelines: gpd.GeoDataFrame, transform, *,
                 cuts: int = 20, cut_length_m: tuple[float, float] = (5.0, 15.0),
                 blobs: int = 20, blob_radius_m: tuple[float, float] = (3.0, 10.0),
                 salt: float = 0.005, seed: int = 0) -> np.ndarray:
    """A road mask degraded as a segmentation is: roads cut, false blobs, salt noise.

    Parameters
    ----------
    mask : ndarray of bool, shape (rows, cols)
    centrelines : GeoDataFrame
        The mask's centre lines with ``width_m`` (metres), where the cuts fall.
    transform : affine.Affine
        Pixel to map coordinates of ``mask``.
    cuts : int
        Number of cuts across roads, at random points of the centre lines (uniform in
        length); each clears a rectangle ``cut_length_m`` long (uniform in the range,
        metres) along the road and one and a half road widths across.
    blobs : int
        Number of false blobs: ellipses with semi-axes in ``blob_radius_m`` (metres) at
        random positions and orientations.
    salt : float
        Share of pixels flipped at random, half to road and half to background.
    seed : int

    Returns
    -------
    ndarray of bool
    """
    rng = np.random.default_rng(seed)
    out = np.asarray(mask, bool).copy()
    rows, cols = out.shape
    pixel_m = abs(transform.a)
    r, c = np.mgrid[0:rows, 0:cols]
    x = transform.a * (c + 0.5) + transform.c
    y = transform.e * (r + 0.5) + transform.f
    lines = centrelines.geometry.values
    if cuts and len(lines):
        length = shapely.length(lines)
        which = rng.choice(len(lines), cuts, p=length / length.sum())
        along = rng.uniform(0.1, 0.9, cuts) * length[which]
        centre = shapely.get_coordinates(shapely.line_interpolate_point(lines[which], along))
        ahead = shapely.get_coordinates(shapely.line_interpolate_point(
            lines[which], np.minimum(along + 1.0, length[which])))
        direction = ahead - centre
        direction /= np.maximum(np.hypot(*direction.T), 1e-9)[:, None]
        half_length = rng.uniform(*cut_length_m, cuts) / 2
        half_across = 0.75 * centrelines["width_m"].to_numpy(float)[which] + pixel_m
        for k in range(cuts):
            dx, dy = x - centre[k, 0], y - centre[k, 1]
            u = dx * direction[k, 0] + dy * direction[k, 1]
            v = -dx * direction[k, 1] + dy * direction[k, 0]
            out[(np.abs(u) <= half_length[k]) & (np.abs(v) <= half_across[k])] = False
    for _ in range(blobs):
        cx, cy = rng.uniform(x.min(), x.max()), rng.uniform(y.min(), y.max())
        a, b = rng.uniform(*blob_radius_m, 2)
        theta = rng.uniform(0, np.pi)
        dx, dy = x - cx, y - cy
        u = dx * np.cos(theta) + dy * np.sin(theta)
        v = -dx * np.sin(theta) + dy * np.cos(theta)
        out[(u / a) ** 2 + (v / b) ** 2 <= 1] = True
    flip = rng.random(out.shape) < salt
    out[flip] = rng.random(int(flip.sum())) < 0.5
    return out
