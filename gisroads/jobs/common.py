"""What the jobs of every method share: reading their inputs (a road map, an aerial image,
a layer), the summary of a written road network, its quick-look, the no-road warning, and
the header facts of ``gisroads info``."""
from __future__ import annotations

import inspect
import warnings
from pathlib import Path

import geopandas as gpd
import numpy as np

from ..errors import GisroadsError, MissingFileError, NoRoadFoundWarning
from ..geo import CENTRELINES, GeoRaster, RoadNetwork
from ..imagery.datasets import warp_to_utm
from ..io.las import las_info
from ..io.quicklook import write_quicklook
from ..io.raster import raster_info, read_raster
from ..io.vector import layer_geometry_types, list_layers, read_layer, write_geopackage
from ..options import keyword_defaults

VECTOR_SUFFIXES = {".gpkg", ".geojson", ".json", ".shp", ".fgb", ".kml", ".gml"}


def stage_default(function, parameter: str):
    """The default of ``parameter`` of the stage ``function``: the one place a default is
    written, read by the jobs, the command line and the QGIS algorithms. A parameter of the
    signature, or a field of its default options object (a dataclass, e.g.
    :class:`gisroads.lidar.hypotheses.HypothesisOptions`; see
    :func:`gisroads.options.keyword_defaults`).

    Examples
    --------
    >>> from gisroads.jobs.common import stage_default
    >>> from gisroads.lidar.hypotheses import T_BD, road_hypotheses
    >>> stage_default(road_hypotheses, "t_bd") == T_BD
    True
    """
    defaults = keyword_defaults(function)
    if parameter in defaults:
        return defaults[parameter]
    parameters = inspect.signature(function).parameters
    if parameter in parameters:  # an options object itself, or **changes
        return parameters[parameter].default
    raise KeyError(f"{function.__name__} has no parameter {parameter!r}")


def parse_metres(text: str, name: str = "value") -> tuple[float, ...]:
    """Positive metres from a comma- (or semicolon-) separated list, e.g. ``"6,9,12"``."""
    try:
        values = tuple(float(v) for v in text.replace(";", ",").split(",") if v.strip())
    except ValueError:
        raise GisroadsError(f"{name}: {text!r} is not a comma-separated list of "
                            "metres") from None
    if not values or min(values) <= 0:
        raise GisroadsError(f"{name}: give positive metres, e.g. 6,9,12")
    return values


def _plain(value):
    """``value`` with numpy scalars and arrays as Python numbers and lists (JSON and text
    show ``636001.76``, not ``np.float64(636001.76)``)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def describe_file(path) -> dict:
    """Header facts of a LAS/LAZ, raster or vector file (see ``gisroads info``).

    Plain Python values throughout. A GeoPackage layer's ``geometry`` is the types of its
    features, or for an empty layer the type the file declares for it; a raster without
    georeferencing has ``georeferenced`` False and no ``extent`` or ``pixel_size``.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in {".las", ".laz"}:
        return _plain({"kind": "point cloud", **las_info(path)})
    if suffix in VECTOR_SUFFIXES:
        if not path.exists():  # else sqlite would create the GeoPackage it cannot open
            raise MissingFileError(f"{path}: no such file")
        names = list_layers(path) if suffix == ".gpkg" else [None]
        declared = layer_geometry_types(path) if suffix == ".gpkg" else {}
        layers = []
        for name in names:
            frame = read_layer(path, name)
            found = sorted(set(frame.geom_type.dropna()))
            layers.append({"layer": name or path.stem, "features": len(frame),
                           "geometry": found or ([declared[name]] if name in declared
                                                 else []),
                           "crs": frame.crs.name if frame.crs else None,
                           "epsg": frame.crs.to_epsg() if frame.crs else None,
                           "extent": [float(v) for v in frame.total_bounds] if len(frame)
                           else None})
        return _plain({"kind": "vector", "path": str(path), "layers": layers})
    return _plain({"kind": "raster", **raster_info(path)})


def _warn_if_empty(frame: gpd.GeoDataFrame, source, found: str = "road", *,
                   stacklevel: int = 3) -> None:
    """Warn that a job found no ``found`` in ``source`` (a file, or a layer given as a
    GeoDataFrame) when ``frame`` is empty, and wrote empty layers: a valid answer, for a
    forest plot or a field."""
    if len(frame) == 0:
        where = "the input layer" if isinstance(source, gpd.GeoDataFrame) else source
        warnings.warn(f"no {found} found in {where}; wrote empty layers",
                      NoRoadFoundWarning, stacklevel=stacklevel)


def _warn_if_no_road(network: RoadNetwork, source) -> None:
    """Warn that a job found no road in ``source`` and wrote empty layers."""
    _warn_if_empty(network.centrelines, source, stacklevel=4)


def network_summary(out_path, network: RoadNetwork) -> dict:
    """What every road job reports of the network it wrote to ``out_path``: the
    GeoPackage, its roads, their length in metres and its junctions."""
    return {"gpkg": Path(out_path), "roads": len(network.centrelines),
            "length_m": float(network.centrelines.length_m.sum()),
            "junctions": len(network.junctions)}


def _write_network(out_path, network, working_crs, source_crs, source) -> None:
    """Every layer of a network into a GeoPackage, back in the input's own CRS when the
    job worked in another (a geographic raster in its UTM zone); a warning when it is
    empty."""
    layers = network.layers()
    if source_crs is not None and source_crs != working_crs:
        layers = {name: frame.to_crs(source_crs) for name, frame in layers.items()}
    write_geopackage(out_path, layers)
    _warn_if_no_road(network, source)


def _network_quicklook(path, network, first: tuple, *, background, title: str) -> Path:
    """A PNG of a network over its raster: ``first`` (a QA layer and its style), the gaps
    the integer program bridged, the centre lines and the junctions."""
    write_quicklook(path, [
        first,
        (network.qa["gap_edges"].query("selected"),
         dict(color="cyan", linewidth=2, label="bridged gaps")),
        (network.centrelines, dict(color="red", linewidth=1.5, label="road centre lines")),
        (network.junctions, dict(color="yellow", markersize=20, label="junctions")),
    ], background=background, title=title)
    return Path(path)


def _named_layer(source) -> tuple[str, str | None]:
    """``"roads.gpkg|layername=streets"`` (QGIS's and OGR's way of naming a layer of a
    file) as ``("roads.gpkg", "streets")``; a plain path as ``(path, None)``."""
    path, _, layer = str(source).partition("|layername=")
    return path, layer or None


def _layer(source, layer: str) -> gpd.GeoDataFrame:
    """A GeoDataFrame as given, or a file's layer: the one its source names
    (``path|layername=...``), else a GeoPackage's ``layer`` when it has one, else the
    file's only (first) layer."""
    if isinstance(source, gpd.GeoDataFrame):
        return source
    path, named = _named_layer(source)
    if not Path(path).is_file():
        raise MissingFileError(f"{path}: no such file")
    if named is None and path.lower().endswith(".gpkg") and layer in list_layers(path):
        named = layer
    return read_layer(path, named)


def _map_lines(map_source) -> gpd.GeoDataFrame:
    """Road map lines from a GeoDataFrame or a line file: the layer its source names
    (``path|layername=...``), a GeoPackage's road_centrelines layer when it has one, else
    its first layer."""
    if isinstance(map_source, gpd.GeoDataFrame):
        return map_source
    path, named = _named_layer(map_source)
    if not Path(path).is_file():
        raise MissingFileError(f"{path}: no such road map file")
    if named is None and path.lower().endswith(".gpkg") and CENTRELINES in list_layers(path):
        named = CENTRELINES
    return read_layer(path, named)


def read_image(path, *, pixel_m: float | None = None, crs=None) -> tuple[GeoRaster, object]:
    """An aerial image in a metre CRS, and the CRS its results go back to.

    A projected GeoTIFF is read as it is; a geographic one (EPSG:4326, as SpaceNet ships) is
    warped to its UTM zone at its own ground resolution; an image without georeferencing
    (PNG, JPEG) needs ``pixel_m`` and a projected ``crs``.
    """
    raster = read_raster(path, pixel_size=pixel_m, crs=crs)
    if raster.crs is None or not raster.crs.is_geographic:
        return raster, raster.crs
    rows, cols = raster.shape
    (west, south, east, north) = raster.bounds
    lat = np.radians((south + north) / 2.0)
    metres_per_pixel = np.sqrt((east - west) / cols * 111_320.0 * np.cos(lat)
                               * (north - south) / rows * 110_540.0)
    warped, _ = warp_to_utm(path, round(float(metres_per_pixel), 2), nodata=raster.nodata)
    return warped, raster.crs
