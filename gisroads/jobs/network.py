"""The network job: any road raster (a mask or a probability) to a road network."""
from __future__ import annotations

from pathlib import Path

from ..errors import GisroadsError
from ..network.rasters import THRESHOLD, raster_to_network
from ..progress import Progress, report, scaled
from .common import _network_quicklook, _write_network, network_summary, read_image


def vectorize_job(raster_path, out_path, *, band: int | None = None,
                  threshold: float = THRESHOLD,
                  pixel_m: float | None = None, crs=None, quicklook=None,
                  progress: Progress = None) -> dict:
    """Any road raster (mask or probability) to a road network in a GeoPackage.

    Writes road_centrelines, road_polygons, junctions and the QA layers gap_edges,
    junction_connections and rejected in the raster's CRS (a geographic raster is worked
    in its UTM zone); optionally a ``quicklook`` PNG. See
    :func:`gisroads.network.rasters.raster_to_network`. ``band``: the 1-based band to read;
    by default the first of a one- or two-band raster, and a raster of three or more bands
    (an image, most likely) is refused.
    """
    raster, source_crs = read_image(raster_path, pixel_m=pixel_m, crs=crs)
    bands = raster.data.shape[0] if raster.data.ndim == 3 else 1
    if band is None and bands >= 3:
        raise GisroadsError(
            f"{raster_path} has {bands} bands, like an image: vectorize takes a road "
            "probability or mask (one band, 0-1 or 0-255); give --band N to read one band "
            "of it, or run 'gisroads image' on an aerial image")
    network = raster_to_network(raster, band=band or 1, threshold=threshold,
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
