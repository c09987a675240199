"""File I/O: the only place gisroads touches files (LAS/LAZ, rasters, vector layers).

:mod:`.las` reads and writes point clouds (:func:`read_las`, :func:`las_info`),
:mod:`.raster` GeoTIFFs (:func:`read_raster`, :func:`write_geotiff`, :func:`raster_info`),
:mod:`.vector` GeoPackages with their QGIS styles (:func:`write_geopackage`,
:func:`read_layer`, :func:`list_layers`), :mod:`.quicklook` PNG previews
(:func:`write_quicklook`).

The names are imported from their modules on first use, so that ``import gisroads.io``
stays cheap.
"""
from typing import TYPE_CHECKING

from .. import _lazy_exports

__all__ = ["LasError", "PointCloud", "RasterError", "las_info", "list_layers", "raster_info",
           "read_las", "read_layer", "read_raster", "write_geopackage", "write_geotiff",
           "write_quicklook"]

__getattr__, __dir__ = _lazy_exports(__name__, {
    **dict.fromkeys(["LasError", "PointCloud", "las_info", "read_las"], ".las"),
    **dict.fromkeys(["RasterError", "raster_info", "read_raster", "write_geotiff"],
                    ".raster"),
    **dict.fromkeys(["list_layers", "read_layer", "write_geopackage"], ".vector"),
    "write_quicklook": ".quicklook",
})

if TYPE_CHECKING:
    from .las import LasError, PointCloud, las_info, read_las
    from .quicklook import write_quicklook
    from .raster import RasterError, raster_info, read_raster, write_geotiff
    from .vector import list_layers, read_layer, write_geopackage
