"""The road database update job: an extraction compared with a road database."""
from __future__ import annotations

from pathlib import Path

import geopandas as gpd

from ..geo import GeoRaster
from ..io.quicklook import write_quicklook
from ..io.raster import read_raster
from ..io.vector import read_layer, write_geopackage
from ..progress import Progress, report, scaled
from ..update import CHANGES, LAYERS, conflate, read_database
from .common import stage_default


def _coverage(path) -> GeoRaster | gpd.GeoDataFrame:
    """An observability coverage: a raster (non-zero cells observable) or polygons."""
    if Path(path).suffix.lower() in {".tif", ".tiff", ".vrt", ".img"}:
        return read_raster(path)
    return read_layer(path)


def update_job(extracted, database, out_path, *, layer: str | None = None,
               id_field: str | None = None, width_field: str | None = None,
               tolerance_m: float = stage_default(conflate, "tolerance_m"),
               search_m: float = stage_default(conflate, "search_m"), coverage=None,
               quicklook=None, progress: Progress = None) -> dict:
    """Compare an extraction with a road database; write the change layers.

    Parameters
    ----------
    extracted : str or Path
        Extracted centre lines: a gisroads GeoPackage (its ``road_centrelines`` layer) or any
        line file.
    database : str or Path
        Any OGR source (file, ``PG:`` connection string ...), any CRS.
    out_path : str or Path
        GeoPackage receiving the styled layers ``confirmed``, ``missing``, ``new``, ``moved``
        and ``proposed_update``, all in the database's CRS.
    layer : str, optional
        The database's layer (table); by default its first.
    id_field, width_field : str, optional
        The database's feature id field (default: OGR's feature ids) and width field
        (metres).
    tolerance_m, search_m : float
        See :func:`gisroads.update.conflate` (metres).
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
    lines = read_layer(extracted)
    roads = read_database(database, layer)
    changes = conflate(lines, roads, id_field=id_field, width_field=width_field,
                       tolerance_m=tolerance_m, search_m=search_m,
                       coverage=_coverage(coverage) if coverage is not None else None,
                       progress=scaled(progress, 0.05, 0.9))
    report(progress, 0.9, "writing")
    write_geopackage(out_path, changes)
    counted = changes["proposed_update"]["change"].value_counts()
    result = {"gpkg": Path(out_path), **{name: len(changes[name]) for name in LAYERS},
              "changes": {name: int(counted.get(name, 0)) for name in CHANGES}}
    if quicklook is not None:
        report(progress, 0.95, "drawing the quick-look")
        result["quicklook"] = _changes_quicklook(quicklook, roads, lines, changes,
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
