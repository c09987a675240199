"""'Junction construction and network generation' through qgis_process on hand-made strings."""
import geopandas as gpd
import numpy as np
import pytest
import shapely

from gisroads.io.vector import STYLES_DIR, list_layers, write_geopackage

EPSG = "EPSG:32633"
X0, Y0 = 500000.0, 4500000.0


def write_lines(path, lines, crs=EPSG, **columns):
    frame = gpd.GeoDataFrame(columns, geometry=[shapely.LineString(np.add(c, (X0, Y0)))
                                                for c in lines], crs=EPSG).to_crs(crs)
    write_geopackage(path, {"lines": frame})
    return f"{path}|layername=lines"


def test_t_junction_from_a_plain_line_layer(qgis_process, qgis_app, tmp_path):
    # no width_m / quality fields: the defaults apply (6 m, quality 0.5: radius 20 m)
    strings = write_lines(tmp_path / "strings.gpkg", [[(-60, 0), (60, 0)], [(0, -60), (0, -6)],
                                                      [(150, 150), (165, 150)]])
    out = tmp_path / "network.gpkg"
    result = qgis_process.run("junctionconstruction", ROAD_STRINGS=strings, OUTPUT=out)
    assert (result["ROADS"], result["JUNCTIONS"], result["CONNECTIONS"]) == (3, 1, 1)
    assert result["LENGTH_M"] == pytest.approx(180.0)       # the 15 m fragment is dropped
    assert list_layers(out) == ["road_centrelines", "road_polygons", "junctions",
                                "junction_connections"]
    junctions = gpd.read_file(out, layer="junctions")
    assert junctions.degree.tolist() == [3]
    point = shapely.get_coordinates(junctions.geometry.values)[0]
    assert np.hypot(*(point - (X0, Y0))) < 1.0
    centrelines = gpd.read_file(out, layer="road_centrelines")
    assert centrelines.width_m.tolist() == [6.0] * 3 and centrelines.crs == EPSG
    connections = gpd.read_file(out, layer="junction_connections")
    kept = connections[connections.verified & connections.significant]
    assert kept.kind.tolist() == ["end-road"] and kept.length_m.tolist() == [6.0]

    from qgis.core import QgsVectorLayer
    layer = QgsVectorLayer(f"{out}|layername=junction_connections", "links", "ogr")
    assert layer.loadNamedStyle(str(STYLES_DIR / "junction_connections.qml"))[1]
    categories = {c.value(): c.symbol().symbolLayer(0).properties()["line_style"]
                  for c in layer.renderer().categories()}
    assert categories["end-road"] == "solid" and categories["hypothesis"] == "dash"
    _, styled = QgsVectorLayer(f"{out}|layername=junction_connections", "links",
                               "ogr").loadDefaultStyle()
    assert styled       # the style stored in the GeoPackage


def test_fields_extent_and_parameters_are_used(qgis_process, tmp_path):
    # an 11 m fragment with both ends at the extent's border is kept; quality 0.1 keeps the
    # side road's radius at 12 m, too short for its 15 m gap
    strings = write_lines(tmp_path / "strings.gpkg",
                          [[(-60, 0), (60, 0)], [(0, -80), (0, -15)], [(95, 90), (100, 80)]],
                          width_m=[10.0, 5.0, 4.0], quality=[1.0, 0.1, 0.9])
    out = tmp_path / "network.gpkg"
    result = qgis_process.run("junctionconstruction", ROAD_STRINGS=strings, OUTPUT=out,
                              EXTENT=f"{X0 - 100},{X0 + 100},{Y0 - 100},{Y0 + 100} [{EPSG}]")
    assert (result["ROADS"], result["JUNCTIONS"]) == (3, 0)
    widths = sorted(gpd.read_file(out, layer="road_centrelines").width_m)
    assert widths == [4.0, 5.0, 10.0]
    joined = qgis_process.run("junctionconstruction", ROAD_STRINGS=strings,
                              OUTPUT=tmp_path / "joined.gpkg", MIN_RADIUS=16)
    assert (joined["ROADS"], joined["JUNCTIONS"]) == (3, 1)    # fragment gone, T built


def test_geographic_strings_fail_cleanly(qgis_process, tmp_path):
    strings = write_lines(tmp_path / "strings.gpkg", [[(0, 0), (50, 0)]], crs="EPSG:4326")
    result = qgis_process("run", "gisroads:junctionconstruction", "--",
                          f"ROAD_STRINGS={strings}", f"OUTPUT={tmp_path / 'n.gpkg'}",
                          check=False)
    assert result.returncode == 1
    assert "projected CRS" in result.stdout + result.stderr
    assert not (tmp_path / "n.gpkg").exists()
