"""Read a road database from any OGR source (files, ``PG:`` connection strings, WFS ...) with
its feature ids.

geopandas reads through pyogrio (modern wheels) or Fiona (Debian's geopandas 0.12); either way
the frame's index holds OGR's feature ids (FIDs), so they go through the comparison
unchanged. The GDAL inside the pyogrio wheel has no PostgreSQL driver: a source it cannot open
that is not a file is copied by the system's ``ogr2ogr`` (FIDs preserved) into a temporary
GeoPackage and read from there.
"""
from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import geopandas as gpd

from ..errors import GisroadsError
from ..io.vector import list_layers


def _read_with_fids(source: str, layer: str | None) -> gpd.GeoDataFrame:
    """One layer of ``source`` with the FIDs as index, through pyogrio or Fiona."""
    try:
        import pyogrio  # noqa: F401
    except ImportError:
        import fiona
        with fiona.open(source, layer=layer) as collection:
            features = list(collection)
            crs = collection.crs_wkt or None
            columns = list(collection.schema["properties"])
        frame = gpd.GeoDataFrame.from_features(features, crs=crs,
                                               columns=columns + ["geometry"])
        frame.index = [int(f.id if hasattr(f, "id") else f["id"]) for f in features]
        return frame
    return gpd.read_file(source, layer=layer, engine="pyogrio", fid_as_index=True)


def _read_through_ogr2ogr(source: str, layer: str | None) -> gpd.GeoDataFrame:
    """``source`` copied by the system's ogr2ogr into a temporary GeoPackage, then read."""
    with tempfile.TemporaryDirectory(prefix="gisroads-db-") as folder:
        copy = Path(folder) / "database.gpkg"
        command = ["ogr2ogr", "-f", "GPKG", "-preserve_fid", "-nln", "database", str(copy),
                   source] + ([layer] if layer else [])
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0:
            raise GisroadsError(f"{source}: cannot be read ({done.stderr.strip()})")
        return _read_with_fids(str(copy), "database")


def read_database(source, layer: str | None = None) -> gpd.GeoDataFrame:
    """A road database layer, its index holding the source's feature ids.

    Parameters
    ----------
    source : str or Path
        Any OGR data source: a file (GeoPackage, Shapefile, GeoJSON ...) or a connection
        string such as ``PG:dbname=roads host=localhost``.
    layer : str, optional
        Layer (table) name; by default the source's first layer.

    Returns
    -------
    GeoDataFrame
        In the source's CRS.
    """
    source = str(source)
    is_file = Path(source).exists()
    if layer is None and is_file and source.lower().endswith(".gpkg"):
        layer = list_layers(source)[0]  # its first feature layer, not layer_styles
    try:
        return _read_with_fids(source, layer)
    except Exception as err:  # pyogrio and Fiona raise their own error classes
        if is_file or shutil.which("ogr2ogr") is None:
            raise GisroadsError(f"{source}: cannot be read as a vector layer ({err})") from None
        return _read_through_ogr2ogr(source, layer)
