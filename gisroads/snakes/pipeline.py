"""Map-guided road extraction with ribbon snakes (Boyko & Funkhouser, 2011) as a composition.

register the map in 3D (:mod:`.registration`) -> one subcloud per road patch
(:mod:`.subclouds`) -> per patch: attractor map (:mod:`.attractor`) -> gradient vector flow
(:mod:`.gvf`) -> ribbon snake (:mod:`.ribbon`) -> ribbons to the road-network contract
(:func:`gisroads.vectorize.ribbons.ribbons_to_network`, the conversion the LiDAR pipeline
shares), one ground level at a time, so that a bridge and the road under it stay two roads
that do not meet; junctions from the map's topology; road points tagged class 11.

Levels: a ribbon whose centre line crosses another one more than ``clearance_m`` above it
is one level higher than that one (a bridge over a road); ribbons of one level are
converted together, and the road polygons carry their ``level``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from functools import partial

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from affine import Affine
from scipy import ndimage

from ..errors import GisroadsError
from ..geo import GeoRaster, RoadNetwork
from ..io.las import ROAD_SURFACE_CLASS, cloud_crs, write_classified
from ..tiling.tilestore import code_fingerprint, digest
from ..options import with_changes
from ..parallel import NOT_KEPT, Parallel, keep_result, kept_result, run_tasks, shared_workers
from ..progress import Progress, report, scaled
from ..vectorize.ribbons import ribbon_areas, ribbons_to_network
from .attractor import ALPHA_ATTR, BETA_ATTR, LANE_M, MIN_NEIGHBOURS, attractor_map
from .gvf import MAX_ITERATIONS as GVF_ITERATIONS
from .gvf import MU, gradient_vector_flow
from .ribbon import (ALPHA_SNAKE, BETA_SNAKE, GAMMA_SNAKE, KAPPA_SNAKE, STEP_M,
                     initial_ribbon, resample_line, ribbon_snake)

METHOD = "boyko-funkhouser"
#: A crossing ribbon this much higher (metres) passes over the other one: a storey.
CLEARANCE_M = 2.5
#: The paper's map is a Cardinal spline through control vertices every 15 m; a digitised or
#: OpenStreetMap polyline zigzags by its vertex noise instead, and a snake that takes the
#: zigzag as its rest shape cannot straighten it (rigidity) and comes out too wide
#: (+0.6 m on a 21 m avenue with 0.5 m vertex noise every 10 m). A Gaussian of this
#: deviation (metres along the line) smooths the line first.
SMOOTH_M = 5.0


@dataclass
class Ribbon:
    """A fitted ribbon snake of one road patch.

    Attributes
    ----------
    road_id : int
        The map road of the patch.
    centre_xyz : ndarray, shape (n, 3)
        Centre line (metres); z interpolated from the registered samples.
    half_width_m : ndarray, shape (n,)
    converged : bool
    attractor : GeoRaster
        The patch's attractor map.
    level : int
        Storey (0: the lowest); set by :func:`ribbon_levels`.
    """

    road_id: int
    centre_xyz: np.ndarray
    half_width_m: np.ndarray
    converged: bool
    attractor: GeoRaster
    level: int = 0

    def polygon(self):
        """The ribbon's surface, kerb to kerb."""
        return ribbon_areas([shapely.linestrings(self.centre_xyz[:, :2])],
                            [2 * self.half_width_m])[0]


@dataclass
class MapGuidedRoads:
    """What :func:`extract_map_guided` returns.

    Attributes
    ----------
    network : RoadNetwork
        Contract layers (polygons with ``level``) and the QA layers ``ribbon_patches``
        (one polygon per patch: road_id, level, width_m, converged) and
        ``registered_map`` (the map's 3D lines).
    ribbons : list of Ribbon
    attractor : GeoRaster or None
        The patches' attractor maps on one grid (the largest value where they overlap).
    registered : RegisteredMap
    tagged_points : int or None
        Points classified as road when a tagged copy of the cloud was written.
    """

    network: RoadNetwork
    ribbons: list
    attractor: GeoRaster | None
    registered: object
    tagged_points: int | None = None


@dataclass(frozen=True)
class RibbonOptions:
    """The options of :func:`fit_ribbon`: the attractor map, the gradient vector flow and the
    ribbon snake of a road patch (Table 1 of the paper).

    Attributes
    ----------
    curb_detector : {"exp", "step", "none"}
        f_nExp, f_nStep or f_n (:func:`gisroads.snakes.attractor.curb_response`).
    cell_m : float
        Attractor grid cell (metres).
    alpha_attr, beta_attr, k_neighbours, lane_m : float
        Attractor parameters (:func:`gisroads.snakes.attractor.attractor_map`).
    mu, gvf_iterations : float
        GVF parameters (:func:`gisroads.snakes.gvf.gradient_vector_flow`).
    alpha, beta, gamma, kappa, step_m, max_iterations : float
        Snake parameters (:func:`gisroads.snakes.ribbon.ribbon_snake`).
    smooth_m : float
        Standard deviation (metres along the line) of the Gaussian that smooths the map
        line before the snake takes it as its rest shape (see :data:`SMOOTH_M`).
    """

    curb_detector: str = "exp"
    cell_m: float = 0.5
    alpha_attr: float = ALPHA_ATTR
    beta_attr: float = BETA_ATTR
    k_neighbours: int = MIN_NEIGHBOURS
    lane_m: float = LANE_M
    mu: float = MU
    gvf_iterations: int = GVF_ITERATIONS
    alpha: float = ALPHA_SNAKE
    beta: float = BETA_SNAKE
    gamma: float = GAMMA_SNAKE
    kappa: float = KAPPA_SNAKE
    step_m: float = STEP_M
    max_iterations: int = 500
    smooth_m: float = SMOOTH_M


def fit_ribbon(points_xyz: np.ndarray, line_xyz: np.ndarray, plane_normal=(0.0, 0.0, 1.0),
               options: RibbonOptions = RibbonOptions(), *, road_id: int = 0, crs=None,
               **changes) -> Ribbon:
    """Attractor map, GVF and ribbon snake of one road patch (Sec. 2.3-2.4).

    Parameters
    ----------
    points_xyz : ndarray, shape (m, 3)
        The patch's subcloud (metres).
    line_xyz : ndarray, shape (k, 3) or (k, 2)
        The patch's registered map samples, in order along the road.
    plane_normal : array_like, shape (3,) or (m, 3)
        Support-plane normal of the patch or of each point's sample.
    options : RibbonOptions
        Attractor, GVF and snake (:class:`RibbonOptions`).
    road_id : int
        The ribbon's road.
    crs : optional
        CRS of the attractor map.
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    Ribbon
    """
    options = replace(options, **changes)
    line = np.asarray(line_xyz, float)
    samples, _ = resample_line(line[:, :2], options.step_m)
    if options.smooth_m > 0:
        samples = ndimage.gaussian_filter1d(samples, options.smooth_m / options.step_m, axis=0,
                                            mode="nearest")
    attractor = attractor_map(points_xyz, line[:, :2], plane_normal, cell_m=options.cell_m,
                              alpha=options.alpha_attr, beta=options.beta_attr,
                              detector=options.curb_detector,
                              k_neighbours=options.k_neighbours, lane_m=options.lane_m, crs=crs)
    u, v = gradient_vector_flow(attractor.data, mu=options.mu, iterations=options.gvf_iterations)
    shift, half = initial_ribbon(attractor, samples, step_m=options.step_m,
                                 min_width_m=options.lane_m, reach_m=6 * options.lane_m)
    centre, half_width, converged = ribbon_snake(
        u, v, attractor.transform, samples, width0_m=2 * half, shift0_m=shift,
        alpha=options.alpha, beta=options.beta, gamma=options.gamma, kappa=options.kappa,
        step_m=options.step_m, max_iterations=options.max_iterations)
    z = _heights_along(line, centre)
    return Ribbon(int(road_id), np.column_stack([centre, z]), half_width, bool(converged),
                  attractor)


def _heights_along(line_xyz: np.ndarray, points_xy: np.ndarray) -> np.ndarray:
    """Heights of the line's nearest samples at points along it (0 for a 2D line)."""
    if line_xyz.shape[1] < 3:
        return np.zeros(len(points_xy))
    stations = np.r_[0.0, np.cumsum(np.hypot(*np.diff(line_xyz[:, :2], axis=0).T))]
    along = np.r_[0.0, np.cumsum(np.hypot(*np.diff(points_xy, axis=0).T))]
    along *= stations[-1] / max(along[-1], 1e-12)
    return np.interp(along, stations, line_xyz[:, 2])


def ribbon_levels(ribbons: list, *, clearance_m: float = CLEARANCE_M) -> np.ndarray:
    """Storey of each ribbon: one above the highest ribbon it crosses ``clearance_m`` above.

    Sets ``Ribbon.level`` and returns the levels.
    """
    lines = np.array([shapely.linestrings(r.centre_xyz[:, :2]) for r in ribbons], dtype=object)
    above = {k: set() for k in range(len(ribbons))}
    if len(lines):
        i, j = shapely.STRtree(lines).query(lines, predicate="crosses")
        for a, b in zip(i, j):  # a few crossings
            crossing = shapely.get_coordinates(shapely.intersection(lines[a], lines[b]))
            if len(crossing) == 0:
                continue
            za, zb = (_height_at(ribbons[k], crossing[0]) for k in (a, b))
            if za - zb > clearance_m:
                above[a].add(b)
    levels = np.zeros(len(ribbons), dtype=np.int64)
    for _ in range(len(ribbons)):  # longest chain of "passes over", a few storeys
        new = np.array([max((levels[b] + 1 for b in above[a]), default=0)
                        for a in range(len(ribbons))], dtype=np.int64)
        if np.array_equal(new, levels):
            break
        levels = new
    for ribbon, level in zip(ribbons, levels):
        ribbon.level = int(level)
    return levels


def _height_at(ribbon: Ribbon, xy) -> float:
    nearest = np.argmin(np.hypot(*(ribbon.centre_xyz[:, :2] - xy).T))
    return float(ribbon.centre_xyz[nearest, 2])


def ribbons_network(ribbons: list, crs, *, map_junctions: gpd.GeoDataFrame | None = None,
                    qa: dict | None = None, **conversion) -> RoadNetwork:
    """Road network from fitted ribbons, one level at a time through the shared conversion.

    Parameters
    ----------
    ribbons : list of Ribbon
        With their ``level`` set (:func:`ribbon_levels`).
    crs
        CRS of the output layers.
    map_junctions : GeoDataFrame, optional
        The map's intersections (``degree``): where given, the junctions are those of degree
        three or more, each moved onto the nearest end of an extracted road within
        ``join_gap_m`` plus the widest half width (it stays where the map has it otherwise).
        Without them, the junctions are the conversion's own, per level.
    qa : dict of GeoDataFrame, optional
        Extra QA layers.
    conversion
        Options of :func:`gisroads.vectorize.ribbons.ribbons_to_network`.

    Returns
    -------
    RoadNetwork
        ``road_polygons`` and ``road_centrelines`` with ``level``; QA layer
        ``ribbon_patches``.
    """
    levels = np.array([r.level for r in ribbons], dtype=np.int64)
    parts = []
    for level in np.unique(levels):  # a few storeys
        chosen = [r for r in ribbons if r.level == level]
        frame = gpd.GeoDataFrame(
            {"widths_m": [2 * r.half_width_m for r in chosen]},
            geometry=gpd.GeoSeries([shapely.linestrings(r.centre_xyz[:, :2]) for r in chosen],
                                   crs=crs), crs=crs)
        parts.append((level, ribbons_to_network(frame, method=METHOD, **conversion)))
    patches = gpd.GeoDataFrame(
        {"road_id": np.array([r.road_id for r in ribbons], dtype=np.int64),
         "level": levels,
         "width_m": np.array([2 * float(np.mean(r.half_width_m)) for r in ribbons]),
         "converged": np.array([r.converged for r in ribbons], dtype=bool)},
        geometry=gpd.GeoSeries([r.polygon() for r in ribbons], crs=crs), crs=crs)
    layers = {"ribbon_patches": patches, **(qa or {})}
    if not parts:
        return ribbons_to_network(gpd.GeoDataFrame({"width_m": []}, geometry=gpd.GeoSeries(
            [], crs=crs), crs=crs), method=METHOD, qa=layers)
    offset = 0
    lines, polygons, junctions = [], [], []
    for level, network in parts:
        for frame, out in ((network.centrelines, lines), (network.polygons, polygons)):
            frame = frame.copy()
            frame["road_id"] = frame["road_id"] + offset
            frame["level"] = level
            out.append(frame)
        junctions.append(network.junctions)
        offset += len(network.centrelines)
    centrelines = pd.concat(lines, ignore_index=True)
    network = RoadNetwork(gpd.GeoDataFrame(centrelines, crs=crs),
                          gpd.GeoDataFrame(pd.concat(polygons, ignore_index=True), crs=crs),
                          _junctions(junctions, map_junctions, centrelines, ribbons,
                                     conversion.get("join_gap_m", 5.0), crs),
                          layers)
    return network


def _junctions(per_level, map_junctions, centrelines, ribbons, join_gap_m, crs):
    if map_junctions is None:
        frame = pd.concat(per_level, ignore_index=True)
        frame["junction_id"] = np.arange(len(frame), dtype=np.int64)
        return gpd.GeoDataFrame(frame, crs=crs)
    nodes = map_junctions[map_junctions["degree"] >= 3]
    xy = shapely.get_coordinates(nodes.geometry.values)
    ends = shapely.get_coordinates(np.concatenate([
        shapely.get_point(centrelines.geometry.values, 0),
        shapely.get_point(centrelines.geometry.values, -1)])) if len(centrelines) else \
        np.empty((0, 2))
    if len(ends) and len(xy):
        reach = join_gap_m + max(float(np.max(r.half_width_m)) for r in ribbons)
        distance = np.hypot(*(xy[:, None, :] - ends[None, :, :]).transpose(2, 0, 1))
        nearest = np.argmin(distance, axis=1)
        close = distance[np.arange(len(xy)), nearest] <= reach
        xy = np.where(close[:, None], ends[nearest], xy)
    return gpd.GeoDataFrame(
        {"junction_id": np.arange(len(xy), dtype=np.int64),
         "degree": nodes["degree"].to_numpy(np.int64)},
        geometry=gpd.GeoSeries(shapely.points(xy), crs=crs), crs=crs)


def mosaic(rasters: list, *, crs=None) -> GeoRaster | None:
    """Rasters on one grid of the same (north-up, aligned) cells; the largest value where
    they overlap, 0 elsewhere."""
    if not rasters:
        return None
    cell = rasters[0].pixel_size
    bounds = np.array([r.bounds for r in rasters])
    xmin, ymin = bounds[:, 0].min(), bounds[:, 1].min()
    xmax, ymax = bounds[:, 2].max(), bounds[:, 3].max()
    shape = (int(round((ymax - ymin) / cell)), int(round((xmax - xmin) / cell)))
    out = np.zeros(shape, dtype=np.float32)
    for r in rasters:  # one per patch
        row0 = int(round((ymax - r.transform.f) / cell))
        col0 = int(round((r.transform.c - xmin) / cell))
        rows, cols = r.shape
        window = out[row0:row0 + rows, col0:col0 + cols]
        np.maximum(window, r.data, out=window)
    return GeoRaster(out, Affine(cell, 0.0, xmin, 0.0, -cell, ymax),
                     crs if crs is not None else rasters[0].crs)


def road_point_indices(patches: list, ribbons: list) -> np.ndarray:
    """Sorted unique file indices of the patches' points inside their ribbon (Sec. 2.5)."""
    chosen = []
    for patch, ribbon in zip(patches, ribbons):  # one per road patch
        area = ribbon.polygon()
        shapely.prepare(area)
        inside = shapely.contains_xy(area, patch.points[:, 0], patch.points[:, 1])
        chosen.append(np.asarray(patch.point_index)[inside])
    return np.unique(np.concatenate(chosen)) if chosen else np.empty(0, dtype=np.int64)


def tag_cloud(source, target, road_indices: np.ndarray, *,
              road_class: int = ROAD_SURFACE_CLASS) -> int:
    """Copy a LAS/LAZ file with the points at ``road_indices`` (file order) classified
    ``road_class``, streamed; returns the number of points tagged."""
    road_indices = np.asarray(road_indices, dtype=np.int64)
    start = 0

    def classify(chunk):
        nonlocal start
        lo, hi = np.searchsorted(road_indices, [start, start + len(chunk)])
        classes = chunk.classification.copy()
        classes[road_indices[lo:hi] - start] = road_class
        start += len(chunk)
        return classes

    write_classified(source, target, classify)
    return len(road_indices)


def _map_in_cloud_crs(cloud_path, map_lines: gpd.GeoDataFrame):
    """``(the map's non-empty lines in the cloud's metre CRS, that CRS or None)``."""
    lines = map_lines[map_lines.geometry.notna() & ~map_lines.geometry.is_empty]
    if len(lines) == 0:
        raise GisroadsError("the road map holds no line")
    working, _ = cloud_crs(cloud_path)
    if working is not None:
        if lines.crs is None:
            raise GisroadsError("the road map has no CRS; cannot match it to the cloud")
        lines = lines.to_crs(working)
    return lines, working


def _register(store, cloud_path, lines: gpd.GeoDataFrame, snap_m: float | None, *,
              progress: Progress = None):
    """The map registered on the points of ``store`` along its lines (Sec. 2.1)."""
    from .registration import SNAP_M, SUPPORT_RADIUS_M, register_map
    from .subclouds import read_corridor

    snap = SNAP_M if snap_m is None else snap_m
    report(progress, 0.0, "reading the points along the map")
    along = shapely.get_coordinates(shapely.segmentize(lines.geometry.values, 0.5))
    cloud, _ = read_corridor(store, along, SUPPORT_RADIUS_M + snap + 0.5)
    if len(cloud) == 0:
        raise GisroadsError(f"{cloud_path}: no point lies along the map's lines; "
                            "does the map cover the cloud?")
    return register_map(lines, cloud, snap_m=snap, progress=progress)


def map_patches(cloud_path, map_lines: gpd.GeoDataFrame, *, snap_m: float | None = None,
                progress: Progress = None):
    """Register a road map on a LAS/LAZ file and cut its road patches (Sec. 2.1-2.2).

    The map (any CRS) is reprojected to the cloud's metre CRS; only the points along its
    lines are read for the registration, and the patches are read chunk by chunk.

    Returns
    -------
    registered : RegisteredMap
    patches : list of RoadPatch
        Those with enough points and samples for a ribbon.
    crs : pyproj.CRS or None
    """
    from ..tiling.tilestore import open_store
    from .subclouds import road_patches

    lines, working = _map_in_cloud_crs(cloud_path, map_lines)
    # the file is decoded once into the LiDAR pipeline's tile store; the three passes
    # below read only its cells along the map
    store = open_store(cloud_path, progress=scaled(progress, 0.0, 0.05))
    try:
        registered = _register(store, cloud_path, lines, snap_m,
                               progress=scaled(progress, 0.1, 0.6))
        report(progress, 0.6, "cutting the road patches")
        patches = [p for p in road_patches(registered, store,
                                           progress=scaled(progress, 0.6, 1))
                   if len(p.points) >= MIN_NEIGHBOURS and len(p.samples_xyz) >= 2]
    finally:
        store.remove()
    if not patches:
        raise GisroadsError(f"{cloud_path}: no road patch holds enough points along the map")
    return registered, patches, working if working is not None else lines.crs


def curb_attractor(cloud_path, map_lines: gpd.GeoDataFrame, *, curb_detector: str = "exp",
                   cell_m: float = 0.5, snap_m: float | None = None,
                   progress: Progress = None, **attractor_options) -> GeoRaster:
    """The attractor maps of every road patch of a map over a cloud, on one grid (Sec. 2.3).

    ``attractor_options`` go to :func:`gisroads.snakes.attractor.attractor_map`; where
    patches overlap the largest value is kept (:func:`mosaic`).
    """
    _, patches, crs = map_patches(cloud_path, map_lines, snap_m=snap_m,
                                  progress=scaled(progress, 0.0, 0.5))
    maps = []
    for k, patch in enumerate(patches):  # one per road patch
        report(progress, 0.5 + 0.5 * k / len(patches), f"attractor {k + 1} of {len(patches)}")
        maps.append(attractor_map(patch.points, patch.samples_xyz[:, :2],
                                  np.asarray(patch.plane_normal)[patch.sample_index],
                                  cell_m=cell_m, detector=curb_detector, crs=crs,
                                  **attractor_options))
    report(progress, 1.0, "done")
    return mosaic(maps, crs=crs)


#: Side (metres) of the tile-store cells the snakes read: a road patch reads the cells within
#: its reach (22 m) of its samples, so small cells keep what a patch reads near its corridor
#: (a 200 m cell of the LiDAR grid would make every patch read 600 m x 600 m).
PATCH_CELL_M = 25.0


@dataclass(frozen=True)
class _PatchJob:
    """What a task needs to fit one road patch: picklable, sent to the Dask workers."""

    store: object
    crs: object
    ribbon: RibbonOptions
    tag: bool
    """Return the file indices of the patch's points inside its ribbon (tagging)."""
    attractor: bool
    """Keep the patch's attractor map in its ribbon (the attractor mosaic)."""
    results: object = None
    """Folder of finished patches (None: nothing kept)."""


def one_road_maps(registered) -> list:
    """The registered map cut into one :class:`RegisteredMap` per road, in the order of
    ``registered.lines``: what one patch task needs (its samples and its line)."""
    from .registration import RegisteredMap

    bounds = np.flatnonzero(np.diff(registered.road_id)) + 1
    starts = np.concatenate([[0], bounds])
    spans = dict(zip(registered.road_id[starts].tolist(),
                     np.split(np.arange(len(registered.road_id)), bounds)))
    no_nodes = registered.intersections.iloc[:0]
    maps = []
    for k, road in enumerate(registered.lines["road_id"].to_numpy()):  # one per road
        span = spans.get(int(road), np.empty(0, np.int64))
        maps.append(RegisteredMap(registered.lines.iloc[k:k + 1], registered.road_id[span],
                                  registered.station_m[span], registered.xyz[span],
                                  registered.tangent[span], registered.seen[span], no_nodes,
                                  registered.crs))
    return maps


def _patch_path(job: _PatchJob, road) -> object:
    if job.results is None:
        return None
    key = digest([int(road.lines["road_id"].iloc[0]), road.xyz.tobytes().hex()])
    return job.results / f"patch_{int(road.lines['road_id'].iloc[0])}_{key}.pkl"


def fit_patch(job: _PatchJob, road):
    """One road patch as a task: its subcloud from the tile store (the cells along it
    only), its ribbon; ``(ribbon, road point indices or None)``, or None for a patch with
    too few points or samples. Kept in ``job.results`` when given, and taken from there."""
    from .subclouds import road_patches

    path = _patch_path(job, road)
    kept = kept_result(path)
    if kept is not NOT_KEPT:
        return kept
    result = None
    patch = road_patches(road, job.store)[0] if len(road.xyz) >= 2 else None
    if patch is not None and len(patch.points) >= MIN_NEIGHBOURS:
        ribbon = fit_ribbon(patch.points, patch.samples_xyz,
                            np.asarray(patch.plane_normal)[np.asarray(patch.sample_index)],
                            job.ribbon, road_id=patch.road_id, crs=job.crs)
        indices = road_point_indices([patch], [ribbon]) if job.tag else None
        if not job.attractor:
            ribbon.attractor = None
        result = (ribbon, indices)
    del patch
    keep_result(path, result)
    return result


def _code_fingerprint() -> str:
    """:func:`gisroads.tiling.tilestore.code_fingerprint` of the snakes' sources and what
    they read the points with."""
    import scipy

    return code_fingerprint(("snakes/*.py", "io/las.py", "tiling/tilestore.py"),
                            (np, scipy, shapely))


def extract_map_guided(cloud_path, map_lines: gpd.GeoDataFrame,
                       ribbon: RibbonOptions = RibbonOptions(),
                       parallel: Parallel = Parallel(), *, snap_m: float | None = None,
                       tagged_las=None, clearance_m: float = CLEARANCE_M,
                       attractor: bool = True, progress: Progress = None,
                       **changes) -> MapGuidedRoads:
    """Roads of a LAS/LAZ file along an approximate road map (Boyko & Funkhouser, 2011).

    The file is decoded once into a tile store of :data:`PATCH_CELL_M` cells
    (:mod:`gisroads.tiling.tilestore`); the map is registered on the points along it; then
    every road patch is a task (:func:`fit_patch`, :func:`gisroads.parallel.run_tasks`)
    that reads its subcloud from the store and fits its ribbon, here or on Dask: the same
    ribbons whatever the number of workers.

    Parameters
    ----------
    cloud_path : str or Path
    map_lines : GeoDataFrame
        Road map lines in any CRS (reprojected to the cloud's metre CRS).
    ribbon : RibbonOptions
        The attractor, GVF and snake of every road patch (:func:`fit_ribbon`; the paper's
        Table 1, its best curb detector f_nExp).
    snap_m : float, optional
        Snapping tolerance of the map's intersections (metres; the registration's default).
    tagged_las : str or Path, optional
        Where to write the cloud with the road points in class 11.
    clearance_m : float
        Height (metres) above which a crossing ribbon passes over another (a bridge).
    parallel : Parallel
        Where the patches run, and the work folder (keyed by the input, the map's
        registered samples and the parameters) a stopped run resumes from
        (:class:`gisroads.parallel.Parallel`).
    attractor : bool
        Return the attractor mosaic (False: the patches' maps are dropped as they finish).
    progress : callable, optional
    **changes
        Fields of ``ribbon`` or ``parallel`` to change for this call, e.g.
        ``curb_detector="step"`` or ``workers=2``.

    Returns
    -------
    MapGuidedRoads

    Examples
    --------
    A synthetic scene's roads from an old map of them, every line 2 m off and jittered:

    >>> import tempfile
    >>> from pathlib import Path
    >>> from gisroads.evaluate import area_metrics
    >>> from gisroads.snakes import extract_map_guided
    >>> from gisroads.synthetic import make_scene, perturb_lines, write_cloud
    >>> scene = make_scene(seed=0, size_m=(300, 300), features=("bridge",))
    >>> old_map = perturb_lines(scene.truth.centrelines, shift_m=2.0, jitter_m=0.5, seed=1)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     cloud = Path(folder) / "cloud.laz"
    ...     points = write_cloud(scene, cloud, density_per_m2=8)
    ...     roads = extract_map_guided(cloud, old_map, snap_m=8.0)
    >>> len(roads.ribbons) >= len(old_map)                 # one ribbon per road patch
    True
    >>> sorted(roads.network.qa)
    ['registered_map', 'ribbon_patches']
    >>> area_metrics(roads.network.polygons, scene.truth.polygons).quality > 0.8
    True
    """
    from pathlib import Path

    from ..tiling.tilestore import open_store

    ribbon, parallel = with_changes(changes, ribbon, parallel)
    workers, scheduler, work_dir = parallel.workers, parallel.scheduler, parallel.work_dir
    lines, working = _map_in_cloud_crs(cloud_path, map_lines)
    with shared_workers():  # one cluster for the reading pass and the patches
        store = open_store(cloud_path, work_dir, tile_m=PATCH_CELL_M, overlap_m=0.0,
                           workers=workers, scheduler=scheduler,
                           progress=scaled(progress, 0.0, 0.1))
        try:
            registered = _register(store, cloud_path, lines, snap_m,
                                   progress=scaled(progress, 0.1, 0.3))
            crs = working if working is not None else lines.crs
            results = None
            if work_dir is not None:
                key = digest([store.key, asdict(ribbon), _code_fingerprint()])
                results = Path(work_dir) / f"patches-{key}"
                results.mkdir(parents=True, exist_ok=True)
            job = _PatchJob(store, crs, ribbon, tagged_las is not None, attractor, results)
            outcomes = [o for o in run_tasks(partial(fit_patch, job), one_road_maps(registered),
                                             workers=workers, scheduler=scheduler,
                                             progress=scaled(progress, 0.3, 0.8),
                                             what="road patches")
                        if o is not None]
        finally:
            if work_dir is None:
                store.remove()
    if not outcomes:
        raise GisroadsError(f"{cloud_path}: no road patch holds enough points along the map")
    ribbons = [ribbon for ribbon, _ in outcomes]
    ribbon_levels(ribbons, clearance_m=clearance_m)
    report(progress, 0.8, "building the road network")
    network = ribbons_network(
        ribbons, crs, map_junctions=registered.intersections,
        qa={"registered_map": registered.lines[["road_id", "length_m", "seen_fraction",
                                                "geometry"]]})
    tagged = None
    if tagged_las is not None:
        report(progress, 0.9, "tagging road points")
        tagged = tag_cloud(cloud_path, tagged_las, np.unique(np.concatenate(
            [indices for _, indices in outcomes])))
    report(progress, 1.0, "done")
    return MapGuidedRoads(network, ribbons,
                          mosaic([r.attractor for r in ribbons], crs=crs) if attractor else None,
                          registered, tagged)
