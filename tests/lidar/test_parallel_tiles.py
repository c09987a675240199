"""Tiles as tasks on Dask (issue 12, item 2): the same network whatever the number of
workers, on a local cluster or on a real scheduler and worker started here on loopback."""
import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from gisroads.io.vector import read_layer
from gisroads.lidar.pipeline import extract_roads
from gisroads.parallel import progress_message, run_tasks, shared_workers, worker_python
from tests.lidar.tile_runs import ENV, GISROADS, assert_same_geometries


pytest.importorskip("distributed")


def _square(x):
    return x * x


def test_results_come_back_in_the_items_order_here_and_on_dask():
    items = list(range(7))
    seen = []
    assert run_tasks(_square, items, progress=lambda f, m: seen.append(m)) == \
        [x * x for x in items]
    assert seen[-1].startswith("7 of 7 tiles done")
    assert run_tasks(_square, items, workers=2) == [x * x for x in items]
    assert progress_message(1, 4, time.monotonic() - 10).endswith("about 0:30 left")


def _worker_pid(_):
    time.sleep(0.05)
    return os.getpid()


def test_rounds_of_tasks_in_a_shared_block_run_on_one_cluster():
    alone = [set(run_tasks(_worker_pid, range(8), workers=2)) for _ in range(2)]
    assert alone[0].isdisjoint(alone[1])  # a cluster per round: new worker processes
    with shared_workers():
        first = set(run_tasks(_worker_pid, range(8), workers=2))
        with shared_workers():  # nested: the outer block's cluster
            second = set(run_tasks(_worker_pid, range(8), workers=2))
    assert first == second and len(first) == 2 and os.getpid() not in first
    assert set(run_tasks(_worker_pid, range(8), workers=2)).isdisjoint(first)


def test_workers_start_with_this_installation_when_sys_executable_is_another(monkeypatch,
                                                                            tmp_path):
    """As inside QGIS, whose sys.executable is the first python3 on PATH or QGIS itself."""
    assert worker_python() == sys.executable
    foreign = tmp_path / "python3"
    foreign.write_text("#!/bin/sh\necho 3.11 /opt/other-python\n")
    foreign.chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(foreign))
    version = "{}.{}".format(*sys.version_info[:2])
    assert worker_python() == os.path.join(sys.base_prefix, "bin", f"python{version}")
    seen = []
    assert run_tasks(_square, [1, 2, 3], workers=2, progress=lambda f, m: seen.append(m)) \
        == [1, 4, 9]
    assert seen[0] == "3 tiles on 2 Dask workers"
    monkeypatch.setattr(sys, "base_prefix", str(tmp_path))
    with pytest.raises(ValueError, match="no interpreter of this Python"):
        worker_python()


def test_two_workers_give_the_network_of_one(tiled_cloud, tiled_network):
    parallel = extract_roads(tiled_cloud, cue="intensity", workers=2)
    assert parallel.run == {"tiles": 6, "reused": 0}
    for name in ("centrelines", "polygons", "junctions"):
        assert_same_geometries(getattr(parallel.network, name),
                               getattr(tiled_network.network, name))
    assert len(tiled_network.network.centrelines) > 10
    np.testing.assert_array_equal(parallel.network.centrelines.width_m,
                                  tiled_network.network.centrelines.width_m)
    # the per-width likelihood maps come back only when asked for (a city's memory)
    assert sum(len(t.likelihood) for t in parallel.tiles) >= len(parallel.tiles)
    lean = extract_roads(tiled_cloud, cue="intensity", workers=2, tile_maps=False)
    assert [len(t.likelihood) for t in lean.tiles] == [0] * 6
    assert_same_geometries(lean.network.centrelines, tiled_network.network.centrelines)
    # ... and the driver keeps of each tile only its core: the same QA layers and mosaics
    for name in ("rectangles", "hypotheses"):
        assert_same_geometries(lean.network.qa[name], tiled_network.network.qa[name])
    np.testing.assert_array_equal(lean.heights.data, tiled_network.heights.data)
    for tile in lean.tiles:
        for raster in (tile.intensity, tile.heights):
            inner = np.array(tile.tile.core) + raster.pixel_size * np.array([-1, -1, 1, 1])
            assert (inner[:2] <= raster.bounds[:2]).all() and \
                (raster.bounds[2:] <= inner[2:]).all()  # to the nearest cell
    # the evidence cue too (its reference tile first, the others on the cluster)
    one = extract_roads(tiled_cloud, cue="evidence")
    two = extract_roads(tiled_cloud, cue="evidence", workers=2)
    assert_same_geometries(one.network.centrelines, two.network.centrelines)
    np.testing.assert_array_equal(one.evidence.data, two.evidence.data)


def test_cli_on_a_real_scheduler_and_worker_on_loopback(tiled_cloud, tiled_network, tmp_path,
                                                         dask_loopback):
    out = tmp_path / "roads.gpkg"
    done = subprocess.run([*GISROADS, "lidar", str(tiled_cloud), "-o", str(out), "--json",
                           "--cue", "intensity", "--scheduler", dask_loopback,
                           "--work-dir", str(tmp_path / "work")],
                          capture_output=True, text=True, env=ENV, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout)
    assert result["tiles_run"] == 6 and result["tiles_reused"] == 0
    assert_same_geometries(read_layer(out, "road_centrelines"),
                           tiled_network.network.centrelines.reset_index(drop=True))
