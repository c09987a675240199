"""The network jobs: any road raster (a mask or a probability) to a road network; the
network stages of the imagery method alone: subgraph linking of road parts, and junction
construction of any line layer."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from ..errors import GisroadsError
from ..imagery.cues import context_rasters, image_cues, normalised_dsm
from ..io.raster import read_raster
from ..io.vector import write_geopackage
from ..network.junctions import NetworkOptions, road_strings_from_lines, strings_to_network
from ..network.rasters import THRESHOLD, raster_to_network
from ..network.subgraph import (GapOptions, WeightOptions, edge_weights, link_road_parts,
                                road_strings)
from ..progress import Progress, report, scaled
from .common import (_layer, _network_quicklook, _warn_if_no_road, _write_network,
                     network_summary, read_image, stage_default)


def vectorize_job(raster_path, out_path, *, band: int | None = None,
                  threshold: float = THRESHOLD,
                  pixel_m: float | None = None, crs=None, wide_areas: bool = False,
                  quicklook=None, progress: Progress = None) -> dict:
    """Any road raster (mask or probability) to a road network in a GeoPackage.

    Writes road_centrelines, road_polygons, junctions and the QA layers gap_edges,
    junction_connections and rejected in the raster's CRS (a geographic raster is worked
    in its UTM zone); optionally a ``quicklook`` PNG. See
    :func:`gisroads.network.rasters.raster_to_network`. ``band``: the 1-based band to read;
    by default the first of a one- or two-band raster, and a raster of three or more bands
    (an image, most likely) is refused. ``wide_areas``: car parks and plazas give the roads
    through them, not their outlines and aisles (:mod:`gisroads.network.areas`; what
    ``gisroads image`` does with its own probability).
    """
    raster, source_crs = read_image(raster_path, pixel_m=pixel_m, crs=crs)
    bands = raster.data.shape[0] if raster.data.ndim == 3 else 1
    if band is None and bands >= 3:
        raise GisroadsError(
            f"{raster_path} has {bands} bands, like an image: vectorize takes a road "
            "probability or mask (one band, 0-1 or 0-255); give --band N to read one band "
            "of it, or run 'gisroads image' on an aerial image")
    network = raster_to_network(raster, band=band or 1, threshold=threshold,
                                wide_areas=wide_areas, progress=scaled(progress, 0.0, 0.95))
    _write_network(out_path, network, raster.crs, source_crs, raster_path)
    result = {**network_summary(out_path, network),
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


def linking_job(road_parts, linked_path, gaps: GapOptions = GapOptions(), *,
                image_path=None, nir_band: int | None = None, red_band: int | None = None,
                dsm_path=None, edited_gap_edges=None,
                small_gap_m: float = stage_default(edge_weights, "small_gap_m"),
                progress: Progress = None, **changes) -> dict:
    """Subgraph linking (Grote et al. 2012, Sec. 2.2): gap edges between the ends of road
    parts, their context and weights, the integer program's selection, road strings
    (:func:`gisroads.network.subgraph.link_road_parts`).

    ``road_parts``: line file (or ``path|layername=``) with ``part_id``, ``width_m``,
    ``quality`` and band means, e.g. :func:`road_parts_job`'s. The optional image and DSM
    give the gaps' context (shadow, asphalt, vegetation, buildings, vehicles); they must be
    in the parts' CRS. ``edited_gap_edges``: a ``gap_edges`` layer of an earlier run, its
    ``selected`` edited by hand: the strings then follow it and nothing is recomputed.
    ``gaps`` (and ``**changes`` to its fields): the limits of a gap edge
    (:func:`gisroads.network.subgraph.gap_edges`); ``small_gap_m``: of the gap edges'
    weights (:class:`gisroads.network.subgraph.WeightOptions`, its other fields at their
    defaults). Writes ``linked_path`` (GeoPackage): ``gap_edges`` and ``road_strings``.
    """
    parts = _layer(road_parts, "road_parts")
    if edited_gap_edges is not None:
        edges = _layer(edited_gap_edges, "gap_edges")
        strings = road_strings(parts, edges)
    else:
        edges, strings = link_road_parts(
            parts, **_gap_context(parts.crs, image_path, dsm_path, nir_band, red_band),
            gap_options=replace(gaps, **changes),
            weight_options=WeightOptions(small_gap_m=small_gap_m), progress=progress)
    write_geopackage(linked_path, {"gap_edges": edges, "road_strings": strings})
    return {"linked": Path(linked_path), "gap_edges": len(edges),
            "selected": int(edges["selected"].fillna(False).astype(bool).sum()),
            "road_strings": len(strings)}


def _gap_context(crs, image_path, dsm_path, nir_band, red_band) -> dict:
    """Keyword arguments of link_road_parts for the optional context rasters."""
    image = read_raster(image_path) if image_path else None
    dsm = read_raster(dsm_path) if dsm_path else None
    for raster, name in ((image, "image"), (dsm, "DSM")):
        if raster is not None and None not in (raster.crs, crs) and raster.crs != crs:
            raise GisroadsError(f"the {name} is in another CRS than the road parts; "
                                "reproject it")
    if image is None and dsm is None:
        return {}
    if image is None:
        return {"transform": dsm.transform, "ndsm": normalised_dsm(dsm, dsm)}
    cues = image_cues(image, nir_band=nir_band, red_band=red_band, dsm=dsm)
    return {"transform": image.transform, **context_rasters(cues)}


def junctions_job(lines, out_path, options: NetworkOptions = NetworkOptions(), *,
                  extent=None, width_m: float = stage_default(road_strings_from_lines, "width_m"),
                  quality: float = stage_default(road_strings_from_lines, "quality"),
                  progress: Progress = None, **changes) -> dict:
    """Junction construction and network generation (Grote et al. 2012, Sec. 2.3) of any
    line layer (:func:`gisroads.network.junctions.strings_to_network`).

    ``lines``: a line file (or ``path|layername=``), e.g. :func:`linking_job`'s road
    strings or lines drawn by hand; ``width_m`` and ``quality`` fill rows without them.
    ``extent``: ``(xmin, ymin, xmax, ymax)`` of the image the strings come from, in their
    CRS (components leaving it are kept however short). ``options``: of the network stage;
    ``**changes`` change its fields for this call. Writes ``out_path``: the network's layers
    and ``junction_connections``.
    """
    source, lines = lines, _layer(lines, "road_strings")
    strings = road_strings_from_lines(lines, width_m=width_m, quality=quality)
    network, connections = strings_to_network(
        strings, options, extent=None if extent is None else tuple(extent), crs=lines.crs,
        progress=progress, **changes)
    write_geopackage(out_path, {**network.layers(), "junction_connections": connections})
    _warn_if_no_road(network, source)
    kept = int((connections["verified"] & connections["significant"]).sum())
    return {**network_summary(out_path, network), "connections": kept}
