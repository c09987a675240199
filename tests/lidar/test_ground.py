"""Multi-level ground planes: hand-made surfaces with known answers, then a synthetic scene."""
import numpy as np
import pytest
import shapely

from gisroads.io.las import concatenate
from gisroads.lidar.ground import ground_planes
from gisroads.synthetic import make_scene, render_cloud, road_surface_mask

RNG = np.random.default_rng(7)


def plane(size_m=40.0, *, z_m=0.0, slope_deg=0.0, density=5.0, noise_m=0.02, x0=0.0, y0=0.0):
    """Random points on a plane rising along x, ``density`` points per square metre."""
    n = int(density * size_m * size_m)
    x, y = RNG.uniform(x0, x0 + size_m, n), RNG.uniform(y0, y0 + size_m, n)
    z = z_m + np.tan(np.radians(slope_deg)) * (x - x0) + noise_m * RNG.standard_normal(n)
    return np.column_stack([x, y, z])


def box_top(x0, y0, width_m, depth_m, z_m, density=5.0):
    """Points on the flat top of a box (a car, a flat roof)."""
    n = int(density * width_m * depth_m)
    return np.column_stack([RNG.uniform(x0, x0 + width_m, n), RNG.uniform(y0, y0 + depth_m, n),
                            z_m + 0.02 * RNG.standard_normal(n)])


def test_flat_plane_is_one_ground_surface_on_level_0():
    xyz = plane()
    planes = ground_planes(xyz)
    assert (planes.surface == 0).mean() > 0.98  # only sparse corner blocks may be too small
    assert set(np.unique(planes.level)) <= {-1, 0}
    assert planes.n_levels == 1
    row = planes.surfaces.iloc[0]
    assert row.n_points == (planes.surface == 0).sum()
    assert row.area_m2 == pytest.approx(1600, rel=0.02)
    assert row.mean_z_m == pytest.approx(0.0, abs=0.01)
    assert planes.surface.dtype == np.int32 and planes.level.dtype == np.int16


def test_two_planes_5m_apart_are_two_surfaces_on_two_levels():
    lower = plane(size_m=50.0, z_m=100.0)
    upper = plane(size_m=34.0, x0=8.0, y0=8.0, z_m=105.0)  # lower ground on every side
    planes = ground_planes(np.vstack([lower, upper]))
    n = len(lower)
    assert planes.n_levels == 2
    assert (planes.level[:n] == 0).mean() > 0.98 and (planes.level[n:] == 1).mean() > 0.98
    low_surfaces = set(np.unique(planes.surface[:n])) - {-1}
    high_surfaces = set(np.unique(planes.surface[n:])) - {-1}
    assert len(low_surfaces) == len(high_surfaces) == 1 and low_surfaces != high_surfaces
    table = planes.surfaces.set_index("surface_id")
    assert table.loc[high_surfaces.pop(), "mean_z_m"] == pytest.approx(105.0, abs=0.01)
    assert table.loc[low_surfaces.pop(), "level"] == 0


def test_a_cliff_top_overlaps_nothing_and_stays_on_level_0():
    """8 m higher than the foot, behind a 4 m wide 63 degree face; no overlap in xy."""
    foot = plane(size_m=40.0)
    face = plane(size_m=4.0, x0=40.0, slope_deg=63.4, density=100.0)
    face[:, 1] = RNG.uniform(0.0, 40.0, len(face))  # stretch the 4 m square along the cliff
    top = plane(size_m=40.0, x0=44.0, z_m=8.0)
    planes = ground_planes(np.vstack([foot, face, top]))
    foot_surface = planes.surface[:len(foot)]
    top_surface = planes.surface[len(foot) + len(face):]
    assert (foot_surface >= 0).mean() > 0.95 and (top_surface >= 0).mean() > 0.95
    assert len(np.unique(foot_surface[foot_surface >= 0])) == 1
    assert len(np.unique(top_surface[top_surface >= 0])) == 1
    assert foot_surface.max() != top_surface.max()
    assert (planes.surface[len(foot):len(foot) + len(face)] < 0).mean() > 0.9
    assert planes.n_levels == 1


def test_a_terrace_behind_a_vertical_wall_is_no_level_of_its_own():
    """3 m above the ground beside it with no face at all between (a retaining wall): its
    edge comes within a column of the lower ground, as a deck's does, but nothing lower
    lies beyond it, so it spans nothing."""
    lower, terrace = plane(size_m=40.0), plane(size_m=40.0, x0=40.0, z_m=3.0)
    planes = ground_planes(np.vstack([lower, terrace]))
    assert planes.n_levels == 1 and (planes.level >= 0).mean() > 0.97
    assert planes.surface[:len(lower)].max() != planes.surface[len(lower):].max()
    # A strip 3 m up and 4 m wide with the lower ground on both sides of it: a deck.
    deck = plane(size_m=4.0, x0=18.0, z_m=3.0, density=50.0)
    deck[:, 1] = RNG.uniform(0.0, 40.0, len(deck))
    under = (lower[:, 0] > 18.0) & (lower[:, 0] < 22.0)  # no return under the deck
    planes = ground_planes(np.vstack([lower[~under], deck]), min_surface_area_m2=100)
    assert planes.n_levels == 2 and (planes.level[-len(deck):] == 1).mean() > 0.97
    assert (planes.level[:-len(deck)] == 0).mean() > 0.97


@pytest.mark.parametrize("slope_deg, ground", [(5, True), (10, True), (20, False), (30, False)])
def test_slopes_steeper_than_t_vert_allows_are_not_ground(slope_deg, ground):
    planes = ground_planes(plane(slope_deg=slope_deg))
    assert bool((planes.surface >= 0).mean() > 0.95) == ground


def test_thresholds_are_the_papers_tests():
    tilted = plane(slope_deg=10.0)  # |u3 . z| = cos 10 deg = 0.985
    assert (ground_planes(tilted, t_vert=0.98).surface >= 0).mean() > 0.95
    assert (ground_planes(tilted, t_vert=0.99).surface >= 0).sum() == 0
    rough = plane(noise_m=0.08)  # lambda3 / sum about 0.002
    assert (ground_planes(rough, t_planar=0.01).surface >= 0).mean() > 0.95
    assert (ground_planes(rough, t_planar=0.001).surface >= 0).sum() == 0


def test_noisy_sphere_is_not_ground():
    direction = RNG.standard_normal((5000, 3))
    sphere = 5.0 * direction / np.linalg.norm(direction, axis=1)[:, None]
    sphere += 0.05 * RNG.standard_normal(sphere.shape) + [20.0, 20.0, 8.0]
    assert (ground_planes(sphere).surface >= 0).sum() == 0


def test_kerb_joins_car_roof_and_small_flat_roof_do_not():
    road = plane(size_m=40.0)
    road = road[~((road[:, 0] > 10) & (road[:, 0] < 14.5) & (road[:, 1] > 10)
                  & (road[:, 1] < 11.8))]  # no return under the car
    sidewalk = plane(size_m=40.0, x0=40.0, z_m=0.15)  # behind a 15 cm kerb
    sidewalk = sidewalk[~((sidewalk[:, 0] > 60) & (sidewalk[:, 1] > 20))]  # under the roof
    car = box_top(10.0, 10.0, 4.5, 1.8, 1.5)
    roof = box_top(60.0, 20.0, 20.0, 20.0, 6.0)  # 400 m2, under min_surface_area_m2
    xyz = np.vstack([road, sidewalk, car, roof])
    n_ground = len(road) + len(sidewalk)
    planes = ground_planes(xyz)
    assert len(set(np.unique(planes.surface[:n_ground])) - {-1}) == 1
    assert (planes.surface[:n_ground] >= 0).mean() > 0.97
    assert (planes.surface[n_ground:] < 0).all()
    assert (ground_planes(xyz, min_surface_area_m2=300).surface[-len(roof):] >= 0).all()


def test_result_does_not_depend_on_point_order():
    xyz = np.vstack([plane(z_m=0.0), plane(z_m=6.0, size_m=20.0, x0=10.0, y0=10.0)])
    planes = ground_planes(xyz)
    shuffle = RNG.permutation(len(xyz))
    again = ground_planes(xyz[shuffle])
    assert np.array_equal(planes.surface[shuffle], again.surface)
    assert np.array_equal(planes.level[shuffle], again.level)


def test_empty_and_bad_input():
    planes = ground_planes(np.empty((0, 3)))
    assert planes.n_levels == 0 and len(planes.surface) == 0 and len(planes.surfaces) == 0
    assert list(planes.surfaces.columns) == ["surface_id", "level", "n_points", "area_m2",
                                             "mean_z_m"]
    with pytest.raises(ValueError):
        ground_planes(np.zeros((5, 2)))


def test_progress_runs_from_0_to_1():
    fractions = []
    ground_planes(plane(size_m=20.0), progress=lambda f, m: fractions.append(f))
    assert fractions[0] == 0.0 and fractions[-1] == 1.0 and fractions == sorted(fractions)


# --- a synthetic scene with exact truth ---------------------------------------------------

@pytest.fixture(scope="module")
def scene():
    return make_scene(seed=3, size_m=(300.0, 300.0))


@pytest.fixture(scope="module")
def cloud(scene):
    return concatenate(list(render_cloud(scene, density_per_m2=6.0, seed=0)))


@pytest.fixture(scope="module")
def planes(cloud):
    return ground_planes(cloud.xyz)


def _road_points(scene, cloud, name):
    road_ids = scene.roads.index[scene.roads["name"] == name]
    polygons = scene.truth.polygons
    area = shapely.union_all(polygons.geometry.values[polygons["road_id"].isin(road_ids)])
    shapely.prepare(area)
    return (shapely.contains_xy(area, cloud.xyz[:, 0], cloud.xyz[:, 1])
            & road_surface_mask(scene, cloud.xyz))


def test_scene_roads_are_ground_and_objects_are_not(scene, cloud, planes):
    ground = planes.surface >= 0
    assert ground[road_surface_mask(scene, cloud.xyz)].mean() >= 0.95
    for las_class in (1, 5, 6):  # cars, tree crowns, buildings
        assert ground[cloud.classification == las_class].mean() < 0.02


def test_cliff_top_and_foot_roads_are_ground_on_different_surfaces(scene, cloud, planes):
    top, foot = (_road_points(scene, cloud, name) for name in ("cliff_top", "cliff_foot"))
    assert top.sum() > 1000 and foot.sum() > 1000
    assert (planes.surface[top] >= 0).mean() > 0.95 and (planes.surface[foot] >= 0).mean() > 0.95
    top_surface = np.bincount(planes.surface[top][planes.surface[top] >= 0]).argmax()
    foot_surface = np.bincount(planes.surface[foot][planes.surface[foot] >= 0]).argmax()
    assert top_surface != foot_surface


def test_bridge_deck_is_ground_on_a_level_above_the_road_under_it(scene, cloud, planes):
    deck = cloud.classification == 17
    assert deck.sum() > 300 and (planes.level[deck] >= 1).all()
    # Points of the avenue just beside the deck, metres below it: the road under the bridge.
    decks = shapely.union_all(scene.bridges.geometry.values)
    beside = shapely.contains_xy(shapely.buffer(decks, 2.0), cloud.xyz[:, 0], cloud.xyz[:, 1])
    under = (_road_points(scene, cloud, "avenue") & beside & ~deck
             & (cloud.xyz[:, 2] < cloud.xyz[deck, 2].min() - 3.0))
    assert under.sum() > 50
    assert (planes.level[under] == 0).mean() > 0.95
    assert not set(planes.surface[deck]) & set(planes.surface[under])
    table = planes.surfaces.set_index("surface_id")
    assert (table.loc[np.unique(planes.surface[deck]), "level"] >= 1).all()
