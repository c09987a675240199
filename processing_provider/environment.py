"""gisroads' own Python environment, made on first use inside the QGIS profile.

When QGIS's Python lacks gisroads' packages (Debian 12's QGIS: shapely 1.8), the algorithms
run an external ``gisroads`` command (:mod:`.external`). This module makes one the way the
GRASS and SAGA providers rely on their tools being there, but without the user's help: a
virtual environment of QGIS's own interpreter (``python -m venv``) in the profile folder,
into which pip installs the gisroads wheel that the plugin carries, with its dependencies
from the package index the user's pip is configured for (pip.conf, ``PIP_INDEX_URL``, a
proxy). The environment counts as made only once its stamp file is written, after its
``gisroads --version`` ran; a failed or cancelled set-up removes the folder.

Standard library only: it runs where gisroads cannot import.
"""
from __future__ import annotations

import json
import os
import queue
import re
import shutil
import subprocess
import sys
import threading
from pathlib import Path

#: Folder of the environment inside the QGIS profile folder.
FOLDER = "gisroads/environment"
#: Written last into a finished environment.
STAMP = "gisroads-environment.json"
#: Oldest Python that gisroads runs on (pyproject.toml's requires-python).
MIN_PYTHON = (3, 11)
#: pip's messages when it cannot reach or does not find a package on its index.
_INDEX_TROUBLE = re.compile(
    r"No matching distribution|Could not find a version|Failed to establish a new connection|"
    r"Temporary failure in name resolution|Name or service not known|ProxyError|"
    r"Max retries exceeded|Could not fetch URL|SSLError|ConnectTimeout|ReadTimeout")
_INDEX_HELP = ("connect to the internet, or give pip an index it can reach (pip config set "
               "global.index-url URL, or the PIP_INDEX_URL environment variable; a proxy in "
               "HTTPS_PROXY), then run Set up gisroads again; or name an existing gisroads "
               "command in the QGIS setting gisroads/executable")


class SetupError(Exception):
    """What failed and what to do, in one message."""


def interpreter() -> Path:
    """QGIS's own Python interpreter: the one beside the running library (inside QGIS
    ``sys.executable`` is QGIS itself, or whatever ``python3`` comes first on PATH).

    Raises
    ------
    SetupError
        None found beside the running Python.
    """
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    candidates = []
    for prefix in dict.fromkeys([Path(sys.exec_prefix), Path(sys.base_exec_prefix)]):
        candidates += [prefix / "bin" / f"python{version}", prefix / "bin" / "python3",
                       prefix / "python.exe", prefix / "python3.exe"]
    for candidate in candidates:
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
    raise SetupError(f"QGIS's Python interpreter was not found in {sys.exec_prefix}: name an "
                     "existing gisroads command in the QGIS setting gisroads/executable")


def executable_in(folder) -> Path:
    """The ``gisroads`` command of an environment folder."""
    folder = Path(folder)
    return (folder / "Scripts" / "gisroads.exe" if os.name == "nt"
            else folder / "bin" / "gisroads")


def ready_executable(folder) -> str | None:
    """The ``gisroads`` command of a finished environment (stamp written), else None."""
    executable = executable_in(folder)
    return str(executable) if (Path(folder) / STAMP).is_file() and executable.is_file() else None


def bundled_wheel(plugin_folder) -> Path | None:
    """The gisroads wheel the plugin carries (``wheels/gisroads-*.whl``), None without one."""
    wheels = sorted(Path(plugin_folder, "wheels").glob("gisroads-*.whl"))
    return wheels[-1] if wheels else None


def _stream(command, *, progress, cancelled, share: tuple[float, float], expected: int,
            env) -> tuple[int, list[str]]:
    """Run ``command``, reporting progress within ``share`` from the packages pip names
    (``expected`` of them fill it); returns its exit status and its output lines. A cancel,
    polled twice a second even while pip is silent (a large download), terminates it and
    raises SetupError."""
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, env=env)
    output: queue.Queue = queue.Queue()

    def read():
        for line in process.stdout:
            output.put(line)
        output.put(None)

    threading.Thread(target=read, daemon=True).start()
    lines, seen, finished = [], 0, False
    try:
        while not cancelled():
            try:
                line = output.get(timeout=0.5)
            except queue.Empty:
                continue
            if line is None:
                finished = True
                break
            line = line.rstrip()
            if not line:
                continue
            lines.append(line)
            if line.startswith(("Collecting ", "Processing ")):
                seen += 1
                progress(share[0] + (share[1] - share[0]) * min(seen / expected, 1.0), line)
            elif line.startswith("Installing collected packages"):
                progress(share[1], "installing the packages")
    finally:
        if not finished and process.poll() is None:
            process.terminate()
        status = process.wait()
    if cancelled():
        raise SetupError("cancelled")
    return status, lines


def create_environment(folder, wheel, *, python=None, progress=None, cancelled=None,
                       expected_packages: int = 40) -> str:
    """Make gisroads' environment in ``folder`` and return its ``gisroads`` command.

    Parameters
    ----------
    folder : str or Path
        Where the environment goes (replaced if it is there already).
    wheel : str or Path
        The gisroads wheel to install; its dependencies come from pip's configured index.
    python : str or Path, optional
        The interpreter of the environment; QGIS's own (:func:`interpreter`) when None.
    progress : callable, optional
        ``progress(fraction, message)``.
    cancelled : callable, optional
        Polled while pip runs; True stops the set-up.
    expected_packages : int
        How many packages pip is expected to name (the progress bar's length).

    Raises
    ------
    SetupError
        What failed and what to do; the folder is removed.
    """
    progress = progress or (lambda fraction, message: None)
    cancelled = cancelled or (lambda: False)
    folder, wheel = Path(folder), Path(wheel)
    if not wheel.is_file():
        raise SetupError(f"{wheel}: no gisroads wheel to install (reinstall the plugin from "
                         "its ZIP, which carries one)")
    python = Path(python) if python is not None else interpreter()
    try:
        found = subprocess.run([str(python), "-c", "import sys; print(*sys.version_info[:2])"],
                               capture_output=True, text=True)
    except OSError as error:
        raise SetupError(f"{python} does not run ({error.strerror}): name an existing "
                         "gisroads command in the QGIS setting gisroads/executable") from None
    version = tuple(int(v) for v in found.stdout.split()) if found.returncode == 0 else ()
    if version < MIN_PYTHON:
        raise SetupError(
            f"{python} is Python {'.'.join(map(str, version)) or 'of unknown version'}; "
            f"gisroads needs Python {'.'.join(map(str, MIN_PYTHON))} or newer: install "
            f"{wheel.name} with a newer Python (python3 -m venv DIR, then DIR/bin/pip install "
            f"{wheel}) and name DIR's gisroads command in the QGIS setting "
            "gisroads/executable")
    env = {**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1", "PIP_PROGRESS_BAR": "off",
           "PYTHONUNBUFFERED": "1"}
    env.pop("PYTHONPATH", None)  # QGIS's own packages must not leak into the environment
    env.pop("PYTHONHOME", None)
    shutil.rmtree(folder, ignore_errors=True)
    try:
        progress(0.0, f"making a Python environment in {folder} with {python}")
        made = subprocess.run([str(python), "-m", "venv", str(folder)], capture_output=True,
                              text=True, env=env)
        if made.returncode != 0:
            detail = (made.stderr or made.stdout).strip().splitlines()
            raise SetupError(
                f"{python} could not make a virtual environment ({detail[-1] if detail else ''})"
                ": on Debian and Ubuntu install its venv module (sudo apt install "
                "python3-venv), then run Set up gisroads again")
        pip = (folder / ("Scripts" if os.name == "nt" else "bin")
               / ("python.exe" if os.name == "nt" else "python"))
        status, lines = _stream([str(pip), "-m", "pip", "install", str(wheel)],
                                progress=progress, cancelled=cancelled, share=(0.1, 0.9),
                                expected=expected_packages, env=env)
        if status != 0:
            trouble = [line for line in lines if _INDEX_TROUBLE.search(line)]
            if trouble:
                raise SetupError(f"pip could not get gisroads' dependencies from its package "
                                 f"index ({trouble[-1].strip()}): {_INDEX_HELP}")
            errors = [line for line in lines if line.startswith("ERROR")] or lines[-1:]
            raise SetupError(f"pip failed to install {wheel.name} (exit status {status}: "
                             f"{errors[-1].strip() if errors else 'no output'}); "
                             f"{_INDEX_HELP}")
        progress(0.95, "checking the gisroads command")
        executable = executable_in(folder)
        checked = subprocess.run([str(executable), "--version"], capture_output=True,
                                 text=True, env=env)
        if checked.returncode != 0 or not checked.stdout.startswith("gisroads"):
            detail = (checked.stderr or checked.stdout).strip().splitlines()
            raise SetupError(f"the installed {executable} does not run "
                             f"({detail[-1] if detail else checked.returncode})")
        (folder / STAMP).write_text(json.dumps(
            {"python": str(python), "wheel": wheel.name,
             "version": checked.stdout.strip()}) + "\n")
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    progress(1.0, f"{checked.stdout.strip()} is ready: {executable}")
    return str(executable)
