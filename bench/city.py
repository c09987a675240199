"""City-scale LiDAR benchmark (issue 12, item 5; ``make bench-city``, not part of ``make bench``).

A synthetic city of ``side_km`` x ``side_km`` (the project's generator: :func:`make_scene`
lays the street grid out over any extent and :func:`write_cloud` renders and streams the
cloud tile by tile, so the cloud is never in memory) goes through the whole LiDAR pipeline
(``gisroads lidar``'s job, the paper's intensity cue) with 1 and 2 workers, each run in a
fresh interpreter and a fresh work folder: the one streaming pass that buckets the points
into the tile grid, then the tiles, stitching and the network, and the GeoPackage with the
tiles' QA layers written one tile at a time. Reported per size and number
of workers: wall time and its split (the reading pass, the tiles, the network stitched from them,
the layers written), seconds per km², the
peak resident memory of the driving process and of the largest worker process, tiles, and
the quality against the synthetic truth (buffer 3 m); then the ratios the issue asks for:
time per km² at the largest size over that at the smallest (linear cost: about 1), and the
speed-up of 2 workers over 1 on the same job, with whether both wrote the same geometries
(every layer, in the same order).

    python bench/city.py --sides 1,2 --density 10 --workers 1,2 --out out/bench-city
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _run(cloud: str, work: str, out: str, workers: int) -> dict:
    """One end-to-end run in this interpreter (called in a subprocess by :func:`measure`):
    the reading pass timed alone, then the job on its tile store."""
    from gisroads.parallel import shared_workers

    with shared_workers():  # one cluster for both, as in the job alone
        figures = _stages(cloud, work, out, workers)
    # after the cluster's end: its worker processes are then counted among the children
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    # this process's own peak: ru_maxrss would also hold the bench process's size when it
    # started this one (Linux keeps a forked process's high-water mark across exec)
    own = _peak_rss_mb()
    children = kids.ru_maxrss / 1024
    return {**figures,
            # CPU seconds of this process and its worker processes: the work done, which
            # other jobs on a shared machine do not change (wall time they do)
            "cpu_s": me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime,
            "peak_rss_driver_mb": own,
            # the largest worker process (a LocalCluster's workers are our descendants)
            "peak_rss_worker_mb": own if workers == 1 else children}


def _peak_rss_mb() -> float:
    """This process's peak resident memory since it started its program (VmHWM)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _stages(cloud: str, work: str, out: str, workers: int) -> dict:
    """The run's wall times: the reading pass, the tiles, the network, the writing."""
    from gisroads.jobs.lidar import lidar_job
    from gisroads.tiling.tilestore import open_store

    start = time.perf_counter()
    store = open_store(cloud, work, workers=workers)
    read_s = time.perf_counter() - start
    marks = {}

    def mark(fraction, message=""):  # when each stage of the job first reports
        stage = ("writing" if message.startswith("writing tile") else
                 "tiles" if " tiles " in message or message.endswith(" tiles done") else None)
        if stage:
            marks.setdefault(stage, time.perf_counter())
            marks[f"{stage}_last"] = time.perf_counter()
    result = lidar_job(cloud, out, cue="intensity", work_dir=work, workers=workers, progress=mark)
    total_s = time.perf_counter() - start
    end = time.perf_counter()
    tiles_end = marks.get("tiles_last", end)
    writing = marks.get("writing", end)
    return {"workers": workers, "points": store.point_count, "tiles": result["tiles_run"],
            "read_s": read_s, "tiles_and_network_s": total_s - read_s, "total_s": total_s,
            # the stages after the reading pass: the tiles, the network stitched from their
            # centre lines, the layers written one tile at a time
            "tiles_s": tiles_end - start - read_s, "network_s": writing - tiles_end,
            "writing_s": end - writing}


def measure(out: Path, *, sides_km=(1.0, 2.0), density: float = 10.0, workers=(1, 2),
            seed: int = 0) -> dict:
    """The figures of the module docstring; quick-look-free, results as a dict."""
    import geopandas as gpd
    import numpy as np
    import shapely

    from gisroads.evaluate import buffer_metrics
    from gisroads.io.vector import list_layers
    from gisroads.synthetic import make_scene, write_cloud

    out.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix="gisroads-city-"))
    sizes = {}
    try:
        for side in sides_km:
            side_m = 1000.0 * side
            start = time.perf_counter()
            scene = make_scene(seed=seed, size_m=(side_m, side_m))
            cloud = scratch / f"city_{side:g}km.laz"
            points = write_cloud(scene, cloud, density_per_m2=density, seed=seed)
            runs = {}
            generated_s = time.perf_counter() - start
            # what reading cost before the tile store: one decode of the whole file per tile
            from gisroads.io.las import iter_las_chunks
            start = time.perf_counter()
            decoded = sum(len(chunk) for chunk in iter_las_chunks(cloud))
            decode_s = time.perf_counter() - start
            for w in workers:
                work = scratch / f"work_{side:g}_{w}"
                gpkg = out / f"city_{side:g}km_{w}w.gpkg"
                done = subprocess.run(
                    [sys.executable, __file__, "--one", json.dumps(
                        [str(cloud), str(work), str(gpkg), w])],
                    capture_output=True, text=True)
                if done.returncode != 0:
                    raise RuntimeError(f"city {side:g} km, {w} workers:\n{done.stderr}")
                run = json.loads(done.stdout.strip().splitlines()[-1])
                lines = gpd.read_file(gpkg, layer="road_centrelines")
                scores = buffer_metrics(lines, scene.truth.centrelines, buffer_m=3.0)
                run.update(km2=side * side, s_per_km2=run["total_s"] / (side * side),
                           completeness=scores.completeness, correctness=scores.correctness,
                           quality=scores.quality, road_km=float(lines.length.sum()) / 1000)
                run["_wkb"] = {name: shapely.to_wkb(gpd.read_file(gpkg, layer=name)
                                                    .geometry.values)
                               for name in list_layers(gpkg)}
                runs[w] = run
                shutil.rmtree(work, ignore_errors=True)
            first = runs[workers[0]]
            for run in runs.values():
                run["same_output_as_1_worker"] = bool(
                    list(run["_wkb"]) == list(first["_wkb"])
                    and all(np.array_equal(run["_wkb"][name], first["_wkb"][name])
                            for name in run["_wkb"]))
            for run in runs.values():
                del run["_wkb"]
            tiles = runs[workers[0]]["tiles"]
            sizes[f"{side:g}km"] = {"side_km": side, "points": points, "decoded": decoded,
                                    "generate_s": generated_s, "decode_once_s": decode_s,
                                    "per_tile_decoding_s": tiles * decode_s, "runs": runs}
            cloud.unlink()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    keys = list(sizes)
    small, large = sizes[keys[0]]["runs"], sizes[keys[-1]]["runs"]
    ratios = {f"s_per_km2_{keys[-1]}_over_{keys[0]}_{w}w": large[w]["s_per_km2"]
              / small[w]["s_per_km2"] for w in workers}
    if len(workers) > 1:
        for key, size in sizes.items():
            runs = size["runs"]
            ratios[f"speedup_{workers[-1]}w_over_{workers[0]}w_{key}"] = \
                runs[workers[0]]["total_s"] / runs[workers[-1]]["total_s"]
            ratios[f"cpu_{workers[-1]}w_over_{workers[0]}w_{key}"] = \
                runs[workers[-1]]["cpu_s"] / runs[workers[0]]["cpu_s"]
    for key, size in sizes.items():  # the reading pass against a decode per tile
        ratios[f"read_once_over_decode_per_tile_{key}"] = \
            size["runs"][workers[0]]["read_s"] / size["per_tile_decoding_s"]
    # the load of the machine while measuring: wall-time ratios mean little on a busy one
    ratios["load_average_1min_at_end"] = os.getloadavg()[0]
    return {"density_per_m2": density, "sizes": sizes, "ratios": ratios}


def table(result: dict) -> str:
    """The figures as a Markdown table."""
    lines = ["| city | points | workers | tiles | read s | tiles s | network s | writing s "
             "| total s | CPU s | s/km² | peak MB driver / worker | C / K / Q | same output |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for size in result["sizes"].values():
        for w, r in size["runs"].items():
            lines.append(
                f"| {size['side_km'] ** 2:g} km² | {size['points'] / 1e6:.1f} M | {w} | "
                f"{r['tiles']} | "
                f"{r['read_s']:.1f} | {r['tiles_s']:.1f} | {r['network_s']:.1f} | "
                f"{r['writing_s']:.1f} | {r['total_s']:.1f} | "
                f"{r['cpu_s']:.1f} | "
                f"{r['s_per_km2']:.1f} | {r['peak_rss_driver_mb']:.0f} / "
                f"{r['peak_rss_worker_mb']:.0f} | {r['completeness']:.3f} / "
                f"{r['correctness']:.3f} / {r['quality']:.3f} | "
                f"{r['same_output_as_1_worker']} |")
    lines += [""] + [f"- {k}: {v:.2f}" for k, v in result["ratios"].items()]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--sides", default="1,2", help="city sides, km (default 1,2)")
    parser.add_argument("--density", type=float, default=10.0, help="pulses per m² (10)")
    parser.add_argument("--workers", default="1,2", help="worker counts (default 1,2)")
    parser.add_argument("--out", type=Path, default=Path("out/bench-city"))
    args = parser.parse_args()
    if args.one:
        print(json.dumps(_run(*json.loads(args.one))))
        return
    result = measure(args.out, sides_km=[float(v) for v in args.sides.split(",")],
                     density=args.density, workers=[int(v) for v in args.workers.split(",")])
    (args.out / "city.json").write_text(json.dumps(result, indent=2))
    (args.out / "city.md").write_text(table(result) + "\n")
    print(table(result))


if __name__ == "__main__":
    main()
