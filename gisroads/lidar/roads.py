"""Zhu & Mordohai's road rectangles to the road network, through the project's network stage.

The minimum cover (:mod:`gisroads.lidar.mincover`) selects rectangles; their mid-lines that
continue each other are chained into centre lines (:func:`rectangle_lines`, step 1 of
:mod:`gisroads.vectorize.ribbons`: curved roads become one line of short rectangles at
narrow angles), tile by tile. The tiles' lines, stitched at their seams, then go through the
network stage every method ends in (:func:`gisroads.network.rasters.parts_to_network`):
gaps between dead ends bridged by the integer program, junctions built where roads meet
(T, X and Y), duplicates and insignificant pieces removed (:func:`lines_to_network`).

The chained rectangles are the cue's evidence of road surface (each line buffered by half
its width: the rectangles it was chained from): a junction connection that runs more than
``max_unsupported_m`` outside it (grown by ``support_margin_m``) is refused, so a road's end
is not extended across a block to the next road.
"""
from __future__ import annotations

from dataclasses import replace

import geopandas as gpd
import numpy as np
import shapely

from ..geo import RoadNetwork
from ..network.junctions import NetworkOptions
from ..network.rasters import RASTER_NETWORK, parts_to_network
from ..progress import Progress
from ..vectorize.ribbons import JOIN_GAP_M, chain_lines, rectangle_centrelines

METHOD = "zhu-mordohai"
#: The network stage's options for rectangles (a raster's,
#: :data:`gisroads.network.rasters.RASTER_NETWORK`, but): an end reaching past a crossing
#: road by its half width plus the chaining distance (5 m) ends there, as rectangles
#: overshoot a junction by up to their sliding step; a connection outside the rectangles
#: (grown 2 m) over more than 15 m is refused (measured on fusa and the synthetic scenes).
RECTANGLE_NETWORK = replace(RASTER_NETWORK, overshoot_m=JOIN_GAP_M, max_unsupported_m=15.0)
SUPPORT_MARGIN_M = 2.0


def rectangle_lines(rectangles: gpd.GeoDataFrame) -> gpd.GeoDataFrame:
    """The rectangles' mid-lines chained into centre lines (``width_m``, ``score``).

    Parameters
    ----------
    rectangles : GeoDataFrame
        Polygons in a metre CRS with ``width_m``, ``theta_rad`` and optionally ``score``.

    Returns
    -------
    GeoDataFrame
        See :func:`gisroads.vectorize.ribbons.chain_lines`.
    """
    width = (rectangles["width_m"].to_numpy(float) if len(rectangles)
             else np.empty(0))  # an empty cover may carry no columns
    score = (rectangles["score"].to_numpy(float) if "score" in rectangles
             else np.full(len(rectangles), np.nan))
    return chain_lines(gpd.GeoDataFrame(
        {"width_m": width, "score": score},
        geometry=gpd.GeoSeries(rectangle_centrelines(rectangles), crs=rectangles.crs),
        crs=rectangles.crs))


def _off_surface_length(surface):
    """``measure(lines) -> metres`` of each line outside ``surface``."""
    def measure(lines):
        return shapely.length(shapely.difference(lines, surface))
    return measure


def lines_to_network(lines: gpd.GeoDataFrame, *, extent=None, method: str = METHOD,
                     support_margin_m: float = SUPPORT_MARGIN_M,
                     network_options: NetworkOptions = RECTANGLE_NETWORK,
                     progress: Progress = None) -> RoadNetwork:
    """Centre lines of road rectangles to the road network (module docstring).

    Parameters
    ----------
    lines : GeoDataFrame
        LineStrings in a metre CRS with ``width_m`` (metres) and ``score``; chained again
        first, so that pieces of one road from neighbouring tiles become one line.
    extent : (xmin, ymin, xmax, ymax), optional
        Where the cloud was observed (metres); by default the lines' bounds grown by the
        widest road.
    method : str
        The ``method`` of every centre line.
    support_margin_m : float
        The road surface grown by this much supports a junction connection, metres.
    network_options : NetworkOptions
        Junctions, duplicates and significance
        (:func:`gisroads.network.junctions.strings_to_network`); default
        :data:`RECTANGLE_NETWORK`. Its ``unsupported`` is the rectangles' surface.
    progress : callable, optional

    Returns
    -------
    RoadNetwork
        QA layers ``gap_edges`` and ``junction_connections``.
    """
    parts = chain_lines(lines).reset_index(drop=True)
    width = parts["width_m"].to_numpy(float)
    if extent is None:
        reach = width.max() if len(parts) else 0.0
        extent = (np.asarray(lines.total_bounds) + [-reach, -reach, reach, reach]
                  if len(lines) else (0.0, 0.0, 1.0, 1.0))
    surface = shapely.union_all(shapely.buffer(parts.geometry.values,
                                               width / 2 + support_margin_m, cap_style="flat"))
    parts["part_id"] = np.arange(len(parts), dtype=np.int64)
    parts["quality"] = np.clip(np.nan_to_num(parts["score"].to_numpy(float), nan=1.0), 0, 1)
    return parts_to_network(parts, extent=tuple(extent), crs=lines.crs, method=method,
                            unsupported=_off_surface_length(surface),
                            network_options=network_options, progress=progress)


def rectangles_to_roads(rectangles: gpd.GeoDataFrame, *, method: str = METHOD,
                        progress: Progress = None) -> RoadNetwork:
    """Road rectangles (the selected minimum-cover hypotheses of one area) to the road
    network: :func:`rectangle_lines`, then :func:`lines_to_network`.

    Returns
    -------
    RoadNetwork
        The contract layers plus the QA layers ``rectangles`` (the input), ``gap_edges`` and
        ``junction_connections``.
    """
    network = lines_to_network(rectangle_lines(rectangles), method=method, progress=progress)
    network.qa["rectangles"] = rectangles.copy()
    return network
