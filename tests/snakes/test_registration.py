import geopandas as gpd
import numpy as np
import pytest
import shapely

from gisroads.io.las import PointCloud, concatenate
from gisroads.snakes.registration import map_topology, register_map
from gisroads.synthetic import make_scene, render_cloud
from gisroads.synthetic.perturb import perturb_lines


def lines_frame(*coords, crs="EPSG:32633"):
    return gpd.GeoDataFrame({"name": [f"l{i}" for i in range(len(coords))]},
                            geometry=[shapely.linestrings(c) for c in coords], crs=crs)


def grid_cloud(z_of, extent=(-5, -5, 105, 5), step=0.1, crs="EPSG:32633"):
    x, y = np.meshgrid(np.arange(extent[0], extent[2], step), np.arange(extent[1], extent[3], step))
    x, y = x.ravel(), y.ravel()
    xyz = np.column_stack([x, y, z_of(x, y)])
    n = len(xyz)
    return PointCloud(xyz, np.zeros(n, np.uint16), np.full(n, 2, np.uint8),
                      np.ones(n, np.uint8), np.ones(n, np.uint8), crs=crs)


def test_topology_of_a_hand_made_map():
    topo = map_topology(lines_frame(
        [(0, 0), (75, 0), (100, 0)],             # A: through line
        [(50, 1.0), (50, 80)],                   # B: ends 1 m from A's interior: T junction
        [(100.8, 0.5), (160, 0)],                # C: starts 0.94 m from A's end: shared end
        [(20, -30), (20, 30)],                   # D: crosses A with no shared vertex: no node
        [(75, -20), (75, 0), (75, 20)]),         # F: shares A's vertex (75, 0): X junction
        snap_m=2.0)
    nodes = shapely.get_coordinates(topo.intersections.geometry.values)
    degree = {tuple(np.round(p, 2)): d for p, d in zip(nodes, topo.intersections["degree"])}
    assert degree == {(0, 0): 1, (50, 0): 3, (75, 0): 4, (100.4, 0.25): 2, (50, 80): 1,
                      (160, 0): 1, (20, -30): 1, (20, 30): 1, (75, -20): 1, (75, 20): 1}
    roads = topo.roads
    assert sorted(roads["name"]) == ["l0", "l0", "l0", "l1", "l2", "l3", "l4", "l4"]
    a = roads[roads["name"] == "l0"].sort_values("road_id")
    assert np.allclose(shapely.length(a.geometry.values), [50, 25, 25.4], atol=0.01)
    # the roads meeting at the T share its node
    t_node = np.flatnonzero(np.all(np.round(nodes, 2) == (50, 0), axis=1))[0]
    at_t = roads[(roads.start_node == t_node) | (roads.end_node == t_node)]
    assert sorted(at_t["name"]) == ["l0", "l0", "l1"]
    d = roads[roads["name"] == "l3"]
    assert len(d) == 1 and shapely.length(d.geometry.values[0]) == pytest.approx(60)


def test_an_end_on_a_shared_crossing_vertex_makes_one_intersection():
    topo = map_topology(lines_frame([(0, 0), (10, 0), (20, 0)], [(10, -10), (10, 0), (10, 10)],
                                    [(10, 0), (15, 8)]))
    nodes = shapely.get_coordinates(topo.intersections.geometry.values)
    centre = np.flatnonzero(np.all(np.abs(nodes - (10, 0)) < 1e-9, axis=1))
    assert len(centre) == 1
    assert topo.intersections["degree"].iloc[centre[0]] == 5
    assert len(topo.roads) == 5


def test_bad_maps_are_refused():
    with pytest.raises(ValueError, match="LineString"):
        map_topology(gpd.GeoDataFrame(geometry=[shapely.points(0, 0)], crs="EPSG:32633"))
    with pytest.raises(ValueError, match="no line"):
        map_topology(lines_frame())
    with pytest.raises(ValueError, match="no point"):
        register_map(lines_frame([(0, 0), (10, 0)]),
                     PointCloud(np.empty((0, 3)), None, *[np.empty(0, np.uint8)] * 3))
    with pytest.raises(ValueError, match="does the map cover the cloud"):
        register_map(lines_frame([(1000, 0), (1010, 0)]), grid_cloud(lambda x, y: x))
    with pytest.raises(ValueError, match="support_radius_m"):
        register_map(lines_frame([(0, 0), (10, 0)]), grid_cloud(lambda x, y: x),
                     support_radius_m=0)


def test_plane_with_a_deck_over_the_road():
    plane = lambda x, y: 10 + 0.05 * x  # noqa: E731
    cloud = grid_cloud(lambda x, y: plane(x, y) + np.where((x >= 40) & (x < 47), 6.0, 0.0))
    reg = register_map(lines_frame([(0, 0), (100, 0)]), cloud)
    x, z = reg.xyz[:, 0], reg.xyz[:, 2]
    assert len(x) == 101 and np.allclose(reg.station_m, np.arange(101))
    assert np.allclose(reg.tangent, [1, 0])
    under = (x > 40) & (x < 47)  # x = 40 still sees the ground at 39.9
    assert np.abs(z - plane(x, 0)).max() < 0.02   # on the road, also under the deck
    assert not reg.seen[under].any() and reg.seen[~under].all()
    line = reg.lines.geometry.values[0]
    assert shapely.has_z(line) and reg.lines["length_m"].iloc[0] == pytest.approx(100)


def test_inclines_are_clamped_not_flattened():
    # A 50 % ramp of 2 m between x = 40 and 44: steeper than any road.
    cloud = grid_cloud(lambda x, y: np.clip((x - 40) * 0.5, 0, 2))
    reg = register_map(lines_frame([(0, 0), (100, 0)]), cloud)
    x, z = reg.xyz[:, 0], reg.xyz[:, 2]
    incline = np.abs(np.diff(z) / np.diff(reg.station_m))
    assert incline.max() <= 0.35 + 1e-9
    assert incline.max() > 0.34  # the ramp is climbed at the limit
    assert np.abs(z[x >= 50] - 2).max() < 0.02  # and the upper level is reached


@pytest.fixture(scope="module")
def registered_scene():
    scene = make_scene(seed=0, size_m=(300.0, 300.0), features=("bridge", "cliff", "trees",
                                                                  "cars", "markings"))
    cloud = concatenate(list(render_cloud(scene, density_per_m2=8.0, seed=0)))
    shifted = perturb_lines(scene.truth_edges, shift_m=3.0, jitter_m=0.3, seed=1)
    return scene, register_map(shifted, cloud, snap_m=8.0)


def surface_truth(scene, reg):
    """The surface under each sample: the ground, or the ramp and deck of the bridge road."""
    x, y = reg.xyz[:, 0], reg.xyz[:, 1]
    edge_road = reg.lines.set_index("road_id").loc[reg.road_id, "map_road_id"].to_numpy()
    bridge = int(scene.bridges["road_id"].iloc[0])
    truth = scene.ground_z(x, y)
    on = edge_road == bridge
    truth[on] = scene.relief.road_z(x[on], y[on], bridge)
    return truth, edge_road == bridge


def test_registered_lines_follow_the_seen_surface(registered_scene):
    scene, reg = registered_scene
    truth, _ = surface_truth(scene, reg)
    error = np.abs(reg.xyz[:, 2] - truth)
    assert reg.seen.mean() > 0.3
    assert np.percentile(error[reg.seen], 95) <= 0.10
    assert np.median(error) <= 0.05
    same_road = np.diff(reg.road_id) == 0
    assert np.abs(np.diff(reg.xyz[:, 2]) / np.diff(reg.station_m))[same_road].max() <= 0.35 + 1e-9


def test_overpass_deck_road_on_deck_lower_road_on_ground(registered_scene):
    scene, reg = registered_scene
    truth, on_bridge_road = surface_truth(scene, reg)
    x, y, z = reg.xyz.T
    deck = scene.deck_z(x, y)
    on_deck = on_bridge_road & np.isfinite(deck)
    under = ~on_bridge_road & np.isfinite(deck)
    assert on_deck.sum() >= 20 and under.sum() >= 4
    assert np.abs(z[on_deck] - deck[on_deck]).max() <= 0.12
    assert np.abs(z[under] - scene.ground_z(x[under], y[under])).max() <= 0.12
    assert (z[under] < deck[under] - 5).all()


def test_topology_of_the_shifted_scene_map(registered_scene):
    scene, reg = registered_scene
    junctions = scene.truth.junctions
    nodes = reg.intersections
    major = nodes[nodes["degree"] >= 3]
    assert len(major) == len(junctions)
    gap = shapely.distance(np.asarray(junctions.geometry.values)[:, None],
                           np.asarray(major.geometry.values)[None])
    assert gap.min(axis=1).max() < 6.0
    # The bridge road shares no node with the avenue it crosses.
    lines = reg.lines
    bridge = int(scene.bridges["road_id"].iloc[0])
    under = int(scene.bridges["under_road_id"].iloc[0])
    bridge_nodes = set(lines.loc[lines.map_road_id == bridge, ["start_node", "end_node"]]
                       .to_numpy().ravel())
    avenue_nodes = set(lines.loc[lines.map_road_id == under, ["start_node", "end_node"]]
                       .to_numpy().ravel())
    assert not bridge_nodes & avenue_nodes
    # Roads meeting at a junction share its sample elevation.
    ends = np.flatnonzero(np.diff(reg.road_id)) + 1
    first, last = np.concatenate([[0], ends]), np.concatenate([ends - 1, [len(reg.road_id) - 1]])
    for node in major["node_id"]:
        at = np.concatenate([first[lines.start_node.to_numpy() == node],
                             last[lines.end_node.to_numpy() == node]])
        assert np.ptp(reg.xyz[at, 2]) <= 0.36  # the same spline value, then one clamped step


def test_register_job_reprojects_the_map_and_writes_the_layer(tmp_path):
    from gisroads.io.las import cloud_crs
    from gisroads.io.vector import list_layers, read_layer
    from gisroads.jobs import register_job
    from gisroads.synthetic import write_cloud

    scene = make_scene(seed=3, size_m=(300.0, 300.0), features=("bridge",))
    write_cloud(scene, tmp_path / "cloud.laz", density_per_m2=3.0, seed=0)
    shifted = perturb_lines(scene.truth_edges, shift_m=2.0, jitter_m=0.2, seed=0)
    result = register_job(tmp_path / "cloud.laz", shifted.to_crs("EPSG:4326"),
                          tmp_path / "out.gpkg", snap_m=6.0, support_radius_m=0.3)
    assert list_layers(tmp_path / "out.gpkg") == ["registered_map"]
    lines = read_layer(tmp_path / "out.gpkg")
    assert lines.crs == cloud_crs(tmp_path / "cloud.laz")[1]
    assert result["roads"] == len(lines) and result["points_read"] > 1000
    xyz = shapely.get_coordinates(lines.geometry.values, include_z=True)
    off_bridge = ~np.isin(lines["map_road_id"].to_numpy()[shapely.get_coordinates(
        lines.geometry.values, return_index=True)[1]], scene.bridges["road_id"].to_numpy())
    dz = np.abs(xyz[off_bridge, 2] - scene.ground_z(xyz[off_bridge, 0], xyz[off_bridge, 1]))
    assert np.percentile(dz, 95) <= 0.10
    with pytest.raises(ValueError, match="no CRS"):
        register_job(tmp_path / "cloud.laz",
                     gpd.GeoDataFrame(geometry=list(shifted.geometry.values)),
                     tmp_path / "bad.gpkg")
    with pytest.raises(ValueError, match="no line"):
        register_job(tmp_path / "cloud.laz", shifted.iloc[:0], tmp_path / "bad.gpkg")
    assert not (tmp_path / "bad.gpkg").exists()


def test_real_cloud_fusa_with_a_shifted_digitised_map(lidar_dir):
    from scipy.spatial import cKDTree

    from gisroads.io.las import read_las
    from gisroads.io.vector import read_layer

    cloud = read_las(lidar_dir / "fusa.laz")
    truth = read_layer(lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson",
                       crs=cloud.crs)
    shifted = perturb_lines(truth, shift_m=3.0, jitter_m=0.3, seed=0)
    reg = register_map(shifted, cloud, snap_m=8.0)
    assert (reg.intersections["degree"] >= 3).sum() >= 5  # the truth has 7 junctions
    # Reference: the median of the ground-class points within 0.6 m of each sample.
    ground = cloud.classification == 2
    near = cKDTree(cloud.xyz[ground, :2]).query_ball_point(reg.xyz[:, :2], 0.6)
    z = cloud.xyz[ground, 2]
    reference = np.array([np.median(z[i]) if len(i) >= 2 else np.nan for i in near])
    error = np.abs(reg.xyz[:, 2] - reference)
    checked = reg.seen & np.isfinite(error)
    assert checked.sum() > 250  # 4.4 points/m2: one sample in three sees a point
    assert np.percentile(error[checked], 95) <= 0.10
    assert np.nanpercentile(error, 95) <= 0.20
