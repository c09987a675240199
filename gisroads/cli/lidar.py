"""``gisroads lidar``: roads from a LAS/LAZ point cloud (Zhu & Mordohai)."""
from pathlib import Path

from .options import (_metres, _positive, add_command, add_database_options,
                      add_parallel_options, job_default, listed, then_compare)
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    p = add_command(
        subparsers, "lidar", run, "extract roads from a LAS/LAZ point cloud (Zhu & Mordohai)",
        "Extract the road network of an airborne LiDAR point cloud: ground planes on "
        "several levels, a 0.5 m intensity image per level, edges and a normalized-cut "
        "segmentation, rectangle road hypotheses scored by boundary and interior "
        "filters, per-width likelihood maps and a minimum cover of the hypotheses. "
        "Writes road centre lines with widths, road polygons, junctions and the QA "
        "layers rectangles and hypotheses to a GeoPackage in the cloud's CRS.")
    p.add_argument("input", nargs="+", help="LAS/LAZ point cloud with intensity; or several "
                   "files, a folder of them or a quoted glob ('tiles/*.laz'): tiles of one "
                   "area in one CRS, read as one cloud")
    p.add_argument("-o", "--out", type=Path, required=True, help="output GeoPackage (.gpkg)")
    add_parallel_options(p, "tiles")
    _add_cue_options(p)
    _add_hypothesis_options(p)
    p.add_argument("--tagged-las", type=Path,
                   help="also write the cloud with road points classified 11")
    p.add_argument("--rasters", type=Path,
                   help="also write intensity, likelihood and ground-height GeoTIFFs here "
                        "(with --cue evidence: road_evidence.tif)")
    p.add_argument("--background", type=Path,
                   help="also write a GeoTIFF to show beneath the roads: the ground intensity "
                        "image where the cloud has intensity, else the road evidence (with "
                        "its QGIS style beside it, .qml)")
    p.add_argument("--quicklook", type=Path, help="also draw a PNG of the result")
    add_database_options(p)


def _add_cue_options(p) -> None:
    """--cue and the --threshold of the evidence cue."""
    from ..jobs import lidar_job
    from ..lidar.pipeline import CUES
    p.add_argument("--cue", choices=CUES, default=job_default(lidar_job, "cue"),
                   help="evidence (default): the road likelihood of every cue the cloud "
                        "carries (intensity, height above the terrain, density, roughness, "
                        "slope, returns, classification, kerbs) through the network stage; "
                        "intensity: the paper's rectangles on the ground intensity alone")
    p.add_argument("--threshold", type=float, default=job_default(lidar_job, "threshold"),
                   help="with --cue evidence: road likelihood at which a cell is road "
                        "(0-1, default %(default)g)")
    p.add_argument("--model", type=Path,
                   help="an evidence model learned from a road layer of the area "
                        "('gisroads train CLOUD ROADS -o model.npz'): its probability "
                        "replaces the evidence rule's likelihood")


def _add_hypothesis_options(p) -> None:
    """The intensity image, the rectangle sizes, the tiles and the segments."""
    from ..jobs import lidar_job
    p.add_argument("--cell", type=_positive,
                   help="intensity image cell in metres (default: 0.5, or the mean point "
                        "spacing of a sparser cloud)")
    p.add_argument("--widths", type=_metres, default=job_default(lidar_job, "widths_m"),
                   help="road widths to try, metres (default "
                        f"{listed(job_default(lidar_job, 'widths_m'))})")
    p.add_argument("--lengths", type=_metres, default=job_default(lidar_job, "lengths_m"),
                   help="rectangle lengths to try, metres (default "
                        f"{listed(job_default(lidar_job, 'lengths_m'))})")
    p.add_argument("--tile", type=_positive, default=job_default(lidar_job, "tile_m"),
                   help="tile side, metres (%(default)g)")
    p.add_argument("--overlap", type=float, default=job_default(lidar_job, "overlap_m"),
                   help="overlap with each neighbouring tile, metres (%(default)g)")
    p.add_argument("--segments", type=int, default=job_default(lidar_job, "n_segments"),
                   help="number of NCut segments per tile image (default %(default)s)")


def run(args) -> int:
    from ..jobs import lidar_job
    from ..parallel import default_workers
    source = args.input[0] if len(args.input) == 1 else args.input
    result = lidar_job(source, args.out, cue=args.cue, cell_m=args.cell, tile_m=args.tile,
                       overlap_m=args.overlap, widths_m=args.widths, lengths_m=args.lengths,
                       n_segments=args.segments, threshold=args.threshold,
                       workers=args.workers or default_workers(), scheduler=args.scheduler,
                       work_dir=args.work_dir, tagged_las=args.tagged_las,
                       rasters_dir=args.rasters, background=args.background,
                       quicklook=args.quicklook, model=args.model,
                       progress=ProgressBar(not args.json))
    print_result(then_compare(args, result), args.json)
    return 0
