"""The network job: any road raster (a mask or a probability) to a road network."""
from __future__ import annotations

from pathlib import Path

from ..network.rasters import THRESHOLD, raster_to_network
from ..progress import Progress, report, scaled
from .common import _network_quicklook, _write_network, network_summary, read_image


def vectorize_job(raster_path, out_path, *, band: int = 1, threshold: float = THRESHOLD,
                  pixel_m: float | None = None, crs=None, quicklook=None,
                  progress: Progress = None) -> dict:
    """Any road raster (mask or probability) to a road network in a GeoPackage.

    Writes road_centrelines, road_polygons, junctions and the QA layers gap_edges,
    junction_connections and rejected in the raster's CRS (a geographic raster is worked
    in its UTM zone); optionally a ``quicklook`` PNG. See
    :func:`gisroads.network.rasters.raster_to_network`.
    """
    raster, source_crs = read_image(raster_path, pixel_m=pixel_m, crs=crs)
    network = raster_to_network(raster, band=band, threshold=threshold,
                                progress=scaled(progress, 0.0, 0.95))
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
