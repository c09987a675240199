"""``gisroads evaluate``: extracted roads scored against a reference."""
from pathlib import Path

from .options import _positive, add_command, job_default
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    from ..jobs import evaluate_job
    p = add_command(
        subparsers, "evaluate", run, "score extracted roads against a reference",
        "Compare extracted road centre lines with reference ones: completeness, "
        "correctness, quality and RMS offset within a buffer (Wiedemann et al. 1998), "
        "connected components and junction precision/recall, an APLS path-length score, "
        "and, when road polygons are available on both sides, Boyko & Funkhouser's "
        "area precision/recall/quality with spill size and direction.")
    p.add_argument("extracted", type=Path,
                   help="extracted centre lines (GeoPackage: layer road_centrelines)")
    p.add_argument("reference", type=Path, help="reference centre lines (any line file)")
    p.add_argument("--buffer", type=_positive, default=job_default(evaluate_job, "buffer_m"),
                   help="buffer width in metres, about half a carriageway (default "
                        "%(default)g)")
    p.add_argument("--cell", type=_positive, default=job_default(evaluate_job, "cell_m"),
                   help="grid cell for the area metrics in metres (default %(default)g)")
    p.add_argument("--junction-radius", type=_positive,
                   default=job_default(evaluate_job, "junction_radius_m"),
                   help="distance within which junctions match, metres (default "
                        "%(default)g)")
    p.add_argument("--extracted-polygons", type=Path,
                   help="road area of the extraction (default: its road_polygons layer)")
    p.add_argument("--reference-polygons", type=Path,
                   help="reference road area (default: its road_polygons layer)")
    p.add_argument("--valid-area", type=Path,
                   help="polygon file: score only inside it (e.g. the surveyed area)")
    p.add_argument("--reference-junctions", type=Path,
                   help="point file of the reference's digitised junctions (default: the "
                        "nodes where three or more of its lines meet)")
    p.add_argument("--qa", type=Path,
                   help="write matched/missed/false pieces to this GeoPackage")


def run(args) -> int:
    from ..evaluate import format_report
    from ..jobs import evaluate_job
    results = evaluate_job(args.extracted, args.reference, buffer_m=args.buffer,
                           cell_m=args.cell, junction_radius_m=args.junction_radius,
                           extracted_polygons=args.extracted_polygons,
                           reference_polygons=args.reference_polygons,
                           reference_junctions=args.reference_junctions,
                           valid_area=args.valid_area, qa_path=args.qa,
                           progress=ProgressBar(not args.json))
    print_result(results, args.json, format_report(results))
    return 0
