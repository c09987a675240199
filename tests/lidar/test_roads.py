"""Zhu & Mordohai's rectangles through the network stage (gisroads.lidar.roads)."""
import numpy as np
import pytest
import shapely
from shapely import LineString, box

from gisroads.lidar.roads import rectangles_to_roads
from tests.rectangle_scenes import EAST, NORTH, along, coords, rectangles


def test_plus_of_four_abutting_rectangles_is_one_junction_of_degree_4():
    net = rectangles_to_roads(rectangles(
        [box(-30, -5, 0, 5), box(0, -5, 30, 5), box(-5, 0, 5, 30), box(-5, -30, 5, 0)],
        [EAST, EAST, NORTH, NORTH]))
    net.validate()
    assert len(net.centrelines) == 4            # two crossing chains, split at the crossing
    assert net.centrelines["length_m"].tolist() == pytest.approx([30.0] * 4)
    assert net.junctions["degree"].tolist() == [4]
    np.testing.assert_allclose(coords(net.junctions.geometry.iloc[0]), [[0, 0]], atol=1e-9)
    assert net.centrelines["method"].unique().tolist() == ["zhu-mordohai"]
    assert net.qa["rectangles"].shape[0] == 4


@pytest.mark.parametrize("stem", [box(-5, 5, 5, 30),      # stops at the bar's edge
                                  box(-5, -5, 5, 30)])    # crosses the bar's surface
def test_t_junction_shares_an_exact_vertex(stem):
    net = rectangles_to_roads(rectangles([box(-30, -5, 0, 5), box(0, -5, 30, 5), stem],
                                           [EAST, EAST, NORTH]))
    assert net.junctions["degree"].tolist() == [3]
    junction = coords(net.junctions.geometry.iloc[0])[0]
    assert junction == pytest.approx([0, 0], abs=1e-9)
    ends = np.concatenate([coords(shapely.get_point(net.centrelines.geometry.values, k))
                           for k in (0, -1)])
    assert (np.all(ends == junction, axis=1)).sum() == 3     # bit-identical vertex
    assert sorted(net.centrelines["length_m"]) == pytest.approx([30, 30, 30], abs=1e-9)


def test_t_junction_with_an_oblique_stem_ending_short_of_the_bar():
    stem, theta = along([(10, 4), (40, 30)], 6.0)
    net = rectangles_to_roads(rectangles([box(-50, -4, 50, 4), stem], [EAST, theta],
                                           width_m=[8.0, 6.0]))
    assert net.junctions["degree"].tolist() == [3]
    junction = net.junctions.geometry.iloc[0]
    assert junction.y == pytest.approx(0.0, abs=1e-9)
    bar = net.centrelines[net.centrelines.width_m == 8.0]
    assert len(bar) == 2 and all(junction.distance(g) == 0.0 for g in bar.geometry)


def test_overlapping_collinear_rectangles_chain_into_their_union():
    net = rectangles_to_roads(rectangles([box(0, -5, 60, 5), box(40, -5, 100, 5)],
                                           [EAST, EAST], score=[0.2, 0.8]))
    assert len(net.centrelines) == 1 and len(net.junctions) == 0
    line = net.centrelines.geometry.iloc[0]
    assert line.length == pytest.approx(100.0, abs=1e-9)
    np.testing.assert_allclose(coords(line)[[0, -1]], [[0, 0], [100, 0]], atol=1e-9)
    assert net.centrelines["score"].iloc[0] == pytest.approx(0.5)   # length-weighted


def test_pieces_offset_sideways_on_a_wide_road_chain_without_a_kink():
    # 20 m road: two pieces 6 m apart sideways, overlapping over 40 m.
    net = rectangles_to_roads(rectangles([box(0, -10, 100, 10), box(60, -4, 160, 16)],
                                           [EAST, EAST], width_m=20.0))
    assert len(net.centrelines) == 1
    xy = coords(net.centrelines.geometry.iloc[0])
    heading = np.degrees(np.arctan2(*np.diff(xy, axis=0).T[::-1]))
    # a smoothstep cross-fade: steepest 1.5 * 6 / 40 rad, about 13 degrees, not a 90-degree jog
    assert np.abs(heading).max() < 14


def test_parallel_roads_side_by_side_stay_apart():
    net = rectangles_to_roads(rectangles([box(0, -5, 100, 5), box(20, 5, 120, 15)],
                                           [EAST, EAST]))
    assert len(net.centrelines) == 2 and len(net.junctions) == 0


def test_l_corner_meets_at_one_node_and_is_one_road():
    # 90 degrees apart, corner squares overlapping: the vertical centre line starts 5 m below
    # the horizontal one's end; that overshoot is cut off and the two merge through the
    # degree-2 corner into one bent road.
    net = rectangles_to_roads(rectangles([box(0, -5, 30, 5), box(25, -5, 35, 30)],
                                           [EAST, NORTH]))
    assert len(net.junctions) == 0 and len(net.centrelines) == 1
    np.testing.assert_allclose(coords(net.centrelines.geometry.iloc[0]),
                               [[0, 0], [30, 0], [30, 30]], atol=1e-9)


def test_polygons_cover_the_rectangles_and_each_road_owns_its_arm():
    rects = rectangles([box(-30, -5, 0, 5), box(0, -5, 30, 5), box(-5, 0, 5, 30),
                        box(-5, -30, 5, 0)], [EAST, EAST, NORTH, NORTH])
    net = rectangles_to_roads(rects)
    union = shapely.union_all(rects.geometry.values)
    covered = shapely.union_all(net.polygons.geometry.values)
    assert set(net.polygons["road_id"]) == set(net.centrelines["road_id"])
    assert shapely.intersection(covered, union).area == pytest.approx(union.area, rel=0.005)
    for road_id, line in zip(net.centrelines.road_id, net.centrelines.geometry):
        polygon = shapely.union_all(net.polygons[net.polygons.road_id == road_id].geometry.values)
        assert polygon.contains(line.interpolate(0.8, normalized=True))


def test_an_end_beside_a_parallel_road_is_no_junction():
    """Two offset pieces of one road side by side (fusa's divided end): no rung between."""
    net = rectangles_to_roads(rectangles([box(0, -5, 60, 5), box(50, 6, 110, 14)],
                                         [NORTH - NORTH, EAST], width_m=[10.0, 8.0]))
    assert len(net.junctions) == 0 and len(net.centrelines) == 2


def test_curved_road_of_six_rectangles_chains_into_one_line_near_the_arc():
    radius, width = 80.0, 8.0
    corners = radius * np.column_stack([np.cos(np.radians(np.arange(0, 61, 10))),
                                        np.sin(np.radians(np.arange(0, 61, 10)))])
    pieces = []
    for a, b in zip(corners[:-1], corners[1:]):
        step = (b - a) / np.linalg.norm(b - a)
        pieces.append(along([a - 2 * step, b + 2 * step], width))   # overlapping by 4 m
    rects = rectangles([p for p, _ in pieces], [t for _, t in pieces], width_m=width)
    net = rectangles_to_roads(rects)
    assert len(net.centrelines) == 1 and len(net.junctions) == 0
    line = net.centrelines.geometry.iloc[0]
    xy = coords(shapely.segmentize(line, 0.25))
    assert np.abs(np.hypot(xy[:, 0], xy[:, 1]) - radius).max() < 1.0
    arc = LineString(radius * np.column_stack([np.cos(np.linspace(0, np.pi / 3, 200)),
                                               np.sin(np.linspace(0, np.pi / 3, 200))]))
    # it spans the arc, plus the 2 m the end rectangles reach past it
    assert shapely.hausdorff_distance(line, arc, densify=0.05) < 2.0 + 1e-6
    heading = np.unwrap(np.arctan2(*np.diff(coords(line), axis=0).T[::-1]))
    assert np.all(np.diff(heading) > -1e-9)                 # turns one way only
    union = shapely.union_all(rects.geometry.values)
    assert shapely.intersection(shapely.union_all(net.polygons.geometry.values),
                                union).area == pytest.approx(union.area, rel=0.01)


def test_short_isolated_pieces_are_dropped_and_empty_input_is_valid():
    net = rectangles_to_roads(rectangles([box(0, -5, 100, 5), box(0, 50, 6, 60)],
                                           [EAST, EAST]))
    assert len(net.centrelines) == 1
    empty = rectangles_to_roads(rectangles([], []))
    empty.validate()
    assert len(empty.centrelines) == len(empty.polygons) == len(empty.junctions) == 0
