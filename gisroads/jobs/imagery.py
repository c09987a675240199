"""The imagery jobs: road extraction from an aerial image (Grote & Rottensteiner's stages
with a learned road cue), its segmentation and grouping stages alone, and training that cue
on an image from a road layer."""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import geopandas as gpd
import shapely

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..imagery.grouping import CRITERIA as GROUPING_CRITERIA
from ..imagery.grouping import group_segments
from ..imagery.pipeline import ImageOptions, extract_image_roads, resolve_model
from ..imagery.roadparts import CRITERIA as ROAD_PART_CRITERIA
from ..imagery.roadparts import extract_road_parts, rasterize_segments
from ..imagery.segments import frame_to_labels, segment_image, segments_to_frame
from ..io.vector import write_geopackage
from ..io.raster import read_raster, write_geotiff
from ..learn.convnet import CHECK_SHARE, FINE_TUNE_CORE_FRACTION, FINE_TUNE_STEPS
from ..learn.model import save_model, with_metadata
from ..learn.training import LayerLabels, train_from_layer
from ..options import with_changes
from ..progress import Progress, report, scaled
from .common import (_layer, _map_lines, _network_quicklook, _write_network,
                     network_summary, read_image, stage_default)


def image_job(image_path, out_path, options: ImageOptions = ImageOptions(), *,
              dsm_path=None, pixel_m: float | None = None, crs=None, quicklook=None,
              model="default", probability_path=None, progress: Progress = None,
              **changes) -> dict:
    """Road extraction of an aerial image into a GeoPackage: Grote & Rottensteiner's stages
    with a learned road cue (see :func:`gisroads.imagery.pipeline.extract_image_roads`).

    Writes ``out_path`` with road_centrelines (width_m, and ``cues``: which of rgb/cir/pan,
    nir, dsm and model were used), road_polygons, junctions and the QA layers (segments,
    road_parts, gap_edges and junction_connections for the papers' stages), in the image's
    CRS; optionally a ``quicklook`` PNG and ``probability_path``, the learned road
    probability as a float32 GeoTIFF (band ``road_probability``, 0-1, NaN no data) on the
    grid the image was worked on (its UTM zone for a geographic image). ``model``:
    ``"default"`` (the convolutional network), ``"boosted"`` (the boosted trees), a model
    file of :func:`train_job` (.onnx or .npz), or ``"none"`` (the papers' pipeline alone).
    ``options`` (and ``**changes`` to its fields: ``nir_band``, ``context``, ``method``
    ...) are those of :func:`gisroads.imagery.pipeline.extract_image_roads`; ``context``
    is the context model that re-scores the probability on the probability path
    (:func:`gisroads.imagery.pipeline.resolve_context`: ``"default"``, ``"none"`` or a
    model file). An image without roads gives
    empty layers and a :class:`~gisroads.errors.NoRoadFoundWarning`.
    """
    options = replace(options, **changes)
    image, source_crs = read_image(image_path, pixel_m=pixel_m, crs=crs)
    band_count = image.data.shape[0] if image.data.ndim == 3 else 1
    for name, band in (("NIR", options.nir_band), ("red", options.red_band)):
        if band is not None and not 1 <= band <= band_count:
            raise GisroadsError(f"{image_path}: no {name} band {band} (the image has "
                             f"{band_count} band(s))")
    model = resolve_model(model)
    if probability_path is not None and model is None:
        raise GisroadsError("a road probability raster needs a model (not --model none)")
    dsm = read_raster(dsm_path) if dsm_path is not None else None
    roads = extract_image_roads(image, options, dsm=dsm, model=model,
                                progress=scaled(progress, 0.0, 0.95))
    network = roads.network
    _write_network(out_path, network, image.crs, source_crs, image_path)
    result = {**network_summary(out_path, network), "cues": roads.report["cues"]["cues"],
              "method": roads.report["method"], "timings_s": roads.report["timings_s"],
              "context_model": roads.report.get("context_model", False),
              "model": roads.report.get("model"),
              "threshold": roads.report.get("threshold")}
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


@dataclass(frozen=True)
class FineTuning:
    """How :func:`train_job` fine-tunes the network (an ``.onnx`` output).

    Attributes
    ----------
    base : str or Path, optional
        The ``.onnx`` model to start from; the bundled one when None.
    steps : int, optional
        Optimiser steps; :data:`gisroads.learn.convnet.FINE_TUNE_STEPS` when None.
    check_share : float
        Share of the layer's roads left out to check the fine-tuned model against the
        base (:func:`gisroads.learn.convnet_training.fine_tune_on_layer`).
    """

    base: object = None
    steps: int | None = None
    check_share: float = CHECK_SHARE


def train_job(image_path, roads_path, out_path, labels: LayerLabels = LayerLabels(),
              tuning: FineTuning = FineTuning(), *, pixel_m: float | None = None, crs=None,
              samples: int = stage_default(train_from_layer, "samples"),
              seed: int = stage_default(train_from_layer, "seed"),
              progress: Progress = None, **changes) -> dict:
    """Train a road model on an image from a road layer over it (the agency's update case).

    An ``out_path`` ending in ``.onnx`` fine-tunes the convolutional network (``tuning``:
    the ``base`` network, the bundled one by default, for ``steps`` optimiser steps:
    :func:`gisroads.learn.convnet_training.fine_tune_on_layer`; needs the ``train`` extra,
    PyTorch), with ``check_share`` of the roads left out to check it against the base
    network, which is written instead (with a warning) when it finds more of them; any other
    suffix trains boosted trees, as follows. ``**changes`` change fields of ``labels`` or
    ``tuning`` for this call.

    Roads (any OGR line layer or a GeoDataFrame, any CRS; a gisroads GeoPackage's
    road_centrelines) are
    rasterised at their width (``labels``: ``width_field``, metres; empty or missing values
    and layers without the field take ``default_width_m``): positives in the core half of
    each road, negatives beyond ``width / 2 + guard_m`` (misregistered lines), calibrated
    to the bundled model's
    road share (:func:`gisroads.learn.train_from_layer` ``road_share="default"``), so that
    the extraction's threshold means the same for both models. Writes the model archive ``out_path``
    (.npz), to give to ``image_job(..., model=out_path)``. Needs scikit-learn.
    """
    labels, tuning = with_changes(changes, labels, tuning)
    width_field = labels.width_field
    image, _ = read_image(image_path, pixel_m=pixel_m, crs=crs)
    roads = _map_lines(roads_path)
    if roads.crs is None and image.crs is not None:
        raise GisroadsError(f"{roads_path}: the road layer has no CRS; cannot place it on the "
                         "image")
    if width_field is not None and width_field not in roads.columns:
        raise GisroadsError(f"{roads_path}: no field {width_field!r} (fields: "
                         f"{', '.join(c for c in roads.columns if c != 'geometry')})")
    if labels.default_width_m <= 0 or labels.guard_m < 0:
        raise GisroadsError("the width must be positive and the guard band at least 0 m")
    if Path(out_path).suffix.lower() == ".onnx":
        return _fine_tune_job(image, roads, out_path, labels, tuning, image_path=image_path,
                              roads_path=roads_path, seed=seed, progress=progress)
    try:
        import sklearn  # noqa: F401  (optional: checked here to say what is missing)
    except ImportError:
        raise GisroadsError("training needs scikit-learn (pip install scikit-learn, or the "
                         "python3-sklearn package)") from None
    report(progress, 0.0, "sampling the image along the roads")
    model = train_from_layer(image, roads, labels,
                             samples=samples, seed=seed, road_share="default",
                             progress=scaled(progress, 0.05, 0.95))
    model = with_metadata(model, image=Path(image_path).name, width_field=width_field,
                          roads=(Path(roads_path).name if not isinstance(
                              roads_path, gpd.GeoDataFrame) else "layer"))
    path = save_model(model, out_path)
    report(progress, 1.0, "done")
    return {"model": path, "samples": model.metadata["samples"],
            "trees": len(model.roots), "road_share": model.metadata["calibrated_road_share"],
            "roads": len(roads)}


def _fine_tune_job(image, roads, out_path, labels: LayerLabels, tuning: FineTuning, *,
                   image_path, roads_path, seed, progress) -> dict:
    """The convolutional network fine-tuned on ``image`` with ``roads`` as labels, written
    as ONNX to ``out_path`` (see :func:`train_job`)."""
    try:
        from ..learn.convnet_training import export_onnx, fine_tune_on_layer
    except ImportError:
        raise GisroadsError("fine-tuning the road network needs PyTorch: "
                            "pip install 'gisroads[train]' (or train boosted trees: "
                            "-o model.npz)") from None
    steps = FINE_TUNE_STEPS if tuning.steps is None else tuning.steps
    if steps < 1:
        raise GisroadsError("the number of fine-tuning steps must be at least 1")
    if not 0 <= tuning.check_share < 1:
        raise GisroadsError(f"the share of roads left out to check the fine-tuning must be "
                            f"at least 0 and below 1, not {tuning.check_share}")
    model, metadata = fine_tune_on_layer(image, roads,
                                         replace(labels, core_fraction=FINE_TUNE_CORE_FRACTION),
                                         model=tuning.base, steps=steps, seed=seed,
                                         check_share=tuning.check_share,
                                         progress=scaled(progress, 0.0, 0.95))
    metadata = {**metadata, "image": Path(image_path).name, "width_field": labels.width_field,
                "roads": (Path(roads_path).name if not isinstance(roads_path, gpd.GeoDataFrame)
                          else "layer")}
    path = export_onnx(model, out_path, metadata)
    report(progress, 1.0, "done")
    check = metadata.get("check")
    if check is not None and check["kept"] == "base":
        warnings.warn(
            f"fine-tuning found less of the {check['held_out_roads']} roads left out to "
            f"check it than the base model ({check['fine-tuned']:.2f} of their length "
            f"against {check['base']:.2f}): {Path(path).name} is the base model",
            stacklevel=2)
    return {"model": path, "steps": steps, "road_share": metadata["road_share"],
            "roads": len(roads), "check": check}


def _segment_layer(frame: gpd.GeoDataFrame) -> gpd.GeoDataFrame:
    """Segments with one geometry type (MultiPolygon), so any GIS layer takes them."""
    parts, owner = shapely.get_parts(frame.geometry.values, return_index=True)
    return frame.set_geometry(gpd.GeoSeries(shapely.multipolygons(parts, indices=owner),
                                            index=frame.index, crs=frame.crs))


def _segment_labels(segments, image: GeoRaster, id_field: str, burn=frame_to_labels):
    labels = burn(_layer(segments, "segments"), image, id_column=id_field)
    if (labels < 0).all():
        raise GisroadsError(f"{segments}: no segment polygon overlaps the image")
    return labels


def segmentation_job(image_path, segments_path, *, nir_band: int | None = None,
                     red_band: int | None = None, n_segments: int | None = None,
                     n_superpixels: int | None = None,
                     ndvi_threshold: float = stage_default(segment_image, "ndvi_threshold"),
                     w_ndvi: float = stage_default(segment_image, "w_ndvi"),
                     progress: Progress = None) -> dict:
    """Imagery stage 1: the NCut over-segmentation of an image
    (:func:`gisroads.imagery.segments.segment_image`; ``n_segments`` and ``n_superpixels``
    None or 0 for their ground-size defaults).

    Writes ``segments_path`` (GeoPackage, layer ``segments``: ``segment_id``, ``area_px``,
    MultiPolygons in the image's CRS).
    """
    image = read_raster(image_path)
    labels = segment_image(image, nir_band=nir_band, red_band=red_band,
                           n_segments=n_segments or None, n_superpixels=n_superpixels or None,
                           ndvi_threshold=ndvi_threshold, w_ndvi=w_ndvi, progress=progress)
    frame = _segment_layer(segments_to_frame(labels, image))
    write_geopackage(segments_path, {"segments": frame})
    return {"segments": Path(segments_path), "n_segments": len(frame)}


def grouping_job(image_path, segments, grouped_path, *, id_field: str = "segment_id",
                 nir_band: int | None = None, dsm_path=None,
                 merge_fraction: float = stage_default(group_segments, "merge_fraction"),
                 max_iterations: int = stage_default(group_segments, "max_iterations"),
                 criteria: dict = GROUPING_CRITERIA,
                 split_branches: bool = stage_default(group_segments, "split_branches"),
                 min_branch_m: float = stage_default(group_segments, "min_branch_m"),
                 progress: Progress = None) -> dict:
    """Imagery stage 2: adjacent segments merged by the paper's criteria and fuzzy rules,
    segments spanning junctions split (:func:`gisroads.imagery.grouping.group_segments`).

    ``segments``: a polygon file (or ``path|layername=``) whose ``id_field`` numbers the
    segments, e.g. :func:`segmentation_job`'s; ``criteria``: ``{name: (poor, very_good)}``
    for any of :data:`gisroads.imagery.grouping.CRITERIA`. Writes ``grouped_path``
    (GeoPackage, layer ``segments``, as :func:`segmentation_job`).
    """
    image = read_raster(image_path)
    dsm = read_raster(dsm_path) if dsm_path else None
    labels = _segment_labels(segments, image, id_field)
    grouped = group_segments(labels, image, dsm=dsm, nir_band=nir_band,
                             merge_fraction=merge_fraction, max_iterations=max_iterations,
                             criteria={**GROUPING_CRITERIA,
                                       **{k: tuple(v) for k, v in criteria.items()}},
                             split_branches=split_branches, min_branch_m=min_branch_m,
                             progress=progress)
    frame = _segment_layer(segments_to_frame(grouped, image))
    write_geopackage(grouped_path, {"segments": frame})
    return {"segments": Path(grouped_path), "n_input": int(labels.max()) + 1,
            "n_segments": len(frame)}


def road_parts_job(image_path, segments, road_parts_path, *, id_field: str = "segment_id",
                   nir_band: int | None = None, red_band: int | None = None, dsm_path=None,
                   criteria: dict = ROAD_PART_CRITERIA,
                   merge: bool = stage_default(extract_road_parts, "merge"),
                   max_direction_diff_rad: float = stage_default(extract_road_parts,
                                                                 "max_direction_diff_rad"),
                   progress: Progress = None) -> dict:
    """Imagery stage 3: the road-part shape filter of every segment
    (:func:`gisroads.imagery.roadparts.extract_road_parts`).

    ``segments`` as in :func:`grouping_job`; ``criteria``: any of
    :data:`gisroads.imagery.roadparts.CRITERIA`. Writes ``road_parts_path`` (GeoPackage):
    ``segments``, every segment with its measurements, ``passed``, ``reason`` and
    ``failures``, and ``road_parts``, the parts' centre lines.
    """
    image = read_raster(image_path)
    dsm = read_raster(dsm_path) if dsm_path else None
    labels = _segment_labels(segments, image, id_field, rasterize_segments)
    criteria = {k: tuple(v) if isinstance(v, list) else v for k, v in criteria.items()}
    result = extract_road_parts(labels, image, nir_band=nir_band, red_band=red_band, dsm=dsm,
                                merge=merge, max_direction_diff_rad=max_direction_diff_rad,
                                progress=progress, **{**ROAD_PART_CRITERIA, **criteria})
    write_geopackage(road_parts_path, {"segments": _segment_layer(result.segments),
                                       "road_parts": result.road_parts})
    return {"road_parts": Path(road_parts_path), "n_parts": len(result.road_parts),
            "n_segments": len(result.segments),
            "n_passed": int(result.segments["passed"].sum()), "cues": result.cues["cues"]}
