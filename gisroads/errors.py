"""What gisroads reports beside its results: warnings about valid but notable outcomes.

The command line prints a :class:`GisroadsWarning` as one line, ``gisroads: warning: ...``,
and the QGIS algorithms push it to their feedback; Python callers get it through
:mod:`warnings` (``warnings.simplefilter("error", NoRoadFoundWarning)`` turns it into an
exception for those who want one).
"""
from __future__ import annotations

import warnings
from contextlib import contextmanager
from typing import Callable, Iterator


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
