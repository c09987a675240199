"""Synthetic scene layout and truth: determinism, the features road methods are tested on."""
import numpy as np
import pytest
import shapely
from pyproj import CRS

from gisroads.geo import junctions_from_lines, line_end_degrees
from gisroads.synthetic import FEATURES, make_scene

SEEDS = [0, 1, 2, 3]


@pytest.fixture(scope="module", params=SEEDS)
def scene(request):
    return make_scene(seed=request.param, size_m=(300.0, 300.0))


def _road(scene, name):
    rows = scene.roads[scene.roads["name"] == name]
    assert len(rows) >= 1, f"no {name} in the scene"
    return rows.iloc[0]


def _layers(scene):
    return [scene.roads, scene.buildings, scene.trees, scene.cars, scene.markings,
            scene.parking_lots, scene.bridges, scene.cliff]


def test_same_seed_same_scene_other_seed_other_scene():
    a, b = make_scene(seed=7, size_m=(300, 300)), make_scene(seed=7, size_m=(300, 300))
    for la, lb in zip(_layers(a), _layers(b)):
        assert len(la) == len(lb)
        assert shapely.equals_exact(la.geometry.values, lb.geometry.values, 0).all()
        assert la.drop(columns="geometry").equals(lb.drop(columns="geometry"))
    c = make_scene(seed=8, size_m=(300, 300))
    assert not (len(c.roads) == len(a.roads) and shapely.equals_exact(
        c.roads.geometry.values, a.roads.geometry.values, 1e-3).all())


def test_leaving_a_feature_out_moves_nothing_else():
    full = make_scene(seed=4, size_m=(300, 300))
    bare = make_scene(seed=4, size_m=(300, 300), features=set(FEATURES) - {"cars"})
    assert len(bare.cars) == 0
    assert shapely.equals_exact(full.buildings.geometry.values,
                                bare.buildings.geometry.values, 0).all()


def test_truth_contract_crs_and_vertices(scene):
    truth = scene.truth
    truth.validate()
    assert truth.crs == CRS.from_user_input("EPSG:32633") == scene.crs
    assert set(truth.centrelines["method"]) == {"truth"}
    lines = truth.centrelines.geometry.values
    assert shapely.has_z(lines).all()
    for line in lines:
        xy = shapely.get_coordinates(line)
        assert np.hypot(*np.diff(xy, axis=0).T).max() <= 2.0 + 1e-9
    xmin, ymin, xmax, ymax = scene.extent
    assert (xmax - xmin, ymax - ymin) == (300.0, 300.0)
    x0, y0, x1, y1 = shapely.total_bounds(lines)
    assert xmin - 1e-6 <= x0 and x1 <= xmax + 1e-6 and ymin - 1e-6 <= y0 and y1 <= ymax + 1e-6


def test_widths_span_lanes_to_avenues(scene):
    width = scene.truth.centrelines["width_m"]
    assert width.min() <= 5.0 and width.max() >= 20.0
    assert width.min() >= 4.0 and width.max() <= 25.0


def test_curved_and_straight_roads(scene):
    def turning_deg(line):
        d = np.diff(shapely.get_coordinates(line), axis=0)
        return np.degrees(np.abs(np.diff(np.unwrap(np.arctan2(d[:, 1], d[:, 0])))))
    turns = [turning_deg(g) for g in scene.roads.geometry.values]
    # Curved: the heading changes by tens of degrees, smoothly (well under 2 deg per vertex).
    assert any(t.sum() > 20 and np.quantile(t, 0.95) < 2 for t in turns)
    assert any(t.sum() < 1 for t in turns)


def test_junction_degrees_include_t_and_x(scene):
    degrees = set(scene.truth.junctions["degree"])
    assert {3, 4} <= degrees


def _junction_angles(scene):
    """Smallest angle between road arms at each truth junction (degrees)."""
    edges = scene.truth_edges.geometry.values
    angles = []
    for junction in scene.truth.junctions.geometry.values:
        headings = []
        for edge in edges[shapely.dwithin(edges, junction, 1e-6)]:
            xy = shapely.get_coordinates(edge)
            if np.allclose(xy[-1], shapely.get_coordinates(junction)[0]):
                xy = xy[::-1]
            arm = shapely.get_coordinates(shapely.line_interpolate_point(
                shapely.linestrings(xy), min(4.0, shapely.length(edge))))[0] - xy[0]
            headings.append(np.arctan2(arm[1], arm[0]))
        headings = np.sort(np.degrees(headings))
        gaps = np.diff(np.append(headings, headings[0] + 360))
        angles.append(gaps.min())
    return np.array(angles)


def test_some_junctions_are_far_from_orthogonal(scene):
    angles = _junction_angles(scene)
    assert (angles < 70).any()
    assert (np.abs(angles - 90) < 10).any()


def test_a_dead_end_inside_the_scene(scene):
    nodes, degree = line_end_degrees(scene.truth_edges.geometry.values)
    xmin, ymin, xmax, ymax = scene.extent
    inner = ((nodes[:, 0] > xmin + 1) & (nodes[:, 0] < xmax - 1)
             & (nodes[:, 1] > ymin + 1) & (nodes[:, 1] < ymax - 1))
    assert (inner & (degree == 1)).sum() >= 1


def test_dual_carriageway_is_two_parallel_lines_with_a_raised_median(scene):
    a = _road(scene, "dual_carriageway_a")
    b = _road(scene, "dual_carriageway_b")
    samples = shapely.line_interpolate_point(a.geometry, np.linspace(0.05, 0.95, 30),
                                             normalized=True)
    gap = shapely.distance(samples, b.geometry)
    assert 10.0 <= gap.min() and gap.max() <= 20.0 and np.ptp(gap) < 0.5
    # The median between them is unpaved, so it stands a kerb above the carriageways.
    mid = (shapely.get_coordinates(samples)
           + shapely.get_coordinates(shapely.line_interpolate_point(
               b.geometry, shapely.line_locate_point(b.geometry, samples)))) / 2
    paved = scene.relief.terrain_z(mid[:, 0], mid[:, 1])
    raised = scene.ground_z(mid[:, 0], mid[:, 1]) - paved
    on_median = ~shapely.intersects_xy(
        shapely.union_all(scene.truth.polygons.geometry.values), mid[:, 0], mid[:, 1])
    assert on_median.sum() > 10
    assert ((raised[on_median] >= 0.10) & (raised[on_median] <= 0.20)).all()


def test_bridge_crossing_is_no_junction_and_its_deck_is_6_to_8_m_up(scene):
    bridge = scene.bridges.iloc[0]
    crossing = shapely.Point(bridge.crossing_x, bridge.crossing_y)
    junctions = scene.truth.junctions.geometry.values
    assert shapely.distance(junctions, crossing).min() > 20
    # A naive 2-D noding of the same lines would put a junction there: the test can fail.
    naive = junctions_from_lines(scene.truth.centrelines.geometry.values, scene.crs)
    assert shapely.distance(naive.geometry.values, crossing).min() < 1e-6
    # The edges of the level-aware graph pass the crossing without a node.
    edges = scene.truth_edges
    assert (shapely.dwithin(edges.geometry.values, crossing, 1e-6)).sum() == 2
    upper = scene.roads.loc[bridge.road_id].geometry
    lower = scene.roads.loc[bridge.under_road_id].geometry
    z_up = shapely.get_coordinates(upper, include_z=True)
    z_low = shapely.get_coordinates(lower, include_z=True)
    near_up = z_up[np.argmin(np.hypot(z_up[:, 0] - crossing.x, z_up[:, 1] - crossing.y)), 2]
    near_low = z_low[np.argmin(np.hypot(z_low[:, 0] - crossing.x, z_low[:, 1] - crossing.y)), 2]
    assert 6.0 <= near_up - near_low <= 8.0
    deck_z = scene.deck_z(crossing.x, crossing.y)
    assert 6.0 <= deck_z - scene.ground_z(crossing.x, crossing.y) <= 8.0
    # Ramps: the upper road climbs smoothly from grade at both ends.
    z = z_up[:, 2] - scene.relief.terrain_z(z_up[:, 0], z_up[:, 1])
    assert abs(z[0]) < 1e-6 and abs(z[-1]) < 1e-6
    assert np.abs(np.diff(z)).max() < 2.0 * 0.15  # under 15 % grade between 2 m vertices


def test_parking_lots_are_compact_and_off_the_road_truth(scene):
    lots = scene.parking_lots
    assert len(lots) >= 1
    roads = shapely.union_all(scene.truth.polygons.geometry.values)
    assert not shapely.intersects(lots.geometry.values, roads).any()
    assert (lots["aspect"] < 2).all()
    assert (shapely.area(lots.geometry.values) > 600).all()
    # Each is joined to a road by its access, which touches the lot and a road.
    access = scene.parking_access.geometry.values
    assert shapely.intersects(access, roads).all()
    assert shapely.intersects(access, lots.geometry.values).all()


def test_kerb_is_a_10_to_20_cm_step_at_every_road_edge(scene):
    polygons = scene.truth.polygons
    all_roads = shapely.union_all(polygons.geometry.values)
    bridge_ids = scene.roads.loc[scene.roads["bridge"], "road_id"]
    # Parking accesses cross the kerb at grade; bridge ramps stand on walls.
    elsewhere = shapely.union_all(np.concatenate([
        scene.parking_lots.geometry.values, scene.parking_access.geometry.values,
        polygons.geometry.values[polygons["road_id"].isin(bridge_ids)]]))
    edge = shapely.difference(shapely.boundary(all_roads), shapely.buffer(elsewhere, 1.0))
    xy = shapely.get_coordinates(shapely.line_interpolate_point(
        edge, np.linspace(0, 1, 500), normalized=True))
    # Probe 0.3 m across the edge: the ring around each edge point is half road, half not.
    ring = np.stack([xy + 0.3 * np.array([np.cos(a), np.sin(a)])
                     for a in np.linspace(0, 2 * np.pi, 16, endpoint=False) + 0.1], axis=1)
    rx, ry = ring[..., 0].ravel(), ring[..., 1].ravel()
    on_road = shapely.contains_xy(all_roads, rx, ry).reshape(ring.shape[:2])
    # Against the bare terrain, so that the undulation does not blur a 10-20 cm step.
    height = (scene.ground_z(rx, ry) - scene.relief.terrain_z(rx, ry)).reshape(ring.shape[:2])
    straddle = on_road.any(axis=1) & ~on_road.all(axis=1)
    assert straddle.sum() > 300
    road_side = np.where(on_road, height, np.nan)[straddle]
    verge_side = np.where(~on_road, height, np.nan)[straddle]
    assert np.nanmax(np.abs(road_side)) < 1e-9
    assert np.nanmin(verge_side) >= 0.10 and np.nanmax(verge_side) <= 0.20
    # And the step is a real one in absolute heights too.
    step = np.nanmean(np.where(~on_road, 1, np.nan) * scene.ground_z(rx, ry).reshape(
        ring.shape[:2]), axis=1) - np.nanmean(np.where(on_road, 1, np.nan) * scene.ground_z(
            rx, ry).reshape(ring.shape[:2]), axis=1)
    assert 0.10 < np.median(step[straddle]) < 0.20


def test_cliff_top_road_runs_6_to_12_m_above_the_foot_road(scene):
    top, foot = _road(scene, "cliff_top"), _road(scene, "cliff_foot")
    z_top = shapely.get_coordinates(top.geometry, include_z=True)[:, 2]
    z_foot = shapely.get_coordinates(foot.geometry, include_z=True)[:, 2]
    assert 6.0 <= np.median(z_top) - np.median(z_foot) <= 12.0
    assert 6.0 <= scene.cliff["height_m"].iloc[0] <= 12.0
    plateau = scene.cliff.geometry.iloc[0]
    assert shapely.within(top.geometry, plateau) and not shapely.intersects(foot.geometry,
                                                                            plateau)


def test_roads_stay_locally_planar(scene):
    for line in scene.roads.geometry.values:
        z = shapely.get_coordinates(line, include_z=True)[:, 2]
        # Second differences over 2 m vertices: centimetres, not steps.
        assert np.abs(np.diff(z, 2)).max() < 0.05


def test_buildings_trees_cars_markings(scene):
    polygons = scene.truth.polygons.geometry.values
    roads = shapely.union_all(polygons)
    buildings = scene.buildings
    assert len(buildings) > 5
    assert not shapely.intersects(buildings.geometry.values, shapely.buffer(roads, 4.0)).any()
    assert buildings["height_m"].between(5, 25).all()
    trees = scene.trees
    crowns = shapely.buffer(trees.geometry.values, trees["crown_radius_m"].to_numpy())
    assert shapely.intersects(crowns, roads).sum() >= 5  # crowns overhang roads
    assert not shapely.intersects(trees.geometry.values, roads).any()  # trunks do not
    cars = scene.cars
    assert {"kerb", "lot"} <= set(cars["where"])
    assert cars["height_m"].between(1.4, 1.6).all()
    corners = shapely.get_coordinates(cars.geometry.values).reshape(-1, 5, 2)
    sides = np.sort(np.linalg.norm(np.diff(corners[:, :3], axis=1), axis=2), axis=1)
    assert ((sides[:, 0] > 1.7) & (sides[:, 0] < 1.95)).all()
    assert ((sides[:, 1] > 4.1) & (sides[:, 1] < 4.9)).all()
    on_road = cars[cars["where"] != "lot"].geometry.values
    assert shapely.within(on_road, roads).all()
    lots = shapely.union_all(scene.parking_lots.geometry.values)
    assert shapely.within(cars[cars["where"] == "lot"].geometry.values, lots).all()
    markings = scene.markings
    assert {"dash", "zebra"} <= set(markings["kind"])
    assert shapely.within(markings.geometry.values, roads).all()
    marked = scene.roads.loc[markings.loc[markings["kind"] == "dash", "road_id"].unique()]
    assert (marked["width_m"] >= 7.0).all()


def test_object_layers_share_the_scene_crs(scene):
    layers = scene.object_layers()
    assert {"roads", "buildings", "trees", "cars", "markings", "parking_lots", "bridges",
            "cliff", "truth_edges"} <= set(layers)
    assert all(layer.crs == scene.crs for layer in layers.values())


def test_large_scene_scales_and_keeps_every_feature():
    scene = make_scene(seed=5, size_m=(1000.0, 700.0))
    names = scene.roads["name"].value_counts()
    assert names["street"] + names.get("curved_street", 0) >= 8
    assert len(scene.bridges) == 1 and len(scene.cliff) == 1
    assert len(scene.truth.junctions) > 25


def test_without_features_only_the_street_grid_remains():
    scene = make_scene(seed=1, size_m=(300, 300), features=())
    assert set(scene.roads["name"]) <= {"street", "curved_street", "avenue"}
    assert not (len(scene.buildings) or len(scene.trees) or len(scene.cars)
                or len(scene.markings) or len(scene.bridges) or len(scene.cliff))
    scene.truth.validate()


def test_refuses_small_scenes_unknown_features_and_geographic_crs():
    with pytest.raises(ValueError):
        make_scene(size_m=(200, 400))
    with pytest.raises(ValueError):
        make_scene(features=("volcano",))
    with pytest.raises(ValueError):
        make_scene(crs="EPSG:4326")
