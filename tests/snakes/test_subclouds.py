import geopandas as gpd
import numpy as np
import pytest
import shapely

from gisroads.io.las import PointCloud, read_las
from gisroads.snakes.registration import register_map
from gisroads.snakes.subclouds import read_corridor, road_patches
from gisroads.synthetic import make_scene, write_cloud
from gisroads.synthetic.perturb import perturb_lines


def overpass_cloud():
    """Ground at z = 0 on a 0.5 m grid, a deck at z = 6 over |x| <= 4, |y| <= 10."""
    x, y = np.meshgrid(np.arange(-30, 30, 0.5), np.arange(-30, 30, 0.5))
    x, y = x.ravel() + 0.25, y.ravel() + 0.25
    deck = (np.abs(x) <= 4) & (np.abs(y) <= 10)
    xyz = np.column_stack([x, y, np.where(deck, 6.0, 0.0)])
    n = len(xyz)
    cloud = PointCloud(xyz, np.arange(n, dtype=np.uint16), np.where(deck, 17, 2).astype(np.uint8),
                       np.ones(n, np.uint8), np.ones(n, np.uint8), crs="EPSG:32633")
    return cloud, deck


def test_hand_made_overpass_gives_two_exact_subclouds():
    cloud, deck = overpass_cloud()
    lines = gpd.GeoDataFrame({"name": ["lower", "deck"]}, geometry=[
        shapely.linestrings([(-30, 0), (30, 0)]), shapely.linestrings([(0, -10), (0, 10)])],
        crs="EPSG:32633")
    reg = register_map(lines, cloud, support_radius_m=0.4)  # the grid is 0.5 m
    assert reg.seen[reg.road_id == 1].all()
    lower, upper = road_patches(reg, cloud)
    assert np.abs(lower.samples_xyz[:, 2]).max() < 1e-9
    assert np.abs(upper.samples_xyz[:, 2] - 6).max() < 1e-9
    assert np.allclose(lower.plane_normal, [0, 0, 1]) and np.allclose(upper.plane_normal, [0, 0, 1])
    assert np.array_equal(upper.point_index, np.flatnonzero(deck))
    expected = np.flatnonzero(~deck & (np.abs(cloud.xyz[:, 1]) <= 22))
    assert np.array_equal(lower.point_index, expected)
    assert np.array_equal(lower.points, cloud.xyz[expected])
    assert np.array_equal(lower.intensity, cloud.intensity[expected])
    # every point knows its nearest sample
    nearest = np.argmin(np.abs(lower.points[:, None, 0] - lower.samples_xyz[None, :, 0]), axis=1)
    assert np.array_equal(np.abs(lower.samples_xyz[lower.sample_index, 0] - lower.points[:, 0]),
                          np.abs(lower.samples_xyz[nearest, 0] - lower.points[:, 0]))


def test_read_corridor_matches_brute_force():
    cloud, _ = overpass_cloud()
    xy = np.array([[0.0, 0.0], [12.3, -7.0]])
    corridor, index = read_corridor(cloud, xy, 3.0, chunk_size=1000)
    distance = np.hypot(cloud.xyz[:, None, 0] - xy[None, :, 0],
                        cloud.xyz[:, None, 1] - xy[None, :, 1]).min(axis=1)
    assert np.array_equal(index, np.flatnonzero(distance <= 3.0))
    assert np.array_equal(corridor.xyz, cloud.xyz[index])


def test_bad_parameters_are_refused():
    cloud, _ = overpass_cloud()
    lines = gpd.GeoDataFrame(geometry=[shapely.linestrings([(-30, 0), (30, 0)])],
                             crs="EPSG:32633")
    reg = register_map(lines, cloud, support_radius_m=0.4)
    with pytest.raises(ValueError, match="reach_m"):
        road_patches(reg, cloud, reach_m=0)
    with pytest.raises(ValueError, match="chunk_size"):
        road_patches(reg, cloud, chunk_size=0)
    with pytest.raises(ValueError, match="PointCloud or a LAS/LAZ path"):
        road_patches(reg, 42)


@pytest.fixture(scope="module")
def bridge_scene(tmp_path_factory):
    scene = make_scene(seed=0, size_m=(300.0, 300.0), features=("bridge", "cliff", "trees",
                                                                  "cars"))
    path = tmp_path_factory.mktemp("subclouds") / "cloud.laz"
    write_cloud(scene, path, density_per_m2=5.0, seed=0)
    cloud = read_las(path)
    shifted = perturb_lines(scene.truth_edges, shift_m=3.0, jitter_m=0.3, seed=1)
    reg = register_map(shifted, cloud, snap_m=8.0)
    return scene, path, cloud, reg, road_patches(reg, cloud)


def test_bridge_and_road_under_it_fall_into_different_subclouds(bridge_scene):
    scene, _, cloud, reg, patches = bridge_scene
    map_road = reg.lines.set_index("road_id")["map_road_id"]
    bridge = int(scene.bridges["road_id"].iloc[0])
    under = int(scene.bridges["under_road_id"].iloc[0])
    crossing = scene.bridges[["crossing_x", "crossing_y"]].to_numpy()[0]
    avenue = scene.truth.polygons
    avenue = shapely.union_all(avenue.geometry.values[avenue["road_id"].to_numpy() == under])
    deck_points = np.flatnonzero(cloud.classification == 17)
    x, y = cloud.xyz[:, 0], cloud.xyz[:, 1]
    avenue_ground = np.flatnonzero((cloud.classification == 2) & shapely.contains_xy(avenue, x, y)
                                   & (np.hypot(x - crossing[0], y - crossing[1]) < 30))
    assert len(deck_points) > 100 and len(avenue_ground) > 100
    bridge_patch = [p for p in patches if map_road[p.road_id] == bridge]
    under_patches = [p for p in patches if map_road[p.road_id] == under]
    assert len(bridge_patch) == 1 and len(under_patches) >= 1
    in_bridge = bridge_patch[0].point_index
    assert np.isin(deck_points, in_bridge).mean() > 0.95
    assert not np.isin(avenue_ground, in_bridge).any()
    for patch in under_patches:
        assert not np.isin(deck_points, patch.point_index).any()
    near_crossing = np.concatenate([p.point_index for p in under_patches])
    assert np.isin(avenue_ground, near_crossing).mean() > 0.95
    # Every subcloud point lies within reach of its sample and near the sample's plane.
    for patch in patches:
        sample = patch.samples_xyz[patch.sample_index]
        assert (np.hypot(*(patch.points[:, :2] - sample[:, :2]).T) <= 22.0).all()
        assert np.isclose(np.linalg.norm(patch.plane_normal, axis=1), 1).all()


def test_chunked_file_read_equals_in_memory(bridge_scene):
    _, path, _, reg, in_memory = bridge_scene
    from_file = road_patches(reg, path, chunk_size=60_000)
    assert len(from_file) == len(in_memory)
    for a, b in zip(from_file, in_memory):
        assert a.road_id == b.road_id
        assert np.array_equal(a.point_index, b.point_index)
        assert np.array_equal(a.sample_index, b.sample_index)
        assert np.array_equal(a.points, b.points)
        assert np.allclose(a.plane_normal, b.plane_normal, atol=1e-9)
    assert sum(len(p.points) for p in in_memory) > 100_000


def test_progress_reaches_the_end_and_can_cancel():
    from gisroads.progress import Cancelled

    cloud, _ = overpass_cloud()
    lines = gpd.GeoDataFrame(geometry=[shapely.linestrings([(-30, 0), (30, 0)])],
                             crs="EPSG:32633")
    reg = register_map(lines, cloud, support_radius_m=0.4)
    seen = []
    road_patches(reg, cloud, chunk_size=5000, progress=lambda f, m: seen.append(f))
    assert seen == sorted(seen) and seen[-1] == 1.0 and len(seen) > 4

    def cancel(fraction, message):
        if fraction > 0.3:
            raise Cancelled()
    with pytest.raises(Cancelled):
        road_patches(reg, cloud, chunk_size=5000, progress=cancel)
