import math

import geopandas as gpd
import numpy as np
import pytest
import shapely
from shapely import LineString, box

from gisroads.vectorize import rectangle_centrelines, ribbon_areas, ribbons_to_network
from tests.rectangle_scenes import UTM, coords, rectangles


def test_centre_line_is_the_long_mid_line_whatever_the_corner():
    rect = shapely.affinity.rotate(box(10, 20, 50, 28), 30, origin=(10, 20))
    theta = math.radians(30)
    (line,) = rectangle_centrelines(rectangles([rect], [theta]))
    u, n = np.array([math.cos(theta), math.sin(theta)]), np.array([-math.sin(theta),
                                                                  math.cos(theta)])
    np.testing.assert_allclose(coords(line), [(10, 20) + 4 * n, (10, 20) + 40 * u + 4 * n],
                               atol=1e-9)
    (flipped,) = rectangle_centrelines(rectangles([rect], [theta + math.pi]))
    np.testing.assert_allclose(coords(flipped), coords(line)[::-1], atol=1e-9)


def test_ribbon_areas_follow_per_vertex_widths():
    (area,) = ribbon_areas([LineString([(0, 0), (10, 0), (20, 0)])], [[2.0, 4.0, 6.0]])
    # the disc of the middle vertex (radius 2) bulges a little past the narrower trapezoid
    assert area.area == pytest.approx(10 * 3 + 10 * 5, rel=1e-4)
    (bent,) = ribbon_areas([LineString([(0, 0), (10, 0), (10, 10)])], [4.0])
    corner = bent.difference(box(0, -2, 10, 2)).difference(box(8, 0, 12, 10))
    assert corner.area == pytest.approx(math.pi * 4 / 4, rel=0.02)   # round outer joint


def test_ribbons_make_the_same_junctions_and_carry_widths():
    ribbons = gpd.GeoDataFrame(
        {"widths_m": [np.array([6.0, 8.0, 10.0]), np.array([7.0, 7.0])], "score": [1.0, 2.0]},
        geometry=[LineString([(0, 0), (50, 0), (100, 0)]), LineString([(50, 3), (50, 40)])],
        crs=UTM)
    net = ribbons_to_network(ribbons, method="boyko-funkhouser")
    net.validate()
    assert net.junctions["degree"].tolist() == [3]
    np.testing.assert_allclose(coords(net.junctions.geometry.iloc[0]), [[50, 0]], atol=1e-9)
    stem = net.centrelines[net.centrelines.score == 2.0]
    assert stem["width_m"].tolist() == [7.0] and stem["length_m"].iloc[0] == pytest.approx(40)
    assert set(net.centrelines["width_m"]) == {8.0, 7.0}    # the ribbon's weighted mean
    assert net.centrelines["method"].unique().tolist() == ["boyko-funkhouser"]
    # the width at every vertex: the bar's halves run from 6 to 8 m and from 8 to 10 m
    per_vertex = [np.array(text.split(","), float) for text in net.centrelines.vertex_widths_m]
    assert [len(w) for w in per_vertex] == [len(coords(g)) for g in net.centrelines.geometry]
    ends = sorted((w[0], w[-1]) if coords(g)[0][0] < coords(g)[-1][0] else (w[-1], w[0])
                  for w, g, score in zip(per_vertex, net.centrelines.geometry,
                                         net.centrelines.score) if score == 1.0)
    assert ends == [(6.0, 8.0), (8.0, 10.0)]
    scalar = ribbons_to_network(ribbons.drop(columns="widths_m").assign(width_m=[8.0, 7.0]),
                                method="x")
    assert scalar.junctions["degree"].tolist() == [3]
    assert scalar.polygons["area_m2"].sum() == pytest.approx(100 * 8 + 36 * 7, rel=0.01)
    assert "vertex_widths_m" not in scalar.centrelines  # one width per ribbon: nothing to add


def test_no_pieces_give_empty_contract_layers():
    import geopandas as gpd
    from gisroads.geo import CONTRACT_SCHEMA
    empty = gpd.GeoDataFrame(geometry=gpd.GeoSeries([], crs="EPSG:32633"), crs="EPSG:32633")
    from gisroads.lidar.roads import rectangles_to_roads
    for network in (rectangles_to_roads(empty), ribbons_to_network(empty, method="x")):
        network.validate()
        assert network.crs == "EPSG:32633"
        for name in CONTRACT_SCHEMA:
            assert len(network.layers()[name]) == 0
