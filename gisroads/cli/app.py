"""The parser of all the subcommands, and :func:`main`: a subcommand run with its outputs
checked first, its warnings, its input errors as one line, a cancel (Ctrl-C, SIGTERM) and
a closed pipe as exit statuses."""
from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

from .. import __version__
from ..errors import INPUT_ERRORS, GisroadsError, reported_warnings
from ..progress import Cancelled
from . import (blocks, demo, evaluate, image, info, job, lidar, snakes, synth, train, update,
               vectorize)
from .options import EPILOG
from .report import ProgressBar

#: The subcommand modules, in the order ``gisroads --help`` lists them.
SUBCOMMANDS = (info, synth, evaluate, lidar, blocks, image, train, vectorize, snakes, demo,
               update, job)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gisroads", epilog=EPILOG,
        description="Road networks from airborne LiDAR and aerial imagery, as GIS layers.")
    parser.add_argument("--version", action="version", version=f"gisroads {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in SUBCOMMANDS:
        command.add_parser(subparsers)
    return parser


#: What the output options name: a file with one of these suffixes, or (None) a folder.
#: ``-o/--out`` names a folder for the commands in _FOLDER_OUT, a GeoPackage for the others.
_OUTPUTS = {"out": (".gpkg",), "qa": (".gpkg",), "changes": (".gpkg",),
            "tagged_las": (".las", ".laz"), "attractor": (".tif", ".tiff"),
            "quicklook": (".png",), "rasters": None, "work_dir": None,
            "probability": (".tif", ".tiff"), "background": (".tif", ".tiff")}
_FOLDER_OUT = {"synth", "demo"}


def check_outputs(args) -> None:
    """Refuse, before any work, an output a job could only fail to write at its end: a
    wrong suffix (``-o roads.shp``), a folder where a file goes or a file where a folder
    goes, or a place that cannot be created or written. Missing folders are created."""
    for dest, suffixes in _OUTPUTS.items():
        path = getattr(args, dest, None)
        if path is None:
            continue
        path = Path(path)
        option = "-o/--out" if dest == "out" else "--" + dest.replace("_", "-")
        if suffixes is None or dest == "out" and args.command in _FOLDER_OUT:
            if path.exists() and not path.is_dir():
                raise GisroadsError(f"{option} {path}: is a file; give a folder")
            _check_writable(path, f"{option} {path}")
            continue
        if dest == "out" and args.command == "train":
            suffixes = (".onnx", ".npz")
        if path.suffix.lower() not in suffixes:
            raise GisroadsError(f"{option} {path}: must end in {' or '.join(suffixes)}")
        if path.is_dir():
            raise GisroadsError(f"{option} {path}: is a folder; give a file name")
        _check_writable(path.parent, f"{option} {path}")


def _check_writable(folder: Path, what: str) -> None:
    """``folder`` is a writable folder, or can be made as one in its nearest existing
    ancestor (``what`` names the option and path in the error)."""
    existing = folder.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise GisroadsError(f"{what}: cannot make the folder {folder}: {existing} is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise GisroadsError(f"{what}: cannot write in {existing}: permission denied")


def _error_text(err: Exception, args) -> str:
    """The one-line error, naming the command's own options where it has them."""
    from ..io.raster import NotGeoreferencedError
    if isinstance(err, NotGeoreferencedError) and hasattr(args, "crs") \
            and err.path == Path(args.input):
        return (f"{err.path}: the image has no georeferencing; give its pixel size and "
                "projected CRS with --pixel METRES --crs CRS (e.g. --pixel 0.3 --crs "
                "EPSG:32633)")
    return str(err)


def cancel_on_sigterm():
    """SIGTERM (``kill``, a program stopping its gisroads run) cancels like Ctrl-C: the
    outputs being written are removed (they are written to temporary files) and the exit
    status is 130. The job stops at its next progress report, where the cancel raises
    (raised in the handler itself it can land inside a C callback, which prints it and
    drops it: threadpoolctl's, or Dask's start-up). Returns the previous handler (None
    outside the main thread, where Python delivers no signal)."""
    import threading
    if threading.current_thread() is not threading.main_thread():
        return None

    def cancel(signum, frame):
        ProgressBar.terminated = True
    return signal.signal(signal.SIGTERM, cancel)


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    notes = []
    ProgressBar.json_lines = getattr(args, "progress_json", False)
    ProgressBar.terminated = False
    previous = None
    try:
        check_outputs(args)
        previous = cancel_on_sigterm()
        with reported_warnings(notes.append):
            status = args.func(args)
        for note in notes:  # after the progress bar and the result
            print(f"gisroads: warning: {note}", file=sys.stderr)
        return status
    except BrokenPipeError:
        # the reader went away (``gisroads info --json f | head``): stop quietly, as a
        # command killed by SIGPIPE does, and keep Python's exit flush from raising again
        devnull = os.open(os.devnull, os.O_WRONLY)
        for stream in (sys.stdout, sys.stderr):
            os.dup2(devnull, stream.fileno())
        return 141
    except INPUT_ERRORS as err:
        ProgressBar.close_all()
        print(f"gisroads: error: {_error_text(err, args)}", file=sys.stderr)
        return 2
    except (Cancelled, KeyboardInterrupt):
        ProgressBar.close_all()
        print("gisroads: cancelled; nothing written", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
