"""Road evidence through the network stage: variants measured on every real cloud and on
the synthetic scenes (issue 10's targets).

Each variant is a likelihood (``gisroads.lidar.evidence.road_evidence``, optionally edited)
and a call of ``gisroads.network.rasters.raster_to_network``. Scored with a 3 m buffer
against the hand-digitised centre lines (fusa; the IGN tile: completeness only, its truth is
partial), ``Ks`` the correctness counting the truth's car-park aisles (``service``) as right,
junctions matched within 10 m; on zurich, crop_1, Megaplot, autzen and the extra-bytes file
the km of lines (no public road in the first three); the synthetic 300 m scenes of
``tests/lidar/test_quality.py`` (street grid with houses and trees; every feature) at 8
pulses/m2 against their exact truth.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/lidar_evidence_network.py \\
        [--variants base,recommended] [--rectangles] [--out /tmp/evidence_network]

``--rectangles`` adds the variant confirmed by the paper's rectangle cover (runs the
paper's pipeline on every file, about 90 s). Not wired into bench/run.py.

Kerb rules (issue 10, ``kerb_*``, :func:`kerb_variant` on top of ``recommended``), measured
on the likelihood before ``road_evidence`` had its ``kerbs`` cue (fusa C / K / Ks /
junctions; synthetic grid and every-feature scene C / K; the IGN tile's 1.9 m cells are left
alone, zurich, crop_1 and the extra-bytes file stay at 0 km in every variant):

=====================  ==========================  ============  ============
variant                fusa                        syn_grid      syn_full
=====================  ==========================  ============  ============
recommended            0.799 / 0.593 / 0.693 / 5   0.989 / 1.0   0.982 / 0.940
kerb_sidewalks         0.802 / 0.647 / 0.723 / 5   0.989 / 1.0   0.891 / 0.949
kerb_sidewalks_beside  0.803 / 0.631 / 0.705 / 5   0.991 / 1.0   0.889 / 0.946
kerb_sidewalks_long    0.802 / 0.596 / 0.696 / 5   0.989 / 1.0   0.982 / 0.940
kerb_medians           0.805 / 0.599 / 0.695 / 6   0.973 / 1.0   0.983 / 0.963
kerb_medians_6m        0.810 / 0.599 / 0.697 / 5   0.989 / 1.0   0.982 / 0.940
kerb_islands           0.787 / 0.587 / 0.688 / 4   0.989 / 1.0   0.982 / 0.940
=====================  ==========================  ============  ============

The sidewalk cuts take the foot of the synthetic overpass's ramp (its edges are steps, the
ramp narrows, and the band across it is cut: the ramp's road is lost); ``kerb_medians``
without a length floor cuts 1-4 cell notches of the grid's carriageway edges (a junction
lost); from a 4 m floor on the grid is whole again, and a car's length (5 m) became the
``kerbs`` cue of ``road_evidence`` (fusa 0.810 / 0.599, 5 of 7 through the pipeline).
"""
from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from rasterio import features
from scipy import ndimage

from gisroads.evaluate.buffer import buffer_metrics
from gisroads.evaluate.topology import junction_metrics
from gisroads.geo import GeoRaster
from gisroads.io.las import concatenate, read_las
from gisroads.lidar.evidence import (KERB_GRADIENT, LANE_RADIUS_M, EvidenceRule, _cell_min,
                                     _disk, kerb_steps, median_cells, road_evidence,
                                     vehicle_cells, without_car_park_aisles)
from gisroads.network.rasters import PartOptions, raster_to_network

LIDAR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "lidar"
TRUTH = LIDAR / "ground_truth"
REAL = {"fusa": "fusa", "IGN": "test_semis_2023_0292_6833_LA93_IGN69", "zurich": "zurich",
        "crop_1": "crop_1", "Megaplot": "Megaplot", "autzen": "autzen_trim",
        "xbytes": "las_with_several_extra_byte_bloc"}
SYNTHETIC = {"syn_grid": {"features": ("buildings", "trees")}, "syn_full": {}}
OLD_RULE = EvidenceRule(intensity=(0.3, 0.8))


def ground_step(cloud, evidence, sigma_m: float = 0.5, trend_m: float = 3.0) -> np.ndarray:
    """:func:`gisroads.lidar.evidence.kerb_steps` of the lowest returns within 0.25 m of the
    terrain (the ``kerbs`` cue takes the ground returns); NaN far from them."""
    lik = evidence.likelihood
    t, (rows, cols), cell = lik.transform, lik.shape, evidence.cell_m
    x, y, z = np.asarray(cloud.xyz, float).T
    col = np.floor((x - t.c) / cell).astype(int)
    row = np.floor((t.f - y) / cell).astype(int)
    ok = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
    lowest = _cell_min((row * cols + col)[ok], z[ok], rows * cols).reshape(rows, cols)
    ground = np.where(evidence.measures["height"].data <= 0.25, lowest, np.nan)
    return kerb_steps(ground, cell, sigma_m=sigma_m, trend_m=trend_m)


def kerb_cut(cloud, evidence, likelihood: GeoRaster) -> GeoRaster:
    """Cells on a kerb or median step (and one cell around) set to 0; clouds with cells
    over 1 m cannot resolve a kerb and are left alone."""
    if evidence.cell_m > 1.0:
        return likelihood
    kerb = ndimage.binary_dilation(np.nan_to_num(ground_step(cloud, evidence)) >= KERB_GRADIENT)
    data = np.array(likelihood.data, np.float32)
    data[kerb & np.isfinite(data)] = 0.0
    return GeoRaster(data, likelihood.transform, likelihood.crs, nodata=np.nan)


def _extent_m(labels: np.ndarray, count: int, cell_m: float) -> np.ndarray:
    """Per label (0 included, as 0), the diagonal of its bounding box, metres."""
    boxes = ndimage.find_objects(labels, count)
    return np.array([0.0] + [np.hypot(b[0].stop - b[0].start, b[1].stop - b[1].start) * cell_m
                             for b in boxes])


def kerb_parts(cloud, evidence, low: float = 0.6):
    """``(paved, kerb, carriageway, corridor)`` masks: paved cells, kerb steps
    (:func:`ground_step` >= :data:`KERB_GRADIENT`), the paved cells a lane-wide disk fits in
    once the kerbs are out, and the same without taking the kerbs out."""
    paved = np.nan_to_num(evidence.likelihood.data) >= low
    kerb = np.nan_to_num(ground_step(cloud, evidence)) >= KERB_GRADIENT
    disk = _disk(LANE_RADIUS_M / evidence.cell_m)
    return (paved, kerb, ndimage.binary_opening(paved & ~kerb, disk),
            ndimage.binary_opening(paved, disk))


def kerb_variant(cloud, evidence, kind: str, *, min_length_m: float = 0.0) -> GeoRaster:
    """The likelihood with the cells a kerb rule takes for no carriageway set to 0 (clouds
    with cells over 1 m cannot resolve a kerb and are left alone).

    ``sidewalks``: paved cells of a wide corridor outside its kerb-free carriageway parts
    (the strips beyond a kerb and the kerbs); ``sidewalks_beside``: only those strips within
    3.5 m of a carriageway part, and the kerb cells along them; ``sidewalks_long``: only the
    strips at least 8 m long and at most 3 m wide on average (a sidewalk, not a band across a
    road where it narrows); ``medians``: paved cells a 2 m closing of the carriageway parts
    spans (between two carriageways), those at least ``min_length_m`` long; ``islands``:
    enclosed holes of the carriageway parts larger than the network stage fills (50 m2)
    holding a kerb step.
    """
    likelihood = evidence.likelihood
    if evidence.cell_m > 1.0:
        return likelihood
    data = np.array(likelihood.data, np.float32)
    cell = evidence.cell_m
    paved, kerb, carriageway, corridor = kerb_parts(cloud, evidence)
    if kind.startswith("sidewalks"):
        cut = paved & corridor & ~carriageway
        if kind != "sidewalks":
            near = ndimage.distance_transform_edt(~carriageway) * cell <= 3.5
            strips = cut & ~kerb & near
            if kind == "sidewalks_long":
                labels, count = ndimage.label(strips, np.ones((3, 3)))
                extent = _extent_m(labels, count, cell)
                area = np.bincount(labels.ravel(), minlength=count + 1) * cell ** 2
                long = (extent >= 8.0) & (area <= 3.0 * extent)
                long[0] = False
                strips = long[labels]
            cut = strips | (kerb & paved & near & ndimage.binary_dilation(strips))
    elif kind == "medians":
        cut = median_cells(paved, kerb, cell, min_length_m=min_length_m)
    elif kind == "islands":
        labels, count = ndimage.label(~carriageway)
        edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
        hole = np.bincount(labels.ravel(), minlength=count + 1) * cell ** 2 > 50.0
        hole &= np.bincount(labels.ravel(), weights=kerb.ravel(), minlength=count + 1) > 0
        hole[edge] = False
        hole[0] = False
        cut = hole[labels]
    else:
        raise ValueError(f"unknown kerb variant {kind!r}")
    data[cut & np.isfinite(data)] = 0.0
    return GeoRaster(data, likelihood.transform, likelihood.crs, nodata=np.nan)


def otsu(values) -> float:
    from skimage.filters import threshold_otsu
    return float(threshold_otsu(values[np.isfinite(values)]))


def network(likelihood, evidence, *, threshold=0.8, low=None, aisles=False):
    options = PartOptions(low_threshold=low)
    net = raster_to_network(likelihood, threshold=threshold, part_options=options)
    if aisles and len(net.centrelines):
        cleared, found = without_car_park_aisles(likelihood, net.centrelines,
                                                 vehicle_cells(evidence))
        if len(found):
            net = raster_to_network(cleared, threshold=threshold, part_options=options)
    return net


def confirmed(likelihood, evidence, paper_lines, *, share=0.3, near_m=4.0):
    """Roads of the network with at least ``share`` of their length within ``near_m`` of
    the paper's centre lines; the others erased from the likelihood, network run again."""
    net = network(likelihood, evidence)
    lines = net.centrelines
    if len(lines) == 0:
        return net
    zone = (shapely.buffer(shapely.union_all(paper_lines.to_crs(lines.crs).geometry.values),
                           near_m) if len(paper_lines) else shapely.Polygon())
    g = lines.geometry.values
    bad = lines[shapely.length(shapely.intersection(g, zone)) / shapely.length(g) < share]
    if len(bad) == 0:
        return net
    erase = features.rasterize(
        list(shapely.buffer(bad.geometry.values, bad["width_m"].to_numpy() / 2 + 1.0)),
        out_shape=likelihood.shape, transform=likelihood.transform).astype(bool)
    data = np.array(likelihood.data, np.float32)
    data[erase] = 0.0
    return raster_to_network(GeoRaster(data, likelihood.transform, likelihood.crs,
                                       nodata=np.nan), threshold=0.8)


#: name: (rule, description, function(cloud, evidence, context) -> network)
VARIANTS = {
    "base": (OLD_RULE, "ramp (0.3, 0.8), threshold 0.8 (before this work)",
             lambda c, e, x: network(e.likelihood, e)),
    "base_t0.5": (OLD_RULE, "ramp (0.3, 0.8), threshold 0.5",
                  lambda c, e, x: network(e.likelihood, e, threshold=0.5)),
    "otsu": (OLD_RULE, "ramp (0.3, 0.8), Otsu threshold of the file's likelihood",
             lambda c, e, x: network(e.likelihood, e, threshold=otsu(e.likelihood.data))),
    "kerb": (OLD_RULE, "ramp (0.3, 0.8), kerb cut, threshold 0.8",
             lambda c, e, x: network(kerb_cut(c, e, e.likelihood), e)),
    "aisles": (OLD_RULE, "ramp (0.3, 0.8), threshold 0.8, car-park aisles out",
               lambda c, e, x: network(e.likelihood, e, aisles=True)),
    "ramp0.6": (EvidenceRule(), "ramp (0.3, 0.6), threshold 0.8",
                lambda c, e, x: network(e.likelihood, e)),
    "ramp0.6_hyst": (EvidenceRule(), "ramp (0.3, 0.6), hysteresis 0.8 / 0.6",
                     lambda c, e, x: network(e.likelihood, e, low=0.6)),
    "recommended": (EvidenceRule(), "ramp (0.3, 0.6), hysteresis 0.8 / 0.6, aisles out",
                    lambda c, e, x: network(e.likelihood, e, low=0.6, aisles=True)),
    "recommended_kerb": (EvidenceRule(), "recommended + kerb cut",
                         lambda c, e, x: network(kerb_cut(c, e, e.likelihood), e, low=0.6,
                                                 aisles=True)),
    "hyst0.5": (EvidenceRule(), "ramp (0.3, 0.6), hysteresis 0.8 / 0.5, aisles out",
                lambda c, e, x: network(e.likelihood, e, low=0.5, aisles=True)),
    **{f"kerb_{kind}{suffix}": (
        EvidenceRule(), f"recommended, kerb rule {kind}{suffix.replace('_', ' ')}",
        lambda c, e, x, kind=kind, length=length: network(
            kerb_variant(c, e, kind, min_length_m=length), e, low=0.6, aisles=True))
       for kind, suffix, length in (
           ("sidewalks", "", 0.0), ("sidewalks_beside", "", 0.0), ("sidewalks_long", "", 0.0),
           ("medians", "", 0.0), ("medians", "_6m", 6.0), ("islands", "", 0.0))},
    "confirmed": (OLD_RULE, "ramp (0.3, 0.8), threshold 0.8, roads confirmed by the paper's "
                            "rectangles", lambda c, e, x: confirmed(e.likelihood, e, x)),
}


def clouds():
    """(name, cloud, truth lines or None, truth junctions or None, service or None)."""
    for name, stem in REAL.items():
        cloud = read_las(LIDAR / f"{stem}.laz")
        folder = TRUTH / stem.replace("_LA93_IGN69", "")
        roads = junctions = service = None
        if (folder / "centrelines.geojson").exists():
            roads = gpd.read_file(folder / "centrelines.geojson")
            junctions = gpd.read_file(folder / "junctions.geojson")
            service = gpd.read_file(folder / "service.geojson")
            if len(roads) == 0:
                roads = None
        yield name, cloud, roads, junctions, service
    from gisroads.synthetic import make_scene, render_cloud
    for name, args in SYNTHETIC.items():
        scene = make_scene(seed=0, size_m=(300.0, 300.0), **args)
        cloud = concatenate(list(render_cloud(scene, density_per_m2=8.0, seed=0)))
        yield name, cloud, scene.truth.centrelines, scene.truth.junctions, None


def score(name, net, roads, junctions, service) -> dict:
    lines = net.centrelines
    row = {"km": lines.length.sum() / 1000, "junctions": len(net.junctions)}
    if roads is None:
        return row
    lines = lines.to_crs(roads.crs) if roads.crs is not None else lines
    scores = buffer_metrics(lines, roads, buffer_m=3.0)
    row["C"] = scores.completeness
    if name != "IGN":  # partial truth: completeness only
        row["K"] = scores.correctness
        if service is not None and len(service):
            row["Ks"] = buffer_metrics(lines, pd.concat([roads, service]),
                                       buffer_m=3.0).correctness
    if junctions is not None and len(junctions):
        found = junction_metrics(net.junctions.to_crs(roads.crs) if roads.crs else
                                 net.junctions, junctions, radius_m=10.0)
        row["J"] = f"{found['junction_matches']}/{found['junctions_reference']}"
    return row


def markdown(frame: pd.DataFrame) -> str:
    """A pipe table, floats to 3 decimals, missing as '-'."""
    def cell(v):
        if isinstance(v, float):
            return "-" if np.isnan(v) else f"{v:.3f}"
        return str(v)
    lines = ["| " + " | ".join(frame.columns) + " |", "|" + "---|" * len(frame.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |"
              for row in frame.itertuples(index=False)]
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", default=",".join(v for v in VARIANTS if v != "confirmed"))
    parser.add_argument("--rectangles", action="store_true")
    parser.add_argument("--out", type=Path, default=Path("/tmp/evidence_network"))
    args = parser.parse_args()
    names = args.variants.split(",") + (["confirmed"] if args.rectangles else [])
    args.out.mkdir(parents=True, exist_ok=True)
    warnings.simplefilter("ignore")
    rows = []
    for name, cloud, roads, junctions, service in clouds():
        paper = None
        if "confirmed" in names:
            from gisroads.lidar.pipeline import extract_roads
            path = LIDAR / f"{REAL.get(name, name)}.laz"
            if not path.exists():
                from gisroads.synthetic import make_scene, write_cloud
                path = args.out / f"{name}.laz"
                write_cloud(make_scene(seed=0, size_m=(300.0, 300.0), **SYNTHETIC[name]),
                            path, density_per_m2=8.0, seed=0)
            paper = extract_roads(path, cue="intensity").network.centrelines
        evidences = {}
        for variant in names:
            rule, _, run = VARIANTS[variant]
            start = time.perf_counter()
            if rule not in evidences:
                evidences[rule] = road_evidence(cloud, rule=rule)
            net = run(cloud, evidences[rule], paper)
            rows.append({"variant": variant, "file": name, **score(name, net, roads, junctions,
                                                                   service),
                         "s": time.perf_counter() - start})
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    table.to_csv(args.out / "results.csv", index=False)
    with open(args.out / "results.md", "w") as out:
        for variant in names:
            part = table[table.variant == variant].drop(columns="variant")
            out.write(f"\n### {variant}: {VARIANTS[variant][1]}\n\n")
            out.write(markdown(part) + "\n")
    print((args.out / "results.md").read_text())


if __name__ == "__main__":
    main()
