"""Grote & Rottensteiner's road extraction from an aerial image, as a composition of stages.

NCut over-segmentation (:mod:`gisroads.imagery.segments`) -> grouping, with the splitting of
branching segments (:mod:`gisroads.segmentation.grouping`) -> road-part shape filtering
(:mod:`gisroads.imagery.roadparts`) -> subgraph generation and the integer program over gap
edges (:mod:`gisroads.network.subgraph`) -> road strings to a network with junctions
(:mod:`gisroads.network.junctions`). Each stage is a function of its own; this module only
chains them and times them.

Distances are metres: the stages' defaults are the paper's (its images had 8-10 cm pixels),
expressed in metres, so they hold at the input's pixel size; the segment counts, which the
paper set per image, follow the image's ground area.
"""
from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from ..geo import GeoRaster, RoadNetwork
from ..progress import Progress, report, scaled
from ..segmentation.grouping import group_segments
from .cues import context_rasters, image_cues
from ..network.junctions import strings_to_network
from .roadparts import extract_road_parts
from .segments import edge_strength, segment_image
from ..network.subgraph import link_road_parts

METHOD = "grote-rottensteiner"

class ImageRoads(NamedTuple):
    """Result of :func:`extract_image_roads`."""

    network: RoadNetwork
    """The contract layers; ``qa`` holds ``segments``, ``road_parts``, ``gap_edges`` and
    ``junction_connections``."""
    report: dict
    """``timings_s`` per stage, ``cues`` (:meth:`ImageCues.record`) and counts."""


def extract_image_roads(image: GeoRaster, *, nir_band: int | None = None,
                        red_band: int | None = None, dsm: GeoRaster | None = None,
                        n_segments: int | None = None, road_part_criteria: dict | None = None,
                        gap_options: dict | None = None, weight_options: dict | None = None,
                        network_options: dict | None = None,
                        progress: Progress = None) -> ImageRoads:
    """The road network of an aerial image (RGB, CIR or panchromatic; NIR and DSM optional).

    Parameters
    ----------
    image : GeoRaster
        ``(bands, rows, cols)`` in a projected CRS in metres; NaN or nodata = no data.
    nir_band, red_band : int, optional
        1-based; a NIR band adds the NDVI factor to the segmentation, the NDVI test of the
        road parts and vegetation as gap context.
    dsm : GeoRaster, optional
        Surface heights (metres), any grid over the image: adds the height criterion of the
        grouping, the nDSM test of the road parts and buildings as gap context.
    n_segments : int, optional
        NCut over-segmentation size; default
        :func:`gisroads.imagery.segments.default_counts`.
    road_part_criteria, gap_options, weight_options, network_options : dict, optional
        Thresholds of :func:`gisroads.imagery.roadparts.filter_road_parts`,
        :func:`gisroads.network.subgraph.gap_edges`,
        :func:`gisroads.network.subgraph.edge_weights` and
        :func:`gisroads.network.junctions.strings_to_network`.
    progress : callable, optional
        ``progress(fraction, message)``; may raise :class:`gisroads.progress.Cancelled`.

    Returns
    -------
    ImageRoads
        An empty network (valid, with its QA layers) when no road is found.
    """
    if image.crs is not None and not image.crs.is_projected:
        raise ValueError("the image must be in a projected CRS in metres (reproject it, "
                         "e.g. to its UTM zone)")
    timings = {}
    clock = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[stage] = now - clock
        clock = now

    report(progress, 0.0, "image cues")
    cues = image_cues(image, nir_band=nir_band, red_band=red_band, dsm=dsm)
    # one local-energy pass for the three stages that weigh edges
    edges = edge_strength(image, nir_band=nir_band, bands=cues.bands)
    lap("cues")
    labels = segment_image(image, nir_band=nir_band, red_band=red_band,
                           n_segments=n_segments, edge_magnitude=edges,
                           progress=scaled(progress, 0.02, 0.4))
    lap("segmentation")
    report(progress, 0.4, "grouping segments")
    labels = group_segments(labels, image, dsm=dsm, ndvi=cues.ndvi, nir_band=nir_band,
                            edge_magnitude=edges, progress=scaled(progress, 0.4, 0.55))
    lap("grouping")
    parts = extract_road_parts(labels, image, cues=cues, edge_magnitude=edges,
                               progress=scaled(progress, 0.55, 0.75),
                               **(road_part_criteria or {}))
    lap("road_parts")
    gaps, strings = link_road_parts(parts.road_parts, transform=image.transform,
                                    **context_rasters(cues), gap_options=gap_options,
                                    weight_options=weight_options,
                                    progress=scaled(progress, 0.75, 0.85))
    lap("subgraphs")
    network, connections = strings_to_network(strings, extent=image.bounds, crs=image.crs,
                                              method=METHOD, progress=scaled(progress, 0.85, 1.0),
                                              **(network_options or {}))
    lap("network")
    record = cues.record()
    network.centrelines["cues"] = record["cues"]
    network.qa = {"segments": parts.segments, "road_parts": parts.road_parts,
                  "gap_edges": gaps, "junction_connections": connections}
    timings["total"] = sum(timings.values())
    report(progress, 1.0, f"{len(network.centrelines)} roads")
    return ImageRoads(network, {
        "timings_s": timings, "cues": record, "segments": int(np.max(labels)) + 1,
        "road_parts": len(parts.road_parts), "gap_edges": len(gaps),
        "selected_gaps": int(gaps["selected"].sum()) if len(gaps) else 0,
        "roads": len(network.centrelines)})
