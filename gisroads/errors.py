"""What gisroads reports beside its results: the errors of inputs it cannot work on, and
warnings about valid but notable outcomes.

Errors: :class:`GisroadsError` is the family of gisroads' own errors: every input or
argument gisroads refuses on purpose (a stage's argument check, a file missing, unreadable
or of the wrong kind) raises it or a subclass (:class:`~gisroads.io.las.LasError`,
:class:`~gisroads.io.raster.RasterError` and its
:class:`~gisroads.io.raster.NotGeoreferencedError`, :class:`MissingFileError`). It is a
ValueError, so the stages' documented contract, "raises ValueError", holds. The command
line and the QGIS algorithms catch :data:`INPUT_ERRORS`, each in one place, and report
them as one line (``gisroads: error: ...``, a QgsProcessingException); anything else,
such as a ValueError raised inside numpy or shapely, is a bug and keeps its traceback.

Warnings: the command line prints a :class:`GisroadsWarning` as one line,
``gisroads: warning: ...``, and the QGIS algorithms push it to their feedback; Python
callers get it through :mod:`warnings` (``warnings.simplefilter("error",
NoRoadFoundWarning)`` turns it into an exception for those who want one).
"""
from __future__ import annotations

import warnings
from contextlib import contextmanager
from collections.abc import Callable, Iterator


class GisroadsError(ValueError):
    """An input gisroads cannot work on (a file missing, unreadable or of the wrong kind), an
    argument a stage refuses, or a job left with nothing it could write."""


class MissingFileError(GisroadsError, FileNotFoundError):
    """An input file that does not exist (also a FileNotFoundError)."""


INPUT_ERRORS = (GisroadsError, FileNotFoundError)
"""What the command line and the QGIS algorithms report as a one-line error: the
:class:`GisroadsError` family, and a file a library found missing on its own (an input
that went away, a path inside a list): a user's error, not a bug. Any other exception,
a plain ValueError included, keeps its traceback."""


class GisroadsWarning(UserWarning):
    """Base class of gisroads' warnings."""


class NoRoadFoundWarning(GisroadsWarning):
    """A road job found no road and wrote its outputs with empty layers.

    Empty is a valid answer (a forest plot, a field): the GeoPackage holds the contract
    layers with their fields and geometry types, and no feature.
    """


@contextmanager
def reported_warnings(report: Callable[[str], None]) -> Iterator[None]:
    """Hand every :class:`GisroadsWarning` raised in the block to ``report`` (its message),
    each time it is raised, instead of printing it; other warnings show as usual.

    Parameters
    ----------
    report : callable
        Gets each warning's message, e.g. a QGIS feedback's ``pushWarning``.
    """
    with warnings.catch_warnings():
        # "always": a long-lived process (QGIS) runs many jobs from the same line
        warnings.simplefilter("always", GisroadsWarning)
        show = warnings.showwarning

        def show_or_report(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, GisroadsWarning):
                report(str(message))
            else:
                show(message, category, filename, lineno, file, line)

        warnings.showwarning = show_or_report
        yield
