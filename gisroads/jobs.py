"""Whole jobs, composed from the stages: what the CLI subcommands and the QGIS algorithms run.

Each job reads files, calls pure stages, and writes its outputs through temporary files.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import geopandas as gpd
import numpy as np
import shapely

from .errors import NoRoadFoundWarning
from .evaluate import evaluate_network, match_layers
from .geo import CENTRELINES, POLYGONS, GeoRaster, RoadNetwork
from .io.las import cloud_crs, las_info, read_las
from .io.quicklook import write_quicklook
from .io.raster import raster_info, read_raster, write_geotiff
from .io.vector import layer_geometry_types, list_layers, read_layer, write_geopackage
from .progress import Progress, report, scaled, to_json
from .resources import demo_dir
from .synthetic import make_scene, render_image, write_cloud

VECTOR_SUFFIXES = {".gpkg", ".geojson", ".json", ".shp", ".fgb", ".kml", ".gml"}


def parse_metres(text: str, name: str = "value") -> tuple[float, ...]:
    """Positive metres from a comma- (or semicolon-) separated list, e.g. ``"6,9,12"``."""
    try:
        values = tuple(float(v) for v in text.replace(";", ",").split(",") if v.strip())
    except ValueError:
        raise ValueError(f"{name}: {text!r} is not a comma-separated list of metres") from None
    if not values or min(values) <= 0:
        raise ValueError(f"{name}: give positive metres, e.g. 6,9,12")
    return values


def _plain(value):
    """``value`` with numpy scalars and arrays as Python numbers and lists (JSON and text
    show ``636001.76``, not ``np.float64(636001.76)``)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def describe_file(path) -> dict:
    """Header facts of a LAS/LAZ, raster or vector file (see ``gisroads info``).

    Plain Python values throughout. A GeoPackage layer's ``geometry`` is the types of its
    features, or for an empty layer the type the file declares for it; a raster without
    georeferencing has ``georeferenced`` False and no ``extent`` or ``pixel_size``.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in {".las", ".laz"}:
        return _plain({"kind": "point cloud", **las_info(path)})
    if suffix in VECTOR_SUFFIXES:
        names = list_layers(path) if suffix == ".gpkg" else [None]
        declared = layer_geometry_types(path) if suffix == ".gpkg" else {}
        layers = []
        for name in names:
            frame = read_layer(path, name)
            found = sorted(set(frame.geom_type.dropna()))
            layers.append({"layer": name or path.stem, "features": len(frame),
                           "geometry": found or ([declared[name]] if name in declared
                                                 else []),
                           "crs": frame.crs.name if frame.crs else None,
                           "epsg": frame.crs.to_epsg() if frame.crs else None,
                           "extent": [float(v) for v in frame.total_bounds] if len(frame)
                           else None})
        return _plain({"kind": "vector", "path": str(path), "layers": layers})
    return _plain({"kind": "raster", **raster_info(path)})


def _warn_if_empty(frame: gpd.GeoDataFrame, source, found: str = "road", *,
                   stacklevel: int = 3) -> None:
    """Warn that a job found no ``found`` in ``source`` (a file, or a layer given as a
    GeoDataFrame) when ``frame`` is empty, and wrote empty layers: a valid answer, for a
    forest plot or a field."""
    if len(frame) == 0:
        where = "the input layer" if isinstance(source, gpd.GeoDataFrame) else source
        warnings.warn(f"no {found} found in {where}; wrote empty layers",
                      NoRoadFoundWarning, stacklevel=stacklevel)


def _warn_if_no_road(network: RoadNetwork, source) -> None:
    """Warn that a job found no road in ``source`` and wrote empty layers."""
    _warn_if_empty(network.centrelines, source, stacklevel=4)


def synth_job(out_dir, *, size_m=(400.0, 400.0), seed: int = 0, density_per_m2: float = 10.0,
              pixel_m: float = 0.25, cloud: bool = True, image: bool = True,
              progress: Progress = None) -> dict[str, Path]:
    """Write a synthetic scene and its exact truth.

    Outputs in ``out_dir``: ``truth.gpkg`` (road_centrelines, road_polygons, junctions and
    the scene's objects), ``cloud.laz`` (airborne point cloud), ``image.tif`` (R, G, B, NIR)
    and ``dsm.tif``.

    Parameters
    ----------
    size_m : (float, float)
        Scene width and height in metres.
    density_per_m2 : float
        Point density of the cloud (points per square metre).
    pixel_m : float
        Orthoimage and DSM pixel size in metres.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report(progress, 0.0, "laying out the scene")
    scene = make_scene(seed=seed, size_m=tuple(size_m))
    paths = {"truth": write_geopackage(out / "truth.gpkg",
                                       {**scene.truth.layers(), **scene.object_layers()})}
    report(progress, 0.05, "truth written")
    if cloud:
        path = out / "cloud.laz"
        write_cloud(scene, path, density_per_m2=density_per_m2, seed=seed,
                    progress=scaled(progress, 0.05, 0.8 if image else 1.0))
        paths["cloud"] = path
    if image:
        report(progress, 0.8 if cloud else 0.05, "rendering the orthoimage and DSM")
        ortho, dsm = render_image(scene, pixel_m=pixel_m, seed=seed)
        paths["image"] = write_geotiff(out / "image.tif", ortho,
                                       band_names=["red", "green", "blue", "nir"])
        paths["dsm"] = write_geotiff(out / "dsm.tif", dsm, band_names=["dsm_m"])
    report(progress, 1.0, "done")
    return paths


def _read_polygons(path) -> gpd.GeoDataFrame | None:
    path = Path(path)
    if path.suffix.lower() == ".gpkg" and POLYGONS in list_layers(path):
        return read_layer(path, POLYGONS)
    return None


def evaluate_job(extracted, reference, *, buffer_m: float = 3.0, cell_m: float = 0.5,
                 junction_radius_m: float = 10.0, extracted_polygons=None,
                 reference_polygons=None, valid_area=None, qa_path=None,
                 progress: Progress = None) -> dict:
    """Score an extracted road network against a reference, from files.

    Centre lines come from the ``road_centrelines`` layer of a GeoPackage (else its first
    layer) or from any line file; road areas from the ``road_polygons`` layers of both
    GeoPackages or from the files given. ``qa_path`` receives the matched/unmatched pieces
    (``eval_extracted``, ``eval_reference``) as a styled GeoPackage.

    Returns
    -------
    dict
        The figures of :func:`gisroads.evaluate.evaluate_network`.
    """
    report(progress, 0.0, "reading")
    extracted_lines = read_layer(extracted)
    reference_lines = read_layer(reference)
    if len(reference_lines) == 0:
        raise ValueError(f"{reference}: the reference holds no road")
    predicted = (read_layer(extracted_polygons) if extracted_polygons
                 else _read_polygons(extracted))
    truth = read_layer(reference_polygons) if reference_polygons else _read_polygons(reference)
    valid = read_layer(valid_area) if valid_area else None
    report(progress, 0.1, "scoring")
    results = evaluate_network(extracted_lines, reference_lines, buffer_m=buffer_m,
                               cell_m=cell_m, junction_radius_m=junction_radius_m,
                               valid_area=valid, extracted_polygons=predicted,
                               reference_polygons=truth)
    if qa_path is not None:
        report(progress, 0.9, "writing the QA layers")
        write_geopackage(qa_path, match_layers(extracted_lines, reference_lines,
                                               buffer_m=buffer_m, valid_area=valid))
    report(progress, 1.0, "done")
    return results


def lidar_job(cloud_path, out_path, *, tagged_las=None, rasters_dir=None,
              quicklook=None, progress: Progress = None, **options) -> dict:
    """The road network of a LAS/LAZ file into a road-network GeoPackage.

    Writes ``out_path`` (road_centrelines, road_polygons, junctions, and the QA layers of
    the cue: rectangles and hypotheses, or gap_edges, junction_connections and rejected)
    in the cloud's CRS; optionally ``tagged_las`` (the cloud with road points in class 11),
    ``rasters_dir`` (per-level intensity and likelihood GeoTIFFs of every tile and the
    per-level ground heights, or ``road_evidence.tif``) and a ``quicklook`` PNG.
    ``options`` go to :func:`gisroads.lidar.pipeline.extract_roads` (``workers``,
    ``scheduler`` and ``work_dir`` included); ``cloud_path`` may also be several files, a
    folder of them or a glob. A cloud without roads gives empty layers and a
    :class:`~gisroads.errors.NoRoadFoundWarning`.

    Returns
    -------
    dict
        Output paths and counts.
    """
    from .lidar.pipeline import DEFAULT_WIDTHS_M, extract_roads, mosaic_cores
    from .lidar.tagging import ground_level_heights, tag_road_points
    from .lidar.tilestore import inputs_crs, las_inputs

    # one file, several, a folder or a glob (extract_roads); tagging copies one file
    inputs = las_inputs(cloud_path)
    if tagged_las is not None and len(inputs) > 1:
        raise ValueError(f"a tagged LAS/LAZ copy is made of one input file, not of "
                         f"{len(inputs)}: tag each file on its own")
    cloud_path = inputs[0] if len(inputs) == 1 else cloud_path
    # the per-width likelihood maps of every tile are kept only to be written
    options.setdefault("tile_maps", rasters_dir is not None)
    roads = extract_roads(cloud_path, progress=scaled(progress, 0.0, 0.85), **options)
    network = roads.network
    write_geopackage(out_path, network.layers())
    _warn_if_no_road(network, cloud_path)
    working, _ = inputs_crs(inputs)
    result = {"gpkg": Path(out_path), "roads": len(network.centrelines),
              "length_m": float(network.centrelines.length_m.sum()),
              "junctions": len(network.junctions), "tiles": len(roads.tiles),
              "cue": options.get("cue", "intensity"), "input_files": len(inputs),
              "tiles_run": roads.run.get("tiles", 0),
              "tiles_reused": roads.run.get("reused", 0)}
    if roads.cues:
        result["cues"] = ",".join(roads.cues)
    # tiles with a ground level to image (a tile of a few metres may have none)
    imaged = [t for t in roads.tiles if len(t.intensity.data)]
    if rasters_dir is not None:
        report(progress, 0.86, "writing rasters")
        rasters = Path(rasters_dir)
        rasters.mkdir(parents=True, exist_ok=True)
        for tile in imaged:
            name = f"tile_r{tile.tile.row}_c{tile.tile.col}"
            levels = [f"level_{k}" for k in range(tile.intensity.data.shape[0])]
            write_geotiff(rasters / f"{name}_intensity.tif", tile.intensity, band_names=levels)
            for k, maps in enumerate(tile.likelihood):
                write_geotiff(rasters / f"{name}_likelihood_level_{k}.tif", maps,
                              band_names=[f"width_{w:g}_m" for w in options.get(
                                  "widths_m", DEFAULT_WIDTHS_M)])
        if imaged:
            write_geotiff(rasters / "ground_heights.tif", roads.heights, band_names=[
                f"level_{k}" for k in range(roads.heights.data.shape[0])])
        if roads.evidence is not None:
            write_geotiff(rasters / "road_evidence.tif", roads.evidence,
                          band_names=["road_likelihood"])
        result["rasters"] = rasters
    if tagged_las is not None:
        report(progress, 0.9, "tagging road points")
        # the evidence cue images one surface: its heights come from the cloud's planes
        heights = (roads.heights if roads.heights is not None
                   else ground_level_heights(read_las(cloud_path)))
        result["tagged_points"] = tag_road_points(cloud_path, tagged_las,
                                                  network.polygons.to_crs(working), heights)
        result["tagged_las"] = Path(tagged_las)
    if quicklook is not None:
        report(progress, 0.97, "drawing the quick-look")
        background = None
        if imaged:
            intensity = mosaic_cores([(t.tile, t.intensity) for t in imaged],
                                     imaged[0].intensity.pixel_size)
            background = GeoRaster(intensity.data[0], intensity.transform, working)
        elif roads.evidence is not None:
            background = roads.evidence
        # the QA layer of the cue: the selected rectangles, or the bridged gaps
        qa = (network.qa["rectangles"] if "rectangles" in network.qa
              else network.qa["gap_edges"].query("selected"))
        write_quicklook(quicklook, [
            (qa.to_crs(working), dict(facecolor="none", edgecolor="cyan", linewidth=0.6)
             if "rectangles" in network.qa else dict(color="cyan", linewidth=2)),
            (network.centrelines.to_crs(working),
             dict(color="red", linewidth=1.5, label="road centre lines")),
            (network.junctions.to_crs(working),
             dict(color="yellow", markersize=20, label="junctions")),
        ], background=background,
            title=f"{Path(str(cloud_path)).name}: roads over the "
                  + ("road evidence" if roads.evidence is not None
                     else "ground intensity (level 0)"))
        result["quicklook"] = Path(quicklook)
    report(progress, 1.0, "done")
    return result


def _layer(source, layer: str) -> gpd.GeoDataFrame:
    """A GeoDataFrame as given, or layer ``layer`` of a file (its only layer otherwise)."""
    if isinstance(source, gpd.GeoDataFrame):
        return source
    return read_layer(source, layer if layer in list_layers(source) else None)


def _level_image(intensity_path, level: int) -> GeoRaster:
    raster = read_raster(intensity_path)
    if not 0 <= level < raster.data.shape[0]:
        raise ValueError(f"{intensity_path}: no level {level} (it has "
                         f"{raster.data.shape[0]} band(s), levels 0..{raster.data.shape[0] - 1})")
    return GeoRaster(raster.data[level].astype("float32"), raster.transform, raster.crs,
                     raster.nodata)


def ground_intensity_job(cloud_path, intensity_path, *, heights_path=None, cell_m=None,
                         t_planar: float = 0.01, t_vert: float = 0.98,
                         progress: Progress = None) -> dict:
    """Stages 1-2 of the LiDAR method on a whole file: ground levels, intensity images.

    Writes ``intensity_path`` (one band per ground level, in [0, 1], NaN where no ground),
    ``<stem>_level_index.tif`` beside it and the per-level ground heights (``heights_path``,
    default ``<stem>_ground_heights.tif`` beside it), in the cloud's metre working CRS. The
    grid is the one :func:`gisroads.lidar.pipeline.extract_tile` uses over the same bounds.
    The whole cloud is held in memory: for large files run the tiled pipeline.
    """
    from .lidar.ground import ground_planes
    from .lidar.intensity import write_intensity_images
    from .lidar.pipeline import auto_cell_m, ground_and_intensity

    cloud = read_las(cloud_path)
    if cloud.intensity is None:
        raise ValueError(f"{cloud_path}: the point cloud records no intensity")
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


def evidence_job(cloud_path, out_path, *, cell_m: float | None = None,
                 tile_m: float = 300.0, overlap_m: float = 100.0,
                 progress: Progress = None) -> dict:
    """The road-evidence raster of a LAS/LAZ file (the ``evidence`` cue of ``gisroads
    lidar``) as a one-band GeoTIFF of road likelihood in [0, 1] (NaN outside the data), in
    the cloud's metre working CRS; see :func:`gisroads.lidar.pipeline.evidence_raster`."""
    from .lidar.pipeline import evidence_raster

    likelihood, _, used, missing = evidence_raster(cloud_path, cell_m=cell_m, tile_m=tile_m,
                                                overlap_m=overlap_m, progress=progress)
    if likelihood is None:
        raise ValueError(f"{cloud_path}: no tile holds enough points to image")
    write_geotiff(out_path, likelihood, band_names=["road_likelihood"])
    return {"raster": Path(out_path), "cell_m": likelihood.pixel_size,
            "cues": ",".join(used),
            "missing": "; ".join(f"{k}: {v}" for k, v in missing.items())}


def lidar_segmentation_job(intensity_path, segments_path, *, level: int = 0,
                           n_segments: int = 150, edges_path=None) -> dict:
    """Stage 3 on one level of an intensity GeoTIFF: local-energy edges and the NCut
    over-segmentation, as in :func:`gisroads.lidar.pipeline.extract_tile`.

    Writes ``segments_path`` (int32 labels, -1 = no data) and, when asked, ``edges_path``
    (bands ``magnitude`` and ``orientation_rad``).
    """
    from .lidar.pipeline import edges_and_segments

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
                   level: int = 0, progress: Progress = None, **options) -> dict:
    """Stage 4: rectangle hypotheses of one level and their per-width likelihood maps.

    The edges are recomputed from the intensity (the same deterministic local energy as
    stage 3). ``options`` go to :func:`gisroads.lidar.hypotheses.road_hypotheses`
    (``widths_m``, ``lengths_m``, ``t_bd``, ``t_int``, ...) and ``l_max`` to the maps.
    Writes ``likelihood_path`` (one band per width) and ``hypotheses_path`` (GeoPackage,
    layer ``hypotheses``); no valid hypothesis gives zero maps, an empty layer and a
    :class:`~gisroads.errors.NoRoadFoundWarning`.
    """
    from .features.edges import local_energy
    from .lidar.hypotheses import DEFAULT_WIDTHS_M, L_MAX, likelihood_maps, road_hypotheses

    image = _level_image(intensity_path, level)
    segments = read_raster(segments_path)
    if segments.data.shape[1:] != image.data.shape or segments.transform != image.transform:
        raise ValueError(f"{segments_path} is not on the grid of {intensity_path}")
    l_max = options.pop("l_max", L_MAX)
    widths_m = tuple(options.get("widths_m", DEFAULT_WIDTHS_M))
    report(progress, 0.05, "edges")
    magnitude, orientation = local_energy(image.data)
    report(progress, 0.2, "hypotheses")
    hypotheses = road_hypotheses(image, magnitude, orientation, segments.data[0], **options)
    report(progress, 0.8, "likelihood maps")
    maps = likelihood_maps(hypotheses, image, widths_m=widths_m, l_max=l_max)
    write_geotiff(likelihood_path, maps, band_names=[f"width_{w:g}_m" for w in widths_m])
    write_geopackage(hypotheses_path, {"hypotheses": hypotheses.assign(level=level)})
    _warn_if_empty(hypotheses, f"{intensity_path} (level {level})", "valid road hypothesis")
    report(progress, 1.0, "done")
    return {"likelihood": Path(likelihood_path), "hypotheses": Path(hypotheses_path),
            "n_hypotheses": len(hypotheses)}


def min_cover_job(hypotheses_path, likelihood_path, rectangles_path, *, exact: bool = False,
                  progress: Progress = None, **options) -> dict:
    """Stage 5: the minimum cover of the hypotheses (greedy, or the exact integer program
    for small instances). ``hypotheses_path`` is a file (its ``hypotheses`` layer) or a
    GeoDataFrame. ``options``: ``l_max``, ``a``, ``d_max`` (greedy only), ``seed_step_m``.
    Writes ``rectangles_path`` (GeoPackage, layer ``rectangles``); an empty cover gives an
    empty layer and a :class:`~gisroads.errors.NoRoadFoundWarning`."""
    from .lidar.hypotheses import L_MAX
    from .lidar.mincover import exact_min_cover, greedy_min_cover

    hypotheses = _layer(hypotheses_path, "hypotheses")
    missing = {"hyp_id", "theta_rad", "width_index", "width_m"} - set(hypotheses.columns)
    if missing:
        raise ValueError(f"{hypotheses_path}: not a hypotheses layer (no {sorted(missing)})")
    likelihood = read_raster(likelihood_path)
    if hypotheses.width_index.max() >= likelihood.data.shape[0]:
        raise ValueError(f"{likelihood_path} has fewer width bands than the hypotheses use")
    options.setdefault("l_max", L_MAX)
    if exact:
        options.pop("d_max", None)
        selected = exact_min_cover(hypotheses, likelihood, **options)
    else:
        selected = greedy_min_cover(hypotheses, likelihood, progress=progress, **options)
    write_geopackage(rectangles_path, {"rectangles": selected})
    _warn_if_empty(selected, hypotheses_path, "road rectangle")
    return {"rectangles": Path(rectangles_path), "n_rectangles": len(selected),
            "cover_cost": float(selected.attrs["cover_cost"])}


def rectangles_network_job(rectangles_path, out_path) -> dict:
    """Stage 6: road rectangles (a file's ``rectangles`` layer, any polygon layer or a
    GeoDataFrame with ``width_m`` and ``theta_rad``) to the road-network GeoPackage (centre
    lines, polygons, junctions, and the rectangles); no rectangle gives empty layers and a
    :class:`~gisroads.errors.NoRoadFoundWarning`."""
    from .vectorize.ribbons import rectangles_to_network

    rectangles = _layer(rectangles_path, "rectangles")
    missing = {"width_m", "theta_rad"} - set(rectangles.columns)
    if missing:
        raise ValueError(f"{rectangles_path}: the rectangles need fields {sorted(missing)}")
    network = rectangles_to_network(rectangles)
    network.qa = {"rectangles": rectangles}
    write_geopackage(out_path, network.layers())
    _warn_if_no_road(network, rectangles_path)
    return {"gpkg": Path(out_path), "roads": len(network.centrelines),
            "length_m": float(network.centrelines.length_m.sum()),
            "junctions": len(network.junctions)}


def tag_job(cloud_path, polygons_path, out_path, *, heights_path=None,
            tolerance_m: float = 0.3) -> dict:
    """Classify the road points of a cloud (class 11) from road polygons with a ``level``
    column (level 0 where it is missing), level by level.

    The per-level ground heights come from the LiDAR pipeline's ``ground_heights.tif``
    (``heights_path``, in the cloud's metre working CRS) or, without it, from the cloud's
    own ground planes (:func:`gisroads.lidar.tagging.ground_level_heights`: the whole cloud
    in memory), e.g. for ribbon-snake polygons. Polygons in any CRS are reprojected to the
    cloud's. Without polygons the cloud is copied with no point tagged, with a
    :class:`~gisroads.errors.NoRoadFoundWarning`.
    """
    from .lidar.tagging import ground_level_heights, tag_road_points

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


def blocks_job(likelihood_path, out_path, *, points_path=None, quicklook=None,
               progress: Progress = None, **options) -> dict:
    """City blocks (Zhu & Mordohai, section 5) of a road-likelihood raster into a GeoPackage.

    ``likelihood_path``: a ``*_likelihood_level_*.tif`` of ``gisroads lidar --rasters`` or
    any single-band road-probability raster (see :func:`gisroads.blocks.road_likelihood`).
    ``points_path``: a LAS/LAZ whose ground points (class 2; every point when the file has
    none) are the graph's nodes, streamed and thinned chunk by chunk, reprojected to the
    raster's CRS. Writes the ``city_blocks`` layer to ``out_path`` and optionally a
    ``quicklook`` PNG of the blocks over the likelihood. ``options`` go to
    :func:`gisroads.blocks.city_blocks`.
    """
    from .blocks import SAMPLE_SPACING_M, city_blocks, road_likelihood

    raster = read_raster(likelihood_path)
    points = None
    if points_path is not None:
        points = _ground_points_xy(points_path, raster.crs,
                                   options.get("sample_spacing_m", SAMPLE_SPACING_M))
    blocks = city_blocks(raster, points_xy=points, progress=scaled(progress, 0.0, 0.9),
                         **options)
    if len(blocks) == 0:
        raise ValueError(f"{likelihood_path}: no city block of the minimum area was found")
    write_geopackage(out_path, {"city_blocks": blocks})
    result = {"gpkg": Path(out_path), "blocks": len(blocks),
              "segments": int(blocks.segment.nunique()),
              "area_m2": float(blocks.area_m2.sum())}
    if quicklook is not None:
        band = road_likelihood(raster, **{k: options[k] for k in ("l_max", "probability")
                                          if k in options})
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
    import numpy as np
    from pyproj import Transformer

    from .blocks import thin_points
    from .io.las import iter_las_chunks

    ground, every = [], []
    for chunk in iter_las_chunks(cloud_path):
        xy = chunk.xyz[:, :2]
        if chunk.crs is not None and crs is not None and chunk.crs != crs:
            xy = np.column_stack(Transformer.from_crs(chunk.crs, crs, always_xy=True)
                                 .transform(xy[:, 0], xy[:, 1]))
        ground.append(thin_points(xy[chunk.classification == 2], spacing_m / 2))
        every.append(thin_points(xy, spacing_m / 2))
    ground = np.concatenate(ground)
    return ground if len(ground) else np.concatenate(every)


def register_job(cloud_path, map_source, out_path, *, progress: Progress = None,
                 **options) -> dict:
    """Register a 2D road map onto a LAS/LAZ cloud (Boyko & Funkhouser, section 2.1).

    ``map_source``: a line file (a GeoPackage's road_centrelines layer, else its first;
    GeoJSON, any OGR format) or a GeoDataFrame, in any CRS: reprojected to the cloud's.
    Only the points near the map's lines are read, chunk by chunk. Writes the
    ``registered_map`` layer (LineString Z, elevations in metres) to ``out_path`` in the
    cloud's CRS. ``options`` go to :func:`gisroads.snakes.registration.register_map`.
    """
    import shapely

    from .io.las import cloud_crs
    from .snakes.registration import SNAP_M, SUPPORT_RADIUS_M, register_map
    from .snakes.subclouds import read_corridor

    working, source_crs = cloud_crs(cloud_path)
    lines = map_source if isinstance(map_source, gpd.GeoDataFrame) else read_layer(map_source)
    lines = lines[lines.geometry.notna() & ~lines.geometry.is_empty]
    if len(lines) == 0:
        raise ValueError(f"{map_source}: the map holds no line")
    if working is not None:
        if lines.crs is None:
            raise ValueError(f"{map_source}: the map has no CRS; cannot match it to the cloud")
        lines = lines.to_crs(working)
    report(progress, 0.0, "reading the points along the map")
    # Intersections move line ends by up to the snapping tolerance: read that much wider.
    reach = (options.get("support_radius_m", SUPPORT_RADIUS_M)
             + options.get("snap_m", SNAP_M) + 0.5)
    along = shapely.get_coordinates(shapely.segmentize(lines.geometry.values, 0.5))
    cloud, _ = read_corridor(cloud_path, along, reach)
    if len(cloud) == 0:
        raise ValueError(f"{cloud_path}: no point lies along the map's lines; "
                         "does the map cover the cloud?")
    registered = register_map(lines, cloud, progress=scaled(progress, 0.5, 0.95), **options)
    out = registered.lines
    if source_crs is not None and working is not None and source_crs != working:
        out = out.to_crs(source_crs)
    write_geopackage(out_path, {"registered_map": out})
    report(progress, 1.0, "done")
    return {"gpkg": Path(out_path), "roads": len(out),
            "length_m": float(out["length_m"].sum()),
            "intersections": len(registered.intersections),
            "seen_fraction": float(registered.seen.mean()),
            "points_read": len(cloud)}


def read_image(path, *, pixel_m: float | None = None, crs=None) -> tuple[GeoRaster, object]:
    """An aerial image in a metre CRS, and the CRS its results go back to.

    A projected GeoTIFF is read as it is; a geographic one (EPSG:4326, as SpaceNet ships) is
    warped to its UTM zone at its own ground resolution; an image without georeferencing
    (PNG, JPEG) needs ``pixel_m`` and a projected ``crs``.
    """
    from .imagery.datasets import warp_to_utm

    raster = read_raster(path, pixel_size=pixel_m, crs=crs)
    if raster.crs is None or not raster.crs.is_geographic:
        return raster, raster.crs
    rows, cols = raster.shape
    (west, south, east, north) = raster.bounds
    lat = np.radians((south + north) / 2.0)
    metres_per_pixel = np.sqrt((east - west) / cols * 111_320.0 * np.cos(lat)
                               * (north - south) / rows * 110_540.0)
    warped, _ = warp_to_utm(path, round(float(metres_per_pixel), 2),
                            nodata=raster.nodata if raster.nodata is not None else 0)
    return warped, raster.crs


def train_job(image_path, roads_path, out_path, *, width_field: str | None = None,
              width_m: float = 6.0, guard_m: float = 5.0, pixel_m: float | None = None,
              crs=None, samples: int = 100_000, seed: int = 0,
              progress: Progress = None) -> dict:
    """Train a road model on an image from a road layer over it (the agency's update case).

    Roads (any OGR line layer or a GeoDataFrame, any CRS; a gisroads GeoPackage's
    road_centrelines) are
    rasterised at their width (``width_field``, metres; empty or missing values and layers
    without the field take ``width_m``): positives in the core half of each road, negatives
    beyond ``width / 2 + guard_m`` (misregistered lines), calibrated to the image's road
    share (:func:`gisroads.learn.train_from_layer`). Writes the model archive ``out_path``
    (.npz), to give to ``image_job(..., model=out_path)``. Needs scikit-learn.
    """
    from .learn.model import save_model, with_metadata
    from .learn.training import train_from_layer

    image, _ = read_image(image_path, pixel_m=pixel_m, crs=crs)
    roads = _map_lines(roads_path)
    if roads.crs is None and image.crs is not None:
        raise ValueError(f"{roads_path}: the road layer has no CRS; cannot place it on the "
                         "image")
    if width_field is not None and width_field not in roads.columns:
        raise ValueError(f"{roads_path}: no field {width_field!r} (fields: "
                         f"{', '.join(c for c in roads.columns if c != 'geometry')})")
    if width_m <= 0 or guard_m < 0:
        raise ValueError("the width must be positive and the guard band at least 0 m")
    try:
        import sklearn  # noqa: F401
    except ImportError:
        raise ValueError("training needs scikit-learn (pip install scikit-learn, or the "
                         "python3-sklearn package)") from None
    report(progress, 0.0, "sampling the image along the roads")
    model = train_from_layer(image, roads, width_field=width_field, default_width_m=width_m,
                             guard_m=guard_m, samples=samples, seed=seed, road_share="layer",
                             progress=scaled(progress, 0.05, 0.95))
    model = with_metadata(model, image=Path(image_path).name, width_field=width_field,
                          roads=(Path(roads_path).name if not isinstance(
                              roads_path, gpd.GeoDataFrame) else "layer"))
    path = save_model(model, out_path)
    report(progress, 1.0, "done")
    return {"model": path, "samples": model.metadata["samples"],
            "trees": len(model.roots), "road_share": model.metadata["calibrated_road_share"],
            "roads": len(roads)}


def image_job(image_path, out_path, *, nir_band: int | None = None,
              red_band: int | None = None, dsm_path=None, pixel_m: float | None = None,
              crs=None, quicklook=None, model="default", probability_path=None,
              progress: Progress = None, **options) -> dict:
    """Road extraction of an aerial image into a GeoPackage: Grote & Rottensteiner's stages
    with a learned road cue (see :func:`gisroads.imagery.pipeline.extract_image_roads`).

    Writes ``out_path`` with road_centrelines (width_m, and ``cues``: which of rgb/cir/pan,
    nir, dsm and model were used), road_polygons, junctions and the QA layers (segments,
    road_parts, gap_edges and junction_connections for the papers' stages), in the image's
    CRS; optionally a ``quicklook`` PNG and ``probability_path``, the learned road
    probability as a float32 GeoTIFF (band ``road_probability``, 0-1, NaN no data) on the
    grid the image was worked on (its UTM zone for a geographic image). ``model``:
    ``"default"``, a model file of :func:`train_job`, or ``"none"`` (the papers' pipeline
    alone). ``options`` go to :func:`gisroads.imagery.pipeline.extract_image_roads`. An
    image without roads gives empty layers and a
    :class:`~gisroads.errors.NoRoadFoundWarning`.
    """
    from .imagery.pipeline import extract_image_roads, resolve_model

    image, source_crs = read_image(image_path, pixel_m=pixel_m, crs=crs)
    band_count = image.data.shape[0] if image.data.ndim == 3 else 1
    for name, band in (("NIR", nir_band), ("red", red_band)):
        if band is not None and not 1 <= band <= band_count:
            raise ValueError(f"{image_path}: no {name} band {band} (the image has "
                             f"{band_count} band(s))")
    model = resolve_model(model)
    if probability_path is not None and model is None:
        raise ValueError("a road probability raster needs a model (not --model none)")
    dsm = read_raster(dsm_path) if dsm_path is not None else None
    roads = extract_image_roads(image, nir_band=nir_band, red_band=red_band, dsm=dsm,
                                model=model, progress=scaled(progress, 0.0, 0.95), **options)
    network = roads.network
    _write_network(out_path, network, image.crs, source_crs, image_path)
    result = {"gpkg": Path(out_path), "roads": len(network.centrelines),
              "length_m": float(network.centrelines.length_m.sum()),
              "junctions": len(network.junctions), "cues": roads.report["cues"]["cues"],
              "method": roads.report["method"], "timings_s": roads.report["timings_s"]}
    if probability_path is not None:
        result["probability"] = write_geotiff(probability_path, roads.report["probability"],
                                              band_names=["road_probability"])
    if quicklook is not None:
        report(progress, 0.97, "drawing the quick-look")
        parts = network.qa.get("road_parts", network.qa.get("rejected"))
        result["quicklook"] = _network_quicklook(
            quicklook, network, (parts, dict(color="orange", linewidth=1, label="road parts")),
            background=image,
            title=f"{Path(image_path).name}: {result['roads']} roads ({result['cues']})")
    report(progress, 1.0, "done")
    return result


def _write_network(out_path, network, working_crs, source_crs, source) -> None:
    """Every layer of a network into a GeoPackage, back in the input's own CRS when the
    job worked in another (a geographic raster in its UTM zone); a warning when it is
    empty."""
    layers = network.layers()
    if source_crs is not None and source_crs != working_crs:
        layers = {name: frame.to_crs(source_crs) for name, frame in layers.items()}
    write_geopackage(out_path, layers)
    _warn_if_no_road(network, source)


def _network_quicklook(path, network, first: tuple, *, background, title: str) -> Path:
    """A PNG of a network over its raster: ``first`` (a QA layer and its style), the gaps
    the integer program bridged, the centre lines and the junctions."""
    write_quicklook(path, [
        first,
        (network.qa["gap_edges"].query("selected"),
         dict(color="cyan", linewidth=2, label="bridged gaps")),
        (network.centrelines, dict(color="red", linewidth=1.5, label="road centre lines")),
        (network.junctions, dict(color="yellow", markersize=20, label="junctions")),
    ], background=background, title=title)
    return Path(path)


def _map_lines(map_source) -> gpd.GeoDataFrame:
    """Road map lines from a GeoDataFrame or a line file (a GeoPackage's road_centrelines
    layer when it has one, else its first layer)."""
    if isinstance(map_source, gpd.GeoDataFrame):
        return map_source
    if not Path(map_source).is_file():
        raise ValueError(f"{map_source}: no such road map file")
    gpkg = str(map_source).lower().endswith(".gpkg")
    return read_layer(map_source, CENTRELINES if gpkg and CENTRELINES in
                      list_layers(map_source) else None)


def attractor_job(cloud_path, map_source, out_path, *, curb_detector: str = "exp",
                  cell_m: float = 0.5, progress: Progress = None, **options) -> dict:
    """Curb attractor map of the road patches of a map over a cloud (Boyko & Funkhouser,
    section 2.3), as a GeoTIFF in the cloud's CRS. ``map_source`` as in
    :func:`snakes_job`; ``options`` go to :func:`gisroads.snakes.pipeline.curb_attractor`.
    """
    from .snakes.pipeline import curb_attractor

    attractor = curb_attractor(cloud_path, _map_lines(map_source), curb_detector=curb_detector,
                               cell_m=cell_m, progress=scaled(progress, 0.0, 0.95), **options)
    path = write_geotiff(out_path, attractor, band_names=["attractor"])
    report(progress, 1.0, "done")
    return {"attractor": path, "max": float(attractor.data.max()),
            "shape": list(attractor.shape)}


def snakes_job(cloud_path, map_source, out_path, *, curb_detector: str = "exp",
               tagged_las=None, attractor_tif=None, progress: Progress = None,
               **options) -> dict:
    """Map-guided road extraction with ribbon snakes (Boyko & Funkhouser, 2011).

    ``map_source``: a line file (a GeoPackage's road_centrelines layer, else its first;
    GeoJSON, any OGR format) or a GeoDataFrame, in any CRS: reprojected to the cloud's.
    Writes ``out_path`` (road_centrelines, road_polygons, junctions and the QA layers
    ribbon_patches and registered_map) in the cloud's CRS; optionally ``tagged_las`` (the
    cloud with road points in class 11) and ``attractor_tif`` (the patches' attractor
    maps). ``options`` go to :func:`gisroads.snakes.pipeline.extract_map_guided`. When
    no road is fitted the layers are empty, with a :class:`~gisroads.errors.NoRoadFoundWarning`.
    """
    from .snakes.pipeline import extract_map_guided

    roads = extract_map_guided(cloud_path, _map_lines(map_source), curb_detector=curb_detector,
                               tagged_las=tagged_las, progress=scaled(progress, 0.0, 0.95),
                               **options)
    network = roads.network
    write_geopackage(out_path, network.layers())
    _warn_if_no_road(network, cloud_path)
    result = {"gpkg": Path(out_path), "roads": len(network.centrelines),
              "length_m": float(network.centrelines.length_m.sum()),
              "junctions": len(network.junctions), "patches": len(roads.ribbons),
              "converged": sum(r.converged for r in roads.ribbons)}
    if tagged_las is not None:
        result.update(tagged_las=Path(tagged_las), tagged_points=roads.tagged_points)
    if attractor_tif is not None and roads.attractor is not None:
        result["attractor"] = write_geotiff(attractor_tif, roads.attractor,
                                            band_names=["attractor"])
    report(progress, 1.0, "done")
    return result


DEMO_IMAGE = "spacenet_paris_img1447.tif"
DEMO_IMAGE_TRUTH = "osm_roads_img1447.geojson"
DEMO_CLOUD = "ign_lidar_hd_0292_6833_thinned.laz"


def demo_job(out_dir, *, data_dir=None, progress: Progress = None) -> dict:
    """The demo on the bundled real data: both road pipelines, their GeoPackages and PNGs.

    ``data_dir`` defaults to the bundled sample data: the package data of a wheel
    (``gisroads/_demo``), the repository's ``data/demo`` in a checkout
    (:func:`gisroads.resources.demo_dir`); its README gives the sources and licences.

    * the imagery pipeline on a SpaceNet Paris tile (RGB, 0.3 m), scored against its
      OpenStreetMap centre lines (``image_roads.gpkg``, ``image_roads.png``,
      ``image_evaluation.json``);
    * the LiDAR pipeline on a thinned IGN LiDAR HD tile of a town (1 km², 0.29 points/m²,
      processed at the coarser cell its density allows) with the paper's intensity cue
      (``lidar_roads.gpkg``, ``lidar_roads.png``) and with the evidence cue
      (``lidar_evidence_roads.gpkg``, ``lidar_evidence_roads.png``).
    """
    from .evaluate import format_report

    data, out = Path(demo_dir() if data_dir is None else data_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    image = image_job(data / DEMO_IMAGE, out / "image_roads.gpkg",
                      quicklook=out / "image_roads.png", progress=scaled(progress, 0.0, 0.3))
    footprint = gpd.GeoDataFrame(geometry=[shapely.box(*read_raster(data / DEMO_IMAGE).bounds)],
                                 crs=read_layer(out / "image_roads.gpkg", CENTRELINES).crs)
    evaluation = evaluate_network(read_layer(out / "image_roads.gpkg", CENTRELINES),
                                  read_layer(data / DEMO_IMAGE_TRUTH), valid_area=footprint)
    (out / "image_evaluation.json").write_text(to_json(evaluation))
    lidar = lidar_job(data / DEMO_CLOUD, out / "lidar_roads.gpkg",
                      quicklook=out / "lidar_roads.png", progress=scaled(progress, 0.3, 0.85))
    evidence = lidar_job(data / DEMO_CLOUD, out / "lidar_evidence_roads.gpkg", cue="evidence",
                         quicklook=out / "lidar_evidence_roads.png",
                         progress=scaled(progress, 0.85, 1.0))
    report(progress, 1.0, "done")
    return {"image": image, "image_evaluation": evaluation,
            "image_report": format_report(evaluation), "lidar": lidar,
            "lidar_evidence": evidence}


def vectorize_job(raster_path, out_path, *, band: int = 1, threshold: float = 0.5,
                  pixel_m: float | None = None, crs=None, quicklook=None,
                  progress: Progress = None) -> dict:
    """Any road raster (mask or probability) to a road network in a GeoPackage.

    Writes road_centrelines, road_polygons, junctions and the QA layers gap_edges,
    junction_connections and rejected in the raster's CRS (a geographic raster is worked
    in its UTM zone); optionally a ``quicklook`` PNG. See
    :func:`gisroads.network.rasters.raster_to_network`.
    """
    from .network.rasters import raster_to_network

    raster, source_crs = read_image(raster_path, pixel_m=pixel_m, crs=crs)
    network = raster_to_network(raster, band=band, threshold=threshold,
                                progress=scaled(progress, 0.0, 0.95))
    _write_network(out_path, network, raster.crs, source_crs, raster_path)
    result = {"gpkg": Path(out_path), "roads": len(network.centrelines),
              "length_m": float(network.centrelines.length_m.sum()),
              "junctions": len(network.junctions),
              "gaps_bridged": int(network.qa["gap_edges"]["selected"].sum())}
    if quicklook is not None:
        report(progress, 0.97, "drawing the quick-look")
        result["quicklook"] = _network_quicklook(
            quicklook, network,
            (network.qa["rejected"], dict(color="grey", linewidth=1, label="rejected")),
            background=raster, title=f"{Path(raster_path).name}: "
                                     f"{len(network.centrelines)} roads, "
                                     f"{len(network.junctions)} junctions")
    report(progress, 1.0, "done")
    return result


# --- road database update (issue 11) -------------------------------------------------------

def _coverage(path) -> GeoRaster | gpd.GeoDataFrame:
    """An observability coverage: a raster (non-zero cells observable) or polygons."""
    if Path(path).suffix.lower() in {".tif", ".tiff", ".vrt", ".img"}:
        return read_raster(path)
    return read_layer(path)


def update_job(extracted, database, out_path, *, layer: str | None = None,
               id_field: str | None = None, width_field: str | None = None,
               tolerance_m: float = 3.0, search_m: float = 15.0, coverage=None,
               progress: Progress = None) -> dict:
    """Compare an extraction with a road database; write the change layers.

    Parameters
    ----------
    extracted : str or Path
        Extracted centre lines: a gisroads GeoPackage (its ``road_centrelines`` layer) or any
        line file.
    database : str or Path
        Any OGR source (file, ``PG:`` connection string ...), any CRS.
    out_path : str or Path
        GeoPackage receiving the styled layers ``confirmed``, ``missing``, ``new``, ``moved``
        and ``proposed_update``, all in the database's CRS.
    layer : str, optional
        The database's layer (table); by default its first.
    id_field, width_field : str, optional
        The database's feature id field (default: OGR's feature ids) and width field
        (metres).
    tolerance_m, search_m : float
        See :func:`gisroads.update.conflate` (metres).
    coverage : str or Path, optional
        Where the data could show a road: a polygon file, or a raster whose non-zero cells
        are observable.

    Returns
    -------
    dict
        Output path, feature count of each layer and count of each change.
    """
    from .update import CHANGES, LAYERS, conflate, read_database

    report(progress, 0.0, "reading")
    lines = read_layer(extracted)
    roads = read_database(database, layer)
    changes = conflate(lines, roads, id_field=id_field, width_field=width_field,
                       tolerance_m=tolerance_m, search_m=search_m,
                       coverage=_coverage(coverage) if coverage is not None else None,
                       progress=scaled(progress, 0.05, 0.9))
    report(progress, 0.9, "writing")
    write_geopackage(out_path, changes)
    report(progress, 1.0, "done")
    counted = changes["proposed_update"]["change"].value_counts()
    return {"gpkg": Path(out_path), **{name: len(changes[name]) for name in LAYERS},
            "changes": {name: int(counted.get(name, 0)) for name in CHANGES}}
