"""Wide paved areas of a road raster, and the lines a network draws in them (beyond the
papers).

A road probability marks a car park, a plaza or a forecourt as much as a street: all are
paved. The skeleton of such an area is its outline with a line down every aisle between
the rows of parked cars, a ladder that no road map holds. The area is known by its width:
once the gaps of parked-car rows are closed, a disk wider than any road fits in it. Of the
lines in such an area, those that join the places where roads enter it by the shortest way
are roads (a street along a car park, a road across a plaza, the ring of a roundabout); the
rest is the ladder, and what then leads only into the area (the access) is a branch into
it (:func:`gisroads.network.branches.branches_into`).
"""
from __future__ import annotations

import numpy as np
import shapely
from affine import Affine
from scipy import ndimage

from ..geo import GeoRaster, _end_nodes
from ..vectorize.regions import segment_polygons
from .branches import branches_into

WIDE_AREA_M = 40.0
"""A disk of this diameter, metres, fits in a wide paved area and in no road: a six-lane
arterial with its median is about 35 m (also the widest road part the network stage keeps,
:data:`gisroads.network.rasters.MAX_WIDTH_M`)."""
CAR_ROW_M = 12.0
"""Gaps in the road pixels up to this wide, metres, are closed before the width is read: a
double row of parked cars, nose to nose (2 x 5 m) with the space between them."""
MAX_ELONGATION = 3.0
"""A wide area is at most this many times as long as wide; a longer one is a wide road, such
as a freeway with its shoulders (a car park is seldom longer than three rows of bays)."""
CELL_M = 2.0
"""The areas are read on a grid of about this cell size, metres: they are tens of metres
wide, and the coarse grid keeps memory and time small on any pixel size."""
IN_AREA_SHARE = 0.5
"""A line with at least this share of its length in a wide area lies in it."""
BORDER_M = 5.0
"""A line in a wide area that ends this close to the edge of the data, metres, goes on past
it (the skeleton of a road stops about a pixel short of the edge)."""


def wide_paved_areas(probability: GeoRaster, threshold: float, *,
                     width_m: float = WIDE_AREA_M, car_row_m: float = CAR_ROW_M,
                     max_elongation: float = MAX_ELONGATION, cell_m: float = CELL_M):
    """Where the road raster is wider than any road: car parks, plazas, forecourts.

    Parameters
    ----------
    probability : GeoRaster
        2-D road probability, 0-1, NaN = no data (never road); projected CRS in metres.
    threshold : float
        Road where the mean probability of a grid cell is at least this.
    width_m : float
        A disk of this diameter fits in a wide area, metres.
    car_row_m : float
        Gaps in the road up to this wide are closed first, metres (rows of parked cars).
    max_elongation : float
        An area is at most this many times as long (its area over its width) as wide (the
        widest disk in it); a longer one is a wide road.
    cell_m : float
        Cell size of the grid the areas are read on, metres (a whole number of pixels).

    Returns
    -------
    shapely geometry
        The wide areas ((Multi)Polygon; empty when there is none), in the raster's CRS.

    Examples
    --------
    A street 10 m wide with a car park of 60 x 50 m beside it, two rows of cars in it:

    >>> import numpy as np
    >>> from affine import Affine
    >>> from gisroads.geo import GeoRaster
    >>> from gisroads.network.areas import wide_paved_areas
    >>> road = np.zeros((100, 100), np.float32)                # 1 m pixels
    >>> road[10:20, :] = 1.0
    >>> road[40:90, 20:80] = 1.0
    >>> road[52:60, 25:75] = road[72:80, 25:75] = 0.0
    >>> area = wide_paved_areas(GeoRaster(road, Affine(1, 0, 0, 0, -1, 100), None), 0.5)
    >>> x0, y0, x1, y1 = area.bounds
    >>> 20 <= x0 and x1 <= 80 and 10 <= y0 and y1 <= 60       # the car park, not the street
    True
    """
    pixel_m = probability.pixel_size
    factor = max(1, int(round(cell_m / pixel_m)))
    data = np.asarray(probability.data, dtype=np.float32)
    rows, cols = -(-data.shape[0] // factor), -(-data.shape[1] // factor)
    padded = np.full((rows * factor, cols * factor), np.nan, np.float32)
    padded[:data.shape[0], :data.shape[1]] = data
    blocks = padded.reshape(rows, factor, cols, factor)
    valid = np.isfinite(blocks).sum(axis=(1, 3))
    total = np.nansum(blocks, axis=(1, 3))
    road = np.zeros((rows + 2, cols + 2), bool)  # a frame of no road: nothing is wide past it
    road[1:-1, 1:-1] = (valid > 0) & (total >= threshold * np.maximum(valid, 1))
    cell = pixel_m * factor
    gap = car_row_m / 2 / cell
    closed = ndimage.distance_transform_edt(
        ndimage.distance_transform_edt(~road) <= gap) > gap
    closed &= np.pad(np.ones((rows, cols), bool), 1)
    radius = width_m / 2 / cell
    inner = ndimage.distance_transform_edt(closed)
    wide = (ndimage.distance_transform_edt(~(inner > radius)) <= radius) & closed
    labels, count = ndimage.label(wide)
    if count:
        # a long one is a wide road (a freeway with its shoulders), not an area
        cells = ndimage.sum_labels(wide, labels, np.arange(1, count + 1))
        across = 2 * ndimage.maximum(inner, labels, np.arange(1, count + 1))
        compact = np.concatenate([[False], cells / across ** 2 <= max_elongation])
        wide = compact[labels]
    wide = wide[1:-1, 1:-1]
    if not wide.any():
        return shapely.Polygon()
    t = probability.transform
    transform = Affine(t.a * factor, t.b * factor, t.c, t.d * factor, t.e * factor, t.f)
    area = segment_polygons(np.where(wide, 0, -1).astype(np.int32), 1, transform)[0]
    return shapely.make_valid(area)


def lines_in_wide_areas(lines, area, *, extent=None, in_area_share: float = IN_AREA_SHARE,
                        snap_m: float = 0.5, border_m: float = BORDER_M) -> np.ndarray:
    """The lines a network draws in wide paved areas, less the roads through them: the
    outlines and aisles of car parks, and the accesses that lead only into them.

    In each area, the lines that join the places where roads enter it by the shortest way
    stay (a road along a car park or across a plaza, the ring of a roundabout, a wide
    junction); every other line in it is taken, and then every branch of the network that
    leads only into an area (:func:`gisroads.network.branches.branches_into`).

    Parameters
    ----------
    lines : array_like of LineString
        The network's centre lines, noded at their junctions, metres.
    area : shapely geometry
        The wide areas (:func:`wide_paved_areas`).
    extent : shapely geometry, optional
        Where the data is: a line in an area that ends within ``border_m`` of its edge
        enters the area from past the data.
    in_area_share : float
        A line with at least this share of its length in ``area`` lies in it.
    snap_m : float
        Line ends closer than this are one node, metres.
    border_m : float
        See ``extent``, metres.

    Returns
    -------
    ndarray of bool
        One per line: taken.

    Examples
    --------
    A street, a car park's access, and the car park's outline with an aisle across it:

    >>> from shapely import LineString, box
    >>> from gisroads.network.areas import lines_in_wide_areas
    >>> lines = [LineString([(0, 0), (50, 0)]), LineString([(50, 0), (100, 0)]),
    ...          LineString([(50, 0), (50, -20)]),
    ...          LineString([(50, -20), (20, -20), (20, -60), (50, -60)]),
    ...          LineString([(50, -20), (80, -20), (80, -60), (50, -60)]),
    ...          LineString([(50, -20), (50, -60)])]
    >>> car_park = box(15, -65, 85, -15)
    >>> [bool(b) for b in lines_in_wide_areas(lines, car_park)]
    [False, False, True, True, True, True]
    """
    import networkx as nx  # a graph library is a cost only a raster with wide areas pays

    lines = np.asarray(lines, dtype=object)
    taken = np.zeros(len(lines), dtype=bool)
    if len(lines) == 0 or area is None or area.is_empty:
        return taken
    lengths = shapely.length(lines)
    inside = shapely.length(shapely.intersection(lines, area)) >= in_area_share * lengths
    if not inside.any():
        return taken
    nodes, node_of_end = _end_nodes(lines, snap_m)
    edges = node_of_end.reshape(2, -1).T
    touches_inside = np.bincount(edges[inside].ravel(), minlength=len(nodes)) > 0
    touches_outside = np.bincount(edges[~inside].ravel(), minlength=len(nodes)) > 0
    entry = touches_inside & touches_outside
    if extent is not None:
        degree = np.bincount(edges.ravel(), minlength=len(nodes))
        entry |= touches_inside & (degree == 1) & (shapely.distance(
            shapely.points(nodes), shapely.boundary(extent)) <= border_m)
    graph = nx.Graph()
    for line in np.flatnonzero(inside).tolist():
        a, b = edges[line].tolist()
        if not graph.has_edge(a, b) or graph.edges[a, b]["length"] > lengths[line]:
            graph.add_edge(a, b, length=lengths[line], line=line)
    through = np.zeros(len(lines), dtype=bool)
    for members in nx.connected_components(graph):
        entries = sorted(members & set(np.flatnonzero(entry).tolist()))
        for i, start in enumerate(entries[:-1]):
            paths = nx.single_source_dijkstra_path(graph, start, weight="length")
            for end in entries[i + 1:]:
                for a, b in zip(paths[end][:-1], paths[end][1:]):
                    through[graph.edges[a, b]["line"]] = True
    taken = inside & ~through
    rest = np.flatnonzero(~taken)
    if extent is not None:  # a way that goes on past the data leads somewhere
        area = shapely.difference(area, shapely.buffer(shapely.boundary(extent), border_m))
    taken[rest] = branches_into(lines[rest], area, snap_m=snap_m)
    return taken
