"""``gisroads update``: extracted roads compared with a road database."""
from pathlib import Path

from .options import _positive, add_command, job_default
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    from ..jobs import update_job
    p = add_command(
        subparsers, "update", run, "compare extracted roads with a road database",
        "Match extracted road centre lines to the lines of a road database and write "
        "the changes to a GeoPackage in the database's CRS: confirmed (database roads "
        "seen, with offsets and widths), missing (roads or stretches not seen, and "
        "whether the data could have seen them), new (extracted roads absent from the "
        "database, and the database roads they meet), moved (roads off by more than "
        "the tolerance, with the proposed geometry) and proposed_update (the database "
        "with the updates applied and a change field). The database's ids and "
        "attributes are carried through unchanged.")
    p.add_argument("extracted", type=Path,
                   help="extracted centre lines (GeoPackage: layer road_centrelines)")
    p.add_argument("database", help="road database: any OGR source, e.g. roads.gpkg, "
                                    "roads.shp or 'PG:dbname=gis host=localhost'")
    p.add_argument("-o", "--out", type=Path, required=True, help="output GeoPackage (.gpkg)")
    p.add_argument("--layer", help="the database's layer or table (default: its first)")
    p.add_argument("--id-field", help="the database's feature id field (default: its "
                                      "OGR feature ids)")
    p.add_argument("--width-field", help="the database's road width field, metres "
                                         "(default: widths measured, not compared)")
    p.add_argument("--tolerance", type=_positive,
                   default=job_default(update_job, "tolerance_m"),
                   help="offset above which a road has moved, metres (default %(default)g)")
    p.add_argument("--search", type=_positive, default=job_default(update_job, "search_m"),
                   help="largest offset still matched as the same road, metres (default "
                        "%(default)g)")
    p.add_argument("--coverage", type=Path,
                   help="where the data could show a road: polygons, or a raster with "
                        "non-zero observable cells (data footprint minus occlusion)")
    p.add_argument("--quicklook", type=Path,
                   help="also draw a PNG of the changes over the database's roads")


def run(args) -> int:
    from ..jobs import update_job
    result = update_job(args.extracted, args.database, args.out, layer=args.layer,
                        id_field=args.id_field, width_field=args.width_field,
                        tolerance_m=args.tolerance, search_m=args.search,
                        coverage=args.coverage, quicklook=args.quicklook,
                        progress=ProgressBar(not args.json))
    print_result(result, args.json, _summary(result))
    return 0


def _summary(result: dict) -> str:
    """The counts in words: the layers hold features (a missing stretch of a road that is
    otherwise seen is one), the changes count database roads."""
    from ..update import LAYERS
    layers = ", ".join(f"{name} {result[name]}" for name in LAYERS)
    roads = ", ".join(f"{name} {count}" for name, count in result["changes"].items())
    lines = [f"gpkg: {result['gpkg']}", f"features per layer: {layers}",
             f"database roads by change: {roads} (missing: the whole road unseen; new: "
             "extracted roads the database lacks)"]
    if "quicklook" in result:
        lines.append(f"quicklook: {result['quicklook']}")
    return "\n".join(lines)
