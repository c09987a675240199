"""Small shared types: a raster with its georeferencing, and the road-network output contract.

Every road pipeline ends in a :class:`RoadNetwork`: three layers in the input's CRS,

``road_centrelines``
    LineString; ``road_id``, ``width_m``, ``length_m``, ``method``, ``score``.
``road_polygons``
    Polygon; ``road_id``, ``width_m``, ``area_m2``.
``junctions``
    Point; ``junction_id``, ``degree`` (number of road ends meeting there, >= 3).

plus method-specific QA layers in ``RoadNetwork.qa``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from affine import Affine
from pyproj import CRS
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

CENTRELINES = "road_centrelines"
POLYGONS = "road_polygons"
JUNCTIONS = "junctions"
#: Car-park aisles and other service ways kept apart from the roads (LiDAR evidence cue).
SERVICE_CENTRELINES = "service_centrelines"

#: Column names and dtypes of the three contract layers (geometry column excluded).
CONTRACT_SCHEMA = {
    CENTRELINES: {"road_id": "int64", "width_m": "float64", "length_m": "float64",
                  "method": "object", "score": "float64"},
    POLYGONS: {"road_id": "int64", "width_m": "float64", "area_m2": "float64"},
    JUNCTIONS: {"junction_id": "int64", "degree": "int64"},
}
CONTRACT_GEOMETRY = {CENTRELINES: "LineString", POLYGONS: "Polygon", JUNCTIONS: "Point"}


LOCAL_CRS = CRS.from_proj4("+proj=tmerc +lat_0=0 +lon_0=0 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 "
                           "+units=m +no_defs")
"""Metric CRS given to images without georeferencing (a stand-in, not their location)."""


def local_transform(shape: tuple[int, int], pixel_m: float) -> Affine:
    """Transform of an image without georeferencing in :data:`LOCAL_CRS`: the lower-left
    corner at (0, 0), north up."""
    return Affine(pixel_m, 0.0, 0.0, 0.0, -pixel_m, shape[0] * pixel_m)


@dataclass(frozen=True)
class GeoRaster:
    """A raster array with the affine transform and CRS that place it on the ground.

    Attributes
    ----------
    data : ndarray
        ``(rows, cols)`` or ``(bands, rows, cols)``.
    transform : affine.Affine
        Pixel (col, row) to map (x, y) of the pixel's upper-left corner.
    crs : pyproj.CRS or None
        A string or an EPSG code (``"EPSG:32633"``, ``32633``) is read as a
        :class:`pyproj.CRS`.
    nodata : float or None
    """

    data: np.ndarray
    transform: Affine
    crs: CRS | None
    nodata: float | None = None

    def __post_init__(self):
        if isinstance(self.crs, (str, int)):
            object.__setattr__(self, "crs", CRS.from_user_input(self.crs))

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)``."""
        return tuple(self.data.shape[-2:])

    @property
    def pixel_size(self) -> float:
        """Side of a (square) pixel in CRS units."""
        return float(abs(self.transform.a))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` in CRS units."""
        rows, cols = self.shape
        x0, y0 = _apply(self.transform, 0, 0)
        x1, y1 = _apply(self.transform, cols, rows)
        return min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1)

    def xy_to_rowcol(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Integer pixel indices of map coordinates (no bounds check)."""
        col, row = _apply(~self.transform, np.asarray(x, float), np.asarray(y, float))
        return np.floor(row).astype(np.int64), np.floor(col).astype(np.int64)


def _apply(t: Affine, u, v):
    """``t`` applied to coordinates; spelt out because affine 3 deprecates ``t * (u, v)``
    and the ``@`` that replaces it does not exist in Debian's affine 2."""
    return t.a * u + t.b * v + t.c, t.d * u + t.e * v + t.f


def _empty_layer(name: str, crs) -> gpd.GeoDataFrame:
    columns = {c: pd.Series(dtype=t) for c, t in CONTRACT_SCHEMA[name].items()}
    return gpd.GeoDataFrame(columns, geometry=gpd.GeoSeries([], crs=crs), crs=crs)


@dataclass
class RoadNetwork:
    """The output contract of every road pipeline (see the module docstring).

    Use :func:`network_from_centrelines` to build one from centre lines with widths.
    """

    centrelines: gpd.GeoDataFrame
    polygons: gpd.GeoDataFrame
    junctions: gpd.GeoDataFrame
    qa: dict[str, gpd.GeoDataFrame] = field(default_factory=dict)

    @property
    def crs(self):
        return self.centrelines.crs

    def layers(self) -> dict[str, gpd.GeoDataFrame]:
        """All layers by name, contract layers first."""
        return {CENTRELINES: self.centrelines, POLYGONS: self.polygons,
                JUNCTIONS: self.junctions, **self.qa}

    def validate(self) -> None:
        """Raise ``ValueError`` unless the three contract layers have their schema."""
        for name, frame in list(self.layers().items())[:3]:
            missing = set(CONTRACT_SCHEMA[name]) - set(frame.columns)
            if missing:
                raise ValueError(f"layer {name!r} lacks columns {sorted(missing)}")
            kinds = set(frame.geom_type.dropna()) - {CONTRACT_GEOMETRY[name]}
            if kinds:
                raise ValueError(f"layer {name!r} has {sorted(kinds)} geometries, "
                                 f"expected {CONTRACT_GEOMETRY[name]}")
            if frame.crs != self.crs:
                raise ValueError(f"layer {name!r} is in another CRS than road_centrelines")


def node_lines(lines) -> np.ndarray:
    """Split lines at every crossing and shared vertex; returns simple LineStrings.

    Parameters
    ----------
    lines : array_like of shapely geometries
        LineStrings or MultiLineStrings.
    """
    lines = np.asarray(lines, dtype=object)
    if len(lines) == 0:
        return np.empty(0, dtype=object)
    # A unary union of linework is fully noded: every crossing becomes a vertex shared by
    # the pieces, and overlapping duplicates are dissolved.
    return shapely.get_parts(shapely.union_all(shapely.get_parts(lines)))


def _end_nodes(lines: np.ndarray, snap_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The distinct end points of ``m`` noded lines (ends closer than ``snap_m`` are one)
    and the node of each of their ``2 m`` ends (the first points, then the last points)."""
    ends = np.concatenate([shapely.get_coordinates(shapely.get_point(lines, 0)),
                           shapely.get_coordinates(shapely.get_point(lines, -1))])
    keys = np.round(ends / snap_m).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    # numpy 2.0 returns the inverse of an axis=0 unique as a column, 1.x and 2.1+ flat.
    return ends[first], inverse.reshape(-1)


def line_end_degrees(lines, *, snap_m: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """End points of noded lines and how many line ends meet at each.

    Parameters
    ----------
    lines : array_like of LineString
        Already noded (see :func:`node_lines`).
    snap_m : float
        End points closer than this (CRS units) are the same node.

    Returns
    -------
    nodes : ndarray, shape (n, 2)
    degree : ndarray of int, shape (n,)
    """
    lines = np.asarray(lines, dtype=object)
    if len(lines) == 0:
        return np.empty((0, 2)), np.empty(0, dtype=np.int64)
    nodes, node_of_end = _end_nodes(lines, snap_m)
    return nodes, np.bincount(node_of_end, minlength=len(nodes))


def free_line_ends(lines, *, snap_m: float = 1e-6) -> np.ndarray:
    """Whether each noded line's start and end touch no other line (a dead end, or a cut
    at the data's edge).

    Parameters
    ----------
    lines, snap_m
        As :func:`line_end_degrees`.

    Returns
    -------
    ndarray of bool, shape (m, 2)
        Per line, its start and its end.
    """
    lines = np.asarray(lines, dtype=object)
    if len(lines) == 0:
        return np.zeros((0, 2), dtype=bool)
    _, node_of_end = _end_nodes(lines, snap_m)
    return (np.bincount(node_of_end)[node_of_end] == 1).reshape(2, -1).T


@dataclass(frozen=True)
class LineGraph:
    """A noded line network as a graph.

    Attributes
    ----------
    lines : ndarray of LineString, shape (m,)
        Noded lines; line ``i`` runs from node ``edges[i, 0]`` to node ``edges[i, 1]``.
    nodes : ndarray, shape (n, 2)
        Node coordinates.
    edges : ndarray of int, shape (m, 2)
    lengths : ndarray, shape (m,)
        Edge lengths in CRS units.
    """

    lines: np.ndarray
    nodes: np.ndarray
    edges: np.ndarray
    lengths: np.ndarray

    @property
    def degree(self) -> np.ndarray:
        """Line ends meeting at each node (a loop counts twice)."""
        return np.bincount(self.edges.ravel(), minlength=len(self.nodes))

    def adjacency(self) -> csr_matrix:
        """Sparse ``(n, n)`` edge-length matrix, for ``scipy.sparse.csgraph`` with
        ``directed=False``: one entry per node pair (the shortest of parallel edges), loops
        left out."""
        low, high = np.sort(self.edges, axis=1).T
        keep = low != high
        low, high, lengths = low[keep], high[keep], self.lengths[keep]
        # csr_matrix sums duplicate entries; parallel edges must give their minimum instead.
        order = np.lexsort((lengths, high, low))
        low, high, lengths = low[order], high[order], lengths[order]
        first = np.ones(len(low), dtype=bool)
        first[1:] = (low[1:] != low[:-1]) | (high[1:] != high[:-1])
        n = len(self.nodes)
        return csr_matrix((lengths[first], (low[first], high[first])), shape=(n, n))

    def components(self) -> tuple[int, np.ndarray]:
        """Number of connected components and the component label of each node."""
        count, labels = connected_components(self.adjacency(), directed=False)
        return int(count), labels


def line_graph(lines, *, snap_m: float = 1e-6) -> LineGraph:
    """Graph of a line network: the lines noded (:func:`node_lines`), every noded line an
    edge weighted by its length, end points closer than ``snap_m`` one node.

    Parameters
    ----------
    lines : array_like of (Multi)LineString
    snap_m : float
        End points closer than this (CRS units) are one node.
    """
    noded = node_lines(lines)
    if len(noded) == 0:
        return LineGraph(lines=noded, nodes=np.empty((0, 2)),
                         edges=np.empty((0, 2), dtype=np.int64), lengths=np.empty(0))
    nodes, node_of_end = _end_nodes(noded, snap_m)
    return LineGraph(lines=noded, nodes=nodes, edges=node_of_end.reshape(2, -1).T.copy(),
                     lengths=shapely.length(noded))


def junctions_from_lines(lines, crs, *, snap_m: float = 1e-6) -> gpd.GeoDataFrame:
    """Junction layer: nodes of the noded network where three or more line ends meet."""
    nodes, degree = line_end_degrees(node_lines(lines), snap_m=snap_m)
    keep = degree >= 3
    return gpd.GeoDataFrame(
        {"junction_id": np.arange(int(keep.sum()), dtype=np.int64),
         "degree": degree[keep].astype(np.int64)},
        geometry=shapely.points(nodes[keep]), crs=crs)


def network_from_centrelines(centrelines: gpd.GeoDataFrame, *, method: str = "",
                             qa: dict | None = None) -> RoadNetwork:
    """Build the contract layers from centre lines that carry a ``width_m`` column.

    Polygons are the centre lines buffered by half their width with flat caps and round
    joins, one per road; junctions are the nodes where three or more noded line ends meet.

    Parameters
    ----------
    centrelines : GeoDataFrame
        LineStrings with ``width_m`` (metres, CRS units); optional ``road_id``, ``score``,
        ``method``.
    method : str
        Fills ``method`` where the frame has none.
    qa : dict of GeoDataFrame, optional
        Method-specific QA layers, stored beside the contract layers.
    """
    crs = centrelines.crs
    if len(centrelines) == 0:
        return RoadNetwork(_empty_layer(CENTRELINES, crs), _empty_layer(POLYGONS, crs),
                           _empty_layer(JUNCTIONS, crs), dict(qa or {}))
    geoms = centrelines.geometry.values
    width = centrelines["width_m"].to_numpy(float)
    road_id = (centrelines["road_id"].to_numpy(np.int64) if "road_id" in centrelines
               else np.arange(len(centrelines), dtype=np.int64))
    score = (centrelines["score"].to_numpy(float) if "score" in centrelines
             else np.full(len(centrelines), np.nan))
    methods = (centrelines["method"].to_numpy(object) if "method" in centrelines
               else np.full(len(centrelines), method, dtype=object))
    lines = gpd.GeoDataFrame(
        {"road_id": road_id, "width_m": width, "length_m": shapely.length(geoms),
         "method": methods, "score": score}, geometry=geoms, crs=crs)
    areas = shapely.buffer(geoms, width / 2.0, cap_style="flat", join_style="round")
    polygons = gpd.GeoDataFrame(
        {"road_id": road_id, "width_m": width, "area_m2": shapely.area(areas)},
        geometry=areas, crs=crs).explode(index_parts=False).reset_index(drop=True)
    polygons["area_m2"] = shapely.area(polygons.geometry.values)
    return RoadNetwork(lines, polygons, junctions_from_lines(geoms, crs), dict(qa or {}))
