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

import hashlib
from dataclasses import dataclass, field, replace
from functools import lru_cache, partial
from pathlib import Path
from typing import NamedTuple

from affine import Affine
import geopandas as gpd
import numpy as np
import pandas as pd
import shapely

from ..features.edges import local_energy
from ..geo import GeoRaster, RoadNetwork
from ..io.las import PointCloud
from ..parallel import NOT_KEPT, for_each_result, keep_result, kept_result
from ..progress import Progress, report, scaled
from ..segmentation.ncut import ncut_segmentation
from ..network.rasters import raster_to_network
from ..vectorize.ribbons import rectangles_to_network, ribbons_to_network
from .evidence import (CAR_PARK_FLANK_SHARE, SHORE_FLANK_SHARE, dropout_cells, road_evidence,
                       vehicle_cells, without_flanked_roads)
from .ground import GroundPlanes, ground_planes
from .hypotheses import (DEFAULT_LENGTHS_M, DEFAULT_WIDTHS_M, L_MAX, likelihood_maps,
                         road_hypotheses)
from .intensity import IntensityImages, auto_cell_m, image_grid, intensity_images
from .mincover import greedy_min_cover
from .tagging import level_heights
from .tiles import Tile, stitch_tiles
from .tilestore import TileStore, digest, inputs_crs, las_inputs, open_store

METHOD = "zhu-mordohai"
EVIDENCE_METHOD = "lidar-evidence"
CUES = ("intensity", "evidence")
#: Likelihood at which an evidence cell is road: the combined cues must all agree, since
#: paved non-road surfaces (car parks, footpaths) score as road on every per-cell cue.
EVIDENCE_THRESHOLD = 0.8
#: The network stage on the evidence: weak cells (0.6) joined to strong ones count as road
#: (hysteresis, as Canny's edge thresholds), so a road stays whole through a stretch its
#: cues doubt and weak patches alone stay out (``bench/lidar_evidence_network.py``).
EVIDENCE_NETWORK_OPTIONS = {"part_options": {"low_threshold": 0.6}}


class EvidenceMosaic(NamedTuple):
    """What :func:`evidence_raster` gives, over the tiles' cores (None without a tile)."""

    likelihood: GeoRaster | None
    """2-D road likelihood, float32 in [0, 1], NaN outside the data, working metre CRS."""
    flanks: GeoRaster | None
    """Two bands on the same grid: vehicle cells (:func:`gisroads.lidar.evidence.vehicle_cells`)
    and pulse dropout cells (:func:`gisroads.lidar.evidence.dropout_cells`)."""
    used: dict
    """Cue -> how it was measured (first tile)."""
    missing: dict
    """Cue -> why it was left out (first tile)."""


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


def edges_and_segments(image: np.ndarray, *, n_segments: int = 150
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stage 3 on one level's intensity image (NaN = no data): local-energy edge magnitude
    and orientation, and the NCut over-segmentation (labels, -1 = no data)."""
    magnitude, orientation = local_energy(image)
    # intensity similarity only, as in the paper (section 4.3): on LiDAR the
    # intervening-edge term lowered the recall of road edges by segment boundaries
    labels = ncut_segmentation(image, n_segments=n_segments, mask=~np.isfinite(image))
    return magnitude, orientation, labels


def extract_tile(cloud: PointCloud, tile: Tile, *, cell_m: float = 0.5,
                 widths_m=DEFAULT_WIDTHS_M, lengths_m=DEFAULT_LENGTHS_M,
                 n_segments: int = 150, t_planar: float = 0.01, t_vert: float = 0.98,
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
        raise ValueError("the point cloud records no intensity; the LiDAR method needs it")
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
    lines = rectangles_to_network(rectangles, method=METHOD).centrelines
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
    options: dict
    results: Path | None
    """Folder of finished tiles (None: nothing kept)."""
    references: object = None
    tile_maps: bool = True
    """Return the intensity cue's per-width likelihood maps (kept on disk either way)."""


def _tile_result_path(job: _TileJob, tile: Tile) -> Path | None:
    return None if job.results is None else job.results / f"tile_{tile.row}_{tile.col}.pkl"


def _run_tile(job: _TileJob, tile: Tile):
    """``(reused, result)`` of one tile: its :class:`TileRoads` (intensity cue) or
    ``(likelihood, vehicle and dropout cells, references, used, missing)`` (evidence cue),
    None for a tile with fewer than ``min_points`` points. A finished tile is written to
    ``job.results`` (atomically) and taken from there when it is already there."""
    path = _tile_result_path(job, tile)
    kept = kept_result(path)
    if kept is not NOT_KEPT:
        return True, _trimmed(job, kept)
    cloud = job.store.read(tile)
    result = None
    if cloud is not None and len(cloud) >= job.min_points:
        if job.cue == "intensity":
            result = extract_tile(cloud, tile, **job.options)
        else:
            evidence = road_evidence(cloud, bounds=tile.bounds, references=job.references,
                                     **job.options)
            raster = evidence.likelihood
            bands = np.stack([raster.data, vehicle_cells(evidence).data,
                              dropout_cells(evidence).data])
            result = (GeoRaster(bands, raster.transform, raster.crs),
                      evidence.references, evidence.used, evidence.missing)
    del cloud
    keep_result(path, result)
    return False, _trimmed(job, result)


def _trimmed(job: _TileJob, result):
    """The result without the per-width likelihood maps unless ``job.tile_maps``."""
    if isinstance(result, TileRoads) and not job.tile_maps:
        result = replace(result, likelihood=[])
    return result


#: The sources a tile's result depends on (relative to the package).
_TILE_SOURCES = ("lidar/*.py", "features/*.py", "segmentation/ncut.py", "vectorize/*.py",
                 "optimize*", "evaluate/topology.py", "geo.py", "io/las.py")


@lru_cache(maxsize=1)
def _code_fingerprint() -> str:
    """Hash of the sources a tile runs and of the libraries' versions: finished tiles of
    another version of the code are not reused."""
    import geopandas
    import scipy
    import skimage
    sha = hashlib.sha1()
    root = Path(__file__).resolve().parents[1]
    sources = {p for pattern in _TILE_SOURCES for p in root.glob(pattern) if p.is_file()}
    for source in sorted(sources):
        sha.update(str(source.relative_to(root)).encode())
        sha.update(source.read_bytes())
    for module in (np, scipy, skimage, shapely, pd, geopandas):
        sha.update(f"{module.__name__} {module.__version__}".encode())
    return sha.hexdigest()[:16]


def _results_folder(store: TileStore, work_dir, cue: str, options: dict) -> Path | None:
    """Where the finished tiles of this input, grid, cue and parameters are kept."""
    if work_dir is None:
        return None
    key = digest({"store": store.key, "cue": cue, "options": options,
                  "code": _code_fingerprint()})
    folder = Path(work_dir) / f"tiles-{cue}-{key}"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _run_tiles(job: _TileJob, tiles: list[Tile], *, workers: int, scheduler, progress,
               run: dict, keep=None) -> list:
    """Results of ``tiles`` in their order (:func:`gisroads.parallel.for_each_result`),
    each passed through ``keep(tile, result)`` as it arrives when given: what the driver
    holds of a tile is then only what ``keep`` returns."""
    results = [None] * len(tiles)
    reused = 0

    def arrived(i, outcome):
        nonlocal reused
        reused += outcome[0]
        result = outcome[1]
        results[i] = result if keep is None or result is None else keep(tiles[i], result)
    for_each_result(partial(_run_tile, job), tiles, arrived, workers=workers,
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
    """What the network, its QA layers and the mosaics need of a finished tile: its QA
    rectangles and hypotheses in its core, its intensity and heights cut to its core, no
    per-width maps (what :func:`assemble` would keep of it anyway). A city's driver then
    holds no overlap: 0.44 of each 300 m tile with the default 100 m overlap."""
    return replace(result, rectangles=_in_core(result.rectangles, tile),
                   hypotheses=_in_core(result.hypotheses, tile), likelihood=[],
                   intensity=_core_raster(result.intensity, tile),
                   heights=_core_raster(result.heights, tile))


def evidence_raster(path, *, tile_m: float = 300.0, overlap_m: float = 100.0,
                    cell_m: float | None = None, min_points: int = 1000,
                    workers: int = 1, scheduler: str | None = None, work_dir=None,
                    progress: Progress = None, _run: dict | None = None
                    ) -> EvidenceMosaic:
    """The road likelihood of a LAS/LAZ file (:func:`gisroads.lidar.evidence.road_evidence`),
    tile by tile, mosaicked from the tiles' cores.

    ``path`` may also be several files, a folder of them or a glob; ``workers``,
    ``scheduler`` and ``work_dir`` as in :func:`extract_roads`. Every tile is normalised by
    the references (open-ground density, noise floor, bright intensity) of the first tile
    holding ``min_points``, so the tiles of one cloud agree.

    Returns
    -------
    EvidenceMosaic
    """
    store = open_store(path, work_dir, tile_m=tile_m, overlap_m=overlap_m,
                       progress=scaled(progress, 0.0, 0.1))
    try:
        return _evidence_from_store(store, cell_m=cell_m, min_points=min_points,
                                    workers=workers, scheduler=scheduler, work_dir=work_dir,
                                    progress=scaled(progress, 0.1, 1.0),
                                    run={} if _run is None else _run)
    finally:
        if work_dir is None:
            store.remove()


def _evidence_from_store(store: TileStore, *, cell_m, min_points, workers, scheduler,
                         work_dir, progress, run) -> EvidenceMosaic:
    tiles = store.tiles
    if cell_m is None:
        cell_m = auto_cell_m(store.point_count, _covered_m2(tiles))
    job = _TileJob(store, "evidence", min_points, {"cell_m": cell_m},
                   _results_folder(store, work_dir, "evidence",
                                   {"cell_m": cell_m, "min_points": min_points}))
    # the first tile with enough points gives the references every other tile is scaled by
    results, first = [], len(tiles)
    for i, tile in enumerate(tiles):
        report(progress, 0.0, f"tile {i + 1} of {len(tiles)}: references")
        results.append(_run_tiles(job, [tile], workers=1, scheduler=None, progress=None,
                                  run=run)[0])
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
    if not pieces:
        return EvidenceMosaic(None, None, {}, {})
    _, _, used, missing = next(r for r in results if r is not None)
    mosaic = mosaic_cores(pieces, cell_m)
    return EvidenceMosaic(GeoRaster(mosaic.data[0], mosaic.transform, mosaic.crs),
                          GeoRaster(mosaic.data[1:], mosaic.transform, mosaic.crs),
                          used, missing)


def _evidence_roads(path, *, threshold: float, network_options: dict | None,
                    progress: Progress, **raster_options) -> LidarRoads:
    working, source = inputs_crs(las_inputs(path))
    run: dict = {}
    likelihood, flanks, used, _ = evidence_raster(
        path, progress=scaled(progress, 0.0, 0.6), _run=run, **raster_options)
    if likelihood is None:
        network = ribbons_to_network(_no_lines(working), method=EVIDENCE_METHOD)
    else:
        options = {**EVIDENCE_NETWORK_OPTIONS, **(network_options or {})}
        network = raster_to_network(likelihood, threshold=threshold, method=EVIDENCE_METHOD,
                                    progress=scaled(progress, 0.6, 0.8), **options)
        # car-park aisles are known by the cars that line them, shores (and the rims of
        # clearings around ponds) by the pulse dropouts of the water: out, and the network
        # again
        vehicles, dropouts = (GeoRaster(band, flanks.transform, flanks.crs)
                              for band in flanks.data)
        likelihood, taken = without_flanked_roads(
            likelihood, network.centrelines,
            {"car-park aisle": (vehicles, CAR_PARK_FLANK_SHARE),
             "shore": (dropouts, SHORE_FLANK_SHARE)})
        if len(taken):
            network = raster_to_network(likelihood, threshold=threshold,
                                        method=EVIDENCE_METHOD,
                                        progress=scaled(progress, 0.8, 1.0), **options)
    network.centrelines["cues"] = ",".join(used)
    network.polygons["level"] = np.zeros(len(network.polygons), np.int64)
    if source is not None and working is not None and source != working:
        network = RoadNetwork(*(frame.to_crs(source) for frame in (
            network.centrelines, network.polygons, network.junctions)),
            {name: frame.to_crs(source) for name, frame in network.qa.items()})
    return LidarRoads(network, None, evidence=likelihood, cues=used, run=run)


def extract_roads(path, *, cue: str = "intensity", tile_m: float = 300.0,
                  overlap_m: float = 100.0, cell_m: float | None = None,
                  widths_m=DEFAULT_WIDTHS_M, lengths_m=DEFAULT_LENGTHS_M,
                  n_segments: int = 150, t_planar: float = 0.01, t_vert: float = 0.98,
                  threshold: float = EVIDENCE_THRESHOLD, network_options: dict | None = None,
                  min_points: int = 1000, workers: int = 1, scheduler: str | None = None,
                  work_dir=None, tile_maps: bool = True,
                  progress: Progress = None) -> LidarRoads:
    """The road network of a point cloud, tile by tile.

    The input is read once: its points are bucketed into the tile grid on disk
    (:mod:`gisroads.lidar.tilestore`), then every tile reads only its own points.

    Parameters
    ----------
    path : str or Path, or a list of them
        A LAS/LAZ file, several, a folder of them or a glob (``"tiles/*.laz"``): tiles of
        one area in one CRS; where files overlap, a tile holds the points of each.
    cue : {"intensity", "evidence"}
        ``intensity``: Zhu & Mordohai's Algorithm 1; ``evidence``: the road likelihood of
        every cue the cloud carries through the network stage (module docstring).
    tile_m, overlap_m : float
        Tile side and overlap with each neighbour, metres (paper: 300 m and 100 m).
    cell_m : float, optional
        Image cell, metres; by default :func:`auto_cell_m` of the cloud.
    threshold : float
        ``cue="evidence"``: likelihood at which a cell is road.
    network_options : dict, optional
        ``cue="evidence"``: keyword arguments of
        :func:`gisroads.network.rasters.raster_to_network`.
    min_points : int
        Tiles with fewer points are skipped.
    workers : int
        Tiles run as tasks on a local Dask cluster of this many single-threaded worker
        processes; 1 runs them in this process, without Dask.
    scheduler : str, optional
        Address of an existing Dask scheduler to run the tiles on instead (its workers
        must see ``work_dir``).
    work_dir : str or Path, optional
        Folder for the tile store and the finished tiles, keyed by the inputs (path, size,
        modification time) and the parameters: a run stopped midway (Ctrl-C, a power cut)
        and started again reuses what was finished. By default a temporary folder,
        removed at the end.
    tile_maps : bool
        Keep every tile's per-width likelihood maps in ``LidarRoads.tiles`` (written by
        ``gisroads lidar --rasters``); False drops them as tiles finish and keeps of each
        tile only its core (its QA layers, intensity and heights; :func:`_core_only`),
        which bounds the memory of a city (about 9 MB per tile and ground level for the
        maps, and 0.44 of the rest).
    Other parameters (``cue="intensity"``): see :func:`extract_tile`.

    Returns
    -------
    LidarRoads
        The network in the cloud's CRS; QA layers ``rectangles`` and ``hypotheses``
        (intensity), ``gap_edges``, ``junction_connections`` and ``rejected`` (evidence).
        ``run`` counts the tiles and those taken from ``work_dir``.

    Raises
    ------
    LasError
        Unreadable file; ValueError when the intensity cue meets a cloud without intensity,
        or for an unknown cue.
    """
    if cue not in CUES:
        raise ValueError(f"cue must be one of {CUES}, not {cue!r}")
    parallel = dict(workers=workers, scheduler=scheduler, work_dir=work_dir)
    if cue == "evidence":
        return _evidence_roads(path, threshold=threshold, network_options=network_options,
                               progress=progress, tile_m=tile_m, overlap_m=overlap_m,
                               cell_m=cell_m, min_points=min_points, **parallel)
    store = open_store(path, work_dir, tile_m=tile_m, overlap_m=overlap_m,
                       progress=scaled(progress, 0.0, 0.1))
    try:
        tiles = store.tiles
        if cell_m is None:
            cell_m = auto_cell_m(store.point_count, _covered_m2(tiles))
        options = dict(cell_m=cell_m, widths_m=tuple(widths_m), lengths_m=tuple(lengths_m),
                       n_segments=n_segments, t_planar=t_planar, t_vert=t_vert)
        job = _TileJob(store, "intensity", min_points, options, _results_folder(
            store, work_dir, "intensity", {**options, "min_points": min_points}),
            tile_maps=tile_maps)
        run: dict = {}
        results = _run_tiles(job, tiles, workers=workers, scheduler=scheduler,
                             progress=scaled(progress, 0.1, 0.95), run=run,
                             keep=None if tile_maps else _core_only)
        roads = assemble([r for r in results if r is not None], crs=store.crs, cell_m=cell_m)
        roads.run = run
        return roads
    finally:
        if work_dir is None:
            store.remove()


def _in_core(frame: gpd.GeoDataFrame, tile: Tile) -> gpd.GeoDataFrame:
    if len(frame) == 0:
        return frame
    centres = shapely.centroid(frame.geometry.values)
    x, y = shapely.get_x(centres), shapely.get_y(centres)
    core = tile.core
    return frame[(x >= core[0]) & (x < core[2]) & (y >= core[1]) & (y < core[3])]


def assemble(results: list[TileRoads], *, crs, cell_m: float = 0.5) -> LidarRoads:
    """Stitch tiles into one network in the file's own CRS (see :func:`extract_roads`).

    ``crs`` is ``(working metre CRS, file CRS)`` as :func:`gisroads.io.las.cloud_crs` gives.
    """
    working, source = crs
    pieces = [(r.tile, r.centrelines) for r in results]
    lines = stitch_tiles(pieces) if pieces else _no_lines(working).assign(level=0)
    network = ribbons_to_network(lines, method=METHOD)
    network.polygons = _with_level(network.polygons,
                                   shapely.point_on_surface(network.polygons.geometry.values),
                                   lines)
    network.qa = {"rectangles": _concat([_in_core(r.rectangles, r.tile) for r in results],
                                        working),
                  "hypotheses": _concat([_in_core(r.hypotheses, r.tile) for r in results],
                                        working)}
    heights = mosaic_cores([(r.tile, r.heights) for r in results], cell_m) if results else None
    if source is not None and working is not None and source != working:
        network = RoadNetwork(network.centrelines.to_crs(source),
                              network.polygons.to_crs(source),
                              network.junctions.to_crs(source),
                              {name: frame.to_crs(source) for name, frame in network.qa.items()})
    return LidarRoads(network, heights, results)


def mosaic_cores(rasters: list[tuple[Tile, GeoRaster]], cell_m: float) -> GeoRaster:
    """One raster over all tiles (per-tile rasters such as ground heights or intensity
    images, bands padded with NaN to the most levels), each cell taken from the tile whose
    core holds it. Tile
    grids are aligned to multiples of ``cell_m`` (see :func:`ground_and_intensity`)."""
    xmin = min(t.core[0] for t, _ in rasters)
    ymin = min(t.core[1] for t, _ in rasters)
    xmax = max(t.core[2] for t, _ in rasters)
    ymax = max(t.core[3] for t, _ in rasters)
    transform, (rows, cols) = image_grid((xmin, ymin, xmax, ymax), cell_m)
    bands = max(r.data.shape[0] for _, r in rasters)
    if bands * rows * cols * 4 > MOSAIC_BUDGET_BYTES:
        raise ValueError(
            f"a mosaic of the tiles over {xmax - xmin:.0f} m x {ymax - ymin:.0f} m at "
            f"{cell_m:g} m cells would take {bands * rows * cols * 4 / 2**30:.1f} GiB (budget "
            f"{MOSAIC_BUDGET_BYTES / 2**30:.0f} GiB): the cloud's points lie far apart; split "
            "the file by area or choose a coarser cell")
    mosaic = np.full((bands, rows, cols), np.nan, np.float32)
    for tile, raster in rasters:  # one copy per tile
        r0 = int(round((transform.f - tile.core[3]) / cell_m))
        r1 = int(round((transform.f - tile.core[1]) / cell_m))
        c0 = int(round((tile.core[0] - transform.c) / cell_m))
        c1 = int(round((tile.core[2] - transform.c) / cell_m))
        sr = int(round((raster.transform.f - tile.core[3]) / cell_m))
        sc = int(round((tile.core[0] - raster.transform.c) / cell_m))
        r1 = min(r1, rows, r0 + raster.data.shape[1] - sr)
        c1 = min(c1, cols, c0 + raster.data.shape[2] - sc)
        mosaic[:raster.data.shape[0], r0:r1, c0:c1] = \
            raster.data[:, sr:sr + r1 - r0, sc:sc + c1 - c0]
    return GeoRaster(mosaic, transform, rasters[0][1].crs)
