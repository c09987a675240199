import re
import sqlite3

import geopandas as gpd
import pytest
import shapely

from gisroads.errors import GisroadsError
from gisroads.geo import network_from_centrelines
from gisroads.io.vector import list_layers, read_layer, write_geopackage
from tests.road_layers import geometry_types


def small_network():
    lines = gpd.GeoDataFrame({"width_m": [8.0, 6.0]},
                             geometry=[shapely.LineString([(0, 50), (100, 50)]),
                                       shapely.LineString([(50, 0), (50, 100)])],
                             crs="EPSG:32754")
    return network_from_centrelines(lines, method="test")


def test_multi_layer_geopackage_with_styles(tmp_path):
    net = small_network()
    path = write_geopackage(tmp_path / "net.gpkg", net.layers())
    assert list_layers(path) == ["road_centrelines", "road_polygons", "junctions"]
    back = read_layer(path)
    assert back.crs.to_epsg() == 32754 and len(back) == 2
    assert set(back.columns) >= {"road_id", "width_m", "length_m", "method", "score"}
    con = sqlite3.connect(path)
    rows = con.execute("SELECT f_table_name, f_geometry_column, useAsDefault, styleQML "
                       "FROM layer_styles").fetchall()
    times = [t for (t,) in con.execute("SELECT update_time FROM layer_styles")]
    (version,) = con.execute("PRAGMA user_version").fetchone()
    con.close()
    assert version == 10200  # GeoPackage 1.2 in both environments (QGIS 3.22's GDAL)
    # GeoPackage datetimes are ISO 8601 with a Z (GDAL warns about SQLite's default format)
    assert all(re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z", t) for t in times)
    assert {r[0] for r in rows} == {"road_centrelines", "road_polygons", "junctions"}
    assert all(r[1] == "geom" and r[2] == 1 and r[3].lstrip().startswith("<!DOCTYPE qgis")
               for r in rows)
    assert [p.name for p in tmp_path.iterdir()] == ["net.gpkg"]


def test_failed_write_keeps_previous_file_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "net.gpkg"
    write_geopackage(target, small_network().layers())
    before = target.read_bytes()
    bad = {"road_centrelines": small_network().centrelines, "broken": "not a frame"}
    with pytest.raises(AttributeError):
        write_geopackage(target, bad)
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["net.gpkg"]


def test_read_layer_reprojects_and_refuses_bad_paths(tmp_path):
    path = write_geopackage(tmp_path / "n.gpkg", small_network().layers())
    wgs = read_layer(path, "junctions", crs="EPSG:4326")
    assert wgs.crs.to_epsg() == 4326 and wgs.geometry.y.iloc[0] < 0  # UTM 54 south
    with pytest.raises(FileNotFoundError):
        read_layer(tmp_path / "none.gpkg")
    with pytest.raises(GisroadsError, match=r"no layer 'streets' \(its layers: "
                                            r"road_centrelines, road_polygons, junctions\)"):
        read_layer(path, "streets")
    with pytest.raises(ValueError, match=".gpkg"):
        write_geopackage(tmp_path / "n.shp", small_network().layers())


def test_empty_layers_keep_their_geometry_type(tmp_path):
    net = small_network()
    single = network_from_centrelines(net.centrelines.iloc[:1])  # one road: no junction
    empty = network_from_centrelines(net.centrelines.iloc[:0])
    empty.qa = {"rectangles": gpd.GeoDataFrame(geometry=[], crs=net.crs),
                "gap_edges": gpd.GeoDataFrame(geometry=[], crs=net.crs),
                "unstyled": gpd.GeoDataFrame(geometry=[], crs=net.crs)}
    write_geopackage(tmp_path / "single.gpkg", single.layers())
    write_geopackage(tmp_path / "empty.gpkg", empty.layers())
    assert len(single.junctions) == 0
    assert geometry_types(tmp_path / "single.gpkg") == {
        "road_centrelines": "LINESTRING", "road_polygons": "POLYGON", "junctions": "POINT"}
    # QA layers take the type their style draws; a layer nothing describes stays GEOMETRY
    assert geometry_types(tmp_path / "empty.gpkg") == {
        "road_centrelines": "LINESTRING", "road_polygons": "POLYGON", "junctions": "POINT",
        "rectangles": "POLYGON", "gap_edges": "LINESTRING", "unstyled": "GEOMETRY"}
    back = read_layer(tmp_path / "empty.gpkg", "road_centrelines")
    assert len(back) == 0 and back.crs.to_epsg() == 32754
    assert set(back.columns) >= {"road_id", "width_m", "length_m", "method", "score"}
