"""How jobs talk to their callers: progress and cancel, and results as strict JSON.

The progress protocol every long stage accepts, so the CLI and QGIS can show and cancel it.

A progress callback is ``progress(fraction, message)`` with ``fraction`` in [0, 1]. To cancel,
the callback raises :class:`Cancelled`; stages write through temporary files, so a cancel
leaves no partial output behind.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from collections.abc import Callable

Progress = Callable[[float, str], None] | None


class Cancelled(Exception):
    """Raised by a progress callback to stop the work."""


def report(progress: Progress, fraction: float, message: str = "") -> None:
    """Call ``progress`` if there is one."""
    if progress is not None:
        progress(min(max(float(fraction), 0.0), 1.0), message)


def scaled(progress: Progress, start: float, stop: float, label: str = "") -> Progress:
    """A callback mapping [0, 1] of a sub-step onto [start, stop] of the whole job; its
    messages start with ``label: `` when one is given (a job of several pipelines)."""
    if progress is None:
        return None
    prefix = f"{label}: " if label else ""
    return lambda fraction, message="": progress(start + (stop - start) * fraction,
                                                 prefix + message)


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "item"):  # numpy scalars
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def to_json(result) -> str:
    """Strict JSON of a job's result: NaN (an undefined ratio) becomes null."""
    return json.dumps(_plain(result), indent=2, allow_nan=False)
