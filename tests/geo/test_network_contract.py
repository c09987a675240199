import geopandas as gpd
import numpy as np
import pytest
import shapely

from gisroads.geo import (CONTRACT_SCHEMA, GeoRaster, junctions_from_lines,
                          network_from_centrelines)
from affine import Affine


def lines(*coords, widths):
    return gpd.GeoDataFrame({"width_m": widths},
                            geometry=[shapely.LineString(c) for c in coords], crs="EPSG:32633")


def test_cross_gives_one_degree_four_junction():
    net = network_from_centrelines(lines([(0, 50), (100, 50)], [(50, 0), (50, 100)],
                                         widths=[10.0, 6.0]), method="test")
    net.validate()
    assert len(net.junctions) == 1
    assert net.junctions.degree.tolist() == [4]
    assert shapely.get_coordinates(net.junctions.geometry.values).tolist() == [[50.0, 50.0]]
    np.testing.assert_allclose(net.centrelines.length_m, [100.0, 100.0])
    np.testing.assert_allclose(sorted(net.polygons.area_m2), [600.0, 1000.0])
    assert set(net.centrelines.method) == {"test"}


def test_t_junction_and_dead_ends():
    j = junctions_from_lines(shapely.linestrings([[(0, 0), (100, 0)], [(50, 0), (50, 80)]]),
                             "EPSG:32633")
    assert j.degree.tolist() == [3]


def test_lines_crossing_mid_segment_without_shared_vertex_are_noded():
    j = junctions_from_lines(shapely.linestrings([[(0, 0), (10, 10)], [(0, 10), (10, 0)]]),
                             None)
    assert j.degree.tolist() == [4]
    np.testing.assert_allclose(shapely.get_coordinates(j.geometry.values), [[5.0, 5.0]])


def test_empty_network_keeps_schema():
    net = network_from_centrelines(lines(widths=[]))
    for name, frame in net.layers().items():
        assert set(CONTRACT_SCHEMA[name]) <= set(frame.columns)
        assert len(frame) == 0


def test_validate_rejects_missing_column():
    net = network_from_centrelines(lines([(0, 0), (1, 0)], widths=[5.0]))
    net.centrelines = net.centrelines.drop(columns="score")
    with pytest.raises(ValueError, match="score"):
        net.validate()


def test_georaster_pixel_indexing():
    r = GeoRaster(np.zeros((4, 6)), Affine(0.5, 0, 100.0, 0, -0.5, 200.0), None)
    assert r.bounds == (100.0, 198.0, 103.0, 200.0)
    rows, cols = r.xy_to_rowcol([100.1, 102.9], [199.9, 198.1])
    assert rows.tolist() == [0, 3] and cols.tolist() == [0, 5]
