import math

import geopandas as gpd
import numpy as np
import pytest
from shapely import LineString, Point, box

from gisroads.evaluate import junction_metrics, topology_metrics
from gisroads.evaluate.topology import line_graph

CROSS = [LineString([(-50, 0), (50, 0)]), LineString([(0, -50), (0, 50)])]


def points(*xy):
    return gpd.GeoSeries([Point(p) for p in xy], crs="EPSG:32633")


def test_cross_is_one_component_with_one_degree_4_junction():
    graph = line_graph(CROSS)
    assert len(graph.lines) == 4
    assert graph.components()[0] == 1
    junction = graph.degree >= 3
    assert graph.degree[junction].tolist() == [4]
    assert graph.nodes[junction].tolist() == [[0.0, 0.0]]
    assert graph.lengths.tolist() == [50.0] * 4


def test_line_ending_on_another_makes_a_degree_3_junction():
    graph = line_graph([LineString([(0, 0), (100, 0)]), LineString([(40, 0), (40, 30)])])
    assert graph.degree[graph.degree >= 3].tolist() == [3]
    assert graph.nodes[graph.degree >= 3].tolist() == [[40.0, 0.0]]


def test_parallel_edges_keep_the_shortest_in_the_adjacency():
    straight = LineString([(0, 0), (10, 0)])
    detour = LineString([(0, 0), (5, 20), (10, 0)])
    adjacency = line_graph([detour, straight]).adjacency()
    assert adjacency.nnz == 1 and adjacency.data.tolist() == [10.0]


def test_topology_metrics_of_a_cross():
    m = topology_metrics(CROSS, CROSS)
    assert m["components_extracted"] == m["components_reference"] == 1
    assert m["junctions_extracted"] == m["junctions_reference"] == m["junction_matches"] == 1
    assert m["junction_precision"] == m["junction_recall"] == 1.0


def test_disjoint_lines_are_two_components_without_junctions():
    lines = [LineString([(0, 0), (100, 0)]), LineString([(0, 50), (100, 50)])]
    m = topology_metrics(lines, CROSS)
    assert m["components_extracted"] == 2
    assert m["junctions_extracted"] == 0
    assert m["junction_matches"] == 0
    assert math.isnan(m["junction_precision"])
    assert m["junction_recall"] == 0.0


def test_shifted_cross_matches_within_the_radius_only():
    near = [LineString([(-47, 4), (53, 4)]), LineString([(3, -46), (3, 54)])]  # 5 m off
    assert topology_metrics(near, CROSS, junction_radius_m=10.0)["junction_matches"] == 1
    assert topology_metrics(near, CROSS, junction_radius_m=4.9)["junction_matches"] == 0


def test_empty_extracted_network():
    m = topology_metrics([], CROSS)
    assert m["components_extracted"] == 0 and m["junction_matches"] == 0


def test_junction_matching_is_one_to_one_with_a_closed_radius():
    # Reference A(0, 0), B(100, 0), C(200, 0). Extracted: two points near A (only one may
    # match it), one 10.001 m from B (outside), one exactly 10 m from C (6-8-10, inside) and
    # a stray one. Matches: A and C -> precision 2/5, recall 2/3.
    extracted = points((1, 1), (3, 4), (100, 10.001), (206, 8), (500, 500))
    reference = points((0, 0), (100, 0), (200, 0))
    m = junction_metrics(extracted, reference, radius_m=10.0)
    assert m["junction_matches"] == 2
    assert m["junction_precision"] == pytest.approx(2 / 5, abs=1e-12)
    assert m["junction_recall"] == pytest.approx(2 / 3, abs=1e-12)


def test_junction_matching_is_optimal_not_greedy():
    # X is nearest to P (5 m), but taking X-P strands Y; Y-P (8 m) and X-Q (10 m) match both.
    reference = points((0, 0), (15, 0))
    extracted = points((5, 0), (-8, 0))
    assert junction_metrics(extracted, reference, radius_m=10.0)["junction_matches"] == 2


def test_junction_metrics_checks_its_input():
    with pytest.raises(ValueError, match="reference"):
        junction_metrics(points((0, 0)), points())
    with pytest.raises(ValueError, match="Point"):
        junction_metrics([box(0, 0, 1, 1)], points((0, 0)))


def test_many_junctions_match_without_a_dense_matrix():
    rng = np.random.default_rng(0)
    xy = np.stack(np.meshgrid(np.arange(100) * 50.0, np.arange(100) * 50.0), -1).reshape(-1, 2)
    moved = xy + rng.uniform(-3, 3, xy.shape)
    m = junction_metrics(gpd.points_from_xy(*moved.T), gpd.points_from_xy(*xy.T), radius_m=10)
    assert m["junction_matches"] == len(xy) == 10000
