"""Measure the road database update (gisroads.update) against databases with known changes.

A truth is edited into a "database" (gisroads.update.edit_database: 20 % of the lines
deleted, 10 % fake lines added, 10 % shifted 5-10 m sideways, 10 % re-widened by 3-6 m), for
several seeds, and the change layers of gisroads.update.conflate are scored per class
(score_changes), pooled over the seeds:

* ``synthetic_truth``: a synthetic scene's truth as the extraction (the method's ceiling);
* ``synthetic_lidar``: the LiDAR pipeline's output (its default cue) on a scene's simulated
  cloud;
* ``synthetic_imagery``: the imagery pipeline's output on the same scene's R,G,B,NIR image;
* ``fusa``: the LiDAR pipeline's output (its default cue, the evidence) on fusa.laz against
  its hand-digitised centre lines (``--fusa-roads`` reuses a finished ``gisroads lidar``
  GeoPackage), fakes kept clear of the paved areas the truth leaves out
  (gisroads.update.truth_pavement);
* ``fusa_intensity``: the same with the paper's cue alone (``--cue intensity``);
* ``fusa_model``: the evidence with a model learned from each edited database
  (``gisroads train fusa.laz database -o model.npz``, then ``gisroads lidar --model``).

Class ``new`` is the deleted roads found again, ``missing`` the fake roads flagged missing.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/road_database_update.py [--out DIR]

``make bench`` runs it too (bench/run.py, case road_database_update).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import geopandas as gpd

from gisroads.io.vector import read_layer
from gisroads.jobs import image_job, lidar_job, train_lidar_job
from gisroads.synthetic import make_scene, write_cloud, write_image
from gisroads.update import FUSA_UNLABELLED_PAVEMENT, pooled_scores, truth_pavement

LIDAR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "lidar"
FUSA_TRUTH = LIDAR / "ground_truth" / "fusa" / "centrelines.geojson"


def scene_edges(scene) -> gpd.GeoDataFrame:
    """Junction-to-junction truth lines with their road's width."""
    return scene.truth_edges.merge(scene.truth.centrelines[["road_id", "width_m"]],
                                   on="road_id")


def lidar_roads(cloud: Path, out: Path, **options) -> gpd.GeoDataFrame:
    """The LiDAR pipeline's centre lines of ``cloud`` (written to ``out``)."""
    lidar_job(cloud, out, **options)
    return read_layer(out)


def measure(out: Path, seeds: int = 10, fusa_roads: Path | None = None) -> dict:
    """Every case's pooled scores over ``seeds`` edits; scratch files in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    edits = range(seeds)
    results = {}

    scene = make_scene(seed=0, size_m=(1000.0, 700.0))
    start = time.perf_counter()
    results["synthetic_truth"] = pooled_scores(scene.truth.centrelines, scene_edges(scene),
                                               edits)
    results["synthetic_truth"]["seconds_per_edit"] = (time.perf_counter() - start) / seeds

    small = make_scene(seed=1, size_m=(500.0, 500.0))
    write_cloud(small, out / "synthetic.laz", density_per_m2=4.0)
    extracted = lidar_roads(out / "synthetic.laz", out / "synthetic_roads.gpkg")
    results["synthetic_lidar"] = pooled_scores(extracted, scene_edges(small), edits)

    write_image(small, out / "synthetic.tif", out / "synthetic_dsm.tif", pixel_m=0.5)
    image_job(out / "synthetic.tif", out / "synthetic_image_roads.gpkg", nir_band=4)
    results["synthetic_imagery"] = pooled_scores(
        read_layer(out / "synthetic_image_roads.gpkg"), scene_edges(small), edits)

    fusa = (read_layer(fusa_roads) if fusa_roads
            else lidar_roads(LIDAR / "fusa.laz", out / "fusa_roads.gpkg"))
    truth = gpd.read_file(FUSA_TRUTH)
    # a 250 m tile: fake roads 20-40 m long, 15 m clear of the digitised roads and of the
    # paved areas they leave out (car-park aisles, the README's unlabelled pavement)
    pavement = truth_pavement(FUSA_TRUTH.parent, FUSA_UNLABELLED_PAVEMENT)
    results["fusa"] = pooled_scores(fusa, truth, edits, fake_length_m=(20.0, 40.0),
                                    fake_clearance_m=15.0, pavement=pavement)
    fusa_intensity = lidar_roads(LIDAR / "fusa.laz", out / "fusa_intensity_roads.gpkg",
                                 cue="intensity")
    results["fusa_intensity"] = pooled_scores(fusa_intensity, truth, edits,
                                              fake_length_m=(20.0, 40.0),
                                              fake_clearance_m=15.0, pavement=pavement)

    def learned(database: gpd.GeoDataFrame) -> gpd.GeoDataFrame:
        layer = out / "fusa_database.gpkg"
        database.to_file(layer, driver="GPKG")
        train_lidar_job(LIDAR / "fusa.laz", layer, out / "fusa_model.npz",
                        width_field="width_m")
        return lidar_roads(LIDAR / "fusa.laz", out / "fusa_model_roads.gpkg",
                           model=out / "fusa_model.npz")

    results["fusa_model"] = pooled_scores(learned, truth, edits, fake_length_m=(20.0, 40.0),
                                          fake_clearance_m=15.0, pavement=pavement)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/bench/road_database_update"))
    parser.add_argument("--seeds", type=int, default=10, help="edits per case (default 10)")
    parser.add_argument("--fusa-roads", type=Path,
                        help="a finished 'gisroads lidar fusa.laz' GeoPackage to reuse")
    args = parser.parse_args()
    results = measure(args.out, args.seeds, args.fusa_roads)
    (args.out / "results.json").write_text(json.dumps(results, indent=2))
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
