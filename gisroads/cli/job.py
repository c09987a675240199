"""``gisroads job``: one job of :mod:`gisroads.jobs` with keyword arguments as JSON (what the
QGIS provider runs in external-tool mode for the pipeline stages)."""
import json

from ..errors import GisroadsError
from .options import add_command
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    p = add_command(
        subparsers, "job", run, "run one job of gisroads.jobs with JSON arguments",
        "Run one job of the gisroads.jobs module, e.g. ground_intensity_job, with its "
        "keyword arguments as a JSON object (paths as strings, tuples as lists): the QGIS "
        "algorithms run this when QGIS's Python lacks gisroads' packages. --defaults "
        "prints every job's defaults instead, as JSON.")
    p.add_argument("name", nargs="?", help="the job, e.g. ground_intensity_job")
    p.add_argument("arguments", nargs="?", default="{}",
                   help="keyword arguments as a JSON object (default {})")
    p.add_argument("--defaults", action="store_true",
                   help="print the defaults of every job's keyword arguments as JSON")


def run(args) -> int:
    from ..jobs import JOBS, job_defaults, run_job
    if args.defaults:
        print_result({name: job_defaults(name) for name in JOBS}, True)
        return 0
    if args.name is None:
        raise GisroadsError(f"name a job: {', '.join(sorted(JOBS))}")
    try:
        arguments = json.loads(args.arguments)
    except json.JSONDecodeError as error:
        raise GisroadsError(f"the arguments are not JSON: {error}") from None
    if not isinstance(arguments, dict):
        raise GisroadsError("the arguments must be a JSON object of keyword arguments")
    result = run_job(args.name, arguments, ProgressBar(not args.json))
    print_result(result, args.json)
    return 0
