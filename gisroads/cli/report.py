"""What a subcommand shows: its progress on stderr and its result on stdout (as JSON with
``--json``)."""
from __future__ import annotations

import json
import sys

from ..progress import Cancelled, to_json


class ProgressBar:
    """Progress on stderr: a tqdm bar on a terminal; elsewhere (a log file, a pipe, CI),
    where a bar's carriage returns garble the text, one line per 10 %; with
    ``--progress-json`` (even with ``--json``), one JSON object per line for a program
    driving gisroads, ``{"progress": 0.42, "message": "..."}`` at each percent or new
    message (other stderr lines, ``gisroads: ...``, are warnings and errors)."""

    active: list[ProgressBar] = []
    """Bars on screen, closed before an error or a cancel is printed (:func:`.app.main`)."""
    json_lines = False
    """Set by :func:`.app.main` from ``--progress-json``."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.tty = sys.stderr.isatty()
        self.last = -1
        self.message = None
        self.bar = None

    terminated = False
    """Set by SIGTERM (:func:`.app.cancel_on_sigterm`): the next report raises
    :class:`~gisroads.progress.Cancelled`, and every later one again."""

    def __call__(self, fraction: float, message: str = "") -> None:
        if ProgressBar.terminated:
            raise Cancelled()
        percent = max(0, min(100, int(fraction * 100)))
        if self.json_lines:
            if percent != self.last or message != self.message:
                sys.stderr.write(json.dumps({"progress": round(min(max(fraction, 0.0), 1.0),
                                                               4), "message": message}) + "\n")
                sys.stderr.flush()
                self.last, self.message = percent, message
            return
        if not self.enabled:
            return
        if self.tty:
            self._draw(percent, message)
            if fraction >= 1.0:
                self.close()
            return
        if percent // 10 != self.last // 10 or fraction >= 1.0 and self.last < 100:
            sys.stderr.write(f"{percent:3d}% {message}\n")
            sys.stderr.flush()
            self.last = percent

    def _draw(self, percent: int, message: str) -> None:
        if self.bar is None:
            from tqdm import tqdm
            self.bar = tqdm(total=100, file=sys.stderr, dynamic_ncols=True, leave=True,
                            bar_format="{percentage:3.0f}%|{bar}| {elapsed}<{remaining} "
                                       "{desc}")
            ProgressBar.active.append(self)
        self.bar.set_description_str(message[:40], refresh=False)
        self.bar.update(percent - self.bar.n)  # tqdm takes steps back too

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
            ProgressBar.active.remove(self)

    @classmethod
    def close_all(cls) -> None:
        for bar in list(cls.active):
            bar.close()


def as_text(value, key: str = "") -> str:
    """A result value as a person reads it: floats to 10 significant digits, durations
    (keys ending in ``_s``) in seconds, a dict as ``name value`` pairs, None as ``none``."""
    if isinstance(value, dict):
        return ", ".join(f"{k} {as_text(v, key)}" for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(as_text(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.2f} s" if key.endswith("_s") else f"{value:.10g}"
    return "none" if value is None else str(value)


def print_result(result: dict, as_json: bool, text: str | None = None) -> None:
    """``result`` as JSON, else ``text`` (by default a ``key: value`` line per item)."""
    if text is None:
        text = "\n".join(f"{k}: {as_text(v, k)}" for k, v in result.items())
    print(to_json(result) if as_json else text)
    sys.stdout.flush()  # a closed pipe raises here, inside main's handler, not at exit
