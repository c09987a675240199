"""Measure the LiDAR road-evidence raster (gisroads.lidar.evidence) on the real clouds.

Pixel AUC of the likelihood and of each cue's membership against fusa's road area and the
IGN tile's partial truth (centre lines buffered by width / 2), share of likelihood > 0.5 on
the negatives, a quick downstream network (threshold 0.5, opening, skeleton, spur pruning)
scored against fusa's centre lines, time per cloud, and PNG quick-looks.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/lidar_evidence.py [--out /tmp/evidence]

Not wired into bench/run.py.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from rasterio import features
from scipy import ndimage
from scipy.stats import rankdata

from gisroads.evaluate import buffer_metrics
from gisroads.geo import GeoRaster
from gisroads.imagery.datasets import prune_spurs
from gisroads.io.las import read_las
from gisroads.io.quicklook import write_quicklook
from gisroads.lidar.evidence import road_evidence
from gisroads.vectorize.skeleton import skeleton_lines

LIDAR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "lidar"
TRUTH = LIDAR / "ground_truth"
IGN = "test_semis_2023_0292_6833"


def pixel_auc(score: np.ndarray, truth: np.ndarray, valid: np.ndarray) -> float:
    """Area under the ROC curve of ``score`` (NaN counted as 0) for ``truth`` pixels, over
    the ``valid`` pixels (Mann-Whitney, ties halved)."""
    s = np.nan_to_num(np.asarray(score, float)[valid], nan=0.0)
    t = np.asarray(truth, bool)[valid]
    n_pos, n_neg = t.sum(), (~t).sum()
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    ranks = rankdata(s)
    return float((ranks[t].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def rasterise(geoms, raster: GeoRaster) -> np.ndarray:
    geoms = [g for g in geoms if g is not None and not g.is_empty]
    if not geoms:
        return np.zeros(raster.shape, bool)
    return features.rasterize(geoms, out_shape=raster.shape, transform=raster.transform,
                              all_touched=False).astype(bool)


def truth_area(scene: str) -> list:
    """fusa: its road-area polygons; the IGN tile: centre lines buffered by width / 2."""
    if scene == "fusa":
        return list(gpd.read_file(TRUTH / scene / "road_area.geojson").geometry)
    lines = gpd.read_file(TRUTH / scene / "centrelines.geojson")
    return list(shapely.buffer(lines.geometry.values, lines["width_m"].to_numpy() / 2,
                               cap_style="flat"))


#: measures where a higher value means road (the others are negated for their raw AUC)
HIGHER_IS_ROAD = {"density"}


def aucs(evidence, truth) -> tuple[dict, dict]:
    """AUC of the likelihood and of each cue's membership; AUC of each raw measure (signed so
    that road is high, NaN as the least road-like)."""
    valid = np.isfinite(evidence.likelihood.data) | truth
    members = {"likelihood": pixel_auc(evidence.likelihood.data, truth, valid)}
    raw = {}
    for name, member in evidence.memberships.items():
        members[name] = pixel_auc(member.data, truth, valid)
        value = evidence.measures[name].data.astype(float)
        value = value if name in HIGHER_IS_ROAD else -value
        raw[name] = pixel_auc(np.where(np.isfinite(value), value, np.nanmin(value) - 1),
                              truth, valid)
    return members, raw


def network(likelihood: GeoRaster, *, threshold: float = 0.5, opening_m: float = 1.0,
            spur_m: float = 5.0, min_length_m: float = 10.0) -> gpd.GeoDataFrame:
    mask = np.nan_to_num(likelihood.data) > threshold
    radius = max(1, int(round(opening_m / likelihood.pixel_size)))
    mask = ndimage.binary_opening(mask, ndimage.generate_binary_structure(2, 1), radius)
    lines = skeleton_lines(mask, likelihood.transform, likelihood.crs,
                           simplify_m=likelihood.pixel_size)
    lines = prune_spurs(lines, spur_m)
    return lines[lines.length >= min_length_m]


def quicklook(path: Path, evidence, lines=None, reference=None, title: str = "") -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xmin, ymin, xmax, ymax = evidence.likelihood.bounds
    names = ["likelihood", *evidence.memberships]
    cols = 4
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.5 * cols, 4.5 * rows), dpi=100)
    for ax, name in zip(axes.ravel(), names):
        data = (evidence.likelihood if name == "likelihood" else evidence.memberships[name]).data
        ax.imshow(data, extent=(xmin, xmax, ymin, ymax), cmap="magma", vmin=0, vmax=1,
                  interpolation="nearest")
        ax.set_title(name, fontsize=10)
        ax.tick_params(labelsize=6)
        if lines is not None and name == "likelihood":
            lines.plot(ax=ax, color="cyan", linewidth=0.6)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    # the likelihood alone, large, under the downstream lines and the truth centre lines
    layers = [] if reference is None else [
        (reference, dict(color="deepskyblue", linewidth=2.5, label="truth centre lines"))]
    if lines is not None:
        layers.append((lines, dict(color="red", linewidth=1, label="threshold 0.5, skeleton")))
    write_quicklook(path.with_name(path.stem + "_likelihood.png"), layers,
                    background=evidence.likelihood, title=title, size_px=1100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="/tmp/evidence")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for scene, path in (("fusa", LIDAR / "fusa.laz"), (IGN, LIDAR / f"{IGN}_LA93_IGN69.laz"),
                        ("zurich", LIDAR / "zurich.laz"), ("crop_1", LIDAR / "crop_1.laz"),
                        ("Megaplot", LIDAR / "Megaplot.laz")):
        start = time.perf_counter()
        cloud = read_las(path)
        read_seconds = time.perf_counter() - start
        start = time.perf_counter()
        evidence = road_evidence(cloud)
        seconds = time.perf_counter() - start
        like = evidence.likelihood.data
        valid = np.isfinite(like)
        record = {"points": len(cloud), "cell_m": evidence.cell_m, "seconds": round(seconds, 2),
                  "read_seconds": round(read_seconds, 2),
                  "share_above_0.5": float((like[valid] > 0.5).mean()),
                  "used": evidence.used, "missing": evidence.missing}
        lines = roads = None
        if scene in ("fusa", IGN):
            truth = rasterise(truth_area(scene), evidence.likelihood)
            record["auc"], record["auc_raw_measure"] = aucs(evidence, truth)
            record["truth_recall_at_0.5"] = float((np.nan_to_num(like)[truth] > 0.5).mean())
            lines = network(evidence.likelihood)
            roads = gpd.read_file(TRUTH / scene / "centrelines.geojson")
            service = gpd.read_file(TRUTH / scene / "service.geojson")
            record["downstream"] = {"lines": len(lines),
                                    "extracted_m": float(lines.length.sum())}
            for name, reference in (("roads", roads), ("roads+service", pd.concat(
                    [roads, service.set_crs(roads.crs, allow_override=True)]))):
                metrics = buffer_metrics(lines, reference.set_crs(lines.crs,
                                                                  allow_override=True),
                                         buffer_m=3.0)
                record["downstream"][name] = {"completeness": metrics.completeness,
                                              "correctness": metrics.correctness}
        quicklook(out / f"{scene}.png", evidence, lines,
                  None if roads is None else roads.set_crs(evidence.likelihood.crs,
                                                           allow_override=True),
                  title=f"{scene}: road likelihood")
        results[scene] = record
        print(scene, json.dumps(record, indent=1, default=float), flush=True)
    (out / "results.json").write_text(json.dumps(results, indent=1, default=float))


if __name__ == "__main__":
    main()
