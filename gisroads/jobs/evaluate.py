"""The evaluation jobs: a synthetic scene with its exact truth, and the scores of an
extracted network against a reference."""
from __future__ import annotations

from pathlib import Path

import geopandas as gpd

from ..errors import GisroadsError
from ..evaluate import evaluate_network, match_layers
from ..geo import CENTRELINES, JUNCTIONS, POLYGONS
from ..io.raster import write_geotiff
from ..io.vector import list_layers, read_layer, write_geopackage
from ..progress import Progress, report, scaled
from ..synthetic import make_scene, render_image, write_cloud
from .common import _layer, _named_layer, stage_default


def synth_job(out_dir, *, size_m: tuple[float, float] = stage_default(make_scene, "size_m"),
              seed: int = stage_default(make_scene, "seed"),
              density_per_m2: float = stage_default(write_cloud, "density_per_m2"),
              pixel_m: float = stage_default(render_image, "pixel_m"), cloud: bool = True,
              image: bool = True, progress: Progress = None) -> dict[str, Path]:
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


def _read_polygons(source) -> gpd.GeoDataFrame | None:
    """The road polygons beside a GeoPackage's centre lines, unless a layer was named."""
    path, named = _named_layer(source)
    path = Path(path)
    if named is None and path.suffix.lower() == ".gpkg" and POLYGONS in list_layers(path):
        return read_layer(path, POLYGONS)
    return None


def evaluate_job(extracted, reference, *,
                 buffer_m: float = stage_default(evaluate_network, "buffer_m"),
                 cell_m: float = stage_default(evaluate_network, "cell_m"),
                 junction_radius_m: float = stage_default(evaluate_network,
                                                          "junction_radius_m"),
                 extracted_polygons=None, reference_polygons=None, valid_area=None,
                 reference_junctions=None, qa_path=None, progress: Progress = None) -> dict:
    """Score an extracted road network against a reference, from files.

    Centre lines come from the ``road_centrelines`` layer of a GeoPackage (else its first
    layer) or from any line file; road areas from the ``road_polygons`` layers of both
    GeoPackages or from the files given; the reference's junctions from
    ``reference_junctions`` (a point file) when given, else from its lines. ``qa_path``
    receives the matched/unmatched pieces
    (``eval_extracted``, ``eval_reference``) as a styled GeoPackage.

    Returns
    -------
    dict
        The figures of :func:`gisroads.evaluate.evaluate_network`.
    """
    report(progress, 0.0, "reading")
    extracted_lines = _layer(extracted, CENTRELINES)
    reference_lines = _layer(reference, CENTRELINES)
    if len(reference_lines) == 0:
        raise GisroadsError(f"{reference}: the reference holds no road")
    predicted = (_layer(extracted_polygons, POLYGONS) if extracted_polygons
                 else _read_polygons(extracted))
    truth = (_layer(reference_polygons, POLYGONS) if reference_polygons
             else _read_polygons(reference))
    valid = _layer(valid_area, None) if valid_area else None
    junctions = _layer(reference_junctions, JUNCTIONS) if reference_junctions else None
    report(progress, 0.1, "scoring")
    results = evaluate_network(extracted_lines, reference_lines, buffer_m=buffer_m,
                               cell_m=cell_m, junction_radius_m=junction_radius_m,
                               valid_area=valid, extracted_polygons=predicted,
                               reference_polygons=truth, reference_junctions=junctions)
    if qa_path is not None:
        report(progress, 0.9, "writing the QA layers")
        write_geopackage(qa_path, match_layers(extracted_lines, reference_lines,
                                               buffer_m=buffer_m, valid_area=valid))
    report(progress, 1.0, "done")
    return results
