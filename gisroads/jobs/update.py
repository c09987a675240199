"""The road database update job: an extraction compared with a road database."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import geopandas as gpd
import shapely

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..io.quicklook import write_quicklook
from ..io.raster import read_raster
from ..io.vector import write_geopackage
from ..progress import Progress, report, scaled
from ..update import CHANGES, LAYERS, MatchOptions, conflate, read_database
from .common import _layer, _named_layer


def _coverage(path) -> GeoRaster | gpd.GeoDataFrame:
    """An observability coverage: a raster (non-zero cells observable) or polygons."""
    if Path(path).suffix.lower() in {".tif", ".tiff", ".vrt", ".img"}:
        return read_raster(path)
    return _layer(path, "coverage")


def _database(source, layer: str | None, fid_field: str | None) -> gpd.GeoDataFrame:
    """The road database with its feature ids as index: the source's, or those a field
    carries (and the field itself left out)."""
    path, named = _named_layer(source)
    roads = read_database(path, layer or named)
    if fid_field is None:
        return roads
    if fid_field not in roads:
        raise GisroadsError(f"the database has no field {fid_field!r}")
    return roads.set_index(roads[fid_field].astype("int64").rename(None)).drop(
        columns=fid_field)


def update_job(extracted, database, out_path, options: MatchOptions = MatchOptions(), *,
               layer: str | None = None, id_field: str | None = None,
               fid_field: str | None = None, width_field: str | None = None, coverage=None,
               quicklook=None, progress: Progress = None, **changes) -> dict:
    """Compare an extraction with a road database; write the change layers.

    Parameters
    ----------
    extracted : str or Path
        Extracted centre lines: a gisroads GeoPackage (its ``road_centrelines`` layer) or any
        line file (``path|layername=`` names a layer).
    database : str or Path
        Any OGR source (file, ``path|layername=``, ``PG:`` connection string ...), any CRS.
    out_path : str or Path
        GeoPackage receiving the styled layers ``confirmed``, ``missing``, ``new``, ``moved``
        and ``proposed_update``, all in the database's CRS, in 2-D.
    layer : str, optional
        The database's layer (table); by default its first.
    id_field, width_field : str, optional
        The database's road id field (default: its feature ids) and width field (metres).
    fid_field : str, optional
        A field that carries the database's feature ids instead of the source's own (a copy
        of a layer whose ids its file cannot keep, e.g. a PostGIS table or a selection
        written to a temporary GeoPackage); it is not one of the database's fields in the
        outputs.
    options : MatchOptions
        How lines match (:func:`gisroads.update.conflate`); ``**changes`` change its fields
        for this call, e.g. ``tolerance_m=4.0``.
    coverage : str or Path, optional
        Where the data could show a road: a polygon file, or a raster whose non-zero cells
        are observable.
    quicklook : str or Path, optional
        Also draw the changes over the database's roads as a PNG.

    Returns
    -------
    dict
        Output path, feature count of each layer and count of each change.
    """
    report(progress, 0.0, "reading")
    lines = _layer(extracted, "road_centrelines")
    roads = _database(database, layer, fid_field)
    found = conflate(lines, roads, replace(options, **changes), id_field=id_field,
                     width_field=width_field,
                     coverage=_coverage(coverage) if coverage is not None else None,
                     progress=scaled(progress, 0.05, 0.9))
    report(progress, 0.9, "writing")
    found = {name: frame.set_geometry(gpd.GeoSeries(shapely.force_2d(frame.geometry.values),
                                                    index=frame.index, crs=frame.crs))
             for name, frame in found.items()}
    write_geopackage(out_path, found)
    counted = found["proposed_update"]["change"].value_counts()
    result = {"gpkg": Path(out_path), **{name: len(found[name]) for name in LAYERS},
              "changes": {name: int(counted.get(name, 0)) for name in CHANGES}}
    if quicklook is not None:
        report(progress, 0.95, "drawing the quick-look")
        result["quicklook"] = _changes_quicklook(quicklook, roads, lines, found,
                                                 title=f"{Path(str(extracted)).name} against "
                                                       "the database")
    report(progress, 1.0, "done")
    return result


def _changes_quicklook(path, database: gpd.GeoDataFrame, extracted: gpd.GeoDataFrame,
                       changes: dict, *, title: str) -> Path:
    """A PNG of the change layers over the database's roads, in metres (the database's CRS,
    or its UTM zone when that is geographic)."""
    crs = database.crs
    if crs is not None and not crs.is_projected:
        crs = database.estimate_utm_crs()

    def drawn(frame):
        return frame.to_crs(crs) if crs is not None and frame.crs is not None else frame

    write_quicklook(path, [
        (drawn(database), dict(color="lightgrey", linewidth=3, label="database")),
        (drawn(extracted), dict(color="steelblue", linewidth=0.8, label="extracted")),
        (drawn(changes["missing"]), dict(color="red", linewidth=2, linestyle="--",
                                         label="missing")),
        (drawn(changes["new"]), dict(color="limegreen", linewidth=2, label="new")),
        (drawn(changes["moved"]), dict(color="orange", linewidth=2, label="moved")),
    ], title=title)
    return Path(path)
