"""gisroads: road networks from airborne LiDAR and aerial imagery, as GIS vector layers.

The core library: pure functions over numpy arrays and GeoDataFrames, no QGIS import.
Subpackages: ``io`` (LAS/LAZ, rasters, GeoPackage), ``synthetic`` (scenes with exact truth),
``evaluate`` (buffer, area, topology and path-length metrics).
"""
__version__ = "0.1.0"
