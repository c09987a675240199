"""Synthetic airborne LiDAR: determinism, density, intensity, kerbs, levels, returns, LAZ."""
import numpy as np
import pytest
import shapely

from gisroads.io.las import concatenate, read_las
from gisroads.synthetic import make_scene, render_cloud, road_surface_mask, write_cloud
from gisroads.synthetic.cloud import INTENSITY_SCALE

DENSITY = 4.0


@pytest.fixture(scope="module")
def scene():
    return make_scene(seed=1, size_m=(300.0, 300.0))


@pytest.fixture(scope="module")
def chunks(scene):
    return list(render_cloud(scene, density_per_m2=DENSITY, seed=0))


@pytest.fixture(scope="module")
def cloud(chunks):
    return concatenate(chunks)


@pytest.fixture(scope="module")
def on_road(scene, cloud):
    return road_surface_mask(scene, cloud.xyz)


def _road_area(scene, name):
    road_id = scene.roads.index[scene.roads["name"] == name][0]
    polygons = scene.truth.polygons
    return shapely.union_all(polygons.geometry.values[polygons["road_id"] == road_id])


def _inside(geom, cloud):
    shapely.prepare(geom)
    return shapely.contains_xy(geom, cloud.xyz[:, 0], cloud.xyz[:, 1])


def _same(a, b):
    return all(np.array_equal(getattr(a, f), getattr(b, f)) for f in
               ("xyz", "intensity", "classification", "return_number", "number_of_returns"))


def test_same_seed_same_chunk_other_seed_other_chunk(scene, chunks):
    again = next(render_cloud(scene, density_per_m2=DENSITY, seed=0))
    assert _same(chunks[0], again)
    other = next(render_cloud(scene, density_per_m2=DENSITY, seed=1))
    assert not _same(chunks[0], other)
    other_scene = next(render_cloud(make_scene(seed=2, size_m=(300.0, 300.0)),
                                    density_per_m2=DENSITY, seed=0))
    assert not _same(chunks[0], other_scene)


def test_chunks_are_tiles_in_the_scene_crs(scene, chunks):
    assert len(chunks) == 9  # 100 m tiles over 300 m
    for chunk in chunks:
        assert chunk.crs == scene.crs and chunk.source_crs == scene.crs
        assert len(chunk) < 1.3 * DENSITY * 100 * 100
        assert chunk.xyz.dtype == np.float64 and chunk.intensity.dtype == np.uint16
    small = list(render_cloud(scene, density_per_m2=DENSITY, tile_m=50.0))
    assert len(small) == 36 and max(len(c) for c in small) < 1.3 * DENSITY * 50 * 50


def test_density_within_10_percent(scene, cloud):
    xmin, ymin, xmax, ymax = scene.extent
    pulses = (cloud.return_number == 1).sum()
    assert abs(pulses / ((xmax - xmin) * (ymax - ymin)) / DENSITY - 1) < 0.1
    assert len(cloud) == pulses + (cloud.return_number == 2).sum()
    assert ((cloud.xyz[:, 0] >= xmin) & (cloud.xyz[:, 0] <= xmax)
            & (cloud.xyz[:, 1] >= ymin) & (cloud.xyz[:, 1] <= ymax)).all()


def test_classes(cloud):
    assert set(np.unique(cloud.classification)) == {1, 2, 5, 6, 17}


def test_asphalt_is_dark_paint_bright(scene, cloud, on_road):
    ground = (cloud.classification == 2) & (cloud.number_of_returns == 1)
    lots = shapely.union_all(np.concatenate([scene.parking_lots.geometry.values,
                                             scene.parking_access.geometry.values]))
    markings = shapely.union_all(scene.markings.geometry.values)
    in_lots, on_paint = _inside(lots, cloud), _inside(markings, cloud)
    road = np.median(cloud.intensity[ground & on_road & ~on_paint])
    verge = np.median(cloud.intensity[ground & ~on_road & ~in_lots])
    lot = np.median(cloud.intensity[ground & in_lots])
    paint = np.median(cloud.intensity[ground & on_paint])
    assert road < 0.5 * verge and lot < 0.5 * verge
    assert paint > 3 * road
    assert 0.08 < road / INTENSITY_SCALE < 0.16 and 0.5 < paint / INTENSITY_SCALE < 0.7


def test_kerb_step_at_a_straight_road_edge(scene, cloud):
    avenue = scene.roads.loc[scene.roads["name"] == "avenue"].iloc[0]
    others = scene.truth.polygons[scene.truth.polygons["road_id"] != avenue.road_id]
    busy = shapely.union_all(np.concatenate([
        shapely.buffer(others.geometry.values, 4.0),
        shapely.buffer(scene.parking_access.geometry.values, 4.0),
        shapely.buffer(scene.bridges.geometry.values, 4.0)]))
    # Ground points near the edges, last returns under the street trees included.
    near = shapely.buffer(avenue.geometry, avenue.width_m / 2 + 1.0, cap_style="flat")
    sel = (cloud.classification == 2) & _inside(near, cloud) & ~_inside(busy, cloud)
    x, y, z = cloud.xyz[sel].T
    points = shapely.points(x, y)
    across = shapely.distance(avenue.geometry, points) - avenue.width_m / 2
    foot = shapely.get_coordinates(shapely.line_interpolate_point(
        avenue.geometry, shapely.line_locate_point(avenue.geometry, points)))
    north = y > foot[:, 1]  # the avenue runs west-east
    inside, outside = (across > -1.0) & (across < -0.2), (across > 0.2) & (across < 1.0)
    height = z - scene.relief.terrain_z(x, y)
    for side in (north, ~north):
        assert (inside & side).sum() > 150 and (outside & side).sum() > 150
        # Against the bare terrain, so that its slope does not blur a 10-20 cm step.
        step = np.median(height[outside & side]) - np.median(height[inside & side])
        assert 0.10 <= step <= 0.20
        # From the points alone: a plane plus a step fitted along 25 m stretches of edge.
        steps = []
        for start in np.arange(x.min(), x.max(), 25.0):
            near = side & (inside | outside) & (x >= start) & (x < start + 25.0)
            if near.sum() > 20 and outside[near].any() and inside[near].any():
                design = np.column_stack([np.ones(near.sum()), x[near] - start,
                                          across[near], outside[near]])
                steps.append(np.linalg.lstsq(design, z[near], rcond=None)[0][3])
        assert len(steps) >= 3 and 0.10 <= np.median(steps) <= 0.20


def test_no_ground_under_the_deck_and_the_deck_6_to_8_m_up(scene, cloud, on_road):
    deck = scene.bridges.geometry.iloc[0]
    under = _inside(deck, cloud)
    assert under.sum() > 200
    first = cloud.return_number == 1
    assert (cloud.classification[under & first] == 17).mean() > 0.95
    # Points within a label pixel of the deck's outline may fall either side of it.
    assert ((cloud.classification == 2) & under).sum() <= 0.03 * under.sum()
    well_under = _inside(shapely.buffer(deck, -0.2), cloud)
    assert ((cloud.classification == 2) & well_under).sum() == 0
    x, y, z = cloud.xyz[under & (cloud.classification == 17)].T
    assert 6.0 <= np.median(z - scene.ground_z(x, y)) <= 8.0
    assert on_road[under & (cloud.classification == 17)].all()  # the deck is the upper road


def test_cliff_top_road_6_to_12_m_above_the_foot_road(scene, cloud, on_road):
    top = on_road & _inside(_road_area(scene, "cliff_top"), cloud)
    foot = on_road & _inside(_road_area(scene, "cliff_foot"), cloud)
    assert top.sum() > 200 and foot.sum() > 200
    assert 6.0 <= np.median(cloud.xyz[top, 2]) - np.median(cloud.xyz[foot, 2]) <= 12.0


def test_canopy_over_roads_gives_last_returns_on_the_road(scene, chunks, on_road, cloud):
    canopy = (cloud.classification == 5) & (cloud.return_number == 1)
    split = canopy & (cloud.number_of_returns == 2)
    assert 0.3 < split.sum() / canopy.sum() < 0.5
    roads = shapely.union_all(scene.truth.polygons.geometry.values)
    # Under a crown a pulse may end on a parked car's roof; on the ground it is the road.
    last = (cloud.return_number == 2) & (cloud.classification == 2) & _inside(roads, cloud)
    assert last.sum() > 50
    assert on_road[last].mean() > 0.97
    assert not on_road[canopy].any()
    # Each last return pairs with a first return of the same pulse, metres above it.
    drops = []
    for chunk in chunks:
        firsts = (chunk.return_number == 1) & (chunk.number_of_returns == 2)
        lasts = chunk.return_number == 2
        assert np.array_equal(chunk.xyz[firsts, :2], chunk.xyz[lasts, :2])
        assert (chunk.number_of_returns[lasts] == 2).all()
        drops.append(chunk.xyz[firsts, 2] - chunk.xyz[lasts, 2])
    assert np.median(np.concatenate(drops)) > 3.0


def test_road_surface_mask_levels(scene, cloud, on_road):
    assert not on_road[cloud.classification == 1].any()  # car roofs
    assert not on_road[cloud.classification == 6].any()
    roads = shapely.union_all(scene.truth.polygons.geometry.values)
    core = shapely.buffer(roads, -0.2)
    ground = (cloud.classification == 2) & _inside(core, cloud)
    assert on_road[ground].mean() > 0.99
    lots = shapely.union_all(scene.parking_lots.geometry.values)
    assert not on_road[_inside(lots, cloud)].any()
    # A point on the lower road under the deck is road, at its level only.
    bridge = scene.bridges.iloc[0]
    x, y = bridge.crossing_x, bridge.crossing_y
    z = scene.ground_z(x, y)
    lower = road_surface_mask(scene, np.array([[x, y, z], [x, y, z + 3.0]]))
    upper = road_surface_mask(scene, np.array([[x, y, scene.deck_z(x, y)]]))
    assert lower.tolist() == [True, False] and upper.tolist() == [True]


def test_laz_round_trip(scene, tmp_path):
    path = tmp_path / "scene.laz"
    count = write_cloud(scene, path, density_per_m2=1.0, seed=3)
    rendered = concatenate(list(render_cloud(scene, density_per_m2=1.0, seed=3)))
    back = read_las(path)
    assert count == len(back) == len(rendered)
    assert back.crs == scene.crs
    assert np.abs(back.xyz - rendered.xyz).max() <= 0.0006
    for field in ("intensity", "classification", "return_number", "number_of_returns"):
        assert np.array_equal(getattr(back, field), getattr(rendered, field))


def test_write_reports_progress_and_a_cancel_leaves_no_file(scene, tmp_path):
    seen = []
    write_cloud(scene, tmp_path / "a.laz", density_per_m2=0.5,
                progress=lambda fraction, message: seen.append(fraction))
    assert seen == sorted(seen) and seen[0] == 0.0 and seen[-1] == 1.0 and len(seen) == 10

    def cancel(fraction, message):
        if fraction > 0.5:
            raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        write_cloud(scene, tmp_path / "b.laz", density_per_m2=0.5, progress=cancel)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.laz"]
