"""The ``gisroads`` command: one subcommand per job, progress on stderr, ``--json`` for scripts.

Errors in the input (unreadable or empty files, missing georeferencing, bad values) print one
line, ``gisroads: error: ...``, and exit with status 2; nothing is written. Any other exception
is a bug and keeps its traceback (see :mod:`gisroads.errors`). Warnings (no road found: the
outputs hold empty layers) print ``gisroads: warning: ...`` after the command's output, which
still exits 0.

One module per subcommand, each with ``add_parser(subparsers)`` (its arguments and help) and
``run(args)`` (the job, its result printed; returns the exit status); the options several
subcommands share are in :mod:`.options`, the progress display and the printed result in
:mod:`.report`, the parser and the error handling around a run in :mod:`.app`.
"""
from .app import build_parser, main

__all__ = ["build_parser", "main"]
