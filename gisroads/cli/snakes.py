"""``gisroads snakes``: road boundaries along a road map (Boyko & Funkhouser)."""
from pathlib import Path

from .options import (add_command, add_database_options, add_parallel_options,
                      add_source_and_out, job_default, then_compare)
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    from ..jobs import snakes_job
    p = add_command(
        subparsers, "snakes", run, "road boundaries along a road map (Boyko & Funkhouser)",
        "Fit the roads of an approximate road map to a LAS/LAZ point cloud: register "
        "the map in 3D, cut a subcloud per road, build a curb attractor map, its "
        "gradient vector flow, and fit a ribbon snake from kerb to kerb. Writes road "
        "centre lines with widths, road polygons (with their level), junctions from the "
        "map's topology and the QA layers ribbon_patches and registered_map to a "
        "GeoPackage in the cloud's CRS.")
    add_source_and_out(p, "input", "LAS/LAZ point cloud")
    p.add_argument("map", type=Path, help="road map lines (GeoPackage, GeoJSON, any OGR "
                                          "line layer, any CRS)")
    p.add_argument("--curb-detector", choices=("exp", "step", "none"),
                   default=job_default(snakes_job, "curb_detector"),
                   help="height weighting of the curb detector: exp (Gaussian, 15 cm mean, "
                        "5 cm deviation; default), step (10-20 cm) or none")
    p.add_argument("--tagged-las", type=Path,
                   help="also write the cloud with road points classified 11")
    p.add_argument("--attractor", type=Path, help="also write the attractor map (GeoTIFF)")
    p.add_argument("--quicklook", type=Path,
                   help="also draw a PNG of the ribbons and the map over the attractor")
    add_parallel_options(p, "road patches")
    add_database_options(p)


def run(args) -> int:
    from ..jobs import snakes_job
    from ..parallel import default_workers
    result = snakes_job(args.input, args.map, args.out, curb_detector=args.curb_detector,
                        tagged_las=args.tagged_las, attractor_tif=args.attractor,
                        quicklook=args.quicklook,
                        workers=args.workers or default_workers(), scheduler=args.scheduler,
                        work_dir=args.work_dir, progress=ProgressBar(not args.json))
    print_result(then_compare(args, result), args.json)
    return 0
