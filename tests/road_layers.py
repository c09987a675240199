"""What tests assert of a road-network GeoPackage: its layers' declared geometry types, and
the empty contract layers of a job that found no road."""
import sqlite3

from gisroads.geo import CONTRACT_GEOMETRY, CONTRACT_SCHEMA
from gisroads.io.vector import read_layer


def geometry_types(path) -> dict[str, str]:
    """Layer name to its ``gpkg_geometry_columns.geometry_type_name`` (what QGIS reads)."""
    con = sqlite3.connect(path)
    try:
        return dict(con.execute("SELECT table_name, geometry_type_name"
                                " FROM gpkg_geometry_columns").fetchall())
    finally:
        con.close()


def assert_empty_road_layers(path) -> None:
    """road_centrelines, road_polygons and junctions are in ``path``, empty, with their
    fields and their own geometry type (QGIS opens them as layers, not tables)."""
    types = geometry_types(path)
    for name, kind in CONTRACT_GEOMETRY.items():
        assert types[name] == kind.upper(), (name, types[name])
        frame = read_layer(path, name)
        assert len(frame) == 0, name
        assert set(CONTRACT_SCHEMA[name]) <= set(frame.columns), name
