import math
from pathlib import Path

import geopandas as gpd
import numpy as np
import pytest
import shapely
from shapely import LineString, MultiLineString, Point
from shapely.ops import substring

from gisroads.evaluate import evaluate_network
from gisroads.geo import line_end_degrees, node_lines
from gisroads.network.junctions import (approximate_strings, find_junctions,
                                      merge_close_junctions, remove_duplicates, road_regions,
                                      road_strings_from_lines, significant_components,
                                      strings_to_network)
from gisroads.progress import Cancelled
from gisroads.synthetic import make_scene

UTM = "EPSG:32633"
SPACENET = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "imagery" / "spacenet"
DIAGONAL = np.array([1.0, 1.0]) / math.sqrt(2)


def strings(lines, width_m=8.0, quality=0.8, crs=UTM):
    n = len(lines)
    return gpd.GeoDataFrame(
        {"string_id": np.arange(n, dtype=np.int64),
         "width_m": np.broadcast_to(np.asarray(width_m, float), (n,)).copy(),
         "quality": np.broadcast_to(np.asarray(quality, float), (n,)).copy()},
        geometry=list(lines), crs=crs)


def xy(geom):
    return shapely.get_coordinates(geom)


def junction_points(network):
    return xy(network.junctions.geometry.values)


def verified(connections):
    return connections[connections["verified"]]


# --- approximation ------------------------------------------------------------------------

def test_approximation_splits_at_the_farthest_vertex_until_within_tolerance():
    # (30, 5) is farthest from the chord; then (20, 0) lies 3.3 m from (0,0)-(30,5) and
    # stays; (10, 0.5) lies 0.5 m from (0,0)-(20,0) and goes
    line = LineString([(0, 0), (10, 0.5), (20, 0), (30, 5), (40, 0)])
    roads = approximate_strings(strings([line], width_m=7.0, quality=0.6), tolerance_m=1.0)
    np.testing.assert_allclose(xy(roads.geometry.iloc[0]), [(0, 0), (20, 0), (30, 5), (40, 0)])
    assert roads["width_m"].tolist() == [7.0] and roads["quality"].tolist() == [0.6]
    assert roads["length_m"].iloc[0] == pytest.approx(20 + 2 * math.hypot(10, 5))
    finer = approximate_strings(strings([line]), tolerance_m=0.4)
    assert len(xy(finer.geometry.iloc[0])) == 5


def test_multipart_strings_become_one_road_per_disjoint_part():
    joined = MultiLineString([[(0, 0), (10, 0)], [(10, 0), (20, 0)]])
    apart = MultiLineString([[(0, 50), (10, 50)], [(30, 50), (40, 50)]])
    frame = strings([joined, apart])
    frame["string_id"] = [7, 9]
    roads = approximate_strings(frame)
    assert roads["string_id"].tolist() == [7, 9, 9]
    assert roads["road_id"].tolist() == [0, 1, 2]
    np.testing.assert_allclose(xy(roads.geometry.iloc[0]), [(0, 0), (20, 0)])


@pytest.mark.parametrize("change, message", [
    (lambda f: f.drop(columns="width_m"), "width_m"),
    (lambda f: f.assign(width_m=-1.0), "width"),
    (lambda f: f.assign(quality=1.5), "quality"),
    (lambda f: f.set_geometry([Point(0, 0)]), "lines"),
    (lambda f: f.to_crs("EPSG:4326"), "projected"),
])
def test_bad_road_strings_are_refused(change, message):
    frame = change(strings([LineString([(500000, 4500000), (500050, 4500000)])]))
    with pytest.raises(ValueError, match=message):
        approximate_strings(frame)


def test_plain_lines_get_default_width_and_quality_where_they_have_none():
    lines = gpd.GeoDataFrame({"width_m": [8.0, None]},
                             geometry=[LineString([(0, 0), (9, 0)])] * 2, crs=UTM)
    frame = road_strings_from_lines(lines, width_m=5.0, quality=0.3)
    assert frame["width_m"].tolist() == [8.0, 5.0] and frame["quality"].tolist() == [0.3] * 2
    assert approximate_strings(frame)["string_id"].tolist() == [0, 1]


def test_road_regions_cover_the_width_with_flat_caps():
    roads = approximate_strings(strings([LineString([(0, 0), (40, 0), (40, 30)])],
                                        width_m=6.0))
    (region,) = road_regions(roads)
    inside = shapely.points([(20, 2.9), (20, -2.9), (42.9, 15), (37.1, 15), (0.1, 0)])
    outside = shapely.points([(20, 3.1), (43.1, 15), (-0.1, 0), (40, 30.1)])
    assert shapely.contains(region, inside).all()
    assert not shapely.intersects(region, outside).any()
    assert region.area == pytest.approx(6 * 70, rel=0.02)


# --- duplicates ---------------------------------------------------------------------------

def test_close_parallel_duplicate_of_lower_quality_is_removed():
    good = LineString([(0, 0), (100, 0)])
    offset = LineString([(3, 2), (98, 2.5)])     # 2 m beside it, nearly as long
    roads = approximate_strings(strings([good, offset], quality=[0.5, 0.9]))
    kept = remove_duplicates(roads)
    assert kept["road_id"].tolist() == [1]      # the better one, whichever is longer
    network, _ = strings_to_network(strings([good, offset], quality=[0.9, 0.5]))
    assert len(network.centrelines) == 1
    np.testing.assert_allclose(xy(network.centrelines.geometry.iloc[0]), [(0, 0), (100, 0)])


def test_dual_carriageway_is_no_duplicate():
    roads = approximate_strings(strings([LineString([(0, 0), (100, 0)]),
                                         LineString([(0, 11), (100, 11)])], width_m=7.5))
    assert len(remove_duplicates(roads)) == 2


def test_road_mostly_overlapped_by_another_is_removed_whatever_its_quality():
    long_road = LineString([(0, 0), (200, 0)])
    on_it = LineString([(50, 1), (80, 1)])
    crossing = LineString([(100, -30), (100, 30)])   # overlaps only across the long road
    roads = approximate_strings(strings([long_road, on_it, crossing], quality=[0.4, 1.0, 0.4]))
    assert remove_duplicates(roads)["road_id"].tolist() == [0, 2]


# --- junctions ----------------------------------------------------------------------------

def test_t_junction_six_metres_short_meets_the_road_at_an_exact_vertex():
    main, side = LineString([(-50, 0), (50, 0)]), LineString([(0, -50), (0, -6)])
    roads, connections = find_junctions(approximate_strings(strings([main, side])))
    (link,) = verified(connections).itertuples()
    assert (link.kind, link.from_road, link.to_road) == ("end-road", 1, 0)
    assert link.length_m == pytest.approx(6.0)
    np.testing.assert_allclose(xy(link.geometry), [(0, -6), (0, 0)])
    assert [0.0, 0.0] in xy(roads.geometry.iloc[0]).tolist()    # the shared vertex
    network, _ = strings_to_network(strings([main, side]))
    network.validate()
    assert network.junctions["degree"].tolist() == [3]
    assert np.hypot(*junction_points(network)[0]) < 1.0
    assert sorted(network.centrelines["length_m"]) == pytest.approx([50, 50, 50])


def test_junction_at_45_degrees_eight_metres_short_is_within_a_metre():
    end = -8 * DIAGONAL
    side = LineString([end - 40 * DIAGONAL, end])
    main = LineString([(-60, 0), (60, 0)])
    network, connections = strings_to_network(strings([main, side]))
    assert verified(connections)["kind"].tolist() == ["end-road"]
    assert verified(connections)["length_m"].tolist() == pytest.approx([8.0])
    assert network.junctions["degree"].tolist() == [3]
    assert np.hypot(*junction_points(network)[0]) < 1.0


def test_non_orthogonal_junction_of_two_short_ends_is_the_polygon_through_the_intersection():
    # neither extension hits the other road: the connection bends at the intersection point
    side = LineString([-45 * DIAGONAL, -5 * DIAGONAL])
    main = LineString([(60, 0), (7, 0)])
    network, connections = strings_to_network(strings([side, main]))
    (link,) = verified(connections).itertuples()
    assert link.kind == "intersection-polygon"
    np.testing.assert_allclose(xy(link.geometry)[1], (0, 0), atol=1e-9)
    assert link.length_m == pytest.approx(12.0)
    (road,) = network.centrelines.geometry.values     # one road around the bend
    assert np.min(np.hypot(*xy(road).T)) < 1e-9


def test_collinear_roads_are_joined_end_to_end_and_their_width_averaged():
    left, right = LineString([(-60, 0), (-5, 0)]), LineString([(5.5, 0.5), (60.5, 0.5)])
    network, connections = strings_to_network(strings([left, right], width_m=[6.0, 10.0]))
    (link,) = verified(connections).itertuples()
    assert link.kind == "end-end"
    np.testing.assert_allclose(xy(link.geometry), [(-5, 0), (5.5, 0.5)])
    assert len(network.centrelines) == 1 and len(network.junctions) == 0
    road = network.centrelines.iloc[0]
    gap = math.hypot(10.5, 0.5)
    assert road["length_m"] == pytest.approx(110 + gap)
    assert road["width_m"] == pytest.approx((55 * 6 + 55 * 10 + gap * 8) / (110 + gap))
    (polygon,) = network.polygons.geometry.values
    assert polygon.area == pytest.approx(road["width_m"] * road["length_m"], rel=0.01)


def test_direction_at_an_end_is_that_of_its_last_metres_not_of_a_hook():
    # the last approximation segment of the left road turns 45 degrees away over 2 m;
    # over its last 10 m the road still points at the right one
    left = LineString([(-60, 0), (-8, 0), (-6.5, 1.5)])
    right = LineString([(6, 0), (60, 0)])
    network, connections = strings_to_network(strings([left, right]))
    assert verified(connections)["kind"].tolist() == ["end-end"]
    assert len(network.centrelines) == 1
    _, unjoined = strings_to_network(strings([left, right]), end_window_m=1.0)
    assert "end-end" not in set(verified(unjoined)["kind"])


def test_crossing_roads_give_one_junction_of_degree_4():
    network, connections = strings_to_network(strings([LineString([(-50, 0), (50, 0)]),
                                                       LineString([(3, -50), (-3, 50)])]))
    assert network.junctions["degree"].tolist() == [4]
    assert np.hypot(*junction_points(network)[0]) < 1e-9
    assert len(network.centrelines) == 4
    assert verified(connections)["kind"].tolist() == ["crossing"]
    assert verified(connections)["length_m"].tolist() == [0.0]


def test_overshooting_end_ends_at_the_road_it_crosses():
    main, side = LineString([(-50, 0), (50, 0)]), LineString([(0, -50), (0, 3)])
    above = LineString([(-50, 12), (50, 12)])    # would be found ahead of the overshoot
    network, connections = strings_to_network(strings([main, side, above]))
    assert "end-road" not in set(verified(connections)["kind"])
    assert network.junctions["degree"].tolist() == [3]
    assert network.centrelines["length_m"].min() == pytest.approx(50)   # spur trimmed


def test_each_end_keeps_its_shortest_junction():
    near, far = LineString([(-50, 0), (50, 0)]), LineString([(-50, 9), (50, 9)])
    side = LineString([(0, -50), (0, -6)])
    _, connections = find_junctions(approximate_strings(strings([near, far, side])))
    hypotheses = connections[connections["from_road"] == 2]
    assert sorted(hypotheses["length_m"]) == pytest.approx([6.0, 15.0])
    assert hypotheses.loc[hypotheses["verified"], "to_road"].tolist() == [0]


def test_search_radius_grows_with_quality():
    main, side = LineString([(-50, 0), (50, 0)]), LineString([(0, -50), (0, -20)])
    for quality, joined in ((0.2, False), (0.8, True)):    # radius 14 m and 26 m
        roads = approximate_strings(strings([main, side], quality=[1.0, quality]))
        _, connections = find_junctions(roads)
        assert len(verified(connections)) == int(joined)


def test_connections_the_evidence_does_not_show_are_refused():
    main, side = LineString([(-50, 0), (50, 0)]), LineString([(0, -50), (0, -20)])
    roads = approximate_strings(strings([main, side], quality=[1.0, 0.8]))
    # the evidence shows road only north of y = -12: the 20 m connection has 8 m unseen
    seen = shapely.box(-100, -12, 100, 100)

    def unsupported(lines):
        return shapely.length(lines) - shapely.length(shapely.intersection(lines, seen))
    for max_unsupported_m, joined in ((10.0, True), (5.0, False)):
        _, connections = find_junctions(roads, unsupported=unsupported,
                                        max_unsupported_m=max_unsupported_m)
        assert len(verified(connections)) == int(joined)


def test_road_interrupted_at_a_t_junction_is_closed_and_the_side_road_meets_it():
    west, east = LineString([(-50, 0), (-8, 0)]), LineString([(8, 0), (50, 0)])
    side = LineString([(0, -50), (0, -7)])
    network, connections = strings_to_network(strings([west, east, side]))
    assert sorted(verified(connections)["kind"]) == ["end-end", "end-road"]
    assert network.junctions["degree"].tolist() == [3]
    assert np.hypot(*junction_points(network)[0]) < 1e-9


def test_crossroads_with_gaps_on_all_four_arms_is_one_junction_of_degree_4():
    arms = [LineString([(-50, 0.3), (-8, 0.3)]), LineString([(8, -0.2), (50, -0.2)]),
            LineString([(0, -50), (0, -8)]), LineString([(0.5, 8), (0.5, 50)])]
    network, _ = strings_to_network(strings(arms))
    assert network.junctions["degree"].tolist() == [4]
    assert np.hypot(*junction_points(network)[0]) < 1.0
    assert len(network.centrelines) == 4


def test_close_junctions_merge_into_one():
    lines = np.array([LineString([(-20, 0), (0, 0)]), LineString([(0, 0), (1, 0)]),
                      LineString([(1, 0), (20, 0)]), LineString([(0, -20), (0, 0)]),
                      LineString([(1, 20), (1, 0)])], dtype=object)
    merged, width, _ = merge_close_junctions(lines, np.arange(5.0), np.zeros(5))
    assert width.tolist() == [0, 2, 3, 4]
    nodes, degree = line_end_degrees(merged)
    assert nodes[degree == 4].tolist() == [[0.5, 0.0]]


# --- significance -------------------------------------------------------------------------

def test_short_isolated_fragment_goes_unless_both_ends_touch_the_border():
    extent = (0, 0, 300, 300)
    long_road = LineString([(50, 150), (250, 150)])
    fragment = LineString([(100, 50), (120, 50)])              # 20 m, far from the border
    corner = LineString([(5, 270), (30, 296)])                  # 36 m across a corner
    one_end = LineString([(280, 50), (296, 50)])                # only one end near it
    network, _ = strings_to_network(strings([long_road, fragment, corner, one_end]),
                                    extent=extent)
    kept = sorted(network.centrelines["length_m"])
    assert kept == pytest.approx([math.hypot(25, 26), 200])
    without_extent, _ = strings_to_network(strings([long_road, fragment, corner, one_end]))
    assert without_extent.centrelines["length_m"].tolist() == pytest.approx([200])


def test_component_made_mostly_of_junction_connections_goes():
    pieces = strings([LineString([(0, 0), (10, 0)]), LineString([(35, 0), (45, 0)])],
                     quality=1.0)
    roads, connections = find_junctions(approximate_strings(pieces))
    assert verified(connections)["length_m"].tolist() == pytest.approx([25.0])
    roads, connections = significant_components(roads, connections, min_total_length_m=0)
    assert not roads["significant"].any()
    assert roads["component"].nunique() == 1
    longer = strings([LineString([(-20, 0), (10, 0)]), LineString([(35, 0), (45, 0)])],
                     quality=1.0)
    roads, connections = significant_components(
        *find_junctions(approximate_strings(longer)), min_total_length_m=0)
    assert roads["significant"].all()


# --- the stage ----------------------------------------------------------------------------

def test_empty_input_gives_empty_valid_layers():
    network, connections = strings_to_network(strings([]), extent=(0, 0, 10, 10))
    network.validate()
    assert len(network.centrelines) == len(network.junctions) == len(connections) == 0
    assert "junction_connections" in network.qa


def test_progress_is_reported_and_cancel_stops():
    seen = []
    strings_to_network(strings([LineString([(0, 0), (60, 0)])]),
                       progress=lambda f, m="": seen.append(f))
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen)

    def cancel(fraction, message=""):
        if fraction > 0.2:
            raise Cancelled()
    with pytest.raises(Cancelled):
        strings_to_network(strings([LineString([(0, 0), (60, 0)])]), progress=cancel)


def cut_near_junctions(lines, widths_m, rng):
    """What the earlier stages might give of a noded road network: every line cut back
    2.5-7.5 m at junctions (gaps of 5-15 m between opposite ends) and interrupted by a 12 m
    gap in its middle when longer than 80 m, pieces wobbling by 0.3 m, widths off by up to
    15 %. Returns (pieces, widths)."""
    nodes, degree = line_end_degrees(lines)
    junctions = nodes[degree >= 3]
    pieces, widths = [], []
    for line, width in zip(lines, widths_m):
        ends = shapely.get_coordinates(line)[[0, -1]]
        at_junction = [len(junctions) > 0 and np.min(np.hypot(*(junctions - end).T)) < 1e-6
                       for end in ends]
        start = rng.uniform(2.5, 7.5) if at_junction[0] else 0.0
        stop = line.length - (rng.uniform(2.5, 7.5) if at_junction[1] else 0.0)
        cuts = [start, stop]
        if stop - start > 80:
            middle = rng.uniform(start + 30, stop - 30)
            cuts = [start, middle - 6, middle + 6, stop]
        for begin, end in zip(cuts[::2], cuts[1::2]):
            if end - begin < 5:
                continue
            coords = xy(shapely.segmentize(substring(line, begin, end), 2.0))
            coords[1:-1] += rng.normal(0, 0.3, coords[1:-1].shape)
            pieces.append(shapely.linestrings(coords))
            widths.append(width * rng.uniform(0.85, 1.1))
    return pieces, widths


def scene_strings(scene, seed):
    """The truth's edges cut near junctions (:func:`cut_near_junctions`) with random
    qualities, plus a lower-quality parallel duplicate of one road and three short false
    fragments away from the roads."""
    rng = np.random.default_rng(seed)
    lines = shapely.force_2d(scene.truth_edges.geometry.values)
    width = scene.roads.set_index("road_id").loc[scene.truth_edges["road_id"], "width_m"]
    pieces, widths = cut_near_junctions(lines, width.to_numpy(float), rng)
    quality = list(rng.uniform(0.4, 1.0, len(pieces)))
    longest = int(np.argmax(shapely.length(pieces)))
    pieces.append(shapely.offset_curve(pieces[longest], 1.5))
    widths.append(widths[longest])
    quality.append(quality[longest] / 2)
    roads_area = shapely.buffer(shapely.union_all(lines), 40)
    x0, y0, x1, y1 = scene.extent
    fragments = []
    while len(fragments) < 3:
        start = rng.uniform([x0 + 60, y0 + 60], [x1 - 60, y1 - 60])
        fragment = LineString([start, start + rng.uniform(-12, 12, 2)])
        if not fragment.intersects(roads_area) and fragment.length > 5:
            fragments.append(fragment)
    return strings(pieces + fragments, width_m=widths + [6.0] * 3,
                   quality=quality + [0.9] * 3, crs=scene.crs)


@pytest.mark.parametrize("seed", [0, 2])
def test_synthetic_scene_pieces_become_the_truth_network(seed):
    scene = make_scene(seed=seed, size_m=(400.0, 400.0))
    road_strings = scene_strings(scene, seed)
    network, connections = strings_to_network(road_strings, extent=scene.extent)
    network.validate()
    truth = scene.truth
    scores = evaluate_network(network.centrelines, truth.centrelines, buffer_m=3.0)
    buffer, topology = scores["buffer"], scores["topology"]
    before = evaluate_network(road_strings, truth.centrelines, buffer_m=3.0)["topology"]
    print(f"seed {seed}: completeness {buffer['completeness']:.3f}, correctness "
          f"{buffer['correctness']:.3f}, junction recall {topology['junction_recall']:.3f} "
          f"(pieces {before['junction_recall']:.3f}), precision "
          f"{topology['junction_precision']:.3f}, components "
          f"{topology['components_extracted']} / {topology['components_reference']}")
    # measured (seeds 0-5 alike): completeness 0.996-1.000, correctness 1.000, junction
    # recall 16/17 (the truth's two junctions 2.5 m apart on the avenue become one),
    # precision 1.000, 2 / 2 components
    assert buffer["completeness"] >= 0.99
    assert buffer["correctness"] >= 0.99          # duplicate and fragments are gone
    assert topology["junction_recall"] >= 0.9 > 0.1 >= before["junction_recall"]
    assert topology["junction_precision"] >= 0.95
    assert topology["components_extracted"] == topology["components_reference"]
    assert set(verified(connections)["kind"]) >= {"end-end", "end-road"}
    width = network.centrelines["width_m"]
    assert width.between(0.8 * truth.centrelines["width_m"].min(),
                         1.15 * truth.centrelines["width_m"].max()).all()


@pytest.mark.parametrize("name, completeness, junction_recall", [
    ("OSMroads_img1447.geojson", 0.98, 0.7),        # Paris, OpenStreetMap: 0.990, 5/7
    ("vegas_pan_roads.geojson", 0.95, 0.99)])       # Las Vegas, SpaceNet: 0.956, 4/4
def test_real_road_networks_cut_near_junctions_are_reconnected(name, completeness,
                                                                junction_recall):
    # Paris: the two junctions missed lie a few metres from the image border, and their
    # arm to the border is shorter than the cut, so the pieces lack it (an L is built).
    # Vegas: a short isolated stub of the labels (4 % of their length) is dropped by the
    # significance rule.
    reference = gpd.read_file(SPACENET / name)
    reference = reference.to_crs(reference.estimate_utm_crs())
    lines = node_lines(shapely.force_2d(reference.geometry.values))
    pieces, widths = cut_near_junctions(lines, np.full(len(lines), 7.0),
                                        np.random.default_rng(0))
    road_strings = strings(pieces, width_m=widths,
                           quality=np.random.default_rng(1).uniform(0.4, 1.0, len(pieces)),
                           crs=reference.crs)
    network, _ = strings_to_network(road_strings,
                                    extent=tuple(shapely.bounds(shapely.union_all(lines))))
    scores = evaluate_network(network.centrelines, gpd.GeoSeries(lines, crs=reference.crs),
                              buffer_m=3.0)
    before = evaluate_network(road_strings, gpd.GeoSeries(lines, crs=reference.crs),
                              buffer_m=3.0)["topology"]
    assert scores["buffer"]["completeness"] >= completeness
    assert scores["buffer"]["correctness"] >= 0.99
    assert scores["topology"]["junction_recall"] >= junction_recall > before["junction_recall"]
    assert scores["topology"]["junction_precision"] >= 0.99
