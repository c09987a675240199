"""The LiDAR jobs: Zhu & Mordohai's pipeline on a whole cloud and each of its stages on
files (ground levels and intensity, segmentation, hypotheses, minimum cover, rectangles to
a network), the evidence raster, tagging the road points, and the city blocks of §5."""
from __future__ import annotations

import warnings
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import numpy as np
from pyproj import Transformer

from ..errors import GisroadsError, NoRoadFoundWarning
from ..features.edges import local_energy
from ..geo import POLYGONS, SERVICE_CENTRELINES, GeoRaster
from ..io.las import GROUND_CLASS, cloud_crs, iter_las_chunks, read_las
from ..io.quicklook import write_quicklook
from ..io.raster import read_raster, write_geotiff
from ..io.vector import (GeoPackageWriter, atomic_path, list_layers, read_layer,
                         write_geopackage)
from ..lidar.blocks import BlockOptions, city_blocks, road_likelihood, thin_points
from ..lidar.ground import ground_planes
from ..lidar.hypotheses import (DEFAULT_LENGTHS_M, DEFAULT_WIDTHS_M, L_MAX, T_BD, T_INT,
                                likelihood_maps, road_hypotheses)
from ..lidar.intensity import data_extent, write_intensity_images
from ..lidar.mincover import A, D_MAX, SEED_STEP_M, exact_min_cover, greedy_min_cover
from ..lidar.roads import rectangles_to_roads
from ..lidar.learned import save_evidence_model
from ..lidar.pipeline import (LidarOptions, TiledRoads, auto_cell_m, edges_and_segments,
                              evidence_raster, extract_roads, ground_and_intensity,
                              train_evidence_model)
from ..options import with_changes
from ..parallel import Parallel
from ..lidar.tagging import ground_level_heights, tag_road_points
from ..tiling.tilestore import inputs_crs, las_inputs
from ..progress import Progress, report, scaled
from ..resources import styles_dir
from .common import (_layer, _map_lines, _warn_if_empty, _warn_if_no_road, network_summary,
                     parse_metres, stage_default)


def lidar_job(cloud_path, out_path, options: LidarOptions = LidarOptions(),
              parallel: Parallel = Parallel(), *, tile_maps: bool | None = None,
              tagged_las=None, rasters_dir=None, background=None, quicklook=None,
              progress: Progress = None, **changes) -> dict:
    """The road network of a LAS/LAZ file into a road-network GeoPackage.

    Writes ``out_path`` (road_centrelines, road_polygons, junctions, and the QA layers of
    the cue: rectangles and hypotheses, or gap_edges, junction_connections and rejected)
    in the cloud's CRS; optionally ``tagged_las`` (the cloud with road points in class 11),
    ``rasters_dir`` (per-level intensity and likelihood GeoTIFFs of every tile and the
    per-level ground heights, or ``road_evidence.tif``), ``background`` (a GeoTIFF to show
    beneath the roads: the ground intensity image of the lowest level where the cloud has
    intensity, else the road evidence, with its QGIS style beside it as ``.qml``; its kind
    in the result's ``background_kind``) and a
    ``quicklook`` PNG over the same image.
    ``options``, ``parallel`` and ``**changes`` are those of
    :func:`gisroads.lidar.pipeline.extract_roads`; ``tile_maps`` defaults to keeping the
    tiles' likelihood maps only when ``rasters_dir`` is given. ``cloud_path`` may also be
    several files, a folder of them or a glob. A cloud without roads gives empty layers
    and a :class:`~gisroads.errors.NoRoadFoundWarning`.

    Returns
    -------
    dict
        Output paths and counts.
    """
    # one file, several, a folder or a glob (extract_roads); tagging copies one file
    inputs = las_inputs(cloud_path)
    if tagged_las is not None and len(inputs) > 1:
        raise GisroadsError(f"a tagged LAS/LAZ copy is made of one input file, not of "
                         f"{len(inputs)}: tag each file on its own")
    cloud_path = inputs[0] if len(inputs) == 1 else cloud_path
    # the network only: the tiles' QA layers and rasters are written one tile at a time
    # from the files the tiles wrote, so that a city's driver holds one tile of them
    options, parallel = with_changes(changes, options, parallel)
    with extract_roads(cloud_path, options, parallel, lazy=True,
                       progress=scaled(progress, 0.0, 0.8)) as roads:
        network = roads.network
        rasters = None if rasters_dir is None else Path(rasters_dir)
        # the tiles' per-width likelihood maps are read only to be written
        tile_maps = rasters is not None if tile_maps is None else tile_maps
        _write_tiles(roads, out_path, rasters, tile_maps=tile_maps, widths_m=options.widths_m,
                     progress=scaled(progress, 0.8, 0.9))
        _warn_if_no_road(network, cloud_path)
        working, _ = inputs_crs(inputs)
        result = {**network_summary(out_path, network),
                  "tiles": roads.run.get("with_points", len(roads.tiles)), "cue": options.cue,
                  "input_files": len(inputs),
                  "tiles_run": roads.run.get("tiles", 0),
                  "tiles_reused": roads.run.get("reused", 0)}
        if roads.cues:
            result["cues"] = ",".join(roads.cues)
        if SERVICE_CENTRELINES in network.qa:
            result["service_ways"] = len(network.qa[SERVICE_CENTRELINES])
            result["service_length_m"] = float(network.qa[SERVICE_CENTRELINES].length.sum())
        if rasters is not None:
            if roads.evidence is not None:
                write_geotiff(rasters / "road_evidence.tif", roads.evidence,
                              band_names=["road_likelihood"])
            result["rasters"] = rasters
        if tagged_las is not None:
            report(progress, 0.9, "tagging road points")
            # the evidence cue images one surface: its heights come from the cloud's planes
            # (both whole in memory, as the copy of one file)
            heights = (roads.mosaic("heights") if roads.tiles
                       else ground_level_heights(read_las(cloud_path)))
            result["tagged_points"] = tag_road_points(cloud_path, tagged_las,
                                                      _in_crs(network.polygons, working),
                                                      heights)
            result["tagged_las"] = Path(tagged_las)
        if background is not None or quicklook is not None:
            report(progress, 0.95, "imaging the background")
            beneath, kind = _background(roads, working)
        if background is not None and beneath is not None:
            style = kind.replace(" ", "_")
            write_geotiff(background, beneath, band_names=[style])
            # QGIS styles a raster with the .qml of the same name beside it
            Path(background).with_suffix(".qml").write_bytes(
                (styles_dir() / f"{style}.qml").read_bytes())
            result["background"], result["background_kind"] = Path(background), kind
        if quicklook is not None:
            report(progress, 0.97, "drawing the quick-look")
            # the QA layer of the cue: the selected rectangles, or the bridged gaps
            qa = (read_layer(out_path, "rectangles") if roads.cue == "intensity"
                  else network.qa["gap_edges"].query("selected"))
            service = network.qa.get(SERVICE_CENTRELINES)
            write_quicklook(quicklook, [
                (_in_crs(qa, working), dict(facecolor="none", edgecolor="cyan", linewidth=0.6)
                 if roads.cue == "intensity" else dict(color="cyan", linewidth=2)),
                *([] if service is None else [(_in_crs(service, working), dict(
                    color="#fdae61", linewidth=1.5, linestyle="--", label="service ways"))]),
                (_in_crs(network.centrelines, working),
                 dict(color="red", linewidth=1.5, label="road centre lines")),
                (_in_crs(network.junctions, working),
                 dict(color="yellow", markersize=20, label="junctions")),
            ], background=beneath,
                title=f"{Path(str(cloud_path)).name}: roads over the {kind}")
            result["quicklook"] = Path(quicklook)
    report(progress, 1.0, "done")
    return result


def _in_crs(frame, crs):
    """``frame`` in ``crs``; as it is where either has no CRS (a cloud without one)."""
    return frame if crs is None or frame.crs is None else frame.to_crs(crs)


def _background(roads: TiledRoads, working) -> tuple[GeoRaster | None, str]:
    """What the roads are shown over, and its name: the ground intensity (the lowest
    level's where the tiles imaged levels), else the road evidence."""
    if roads.imaged:
        intensity = roads.mosaic("intensity", bands=1)
        return GeoRaster(intensity.data[0], intensity.transform, working), "ground intensity"
    if roads.ground_intensity is not None and np.isfinite(roads.ground_intensity.data).any():
        return roads.ground_intensity, "ground intensity"
    if roads.evidence is not None:
        return roads.evidence, "road evidence"
    return None, ""


def _write_tiles(roads: TiledRoads, out_path, rasters: Path | None, *, tile_maps: bool,
                 widths_m, progress: Progress) -> None:
    """The network's layers and the tiles' QA layers into the GeoPackage ``out_path`` and,
    into the folder ``rasters``, each tile's intensity images (whole with its per-width
    likelihood maps when ``tile_maps``, else its core) and the mosaic of the ground
    heights: one tile read at a time, in grid order."""
    with ExitStack() as outputs:
        gpkg = outputs.enter_context(GeoPackageWriter(out_path))
        for name, frame in roads.network.layers().items():
            gpkg.write(name, frame)
        for name, frame in roads.qa().items():  # their schema when no tile has a feature
            gpkg.append(name, frame)
        heights = None
        if rasters is not None:
            rasters.mkdir(parents=True, exist_ok=True)
            if roads.imaged:
                heights = outputs.enter_context(roads.mosaic_file(
                    rasters / "ground_heights.tif", "heights",
                    band_names=[f"level_{k}" for k in range(roads.levels)]))
        for i, tile in enumerate(roads.results(maps=tile_maps)):
            report(progress, i / len(roads.tiles), f"writing tile {i + 1} of "
                                                   f"{len(roads.tiles)}")
            for name, frame in roads.qa(tile).items():
                gpkg.append(name, frame)
            if heights is not None:
                heights(tile)
            if rasters is not None and len(tile.intensity.data):
                name = f"tile_r{tile.tile.row}_c{tile.tile.col}"
                levels = [f"level_{k}" for k in range(tile.intensity.data.shape[0])]
                write_geotiff(rasters / f"{name}_intensity.tif", tile.intensity,
                              band_names=levels)
                for k, maps in enumerate(tile.likelihood):
                    # NaN past the cloud: city blocks and other readers see where it ends
                    inside = data_extent(tile.intensity.data[k],
                                         cell_m=tile.intensity.pixel_size)
                    maps = GeoRaster(np.where(inside, maps.data, np.float32(np.nan)),
                                     maps.transform, maps.crs)
                    write_geotiff(rasters / f"{name}_likelihood_level_{k}.tif", maps,
                                  band_names=[f"width_{w:g}_m" for w in widths_m])
        report(progress, 1.0, "writing the layers")


def _level_image(intensity_path, level: int) -> GeoRaster:
    raster = read_raster(intensity_path)
    if not 0 <= level < raster.data.shape[0]:
        raise GisroadsError(f"{intensity_path}: no level {level} (it has "
                         f"{raster.data.shape[0]} band(s), levels 0..{raster.data.shape[0] - 1})")
    return GeoRaster(raster.data[level].astype("float32"), raster.transform, raster.crs,
                     raster.nodata)


def ground_intensity_job(cloud_path, intensity_path, *, heights_path=None, cell_m=None,
                         t_planar: float = stage_default(ground_planes, "t_planar"),
                         t_vert: float = stage_default(ground_planes, "t_vert"),
                         progress: Progress = None) -> dict:
    """Stages 1-2 of the LiDAR method on a whole file: ground levels, intensity images.

    Writes ``intensity_path`` (one band per ground level, in [0, 1], NaN where no ground),
    ``<stem>_level_index.tif`` beside it and the per-level ground heights (``heights_path``,
    default ``<stem>_ground_heights.tif`` beside it), in the cloud's metre working CRS. The
    grid is the one :func:`gisroads.lidar.pipeline.extract_tile` uses over the same bounds.
    The whole cloud is held in memory: for large files run the tiled pipeline.
    """
    cloud = read_las(cloud_path)
    if cloud.intensity is None:
        raise GisroadsError(f"{cloud_path}: the point cloud records no intensity")
    bounds = (*cloud.xyz[:, :2].min(axis=0), *cloud.xyz[:, :2].max(axis=0))
    if cell_m is None:
        cell_m = auto_cell_m(len(cloud), (bounds[2] - bounds[0]) * (bounds[3] - bounds[1]))
    report(progress, 0.05, "ground planes")
    planes = ground_planes(cloud.xyz, t_planar=t_planar, t_vert=t_vert)
    report(progress, 0.7, "intensity images")
    images, heights = ground_and_intensity(cloud, planes, bounds=bounds, cell_m=cell_m)
    intensity, index = write_intensity_images(intensity_path, images)
    heights_path = Path(heights_path or intensity.with_name(f"{intensity.stem}_ground_heights.tif"))
    write_geotiff(heights_path, heights,
                  band_names=[f"level_{k}" for k in range(heights.data.shape[0])])
    report(progress, 1.0, "done")
    return {"intensity": intensity, "level_index": index, "ground_heights": heights_path,
            "levels": planes.n_levels, "cell_m": cell_m,
            "ground_points": int((planes.level >= 0).sum()), "points": len(cloud)}


def train_lidar_job(cloud_path, roads_path, out_path, *, width_field: str | None = None,
                    width_m: float = stage_default(train_evidence_model, "default_width_m"),
                    guard_m: float = stage_default(train_evidence_model, "guard_m"),
                    seed: int = stage_default(train_evidence_model, "seed"),
                    tile_m: float = stage_default(extract_roads, "tile_m"),
                    overlap_m: float = stage_default(extract_roads, "overlap_m"),
                    cell_m: float | None = None, progress: Progress = None) -> dict:
    """An evidence model of a LAS/LAZ cloud learned from a road layer of its area (the
    road-database update; :func:`gisroads.lidar.pipeline.train_evidence_model`), written to
    ``out_path`` (.npz) for ``lidar_job(..., model=out_path)``. Roads as ``train_job``
    takes them (any OGR line layer, any CRS; ``width_field`` or ``width_m`` per road).
    Needs scikit-learn."""
    try:
        import sklearn  # noqa: F401  (optional: checked here to say what is missing)
    except ImportError:
        raise GisroadsError("training a model needs scikit-learn: pip install scikit-learn"
                            ) from None
    if Path(out_path).suffix.lower() != ".npz":
        raise GisroadsError(f"{out_path}: a LiDAR model is written as .npz")
    roads = _map_lines(roads_path)
    if roads.crs is None:
        raise GisroadsError(f"{roads_path}: the road layer has no CRS; cannot place it on "
                            "the cloud")
    if width_field is not None and width_field not in roads.columns:
        raise GisroadsError(f"{roads_path}: no field {width_field!r}")
    if width_m <= 0 or guard_m < 0:
        raise GisroadsError("the width must be positive and the guard band at least 0 m")
    model = train_evidence_model(cloud_path, roads, width_field=width_field,
                                 default_width_m=width_m, guard_m=guard_m, seed=seed,
                                 tile_m=tile_m, overlap_m=overlap_m, cell_m=cell_m,
                                 progress=progress)
    with atomic_path(out_path) as tmp:
        save_evidence_model(model, tmp)
    meta = model.metadata
    return {"model": Path(out_path), "kind": meta["kind"], "road_cells": meta["road_cells"],
            "other_cells": meta["other_cells"], "cell_m": meta["cell_m"],
            "guard_m": meta["guard_m"], "trees": model.n_trees}


def evidence_job(cloud_path, out_path, *, cell_m: float | None = None,
                 tile_m: float = stage_default(evidence_raster, "tile_m"),
                 overlap_m: float = stage_default(evidence_raster, "overlap_m"),
                 progress: Progress = None) -> dict:
    """The road-evidence raster of a LAS/LAZ file (the ``evidence`` cue of ``gisroads
    lidar``) as a one-band GeoTIFF of road likelihood in [0, 1] (NaN outside the data), in
    the cloud's metre working CRS; see :func:`gisroads.lidar.pipeline.evidence_raster`."""
    likelihood, _, _, used, missing, _ = evidence_raster(
        cloud_path, cell_m=cell_m, tile_m=tile_m, overlap_m=overlap_m, progress=progress)
    if likelihood is None:
        raise GisroadsError(f"{cloud_path}: no tile holds enough points to image")
    write_geotiff(out_path, likelihood, band_names=["road_likelihood"])
    return {"raster": Path(out_path), "cell_m": likelihood.pixel_size,
            "cues": ",".join(used),
            "missing": "; ".join(f"{k}: {v}" for k, v in missing.items())}


def lidar_segmentation_job(intensity_path, segments_path, *, level: int = 0,
                           n_segments: int = stage_default(edges_and_segments, "n_segments"),
                           edges_path=None) -> dict:
    """Stage 3 on one level of an intensity GeoTIFF: local-energy edges and the NCut
    over-segmentation, as in :func:`gisroads.lidar.pipeline.extract_tile`.

    Writes ``segments_path`` (int32 labels, -1 = no data) and, when asked, ``edges_path``
    (bands ``magnitude`` and ``orientation_rad``).
    """
    image = _level_image(intensity_path, level)
    magnitude, orientation, labels = edges_and_segments(image.data, n_segments=n_segments)
    write_geotiff(segments_path, GeoRaster(labels.astype("int32"), image.transform, image.crs),
                  nodata=-1, band_names=["segment"])
    result = {"segments": Path(segments_path), "n_segments": int(labels.max()) + 1}
    if edges_path is not None:
        write_geotiff(edges_path, GeoRaster(np.stack([magnitude, orientation]).astype("float32"),
                                            image.transform, image.crs),
                      band_names=["magnitude", "orientation_rad"])
        result["edges"] = Path(edges_path)
    return result


def likelihood_job(intensity_path, segments_path, likelihood_path, hypotheses_path, *,
                   level: int = 0, widths_m=DEFAULT_WIDTHS_M, lengths_m=DEFAULT_LENGTHS_M,
                   t_bd: float = T_BD, t_int: float = T_INT, l_max: float = L_MAX,
                   progress: Progress = None) -> dict:
    """Stage 4: rectangle hypotheses of one level and their per-width likelihood maps.

    The edges are recomputed from the intensity (the same deterministic local energy as
    stage 3). ``widths_m``, ``lengths_m`` (metres, or their text: "6,9,12"), ``t_bd`` and
    ``t_int`` as in
    :func:`gisroads.lidar.hypotheses.road_hypotheses`, ``l_max`` as in its maps.
    Writes ``likelihood_path`` (one band per width) and ``hypotheses_path`` (GeoPackage,
    layer ``hypotheses``); no valid hypothesis gives zero maps, an empty layer and a
    :class:`~gisroads.errors.NoRoadFoundWarning`.
    """
    widths_m = (parse_metres(widths_m, "widths") if isinstance(widths_m, str)
                else tuple(widths_m))
    if isinstance(lengths_m, str):
        lengths_m = parse_metres(lengths_m, "lengths")
    image = _level_image(intensity_path, level)
    segments = read_raster(segments_path)
    if segments.data.shape[1:] != image.data.shape or segments.transform != image.transform:
        raise GisroadsError(f"{segments_path} is not on the grid of {intensity_path}")
    report(progress, 0.05, "edges")
    magnitude, orientation = local_energy(image.data)
    report(progress, 0.2, "hypotheses")
    hypotheses = road_hypotheses(image, magnitude, orientation, segments.data[0],
                                 widths_m=widths_m, lengths_m=lengths_m, t_bd=t_bd,
                                 t_int=t_int)
    report(progress, 0.8, "likelihood maps")
    maps = likelihood_maps(hypotheses, image, widths_m=widths_m, l_max=l_max)
    write_geotiff(likelihood_path, maps, band_names=[f"width_{w:g}_m" for w in widths_m])
    write_geopackage(hypotheses_path, {"hypotheses": hypotheses.assign(level=level)})
    _warn_if_empty(hypotheses, f"{intensity_path} (level {level})", "valid road hypothesis")
    report(progress, 1.0, "done")
    return {"likelihood": Path(likelihood_path), "hypotheses": Path(hypotheses_path),
            "n_hypotheses": len(hypotheses)}


def min_cover_job(hypotheses_path, likelihood_path, rectangles_path, *, exact: bool = False,
                  l_max: float = L_MAX, a: float = A, d_max: float = D_MAX,
                  seed_step_m: float = SEED_STEP_M, progress: Progress = None) -> dict:
    """Stage 5: the minimum cover of the hypotheses (greedy, or the exact integer program
    for small instances; ``d_max`` and ``progress`` are the greedy cover's).
    ``hypotheses_path`` is a file (its ``hypotheses`` layer) or a GeoDataFrame.
    Writes ``rectangles_path`` (GeoPackage, layer ``rectangles``); an empty cover gives an
    empty layer and a :class:`~gisroads.errors.NoRoadFoundWarning`."""
    hypotheses = _layer(hypotheses_path, "hypotheses")
    missing = {"hyp_id", "theta_rad", "width_index", "width_m"} - set(hypotheses.columns)
    if missing:
        raise GisroadsError(f"{hypotheses_path}: not a hypotheses layer "
                            f"(no {sorted(missing)})")
    likelihood = read_raster(likelihood_path)
    if hypotheses.width_index.max() >= likelihood.data.shape[0]:
        raise GisroadsError(f"{likelihood_path} has fewer width bands than the hypotheses "
                            "use")
    if exact:
        selected = exact_min_cover(hypotheses, likelihood, l_max=l_max, a=a,
                                   seed_step_m=seed_step_m)
    else:
        selected = greedy_min_cover(hypotheses, likelihood, l_max=l_max, a=a, d_max=d_max,
                                    seed_step_m=seed_step_m, progress=progress)
    write_geopackage(rectangles_path, {"rectangles": selected})
    _warn_if_empty(selected, hypotheses_path, "road rectangle")
    return {"rectangles": Path(rectangles_path), "n_rectangles": len(selected),
            "cover_cost": float(selected.attrs["cover_cost"])}


def rectangles_network_job(rectangles_path, out_path) -> dict:
    """Stage 6: road rectangles (a file's ``rectangles`` layer, any polygon layer or a
    GeoDataFrame with ``width_m`` and ``theta_rad``) to the road-network GeoPackage (centre
    lines, polygons, junctions, and the rectangles); no rectangle gives empty layers and a
    :class:`~gisroads.errors.NoRoadFoundWarning`."""
    rectangles = _layer(rectangles_path, "rectangles")
    missing = {"width_m", "theta_rad"} - set(rectangles.columns)
    if missing:
        raise GisroadsError(f"{rectangles_path}: the rectangles need fields "
                            f"{sorted(missing)}")
    network = rectangles_to_roads(rectangles)
    network.qa = {"rectangles": rectangles}
    write_geopackage(out_path, network.layers())
    _warn_if_no_road(network, rectangles_path)
    return network_summary(out_path, network)


def tag_job(cloud_path, polygons_path, out_path, *, heights_path=None,
            tolerance_m: float = stage_default(tag_road_points, "tolerance_m")) -> dict:
    """Classify the road points of a cloud (class 11) from road polygons with a ``level``
    column (level 0 where it is missing), level by level.

    The per-level ground heights come from the LiDAR pipeline's ``ground_heights.tif``
    (``heights_path``, in the cloud's metre working CRS) or, without it, from the cloud's
    own ground planes (:func:`gisroads.lidar.tagging.ground_level_heights`: the whole cloud
    in memory), e.g. for ribbon-snake polygons. Polygons in any CRS are reprojected to the
    cloud's. Without polygons the cloud is copied with no point tagged, with a
    :class:`~gisroads.errors.NoRoadFoundWarning`.
    """
    working, _ = cloud_crs(cloud_path)
    polygons = read_layer(polygons_path, POLYGONS if str(polygons_path).endswith(".gpkg")
                          and POLYGONS in list_layers(polygons_path) else None)
    if working is not None and polygons.crs is not None:
        polygons = polygons.to_crs(working)
    if len(polygons) == 0:
        warnings.warn(f"no road polygon in {polygons_path}; wrote the cloud with no point "
                      "tagged", NoRoadFoundWarning, stacklevel=2)
        heights = None  # without polygons no point is looked up in them
    else:
        heights = (read_raster(heights_path) if heights_path is not None
                   else ground_level_heights(read_las(cloud_path)))
    tagged = tag_road_points(cloud_path, out_path, polygons, heights, tolerance_m=tolerance_m)
    return {"tagged_las": Path(out_path), "tagged_points": tagged}


def blocks_job(likelihood_path, out_path, options: BlockOptions = BlockOptions(), *,
               points_path=None, quicklook=None, progress: Progress = None,
               **changes) -> dict:
    """City blocks (Zhu & Mordohai, section 5) of a road-likelihood raster into a GeoPackage.

    ``likelihood_path``: a ``*_likelihood_level_*.tif`` of ``gisroads lidar --rasters`` or
    any single-band road-probability raster (see :func:`gisroads.lidar.blocks.road_likelihood`).
    ``points_path``: a LAS/LAZ whose ground points (class 2; every point when the file has
    none) are the graph's nodes, streamed and thinned chunk by chunk, reprojected to the
    raster's CRS. Writes the ``city_blocks`` layer to ``out_path`` and optionally a
    ``quicklook`` PNG of the blocks over the likelihood. ``options`` (and ``**changes`` to
    its fields) are those of :func:`gisroads.lidar.blocks.city_blocks`.
    """
    options = replace(options, **changes)
    raster = read_raster(likelihood_path)
    points = None
    if points_path is not None:
        points = _ground_points_xy(points_path, raster.crs, options.sample_spacing_m)
    blocks = city_blocks(raster, options, points_xy=points,
                         progress=scaled(progress, 0.0, 0.9))
    if len(blocks) == 0:
        raise GisroadsError(f"{likelihood_path}: no city block of the minimum area was "
                            "found")
    write_geopackage(out_path, {"city_blocks": blocks})
    result = {"gpkg": Path(out_path), "blocks": len(blocks),
              "segments": int(blocks.segment.nunique()),
              "area_m2": float(blocks.area_m2.sum())}
    if quicklook is not None:
        band = road_likelihood(raster, l_max=options.l_max, probability=options.probability)
        write_quicklook(quicklook, [
            (blocks, dict(column="block_id", cmap="tab20", alpha=0.45, edgecolor="black",
                          linewidth=0.8)),
        ], background=band, title=f"{Path(likelihood_path).name}: {len(blocks)} city blocks")
        result["quicklook"] = Path(quicklook)
    report(progress, 1.0, "done")
    return result


def _ground_points_xy(cloud_path, crs, spacing_m: float):
    """Ground points of a cloud (class 2, or all points when none is), thinned to one per
    half node spacing per chunk, in ``crs``."""
    ground, every = [], []
    for chunk in iter_las_chunks(cloud_path):
        xy = chunk.xyz[:, :2]
        if chunk.crs is not None and crs is not None and chunk.crs != crs:
            xy = np.column_stack(Transformer.from_crs(chunk.crs, crs, always_xy=True)
                                 .transform(xy[:, 0], xy[:, 1]))
        ground.append(thin_points(xy[chunk.classification == GROUND_CLASS], spacing_m / 2))
        every.append(thin_points(xy, spacing_m / 2))
    ground = np.concatenate(ground)
    return ground if len(ground) else np.concatenate(every)
