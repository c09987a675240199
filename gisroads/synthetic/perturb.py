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
