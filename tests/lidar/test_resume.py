"""Resumable (issue 12, item 3): a run killed midway (a power cut: SIGKILL) and started
again takes the finished tiles from its work folder, redoes only the others and writes the
network of an uninterrupted run; a killed run leaves no half-written output."""
import json
import os
import signal
import subprocess
import time

from gisroads.io.vector import read_layer
from tests.lidar.tile_runs import ENV, GISROADS, assert_same_geometries


def test_a_killed_run_resumes_without_redoing_finished_tiles(tiled_cloud, tiled_network,
                                                             tmp_path):
    work, out = tmp_path / "work", tmp_path / "roads.gpkg"
    command = [*GISROADS, "lidar", str(tiled_cloud), "-o", str(out), "--json", "--workers", "1",
               "--cue", "intensity", "--work-dir", str(work)]
    run = subprocess.Popen(command, env=ENV, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        finished = []
        while time.monotonic() < deadline and run.poll() is None:
            finished = list(work.glob("tiles-*/tile_*.pkl"))
            if len(finished) >= 2:
                break
            time.sleep(0.05)
        assert len(finished) >= 2 and run.poll() is None, "the run ended before its tiles"
        os.killpg(run.pid, signal.SIGKILL)  # a power cut: no clean-up runs
        run.wait()
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
            run.wait()
    kept = len(list(work.glob("tiles-*/tile_*.pkl")))
    assert 2 <= kept < 6
    assert not out.exists() and not list(tmp_path.glob("*.gpkg*"))  # no half-written output
    done = subprocess.run(command, capture_output=True, text=True, env=ENV, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout)
    assert result["tiles_run"] == 6 and result["tiles_reused"] == kept
    assert_same_geometries(read_layer(out, "road_centrelines"),
                     tiled_network.network.centrelines.reset_index(drop=True))
    # a third run takes every tile from the work folder; without --json the progress on
    # stderr counts the tiles done and estimates the time left
    again = subprocess.run([c for c in command if c != "--json"], capture_output=True,
                           text=True, env=ENV, timeout=600, check=True)
    assert "tiles_reused: 6" in again.stdout.splitlines()
    assert "6 of 6 tiles done, about 0:00 left" in again.stderr
    assert " of 6 tiles done, about " in again.stderr.split("6 of 6")[0]
