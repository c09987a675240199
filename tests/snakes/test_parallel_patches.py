"""Road patches as tasks (issue 12, item 4): the same ribbons and network whatever the
number of workers, on a local cluster or on a real scheduler; finished patches resumed."""
import json
import subprocess

import numpy as np
import pytest

import gisroads.snakes.pipeline as snakes
from gisroads.io.vector import read_layer
from gisroads.snakes.pipeline import extract_map_guided
from gisroads.synthetic import make_scene, write_cloud
from gisroads.synthetic.perturb import perturb_lines
from tests.lidar.tile_runs import ENV, GISROADS, assert_same_geometries

pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def town(tmp_path_factory):
    """A 300 m scene at 4 pulses/m2 and its map (a GeoPackage too): the truth shifted
    1 m, jittered 0.5 m."""
    scene = make_scene(seed=3, size_m=(300.0, 300.0))
    folder = tmp_path_factory.mktemp("patches")
    cloud = folder / "cloud.laz"
    write_cloud(scene, cloud, density_per_m2=4.0, seed=3)
    road_map = perturb_lines(scene.truth.centrelines, shift_m=1.0, jitter_m=0.5, seed=1)
    road_map.to_file(folder / "map.gpkg")
    one = extract_map_guided(cloud, road_map, tagged_las=folder / "one.laz")
    return cloud, road_map, folder, one


def _assert_same(a, b):
    assert len(a.ribbons) == len(b.ribbons) >= 5
    for r, s in zip(a.ribbons, b.ribbons):
        assert r.road_id == s.road_id and r.level == s.level
        assert np.array_equal(r.centre_xyz, s.centre_xyz)
        assert np.array_equal(r.half_width_m, s.half_width_m)
    for name in ("centrelines", "polygons", "junctions"):
        assert_same_geometries(getattr(a.network, name), getattr(b.network, name))


def test_two_workers_fit_the_ribbons_of_one(town):
    cloud, road_map, folder, one = town
    two = extract_map_guided(cloud, road_map, tagged_las=folder / "two.laz",
                             workers=2)
    _assert_same(one, two)
    assert two.tagged_points == one.tagged_points > 1000
    assert (folder / "two.laz").read_bytes() == (folder / "one.laz").read_bytes()
    np.testing.assert_array_equal(two.attractor.data, one.attractor.data)


def test_finished_patches_are_taken_from_the_work_folder(town, tmp_path, monkeypatch):
    cloud, road_map, _, one = town
    first = extract_map_guided(cloud, road_map, work_dir=tmp_path,
                               attractor=False)
    _assert_same(one, first)
    assert first.attractor is None and all(r.attractor is None for r in first.ribbons)
    assert len(list(tmp_path.glob("store-*"))) == 1
    assert len(list(tmp_path.glob("patches-*/patch_*.pkl"))) >= len(one.ribbons)

    def refit(*args, **kwargs):
        raise AssertionError("a finished patch was fitted again")
    monkeypatch.setattr(snakes, "fit_ribbon", refit)
    _assert_same(one, extract_map_guided(cloud, road_map, work_dir=tmp_path,
                                         attractor=False))


def test_cli_runs_the_patches_on_a_real_scheduler_and_worker_on_loopback(town, tmp_path,
                                                                          dask_loopback):
    cloud, _, folder, one = town
    out = tmp_path / "roads.gpkg"
    done = subprocess.run([*GISROADS, "snakes", str(cloud), str(folder / "map.gpkg"), "-o",
                           str(out), "--json", "--scheduler", dask_loopback, "--work-dir",
                           str(tmp_path / "work")],
                          capture_output=True, text=True, env=ENV, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert json.loads(done.stdout)["patches"] == len(one.ribbons)
    for layer, frame in (("road_centrelines", one.network.centrelines),
                         ("road_polygons", one.network.polygons)):
        assert_same_geometries(read_layer(out, layer), frame.reset_index(drop=True))
