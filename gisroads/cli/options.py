"""The options several subcommands share, their value types and defaults (the model:
rasterio's ``rio`` options)."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import GisroadsError

EPILOG = "Distances are in metres. Outputs are written in the input's CRS."


def add_command(subparsers, name: str, run, help_text: str,
                description: str) -> argparse.ArgumentParser:
    """The subcommand ``name`` that ``run(args)`` carries out, with ``--json`` and
    ``--progress-json``."""
    p = subparsers.add_parser(name, help=help_text, description=description, epilog=EPILOG)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--progress-json", action="store_true",
                   help="report progress on stderr as JSON lines, {\"progress\": 0.42, "
                        "\"message\": \"...\"} (for programs running gisroads)")
    p.set_defaults(func=run)
    return p


def add_source_and_out(p, source: str, source_help: str) -> None:
    """The positional ``source`` a job reads and the GeoPackage ``-o/--out`` it writes."""
    p.add_argument(source, type=Path, help=source_help)
    p.add_argument("-o", "--out", type=Path, required=True, help="output GeoPackage (.gpkg)")


def add_georeferencing_options(p, what: str) -> None:
    """``--pixel`` and ``--crs`` for ``what`` (an image, a raster) without georeferencing."""
    p.add_argument("--pixel", type=_positive,
                   help=f"pixel size in metres, for {what} without georeferencing")
    p.add_argument("--crs", help=f"projected CRS for {what} without georeferencing, "
                                 "e.g. EPSG:32633")


def add_parallel_options(p, what: str) -> None:
    """--workers, --scheduler and --work-dir: ``what`` (tiles, road patches) as Dask tasks."""
    p.add_argument("--workers", type=int, metavar="N",
                   help=f"{what} in parallel on a local Dask cluster of N worker processes "
                        "(default or 0: one per core; 1 runs them in this process)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help=f"run the {what} on an existing Dask cluster (e.g. "
                        "tcp://host:8786); its workers must see --work-dir")
    p.add_argument("--work-dir", type=Path, metavar="DIR",
                   help=f"keep the points bucketed by tile and the finished {what} here: a "
                        "stopped run started again resumes where it was (default: a "
                        "temporary folder, removed at the end)")


def add_database_options(p) -> None:
    """``--database`` and its options, on the road-extraction subcommands (see
    :func:`then_compare`)."""
    p.add_argument("--database", help="also compare the roads found with this road database "
                                      "(any OGR source, e.g. roads.gpkg or 'PG:dbname=gis'), "
                                      "as gisroads update does")
    p.add_argument("--changes", type=Path,
                   help="GeoPackage of the change layers (default: OUT_changes.gpkg)")
    p.add_argument("--database-layer", help="the database's layer or table (default: its "
                                            "first)")
    p.add_argument("--id-field", help="the database's feature id field (default: its OGR "
                                      "feature ids)")
    p.add_argument("--width-field", help="the database's road width field, metres")


def then_compare(args, result: dict) -> dict:
    """With ``--database``, compare the roads just written with the road database."""
    if args.database is None:
        return result
    from ..jobs import update_job
    changes = args.changes or args.out.with_name(f"{args.out.stem}_changes.gpkg")
    result["changes"] = update_job(args.out, args.database, changes,
                                   layer=args.database_layer, id_field=args.id_field,
                                   width_field=args.width_field)
    return result


def job_default(job, parameter: str):
    """A job's default for ``parameter``: the one its stage defines (see
    :func:`gisroads.jobs.stage_default`), so argparse, QGIS and the docs show the same."""
    from ..jobs import stage_default
    return stage_default(job, parameter)


# The option types keep the names argparse shows for a value they cannot read
# ("argument --tile: invalid _positive value: 'x'").
def _positive(text: str) -> float:
    """A positive number (an option's type)."""
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text} must be positive")
    return value


def _metres(text: str) -> tuple[float, ...]:
    """Comma-separated metres, ``6,9,12`` (an option's type)."""
    from ..jobs import parse_metres
    try:
        return parse_metres(text)
    except GisroadsError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def listed(values) -> str:
    """``6,9,12``: metres as the comma-separated list :func:`_metres` reads."""
    return ",".join(f"{m:g}" for m in values)
