"""``gisroads vectorize``: any road raster (mask or probability) to a road network."""
from pathlib import Path

from .options import add_command, add_georeferencing_options, add_source_and_out, job_default
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    from ..jobs import vectorize_job
    p = add_command(
        subparsers, "vectorize", run, "any road raster (mask or probability) to a network",
        "Turn a road raster (a binary mask, or a road probability 0-1 or 0-255: a "
        "deep-learning segmentation, a classified land-cover map, a thresholded index) "
        "into a clean, connected road network: smoothed, thresholded and cleaned, "
        "skeletonised tile by tile, spurs pruned, junction clusters contracted into single "
        "nodes, gaps across occlusions bridged by an integer program, junctions built, "
        "insignificant pieces dropped. Writes road centre lines with widths (from the "
        "raster), road polygons, junctions and the QA layers gap_edges, "
        "junction_connections and rejected to a GeoPackage in the raster's CRS.")
    add_source_and_out(p, "input", "road raster: GeoTIFF (or PNG with --pixel and --crs)")
    p.add_argument("--threshold", type=float, default=job_default(vectorize_job, "threshold"),
                   help="road probability threshold, 0-1 (a 0-255 raster is scaled to 0-1 "
                        "first; default %(default)g)")
    p.add_argument("--band", type=int,
                   help="1-based band to read (default: the first of a one- or two-band "
                        "raster; a raster of three or more bands needs it)")
    p.add_argument("--wide-areas", action="store_true",
                   help="draw the roads through car parks and plazas, not their outlines and "
                        "aisles (what 'gisroads image' does with its own probability)")
    add_georeferencing_options(p, "a raster")
    p.add_argument("--quicklook", type=Path, help="also draw a PNG of the result")


def run(args) -> int:
    from ..jobs import vectorize_job
    result = vectorize_job(args.input, args.out, band=args.band, threshold=args.threshold,
                           pixel_m=args.pixel, crs=args.crs, wide_areas=args.wide_areas,
                           quicklook=args.quicklook,
                           progress=ProgressBar(not args.json))
    print_result(result, args.json)
    return 0
