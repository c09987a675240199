"""The canal town: paver streets along canals, water without returns, 8-12 cm kerbs."""
import numpy as np
import pytest
import shapely

from gisroads.errors import GisroadsError
from gisroads.synthetic import make_canal_scene, render_cloud
from gisroads.synthetic.canal import CANAL_KERB_RANGE_M
from gisroads.synthetic.cloud import INTENSITY_SCALE


@pytest.fixture(scope="module")
def scene():
    return make_canal_scene(seed=3)


@pytest.fixture(scope="module")
def cloud(scene):
    chunks = list(render_cloud(scene, density_per_m2=14.0, seed=3))
    xyz = np.concatenate([c.xyz for c in chunks])
    return xyz, np.concatenate([c.intensity for c in chunks])


def test_every_canal_street_has_water_on_one_flank(scene):
    water = shapely.union_all(scene.water.geometry.values)
    canal = scene.roads[scene.roads["name"].str.startswith("canal")]
    assert len(canal) == 4 and set(scene.roads["surface"]) == {"pavers"}
    for line, width in zip(canal.geometry.values, canal["width_m"]):
        flanks = [shapely.offset_curve(shapely.force_2d(line), side * (width / 2 + 1.0))
                  for side in (-1, 1)]
        wet = [shapely.intersection(f, water).length / f.length for f in flanks]
        assert max(wet) > 0.8 and min(wet) == 0.0


def test_cross_streets_bridge_the_canals_at_street_level(scene):
    water = shapely.union_all(scene.water.geometry.values)
    cross = scene.roads[scene.roads["name"].str.startswith("cross")]
    for line, width in zip(cross.geometry.values, cross["width_m"]):
        assert not shapely.intersects(shapely.buffer(shapely.force_2d(line), width / 2), water)
    assert len(scene.truth.junctions) == 8


def test_water_returns_nothing(scene, cloud):
    xyz, _ = cloud
    # surfaces are rasterised on cells of a few cm: a point that close to the quay may be
    # either
    water = shapely.buffer(shapely.union_all(scene.water.geometry.values), -0.1)
    shapely.prepare(water)
    assert not shapely.contains_xy(water, xyz[:, 0], xyz[:, 1]).any()
    assert len(xyz) > 0.6 * 14.0 * 300 * 300


def test_pavers_are_as_bright_as_the_footways_and_a_kerb_lower(scene, cloud):
    xyz, intensity = cloud
    street = shapely.union_all(scene.truth.polygons.geometry.values)
    footway = shapely.difference(shapely.buffer(street, 1.8, cap_style="flat"),
                                 shapely.buffer(street, 0.3))
    footway = shapely.difference(footway, shapely.buffer(
        shapely.union_all(scene.water.geometry.values), 0.3))
    on_street = shapely.contains_xy(shapely.buffer(street, -0.5), xyz[:, 0], xyz[:, 1])
    on_footway = shapely.contains_xy(footway, xyz[:, 0], xyz[:, 1])
    bright = [np.median(intensity[m]) / INTENSITY_SCALE for m in (on_street, on_footway)]
    assert bright[0] == pytest.approx(bright[1], abs=0.02)
    x, y = np.meshgrid(np.linspace(*scene.extent[::2], 50), np.linspace(*scene.extent[1::2], 50))
    kerb = scene.relief.kerb_m(x.ravel(), y.ravel())
    assert CANAL_KERB_RANGE_M[0] <= kerb.min() and kerb.max() <= CANAL_KERB_RANGE_M[1]
    assert kerb.min() >= 0.08 and kerb.max() <= 0.12


def test_same_seed_same_town_and_small_towns_refused():
    assert make_canal_scene(seed=5).roads.equals(make_canal_scene(seed=5).roads)
    with pytest.raises(GisroadsError, match="at least 300"):
        make_canal_scene(size_m=(200, 300))
