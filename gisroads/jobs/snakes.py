"""The map-guided jobs (Boyko & Funkhouser, 2011): registering a road map on a cloud, its
curb attractor map, and the roads fitted by ribbon snakes."""
from __future__ import annotations

from pathlib import Path

import shapely

from ..errors import GisroadsError
from ..io.las import cloud_crs
from ..io.quicklook import write_quicklook
from ..io.raster import write_geotiff
from ..io.vector import write_geopackage
from ..parallel import Parallel
from ..progress import Progress, report, scaled
from ..snakes.pipeline import CLEARANCE_M, RibbonOptions, curb_attractor, extract_map_guided
from ..snakes.registration import SNAP_M, SUPPORT_RADIUS_M, register_map
from ..snakes.subclouds import read_corridor
from .common import _map_lines, _warn_if_no_road, network_summary, stage_default


def attractor_job(cloud_path, map_source, out_path, *,
                  curb_detector: str = stage_default(curb_attractor, "curb_detector"),
                  cell_m: float = stage_default(curb_attractor, "cell_m"),
                  snap_m: float = SNAP_M, progress: Progress = None) -> dict:
    """Curb attractor map of the road patches of a map over a cloud (Boyko & Funkhouser,
    section 2.3), as a GeoTIFF in the cloud's CRS. ``map_source`` as in
    :func:`snakes_job`; the parameters as in :func:`gisroads.snakes.pipeline.curb_attractor`.
    """
    attractor = curb_attractor(cloud_path, _map_lines(map_source), curb_detector=curb_detector,
                               cell_m=cell_m, snap_m=snap_m,
                               progress=scaled(progress, 0.0, 0.95))
    path = write_geotiff(out_path, attractor, band_names=["attractor"])
    report(progress, 1.0, "done")
    return {"attractor": path, "max": float(attractor.data.max()),
            "shape": list(attractor.shape)}


def snakes_job(cloud_path, map_source, out_path, ribbon: RibbonOptions = RibbonOptions(),
               parallel: Parallel = Parallel(), *, snap_m: float | None = None,
               clearance_m: float = CLEARANCE_M, tagged_las=None, attractor_tif=None,
               quicklook=None, progress: Progress = None, **changes) -> dict:
    """Map-guided road extraction with ribbon snakes (Boyko & Funkhouser, 2011).

    ``map_source``: a line file (the layer its source names, ``path|layername=...``, else
    a GeoPackage's road_centrelines layer, else its first; GeoJSON, any OGR format) or a
    GeoDataFrame, in any CRS: reprojected to the cloud's.
    Writes ``out_path`` (road_centrelines, road_polygons, junctions and the QA layers
    ribbon_patches and registered_map) in the cloud's CRS; optionally ``tagged_las`` (the
    cloud with road points in class 11), ``attractor_tif`` (the patches' attractor maps)
    and a ``quicklook`` PNG (the ribbons and the map over the attractor maps). The
    parameters (``ribbon``, ``parallel``, ``**changes`` to their fields) as in
    :func:`gisroads.snakes.pipeline.extract_map_guided`. When no road is
    fitted the layers are empty, with a :class:`~gisroads.errors.NoRoadFoundWarning`.
    """
    road_map = _map_lines(map_source)
    roads = extract_map_guided(cloud_path, road_map, ribbon, parallel, snap_m=snap_m,
                               clearance_m=clearance_m, tagged_las=tagged_las,
                               attractor=attractor_tif is not None or quicklook is not None,
                               progress=scaled(progress, 0.0, 0.95), **changes)
    network = roads.network
    write_geopackage(out_path, network.layers())
    _warn_if_no_road(network, cloud_path)
    result = {**network_summary(out_path, network), "patches": len(roads.ribbons),
              "converged": sum(r.converged for r in roads.ribbons)}
    if tagged_las is not None:
        result.update(tagged_las=Path(tagged_las), tagged_points=roads.tagged_points)
    if attractor_tif is not None and roads.attractor is not None:
        result["attractor"] = write_geotiff(attractor_tif, roads.attractor,
                                            band_names=["attractor"])
    if quicklook is not None:
        report(progress, 0.97, "drawing the quick-look")
        crs = network.polygons.crs if roads.attractor is None else roads.attractor.crs
        write_quicklook(quicklook, [
            (road_map.to_crs(crs),
             dict(color="deepskyblue", linewidth=1, linestyle="--", label="road map")),
            (network.polygons.to_crs(crs), dict(facecolor="orange", edgecolor="darkorange",
                                                alpha=0.45, linewidth=0.8)),
            (network.centrelines.to_crs(crs),
             dict(color="red", linewidth=1.2, label="road centre lines")),
            (network.junctions.to_crs(crs),
             dict(color="yellow", markersize=20, label="junctions")),
        ], background=roads.attractor,
            title=f"{Path(str(cloud_path)).name}: {len(roads.ribbons)} ribbons over the curb "
                  "attractor")
        result["quicklook"] = Path(quicklook)
    report(progress, 1.0, "done")
    return result


def register_job(cloud_path, map_source, out_path, *,
                 control_spacing_m: float = stage_default(register_map, "control_spacing_m"),
                 sample_spacing_m: float = stage_default(register_map, "sample_spacing_m"),
                 support_radius_m: float = SUPPORT_RADIUS_M,
                 max_incline: float = stage_default(register_map, "max_incline"),
                 snap_m: float = SNAP_M, progress: Progress = None) -> dict:
    """Register a 2D road map onto a LAS/LAZ cloud (Boyko & Funkhouser, section 2.1).

    ``map_source``: a line file (the layer its source names, ``path|layername=...``, else
    a GeoPackage's road_centrelines layer, else its first; GeoJSON, any OGR format) or a
    GeoDataFrame, in any CRS: reprojected to the cloud's.
    Only the points near the map's lines are read, chunk by chunk. Writes the
    ``registered_map`` layer (LineString Z, elevations in metres) to ``out_path`` in the
    cloud's CRS. The parameters as in :func:`gisroads.snakes.registration.register_map`.
    """
    working, source_crs = cloud_crs(cloud_path)
    lines = _map_lines(map_source)
    lines = lines[lines.geometry.notna() & ~lines.geometry.is_empty]
    if len(lines) == 0:
        raise GisroadsError(f"{map_source}: the map holds no line")
    if working is not None:
        if lines.crs is None:
            raise GisroadsError(f"{map_source}: the map has no CRS; cannot match it to the "
                                "cloud")
        lines = lines.to_crs(working)
    report(progress, 0.0, "reading the points along the map")
    # Intersections move line ends by up to the snapping tolerance: read that much wider.
    reach = support_radius_m + snap_m + 0.5
    along = shapely.get_coordinates(shapely.segmentize(lines.geometry.values, 0.5))
    cloud, _ = read_corridor(cloud_path, along, reach)
    if len(cloud) == 0:
        raise GisroadsError(f"{cloud_path}: no point lies along the map's lines; "
                            "does the map cover the cloud?")
    registered = register_map(lines, cloud, control_spacing_m=control_spacing_m,
                              sample_spacing_m=sample_spacing_m,
                              support_radius_m=support_radius_m, max_incline=max_incline,
                              snap_m=snap_m, progress=scaled(progress, 0.5, 0.95))
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
