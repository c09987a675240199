"""LiDAR road extraction as a composition of the stages, with two road cues.

``cue="intensity"``, Zhu & Mordohai's Algorithm 1 (:func:`extract_tile`): per tile,
multi-level ground planes -> one 0.5 m intensity image per ground level -> local-energy
edges and an NCut over-segmentation -> rectangle hypotheses and per-width likelihood maps ->
greedy minimum cover -> rectangles to centre lines. Tiles are stitched at their seams into
one road network; road polygons carry their ground level so that the points of the cloud
can be classified back in 3D (:mod:`gisroads.lidar.tagging`).

``cue="evidence"``, beyond the paper (:func:`evidence_raster`): per tile, the road
likelihood of everything the cloud carries (:mod:`gisroads.lidar.evidence`: intensity,
height above the terrain, density, pulses, roughness, slope, returns, the file's
classification), every tile normalised by the references of the first, mosaicked from the
tiles' cores; then the project's one network stage
(:func:`gisroads.network.rasters.raster_to_network`): gaps bridged by the integer program,
junctions built, curved roads followed; car-park aisles and shores (known by what lines
them) out, and the network stage again.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache, partial
from pathlib import Path
from typing import NamedTuple
from collections.abc import Iterator

from affine import Affine
import geopandas as gpd
import numpy as np
import pandas as pd
from rasterio.windows import Window
import shapely

from ..errors import GisroadsError
from ..features.edges import local_energy
from ..geo import SERVICE_CENTRELINES, GeoRaster, RoadNetwork
from ..io.las import PointCloud
from ..io.raster import geotiff_writer
from ..options import with_changes
from ..parallel import (NOT_KEPT, Parallel, for_each_result, keep_result, kept_result,
                        shared_workers)
from ..progress import Progress, report, scaled
from ..segmentation.ncut import ncut_segmentation
from ..network.branches import branches_into
from ..network.junctions import NetworkOptions
from ..network.rasters import PartOptions, raster_to_network, without_lines
from ..network.subgraph import GapOptions, WeightOptions
from ..tiling.tiles import OVERLAP_M, TILE_M, Tile, stitch_tiles
from ..tiling.tilestore import (TileStore, code_fingerprint, digest, file_digest, inputs_crs,
                                las_inputs, open_store)
from .evidence import (CAR_PARK_FLANK_SHARE, FLANK_DEPTH_M, FLANK_GAP_M, PAVED_LIKELIHOOD,
                       SHORE_FLANK_SHARE, dropout_cells, kerb_cells, road_evidence,
                       vehicle_cells, without_flanked_roads, without_unkerbed_ways)
from .ground import T_PLANAR, T_VERT, GroundPlanes, ground_planes
from .learned import (evidence_features, fit_evidence_model, learned_likelihood,
                      load_evidence_model)
from .hypotheses import (DEFAULT_LENGTHS_M, DEFAULT_WIDTHS_M, L_MAX, likelihood_maps,
                         road_hypotheses)
from .intensity import CELL_M, IntensityImages, auto_cell_m, image_grid, intensity_images
from .mincover import greedy_min_cover
from .roads import lines_to_network, rectangle_lines
from .tagging import level_heights

METHOD = "zhu-mordohai"
EVIDENCE_METHOD = "lidar-evidence"
CUES = ("intensity", "evidence")
#: Likelihood at which an evidence cell is road: the combined cues must all agree, since
#: paved non-road surfaces (car parks, footpaths) score as road on every per-cell cue.
EVIDENCE_THRESHOLD = 0.8
#: The road parts of the evidence (the network stage's
#: :class:`gisroads.network.rasters.PartOptions`): weak cells (0.6,
#: :data:`gisroads.lidar.evidence.PAVED_LIKELIHOOD`) joined to strong ones count as road
#: (hysteresis, as Canny's edge thresholds), so a road stays whole through a stretch its
#: cues doubt and weak patches alone stay out (``bench/lidar_evidence_network.py``).
EVIDENCE_PARTS = PartOptions(low_threshold=PAVED_LIKELIHOOD)
#: The same hysteresis for an evidence model's probability: its low threshold is this
#: share of the model's threshold (as 0.6 is of 0.8).
LOW_SHARE = 0.75
N_SEGMENTS = 150
"""NCut regions per tile image (Zhu & Mordohai, section 4.2: 100-200)."""


class EvidenceMosaic(NamedTuple):
    """What :func:`evidence_raster` gives, over the tiles' cores (None without a tile)."""

    likelihood: GeoRaster | None
    """2-D road likelihood, float32 in [0, 1], NaN outside the data, working metre CRS."""
    flanks: GeoRaster | None
    """Three bands on the same grid: vehicle cells
    (:func:`gisroads.lidar.evidence.vehicle_cells`), pulse dropout cells
    (:func:`gisroads.lidar.evidence.dropout_cells`) and kerb cells
    (:func:`gisroads.lidar.evidence.kerb_cells`)."""
    ground_intensity: GeoRaster | None
    """2-D mean intensity of the ground's last returns over that of the bright ground, on the
    same grid; NaN where the file records none: what the roads are seen over."""
    used: dict
    """Cue -> how it was measured (first tile)."""
    missing: dict
    """Cue -> why it was left out (first tile)."""
    features: GeoRaster | None = None
    """With ``features=True``: the evidence model's features
    (:data:`gisroads.lidar.learned.EVIDENCE_FEATURES` bands) on the same grid."""


#: Largest mosaic of tile rasters (ground heights, intensity, evidence) made in memory.
MOSAIC_BUDGET_BYTES = 4 * 2**30
@dataclass
class TileRoads:
    """What one tile gives: its roads and the intermediate products, for QA."""

    tile: Tile
    centrelines: gpd.GeoDataFrame
    rectangles: gpd.GeoDataFrame
    hypotheses: gpd.GeoDataFrame
    intensity: GeoRaster
    likelihood: list[GeoRaster]
    heights: GeoRaster


@dataclass
class LidarRoads:
    """The road network of a point cloud, with the layers and rasters a user checks."""

    network: RoadNetwork
    heights: GeoRaster | None
    tiles: list[TileRoads] = field(default_factory=list)
    evidence: GeoRaster | None = None
    """The road likelihood (``cue="evidence"``), in the working metre CRS."""
    ground_intensity: GeoRaster | None = None
    """The ground's intensity on the evidence's grid (``cue="evidence"``; see
    :class:`EvidenceMosaic`)."""
    cues: dict = field(default_factory=dict)
    """Cue name -> how it was measured (``cue="evidence"``: those the file allowed)."""
    run: dict = field(default_factory=dict)
    """``tiles``: tiles run; ``reused``: those taken finished from the work folder."""


def ground_and_intensity(cloud: PointCloud, planes: GroundPlanes, *, bounds, cell_m: float
                         ) -> tuple[IntensityImages, GeoRaster]:
    """Stage 2: the intensity image of every ground level and the ground height of every
    level, on the grid of ``cell_m`` over ``bounds`` snapped outward to the cell (so that
    the grids of all tiles align)."""
    transform, shape = image_grid(bounds, cell_m)
    grid_bounds = (transform.c, transform.f - shape[0] * cell_m,
                   transform.c + shape[1] * cell_m, transform.f)
    images = intensity_images(cloud.xyz, cloud.intensity, planes.level, cell_m=cell_m,
                              bounds=grid_bounds, crs=cloud.crs,
                              single_return=cloud.number_of_returns <= 1)
    heights = level_heights(cloud.xyz, planes.level, planes.n_levels, transform=transform,
                            shape=shape, crs=cloud.crs)
    return images, heights


def edges_and_segments(image: np.ndarray, *, n_segments: int = N_SEGMENTS
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stage 3 on one level's intensity image (NaN = no data): local-energy edge magnitude
    and orientation, and the NCut over-segmentation (labels, -1 = no data)."""
    magnitude, orientation = local_energy(image)
    # intensity similarity only, as in the paper (section 4.3): on LiDAR the
    # intervening-edge term lowered the recall of road edges by segment boundaries
    labels = ncut_segmentation(image, n_segments=n_segments, mask=~np.isfinite(image))
    return magnitude, orientation, labels


def extract_tile(cloud: PointCloud, tile: Tile, *, cell_m: float = CELL_M,
                 widths_m=DEFAULT_WIDTHS_M, lengths_m=DEFAULT_LENGTHS_M,
                 n_segments: int = N_SEGMENTS, t_planar: float = T_PLANAR,
                 t_vert: float = T_VERT,
                 progress: Progress = None) -> TileRoads:
    """Roads of one tile (Algorithm 1, steps 1-6) from the points inside its bounds.

    Parameters
    ----------
    cloud : PointCloud
        The tile's points, metres, with intensity.
    tile : Tile
    cell_m : float
        Intensity image cell, metres (paper: 0.5 m).
    widths_m, lengths_m : sequence of float
        Rectangle hypothesis sizes, metres.
    n_segments : int
        NCut over-segmentation size (paper: 100-200 regions).
    t_planar, t_vert : float
        Ground-plane thresholds (paper section 4.1: 0.01 and 0.98).
    """
    if cloud.intensity is None:
        raise GisroadsError("the point cloud records no intensity; the LiDAR method needs it")
    report(progress, 0.0, "ground planes")
    planes = ground_planes(cloud.xyz, t_planar=t_planar, t_vert=t_vert)
    report(progress, 0.25, "intensity images")
    images, heights = ground_and_intensity(cloud, planes, bounds=tile.bounds, cell_m=cell_m)
    rectangles, hypotheses, likelihood = [], [], []
    for level in range(planes.n_levels):
        image = images.image.data[level]
        if np.isfinite(image).sum() < 0.02 * image.size:
            continue
        step = scaled(progress, 0.3 + 0.65 * level / planes.n_levels,
                      0.3 + 0.65 * (level + 1) / planes.n_levels)
        report(step, 0.0, f"level {level}: edges and NCut")
        magnitude, orientation, labels = edges_and_segments(image, n_segments=n_segments)
        report(step, 0.4, f"level {level}: hypotheses")
        level_image = GeoRaster(image, images.image.transform, cloud.crs)
        hyps = road_hypotheses(level_image, magnitude, orientation, labels, widths_m=widths_m,
                               lengths_m=lengths_m)
        if len(hyps) == 0:
            continue
        maps = likelihood_maps(hyps, level_image, widths_m=widths_m, l_max=L_MAX)
        report(step, 0.8, f"level {level}: minimum cover")
        selected = greedy_min_cover(hyps, maps, l_max=L_MAX)
        hypotheses.append(hyps.assign(level=level))
        rectangles.append(selected.assign(level=level))
        likelihood.append(maps)
    rectangles = _concat(rectangles, cloud.crs)
    lines = rectangle_lines(rectangles)
    report(progress, 1.0, "tile done")
    # a centre line takes the ground level of the rectangle nearest to its middle
    middles = shapely.line_interpolate_point(lines.geometry.values, 0.5, normalized=True)
    return TileRoads(tile, _with_level(lines, middles, rectangles), rectangles,
                     _concat(hypotheses, cloud.crs), images.image, likelihood, heights)


def _no_lines(crs) -> gpd.GeoDataFrame:
    return gpd.GeoDataFrame({"width_m": pd.Series(dtype=float), "score": pd.Series(dtype=float)},
                            geometry=gpd.GeoSeries([], crs=crs), crs=crs)


def _concat(frames: list[gpd.GeoDataFrame], crs) -> gpd.GeoDataFrame:
    frames = [f for f in frames if len(f)]
    if not frames:
        return gpd.GeoDataFrame({"level": pd.Series(dtype="int64")},
                                geometry=gpd.GeoSeries([], crs=crs), crs=crs)
    return gpd.GeoDataFrame(pd.concat(frames, ignore_index=True), crs=crs)


def _with_level(frame: gpd.GeoDataFrame, anchors, levelled: gpd.GeoDataFrame
                ) -> gpd.GeoDataFrame:
    """``frame`` with the ``level`` of the ``levelled`` feature nearest to each anchor point
    (one point per row of ``frame``); level 0 when nothing is levelled."""
    frame = frame.copy()
    if len(frame) == 0 or len(levelled) == 0:
        frame["level"] = np.zeros(len(frame), np.int64)
        return frame
    nearest = shapely.STRtree(levelled.geometry.values).query_nearest(
        anchors, all_matches=False, return_distance=False)[1]
    frame["level"] = levelled["level"].to_numpy(np.int64)[nearest]
    return frame


def _covered_m2(tiles) -> float:
    """Ground the tiles' cores cover (the cloud's area, not its bounding box's)."""
    return float(sum((t.core[2] - t.core[0]) * (t.core[3] - t.core[1]) for t in tiles))


@dataclass(frozen=True)
class _TileJob:
    """What a task needs to process one tile: picklable, sent to the Dask workers."""

    store: TileStore
    cue: str
    min_points: int
    cell_m: float
    results: Path
    """Folder of finished tiles."""
    stages: LidarOptions | None = None
    """Intensity cue: the options of its stages (``widths_m``, ``lengths_m``, ``n_segments``,
    ``t_planar``, ``t_vert``) for :func:`extract_tile`."""
    references: object = None
    model: str | None = None
    """Evidence cue: an evidence model file (:mod:`gisroads.lidar.learned`) whose
    probability replaces the rule's likelihood."""
    features: bool = False
    """Evidence cue: keep the model features (:func:`evidence_features`) as extra bands."""


class _Finished(NamedTuple):
    """What the driver holds of a finished tile of the intensity cue: the rest of its
    result (QA layers, rasters) stays in its file until the outputs are written, one tile
    at a time (:class:`TiledRoads`)."""

    centrelines: gpd.GeoDataFrame
    levels: int
    """Bands of its ground heights."""
    imaged: bool
    """It has an intensity image (a ground level)."""


def _tile_result_path(job: _TileJob, tile: Tile) -> Path:
    return job.results / f"tile_{tile.row}_{tile.col}.pkl"


def _run_tile(job: _TileJob, tile: Tile, progress: Progress = None):
    """``(reused, result)`` of one tile: :class:`_Finished` of its :class:`TileRoads`
    (intensity cue) or ``(likelihood, vehicle and dropout cells, references, used,
    missing)`` (evidence cue), None for a tile with fewer than ``min_points`` points. A
    finished tile is written whole to ``job.results`` (atomically) and taken from there when
    it is already there."""
    path = _tile_result_path(job, tile)
    kept = kept_result(path)
    if kept is not NOT_KEPT:
        return True, _for_driver(kept)
    cloud = job.store.read(tile)
    result = None
    if cloud is not None and len(cloud) >= job.min_points:
        if job.cue == "intensity":
            stages = job.stages
            result = extract_tile(cloud, tile, cell_m=job.cell_m, widths_m=stages.widths_m,
                                  lengths_m=stages.lengths_m, n_segments=stages.n_segments,
                                  t_planar=stages.t_planar, t_vert=stages.t_vert)
        else:
            evidence = road_evidence(cloud, bounds=tile.bounds, references=job.references,
                                     progress=progress, cell_m=job.cell_m)
            raster = (evidence.likelihood if job.model is None
                      else learned_likelihood(evidence, _evidence_model(job.model)))
            intensity = evidence.measures.get("intensity")
            bands = np.stack([raster.data, vehicle_cells(evidence).data,
                              dropout_cells(evidence).data, kerb_cells(evidence).data,
                              np.full(raster.data.shape, np.nan, np.float32)
                              if intensity is None else intensity.data])
            if job.features:
                bands = np.concatenate([bands, evidence_features(evidence)])
            result = (GeoRaster(bands, raster.transform, raster.crs),
                      evidence.references, evidence.used, evidence.missing)
    del cloud
    keep_result(path, result)
    return False, _for_driver(result)


@lru_cache(maxsize=2)
def _evidence_model(path: str):
    return load_evidence_model(path)


def _for_driver(result):
    """What a task sends the driver: the evidence cue's whole result (mosaicked in
    memory), the intensity cue's :class:`_Finished` (a city's QA layers and rasters are
    read back from the tiles' files one at a time)."""
    if isinstance(result, TileRoads):
        return _Finished(result.centrelines, result.heights.data.shape[0],
                         len(result.intensity.data) > 0)
    return result


#: The sources a tile's result depends on (relative to the package).
_TILE_SOURCES = ("lidar/*.py", "tiling/*.py", "features/*.py", "segmentation/ncut.py",
                 "vectorize/*.py", "optimize*", "evaluate/topology.py", "geo.py", "io/las.py")


@lru_cache(maxsize=1)
def _code_fingerprint() -> str:
    """:func:`gisroads.tiling.tilestore.code_fingerprint` of the sources a tile runs and
    the libraries it calls."""
    import geopandas
    import scipy
    import skimage
    return code_fingerprint(_TILE_SOURCES, (np, scipy, skimage, shapely, pd, geopandas))


def _results_folder(store: TileStore, work_dir, cue: str, options: dict) -> Path:
    """Where the finished tiles of this input, grid, cue and parameters are kept: in the
    work folder, or without one beside the temporary tile store (removed with it)."""
    key = digest({"store": store.key, "cue": cue, "options": options,
                  "code": _code_fingerprint()})
    folder = Path(store.temporary if work_dir is None else work_dir) / f"tiles-{cue}-{key}"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _run_tiles(job: _TileJob, tiles: list[Tile], *, workers: int, scheduler, progress,
               run: dict, tile_progress: Progress = None) -> list:
    """What the driver gets of ``tiles`` (:func:`_for_driver`), in their order
    (:func:`gisroads.parallel.for_each_result`); ``tile_progress`` reports inside the one
    tile the driver runs itself (not picklable: for one tile, one worker)."""
    results = [None] * len(tiles)
    reused = 0

    def arrived(i, outcome):
        nonlocal reused
        reused += outcome[0]
        results[i] = outcome[1]
    for_each_result(partial(_run_tile, job, progress=tile_progress), tiles, arrived,
                    workers=workers,
                    scheduler=scheduler, progress=progress)
    run["tiles"] = run.get("tiles", 0) + len(tiles)
    run["reused"] = run.get("reused", 0) + reused
    return results


def _core_raster(raster: GeoRaster, tile: Tile) -> GeoRaster:
    """A tile's raster cut to the cells of its core (a copy), as :func:`mosaic_cores`
    takes them: the rest of it is overlap that another tile's core holds."""
    cell = raster.pixel_size
    transform = raster.transform
    r0 = max(0, int(round((transform.f - tile.core[3]) / cell)))
    c0 = max(0, int(round((tile.core[0] - transform.c) / cell)))
    r1 = max(r0, int(round((transform.f - tile.core[1]) / cell)))
    c1 = max(c0, int(round((tile.core[2] - transform.c) / cell)))
    data = np.array(raster.data[..., r0:r1, c0:c1])
    return GeoRaster(data, transform * Affine.translation(c0, r0), raster.crs)


def _core_only(tile: Tile, result: TileRoads) -> TileRoads:
    """What the QA layers and the mosaics need of a finished tile: its QA rectangles and
    hypotheses in its core, its intensity and heights cut to its core, no per-width maps:
    0.44 of a 300 m tile with the default 100 m overlap."""
    return replace(result, rectangles=_in_core(result.rectangles, tile),
                   hypotheses=_in_core(result.hypotheses, tile), likelihood=[],
                   intensity=_core_raster(result.intensity, tile),
                   heights=_core_raster(result.heights, tile))


def evidence_raster(path, *, tile_m: float = TILE_M, overlap_m: float = OVERLAP_M,
                    cell_m: float | None = None, min_points: int = 1000,
                    workers: int = 1, scheduler: str | None = None, work_dir=None,
                    model=None, features: bool = False,
                    progress: Progress = None, _run: dict | None = None
                    ) -> EvidenceMosaic:
    """The road likelihood of a LAS/LAZ file (:func:`gisroads.lidar.evidence.road_evidence`),
    tile by tile, mosaicked from the tiles' cores.

    ``path`` may also be several files, a folder of them or a glob; ``workers``,
    ``scheduler``, ``work_dir`` and ``model`` as in :func:`extract_roads`. Every tile is
    normalised by the references (open-ground density, noise floor, bright intensity) of the
    first tile holding ``min_points``, so the tiles of one cloud agree. ``features`` keeps
    the evidence model's features too (memory: 13 float32 bands per cell).

    Returns
    -------
    EvidenceMosaic
    """
    store = open_store(path, work_dir, tile_m=tile_m, overlap_m=overlap_m, workers=workers,
                       scheduler=scheduler, progress=scaled(progress, 0.0, 0.1))
    try:
        return _evidence_from_store(store, cell_m=cell_m, min_points=min_points,
                                    workers=workers, scheduler=scheduler, work_dir=work_dir,
                                    model=None if model is None else str(Path(model).resolve()),
                                    features=features,
                                    progress=scaled(progress, 0.1, 1.0),
                                    run={} if _run is None else _run)
    finally:
        if work_dir is None:
            store.remove()


def _evidence_from_store(store: TileStore, *, cell_m, min_points, workers, scheduler,
                         work_dir, model, features, progress, run) -> EvidenceMosaic:
    tiles = store.tiles
    if cell_m is None:
        cell_m = auto_cell_m(store.point_count, _covered_m2(tiles))
    key = {"cell_m": cell_m, "min_points": min_points, "features": features,
           "model": None if model is None else file_digest(model)}
    job = _TileJob(store, "evidence", min_points, cell_m,
                   _results_folder(store, work_dir, "evidence", key), model=model,
                   features=features)
    # the first tile with enough points gives the references every other tile is scaled by
    results, first = [], len(tiles)
    for i, tile in enumerate(tiles):
        report(progress, i / len(tiles), f"tile {i + 1} of {len(tiles)}: references")
        results.append(_run_tiles(job, [tile], workers=1, scheduler=None, progress=None,
                                  run=run, tile_progress=scaled(
                                      progress, i / len(tiles), (i + 1) / len(tiles)))[0])
        if results[-1] is not None:
            first = i + 1
            break
    if first < len(tiles):
        _, references, _, _ = results[-1]
        job = replace(job, references=references)
        results += _run_tiles(job, tiles[first:], workers=workers, scheduler=scheduler,
                              progress=scaled(progress, first / len(tiles), 1.0), run=run)
    report(progress, 1.0, "road evidence done")
    pieces = [(tile, r[0]) for tile, r in zip(tiles, results) if r is not None]
    run["with_points"] = len(pieces)
    if not pieces:
        return EvidenceMosaic(None, None, None, {}, {})
    _, _, used, missing = next(r for r in results if r is not None)
    mosaic = mosaic_cores(pieces, cell_m)
    band = [GeoRaster(data, mosaic.transform, mosaic.crs)
            for data in (mosaic.data[0], mosaic.data[1:4], mosaic.data[4], mosaic.data[5:])]
    return EvidenceMosaic(*band[:3], used, missing, band[3] if features else None)


def _evidence_network(options: LidarOptions, threshold: float, model):
    """:func:`raster_to_network` at ``threshold`` with the evidence cue's stages: those of
    ``options``, None taking the defaults (the road parts :data:`EVIDENCE_PARTS`, with a
    model its low threshold :data:`LOW_SHARE` of the model's ``threshold``)."""
    parts = options.part_options
    if parts is None:
        parts = (EVIDENCE_PARTS if model is None
                 else replace(EVIDENCE_PARTS, low_threshold=LOW_SHARE * threshold))
    stages = {name: getattr(options, name)
              for name in ("gap_options", "weight_options", "network_options")
              if getattr(options, name) is not None}
    return partial(raster_to_network, threshold=threshold, method=EVIDENCE_METHOD,
                   part_options=parts, **stages)


def _evidence_roads(path, options: LidarOptions, *, model, progress: Progress,
                    **raster_options) -> LidarRoads:
    working, source = inputs_crs(las_inputs(path))
    run: dict = {}
    likelihood, flanks, intensity, used, _, _ = evidence_raster(
        path, progress=scaled(progress, 0.0, 0.6), _run=run, model=model, **raster_options)
    threshold = options.threshold
    if model is not None:
        threshold = float(load_evidence_model(model).metadata["threshold"])
        used = {**used, "model": f"learned from a road layer ({Path(model).name})"}
    if likelihood is None:
        network = lines_to_network(_no_lines(working), method=EVIDENCE_METHOD)
    else:
        network_stage = _evidence_network(options, threshold, model)
        network = network_stage(likelihood, progress=scaled(progress, 0.6, 0.8))
        # car-park aisles are known by the cars that line them, shores (and the rims of
        # clearings around ponds) by the pulse dropouts of the water: out, and the network
        # again
        vehicles, dropouts, kerbs = (GeoRaster(band, flanks.transform, flanks.crs)
                                     for band in flanks.data)
        likelihood, taken = without_flanked_roads(
            likelihood, network.centrelines,
            {"car-park aisle": (vehicles, CAR_PARK_FLANK_SHARE),
             "shore": (dropouts, SHORE_FLANK_SHARE)})
        if len(taken):
            network = network_stage(likelihood, progress=scaled(progress, 0.8, 0.9))
        aisles = taken.query("reason == 'car-park aisle'")
        likelihood, accesses = without_car_park_accesses(likelihood, network.centrelines,
                                                         aisles)
        if len(accesses):
            network = network_stage(likelihood, progress=scaled(progress, 0.9, 0.95))
        likelihood, unkerbed = without_unkerbed_ways(likelihood, network.centrelines, kerbs)
        if len(unkerbed):
            network = network_stage(likelihood, progress=scaled(progress, 0.95, 1.0))
        network.qa[SERVICE_CENTRELINES] = service_lines(pd.concat([aisles, accesses,
                                                                   unkerbed]))
    network.qa.setdefault(SERVICE_CENTRELINES, service_lines(network.centrelines.iloc[:0]))
    report(progress, 1.0, f"{len(network.centrelines)} roads, {len(network.junctions)} "
                          f"junctions, {len(network.qa[SERVICE_CENTRELINES])} service ways")
    network.centrelines["kind"] = "road"
    network.centrelines["cues"] = ",".join(used)
    network.polygons["level"] = np.zeros(len(network.polygons), np.int64)
    if source is not None and working is not None and source != working:
        network = RoadNetwork(*(frame.to_crs(source) for frame in (
            network.centrelines, network.polygons, network.junctions)),
            {name: frame.to_crs(source) for name, frame in network.qa.items()})
    return LidarRoads(network, None, evidence=likelihood, ground_intensity=intensity,
                      cues=used, run=run)


def train_evidence_model(path, roads: gpd.GeoDataFrame, *, width_m=None,
                         width_field: str | None = None, default_width_m: float = 6.0,
                         guard_m: float = 3.0, seed: int = 0, threads: int = 1,
                         progress: Progress = None, **raster_options):
    """An evidence model of a point cloud learned from a road layer of its area (beyond the
    paper; :mod:`gisroads.lidar.learned`).

    Parameters
    ----------
    path : str or Path, or a list of them
        LAS/LAZ file(s), as :func:`extract_roads` takes them.
    roads : GeoDataFrame
        The area's road centre lines (any CRS; reprojected).
    width_m, width_field, default_width_m, guard_m, seed, threads
        See :func:`gisroads.lidar.learned.fit_evidence_model`.
    progress : callable, optional
    **raster_options
        ``tile_m``, ``overlap_m``, ``cell_m``, ``min_points``, ``workers``, ``scheduler``,
        ``work_dir`` of :func:`evidence_raster`.

    Returns
    -------
    RoadModel
        Save it with :func:`gisroads.lidar.learned.save_evidence_model`; use it with
        ``extract_roads(..., model=path)``.
    """
    mosaic = evidence_raster(path, features=True, progress=scaled(progress, 0.0, 0.8),
                             **raster_options)
    if mosaic.features is None:
        raise GisroadsError("the cloud has no tile with enough points to learn from")
    report(progress, 0.8, "fitting the model")
    model = fit_evidence_model(mosaic.features, roads, width_m=width_m,
                               width_field=width_field, default_width_m=default_width_m,
                               guard_m=guard_m, seed=seed, threads=threads)
    report(progress, 1.0, "model fitted")
    return model


def without_car_park_accesses(likelihood: GeoRaster, centrelines: gpd.GeoDataFrame,
                              aisles: gpd.GeoDataFrame) -> tuple[GeoRaster, gpd.GeoDataFrame]:
    """The likelihood with the ways that lead only into a car park set to 0 (beyond the
    paper): the branches of the network (:func:`gisroads.network.branches.branches_into`)
    that end only among the car park's aisles (entrances with their islands, driveways into
    the lot, what is left of the lot's lanes).

    Parameters
    ----------
    likelihood : GeoRaster
        The road likelihood, NaN outside the data, the aisles already at 0.
    centrelines : GeoDataFrame
        The roads of a network built on it (``width_m``), in its CRS.
    aisles : GeoDataFrame
        The car-park aisles taken out (:func:`gisroads.lidar.evidence.without_flanked_roads`);
        the car park is their band with its rows of cars (``width / 2`` plus the flank
        :func:`gisroads.lidar.evidence.flank_share` reads).

    Returns
    -------
    likelihood : GeoRaster
        A copy, the accesses at 0.
    accesses : GeoDataFrame
        The lines taken, ``reason`` "car-park access".
    """
    if not len(aisles) or not len(centrelines):
        return likelihood, centrelines.iloc[:0].assign(reason=np.array([], dtype=object))
    reach = aisles["width_m"].to_numpy(float) / 2 + FLANK_GAP_M + FLANK_DEPTH_M
    car_park = shapely.union_all(shapely.buffer(aisles.geometry.values, reach))
    taken = branches_into(centrelines.geometry.values, car_park)
    accesses = centrelines[taken].assign(reason="car-park access")
    return without_lines(likelihood, accesses), accesses


def service_lines(lines: gpd.GeoDataFrame) -> gpd.GeoDataFrame:
    """Service ways (car-park aisles, taken out of the road network by
    :func:`gisroads.lidar.evidence.without_flanked_roads`) as their own layer.

    Parameters
    ----------
    lines : GeoDataFrame
        LineStrings with ``width_m`` and, when taken for a reason, ``reason`` and
        ``flank_share``.

    Returns
    -------
    GeoDataFrame
        ``service_id``, ``kind`` ("service"), ``reason``, ``width_m``, ``length_m`` and
        ``flank_share`` (the share of the flanks that marked it), in the lines' CRS.
    """
    frame = lines.reset_index(drop=True)
    count = len(frame)
    return gpd.GeoDataFrame({
        "service_id": np.arange(1, count + 1, dtype=np.int64),
        "kind": np.full(count, "service", dtype=object),
        "reason": (frame["reason"].to_numpy(object) if "reason" in frame
                   else np.full(count, "", dtype=object)),
        "width_m": frame["width_m"].to_numpy(np.float64),
        "length_m": frame.geometry.length.to_numpy(np.float64),
        "flank_share": (frame["flank_share"].to_numpy(np.float64) if "flank_share" in frame
                        else np.zeros(count)),
    }, geometry=frame.geometry.values, crs=lines.crs)


@dataclass(frozen=True)
class LidarOptions:
    """The options of :func:`extract_roads`: the cue and its model, the tiles, the image
    cell, the evidence cue's threshold and network stage, and the intensity cue's stages
    (``widths_m``, ``lengths_m``, ``n_segments``, ``t_planar``, ``t_vert``: see
    :func:`extract_tile`).

    Attributes
    ----------
    cue : {"evidence", "intensity"}
        ``evidence`` (the default, beyond the paper): the road likelihood of every cue the
        cloud carries (the paper's ground intensity among them, and height, density,
        roughness, slope, returns, classification, kerbs, whichever the file has) through
        the network stage (module docstring); ``intensity``: Zhu & Mordohai's Algorithm 1
        alone.
    model : str or Path, optional
        ``cue="evidence"``: an evidence model learned from a road layer of the area
        (:func:`train_evidence_model`; beyond the paper): its probability replaces the
        rule's likelihood.
    tile_m, overlap_m : float
        Tile side and overlap with each neighbour, metres (paper: 300 m and 100 m).
    cell_m : float, optional
        Image cell, metres; by default :func:`auto_cell_m` of the cloud.
    threshold : float
        ``cue="evidence"``: likelihood at which a cell is road (a model brings its own).
    part_options : PartOptions, optional
        ``cue="evidence"``: the road parts of the likelihood
        (:func:`gisroads.network.rasters.skeleton_parts`); None: :data:`EVIDENCE_PARTS`
        (hysteresis down to 0.6), with a model its low threshold :data:`LOW_SHARE` of the
        model's threshold. One given is taken as it is (its ``low_threshold`` None: no
        hysteresis).
    gap_options : GapOptions, optional
    weight_options : WeightOptions, optional
    network_options : NetworkOptions, optional
        ``cue="evidence"``: the gap edges, their weights and the network generation of
        :func:`gisroads.network.rasters.raster_to_network`; None: its defaults
        (:data:`gisroads.network.rasters.RASTER_GAPS`, ``RASTER_WEIGHTS``,
        ``RASTER_NETWORK``). One given replaces the default whole: change a field of the
        default with :func:`dataclasses.replace`, e.g.
        ``replace(RASTER_NETWORK, max_unsupported_m=30.0)``.
    min_points : int
        Tiles with fewer points are skipped.
    """

    cue: str = "evidence"
    model: object = None
    tile_m: float = TILE_M
    overlap_m: float = OVERLAP_M
    cell_m: float | None = None
    widths_m: tuple = DEFAULT_WIDTHS_M
    lengths_m: tuple = DEFAULT_LENGTHS_M
    n_segments: int = N_SEGMENTS
    t_planar: float = T_PLANAR
    t_vert: float = T_VERT
    threshold: float = EVIDENCE_THRESHOLD
    part_options: PartOptions | None = None
    gap_options: GapOptions | None = None
    weight_options: WeightOptions | None = None
    network_options: NetworkOptions | None = None
    min_points: int = 1000


def extract_roads(path, options: LidarOptions = LidarOptions(),
                  parallel: Parallel = Parallel(), *, tile_maps: bool = True,
                  lazy: bool = False, progress: Progress = None,
                  **changes) -> LidarRoads | TiledRoads:
    """The road network of a point cloud, tile by tile.

    The input is read once: its points are bucketed into the tile grid on disk
    (:mod:`gisroads.tiling.tilestore`), then every tile reads only its own points.

    Parameters
    ----------
    path : str or Path, or a list of them
        A LAS/LAZ file, several, a folder of them or a glob (``"tiles/*.laz"``): tiles of
        one area in one CRS; where files overlap, a tile holds the points of each.
    tile_maps : bool
        Keep every tile whole with its per-width likelihood maps in ``LidarRoads.tiles``;
        False keeps of each tile only its core (its QA layers, intensity and heights;
        :func:`_core_only`). With ``lazy``, :meth:`TiledRoads.results` chooses.
    lazy : bool
        Return a :class:`TiledRoads`: the network, with the tiles' QA layers and rasters
        left in the files the tiles wrote, to be read one tile at a time (a city's outputs
        written in the memory of one tile: :func:`gisroads.jobs.lidar.lidar_job`). Use it
        as a context manager: its end removes the temporary tile store.
    options : LidarOptions
        The cue, its model, tiles, cell and the cues' options (:class:`LidarOptions`).
    parallel : Parallel
        Where the tiles run, and the work folder a stopped run resumes from
        (:class:`gisroads.parallel.Parallel`).
    **changes
        Fields of ``options`` or ``parallel`` to change for this call, e.g.
        ``cue="intensity"`` or ``workers=2``.

    Returns
    -------
    LidarRoads
        The network in the cloud's CRS; QA layers ``rectangles`` and ``hypotheses``
        (intensity), ``gap_edges``, ``junction_connections`` and ``rejected`` (evidence),
        and with the evidence cue the car-park aisles in ``service_centrelines``
        (:func:`service_lines`; the roads' ``kind`` is "road").
        ``run`` counts the tiles and those taken from ``work_dir``. A :class:`TiledRoads`
        when ``lazy``.

    Raises
    ------
    LasError
        Unreadable file; ValueError when the intensity cue meets a cloud without intensity,
        or for an unknown cue.

    Examples
    --------
    A synthetic scene surveyed at 4 pulses per square metre, and its roads found again:

    >>> import tempfile
    >>> from pathlib import Path
    >>> from gisroads.evaluate import buffer_metrics
    >>> from gisroads.lidar import extract_roads
    >>> from gisroads.synthetic import make_scene, write_cloud
    >>> scene = make_scene(seed=0, size_m=(300, 300))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     cloud = Path(folder) / "cloud.laz"
    ...     points = write_cloud(scene, cloud, density_per_m2=4)
    ...     roads = extract_roads(cloud, cue="intensity")  # the paper's intensity cue
    ...     evidence = extract_roads(cloud)             # every cue: beyond the paper
    >>> network = roads.network                         # centre lines, polygons, junctions
    >>> network.crs == scene.crs, sorted(network.qa)
    (True, ['hypotheses', 'rectangles'])
    >>> scores = buffer_metrics(network.centrelines, scene.truth.centrelines, buffer_m=3.0)
    >>> scores.completeness > 0.8, scores.correctness > 0.8
    (True, True)
    >>> sorted(evidence.network.qa)
    ['gap_edges', 'junction_connections', 'rejected', 'service_centrelines']
    >>> buffer_metrics(evidence.network.centrelines, scene.truth.centrelines).completeness > 0.9
    True
    """
    options, parallel = with_changes(changes, options, parallel)
    cue, model = options.cue, options.model
    where = asdict(parallel)
    if cue not in CUES:
        raise GisroadsError(f"cue must be one of {CUES}, not {cue!r}")
    if model is not None:
        if cue != "evidence":
            raise GisroadsError("a model works on the evidence cue; leave --cue out")
        load_evidence_model(model)  # refused before any work
    with shared_workers():  # one cluster for the reading pass and the tiles
        if cue == "evidence":
            roads = _evidence_roads(path, options, model=model,
                                    progress=progress, tile_m=options.tile_m,
                                    overlap_m=options.overlap_m, cell_m=options.cell_m,
                                    min_points=options.min_points, **where)
            tiled = TiledRoads(roads.network, cue, tiles=[], files=[], levels=0, imaged=False,
                               evidence=roads.evidence,
                               ground_intensity=roads.ground_intensity, cues=roads.cues,
                               run=roads.run)
        else:
            store = open_store(path, parallel.work_dir, tile_m=options.tile_m,
                               overlap_m=options.overlap_m, workers=parallel.workers,
                               scheduler=parallel.scheduler,
                               progress=scaled(progress, 0.0, 0.1))
            try:
                tiled = _intensity_roads(store, options,
                                         progress=scaled(progress, 0.1, 0.95), **where)
            except BaseException:
                if parallel.work_dir is None:
                    store.remove()
                raise
    if lazy:
        return tiled
    with tiled:
        return tiled.in_memory(maps=tile_maps)


def _intensity_roads(store: TileStore, options: LidarOptions, *, workers, scheduler,
                     work_dir, progress) -> TiledRoads:
    """The intensity cue's tiles run and their centre lines stitched into the network."""
    tiles = store.tiles
    cell_m = (auto_cell_m(store.point_count, _covered_m2(tiles)) if options.cell_m is None
              else options.cell_m)
    # the resume key: what changes a tile's result
    key = {"cell_m": cell_m, "widths_m": tuple(options.widths_m),
           "lengths_m": tuple(options.lengths_m), "n_segments": options.n_segments,
           "t_planar": options.t_planar, "t_vert": options.t_vert,
           "min_points": options.min_points}
    job = _TileJob(store, "intensity", options.min_points, cell_m,
                   _results_folder(store, work_dir, "intensity", key), stages=options)
    run: dict = {}
    finished = _run_tiles(job, tiles, workers=workers, scheduler=scheduler,
                          progress=progress, run=run)
    done = [(tile, f) for tile, f in zip(tiles, finished) if f is not None]
    network = _stitched_network([(tile, f.centrelines) for tile, f in done], store.crs)
    return TiledRoads(network, "intensity", [tile for tile, _ in done],
                      [_tile_result_path(job, tile) for tile, _ in done],
                      max((f.levels for _, f in done), default=0),
                      any(f.imaged for _, f in done), run=run, crs=store.crs, cell_m=cell_m,
                      store=store if work_dir is None else None)


def _in_core(frame: gpd.GeoDataFrame, tile: Tile) -> gpd.GeoDataFrame:
    """The rectangles of ``frame`` whose centre is in the tile's core."""
    if len(frame) == 0:
        return frame
    # a rectangle's centroid is the centre of its bounding box (30x faster to get)
    bounds = shapely.bounds(np.asarray(frame.geometry.values))
    x, y = (bounds[:, 0] + bounds[:, 2]) / 2, (bounds[:, 1] + bounds[:, 3]) / 2
    core = tile.core
    return frame[(x >= core[0]) & (x < core[2]) & (y >= core[1]) & (y < core[3])]


#: The QA layers of the intensity cue's tiles.
TILE_QA = ("rectangles", "hypotheses")


def _stitched_network(pieces: list[tuple[Tile, gpd.GeoDataFrame]], crs) -> RoadNetwork:
    """The tiles' centre lines stitched into one network (no QA layer) in the file's own
    CRS; ``crs`` is ``(working metre CRS, file CRS)`` as
    :func:`gisroads.io.las.cloud_crs` gives."""
    working, _ = crs
    lines = stitch_tiles(pieces) if pieces else _no_lines(working).assign(level=0)
    cores = np.array([tile.core for tile, _ in pieces]).reshape(-1, 4)
    network = lines_to_network(lines, method=METHOD, extent=(
        (*cores[:, :2].min(axis=0), *cores[:, 2:].max(axis=0)) if len(cores) else None))
    network.polygons = _with_level(network.polygons,
                                   shapely.point_on_surface(network.polygons.geometry.values),
                                   lines)
    return RoadNetwork(*(_to_output(frame, crs) for frame in (
        network.centrelines, network.polygons, network.junctions)))


def _output_crs(crs):
    """The CRS the outputs are written in, of ``crs`` ``(working metre CRS, file CRS)``:
    the file's own when it has one, else the working CRS."""
    working, source = crs
    return source if source is not None and working is not None else working


def _to_output(frame: gpd.GeoDataFrame, crs) -> gpd.GeoDataFrame:
    """``frame`` (in the working CRS) in the output CRS (:func:`_output_crs`)."""
    out = _output_crs(crs)
    return frame if out == crs[0] else frame.to_crs(out)


@dataclass
class TiledRoads:
    """The road network of a point cloud, with the outputs of its tiles (QA layers,
    intensity images, ground heights, per-width likelihood maps) left in the files the
    tiles wrote and read one tile at a time (:meth:`results`): the driver of a city holds
    the centre lines and one tile. ``extract_roads(..., lazy=True)`` gives it; use it as a
    context manager, whose end removes the temporary tile store (there is none with a
    ``work_dir``)."""

    network: RoadNetwork
    """In the cloud's CRS; the QA layers of the evidence cue (those of the intensity cue's
    tiles: :meth:`qa`)."""
    cue: str
    tiles: list[Tile]
    """The tiles with a result, in grid order (row by row)."""
    files: list[Path]
    """Each tile's result (:class:`TileRoads`)."""
    levels: int
    """The most ground levels of a tile: bands of the heights mosaic."""
    imaged: bool
    """Some tile has an intensity image."""
    evidence: GeoRaster | None = None
    ground_intensity: GeoRaster | None = None
    cues: dict = field(default_factory=dict)
    run: dict = field(default_factory=dict)
    crs: tuple | None = None
    """``(working metre CRS, file CRS)``."""
    cell_m: float | None = None
    """Image cell, metres."""
    store: TileStore | None = None
    """The temporary tile store, removed at the end."""

    def __enter__(self) -> TiledRoads:
        return self

    def __exit__(self, *exc) -> None:
        if self.store is not None:
            self.store.remove()
            self.store = None

    def results(self, *, maps: bool = False) -> Iterator[TileRoads]:
        """Each tile's result, in grid order, read from its file when asked for: whole
        with its per-width likelihood maps (``maps``), or its core (:func:`_core_only`)."""
        for tile, path in zip(self.tiles, self.files):
            result = kept_result(path)
            yield result if maps else _core_only(tile, result)

    def qa(self, result: TileRoads | None = None) -> dict[str, gpd.GeoDataFrame]:
        """A tile's share of the QA layers (its rectangles and hypotheses whose centre is
        in its core) in the output CRS; without a result, the layers empty (their schema
        when no tile has a feature)."""
        if self.cue != "intensity":
            return {}
        if result is None:
            return {name: _concat([], _output_crs(self.crs)) for name in TILE_QA}
        return {name: _to_output(_in_core(getattr(result, name), result.tile), self.crs)
                for name in TILE_QA}

    def mosaic(self, name: str, bands: int | None = None) -> GeoRaster | None:
        """The tiles' rasters ``name`` (``"heights"``, ``"intensity"``) mosaicked from
        their cores in memory (:func:`mosaic_cores`), their first ``bands`` (all by
        default); None without a tile."""
        if not self.tiles:
            return None
        rasters = ((r.tile, getattr(r, name)) for r in self.results())
        return mosaic_cores([(tile, GeoRaster(raster.data[:bands], raster.transform,
                                              raster.crs)) for tile, raster in rasters],
                            self.cell_m)

    @contextmanager
    def mosaic_file(self, path, name: str, *, band_names: list[str] | None = None):
        """A GeoTIFF of the tiles' rasters ``name`` mosaicked from their cores, as
        :meth:`mosaic`, written one tile at a time: yields ``write(result)``, to be called
        with each of :meth:`results`; the file is there when the block ends."""
        transform, (rows, cols) = _mosaic_grid(self.tiles, self.cell_m, self.levels)
        with geotiff_writer(path, shape=(self.levels, rows, cols), dtype=np.float32,
                            transform=transform, crs=self.crs[0],
                            band_names=band_names) as dst:
            # NaN where no core is: GDAL gives 0 to the unwritten cells of a block written
            # in part (one strip of blocks at a time, as GDAL stores them)
            for r in range(0, rows, 256):
                strip = min(256, rows - r)
                dst.write(np.full((self.levels, strip, cols), np.nan, np.float32),
                          window=Window(0, r, cols, strip))

            def write(result: TileRoads) -> None:
                raster = getattr(result, name)
                (r0, r1, c0, c1), (sr, sc) = _core_window(result.tile, raster, transform,
                                                          (rows, cols), self.cell_m)
                if r1 <= r0 or c1 <= c0:
                    return
                # every band: GDAL fills the bands of a block never written with 0, not NaN
                window = np.full((self.levels, r1 - r0, c1 - c0), np.nan, np.float32)
                window[:len(raster.data)] = raster.data[:, sr:sr + r1 - r0, sc:sc + c1 - c0]
                dst.write(window, window=Window(c0, r0, c1 - c0, r1 - r0))
            yield write

    def in_memory(self, *, maps: bool = True) -> LidarRoads:
        """Everything in memory: the QA layers in ``network.qa``, the heights mosaic and
        every tile's result (``maps`` as in :meth:`results`), for inputs that fit."""
        if self.cue == "evidence":
            return LidarRoads(self.network, None, evidence=self.evidence,
                              ground_intensity=self.ground_intensity, cues=self.cues,
                              run=self.run)
        results = list(self.results(maps=maps))
        parts = [self.qa(r) for r in results]
        qa = {name: _concat([p[name] for p in parts], _output_crs(self.crs))
              for name in TILE_QA}
        heights = (mosaic_cores([(r.tile, r.heights) for r in results], self.cell_m)
                   if results else None)
        network = replace(self.network, qa={**self.network.qa, **qa})
        return LidarRoads(network, heights, results, run=self.run)


def _mosaic_grid(tiles: list[Tile], cell_m: float, bands: int) -> tuple[Affine, tuple]:
    """Transform and ``(rows, cols)`` of a mosaic of the tiles' cores at ``cell_m``.

    Raises
    ------
    ValueError
        When ``bands`` of it would take more than :data:`MOSAIC_BUDGET_BYTES`.
    """
    xmin = min(t.core[0] for t in tiles)
    ymin = min(t.core[1] for t in tiles)
    xmax = max(t.core[2] for t in tiles)
    ymax = max(t.core[3] for t in tiles)
    transform, (rows, cols) = image_grid((xmin, ymin, xmax, ymax), cell_m)
    if bands * rows * cols * 4 > MOSAIC_BUDGET_BYTES:
        raise GisroadsError(
            f"a mosaic of the tiles over {xmax - xmin:.0f} m x {ymax - ymin:.0f} m at "
            f"{cell_m:g} m cells would take {bands * rows * cols * 4 / 2**30:.1f} GiB (budget "
            f"{MOSAIC_BUDGET_BYTES / 2**30:.0f} GiB): the cloud's points lie far apart; split "
            "the file by area or choose a coarser cell")
    return transform, (rows, cols)


def _core_window(tile: Tile, raster: GeoRaster, transform: Affine, shape: tuple,
                 cell_m: float) -> tuple[tuple, tuple]:
    """Where a tile's raster goes in a mosaic of grid ``transform`` and ``shape``: the
    mosaic's rows and columns ``(r0, r1, c0, c1)`` of the tile's core and the raster's
    row and column ``(sr, sc)`` at ``(r0, c0)``."""
    rows, cols = shape
    r0 = int(round((transform.f - tile.core[3]) / cell_m))
    r1 = int(round((transform.f - tile.core[1]) / cell_m))
    c0 = int(round((tile.core[0] - transform.c) / cell_m))
    c1 = int(round((tile.core[2] - transform.c) / cell_m))
    sr = int(round((raster.transform.f - tile.core[3]) / cell_m))
    sc = int(round((tile.core[0] - raster.transform.c) / cell_m))
    r1 = min(r1, rows, r0 + raster.data.shape[1] - sr)
    c1 = min(c1, cols, c0 + raster.data.shape[2] - sc)
    return (r0, r1, c0, c1), (sr, sc)


def mosaic_cores(rasters: list[tuple[Tile, GeoRaster]], cell_m: float) -> GeoRaster:
    """One raster over all tiles (per-tile rasters such as ground heights or intensity
    images, bands padded with NaN to the most levels), each cell taken from the tile whose
    core holds it. Tile grids are aligned to multiples of ``cell_m`` (see
    :func:`ground_and_intensity`)."""
    bands = max(r.data.shape[0] for _, r in rasters)
    transform, shape = _mosaic_grid([t for t, _ in rasters], cell_m, bands)
    mosaic = np.full((bands, *shape), np.nan, np.float32)
    for tile, raster in rasters:  # one copy per tile
        (r0, r1, c0, c1), (sr, sc) = _core_window(tile, raster, transform, shape, cell_m)
        mosaic[:raster.data.shape[0], r0:r1, c0:c1] = \
            raster.data[:, sr:sr + r1 - r0, sc:sc + c1 - c0]
    return GeoRaster(mosaic, transform, rasters[0][1].crs)
