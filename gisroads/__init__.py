"""gisroads: road networks from airborne LiDAR and aerial imagery, as GIS vector layers.

The core library: pure functions over numpy arrays and GeoDataFrames, no QGIS import.
The entry points a user calls are importable from their packages (``help()`` on a package
lists them; ``docs/python.md`` shows them at work):

- ``gisroads.lidar``: :func:`~gisroads.lidar.pipeline.extract_roads` (Zhu & Mordohai),
  :func:`~gisroads.lidar.blocks.city_blocks`;
- ``gisroads.imagery``: :func:`~gisroads.imagery.pipeline.extract_image_roads` (Grote &
  Rottensteiner, and the learned cue);
- ``gisroads.snakes``: :func:`~gisroads.snakes.pipeline.extract_map_guided` (Boyko &
  Funkhouser's ribbon snakes along a map);
- ``gisroads.network``: :func:`~gisroads.network.rasters.raster_to_network`, any road raster
  to a network;
- ``gisroads.update``: :func:`~gisroads.update.conflate.conflate`, the change layers of a
  road database;
- ``gisroads.evaluate``: :func:`~gisroads.evaluate.report.evaluate_network` and the metrics;
- ``gisroads.synthetic``: :func:`~gisroads.synthetic.network.make_scene`, scenes with exact
  truth, and their LiDAR and imagery;
- ``gisroads.io``: LAS/LAZ, rasters and GeoPackages.

Importing ``gisroads`` imports none of them; a package imports the module of a name on its
first use (:func:`_lazy_exports`), so ``import gisroads.network`` stays cheap for the
modules that need one function of it.
"""
__version__ = "0.1.0"


def _lazy_exports(package: str, exports: dict[str, str]):
    """The module-level ``__getattr__`` and ``__dir__`` (PEP 562) of a package whose public
    names live in its modules, each imported on the first use of one of its names.

    ``exports`` maps a name to its module, relative to ``package`` (``".pipeline"``). The
    package lists the names in ``__all__``, and imports them under ``TYPE_CHECKING`` too,
    for readers, linters and the import-layer test. A name must not be the name of one of
    the package's modules: importing the module would replace it.
    """
    import importlib
    import sys

    def __getattr__(name: str):
        if name not in exports:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(exports[name], package), name)
        setattr(sys.modules[package], name, value)  # the next lookup finds it directly
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(exports))

    return __getattr__, __dir__
