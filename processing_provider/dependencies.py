"""The Python packages the gisroads algorithms need, checked before any of them is imported.

QGIS runs plugins in its own Python (Debian 12: /usr/bin/python3, whose shapely is 1.8 and
which has no laspy or lazrs). Importing gisroads there fails deep inside shapely or laspy
with a traceback; this module looks at the installed versions first (package metadata, no
import) so the plugin can say in one message what is missing and how to fix it.
Standard library only: it must import in any QGIS.
"""
from __future__ import annotations

import importlib.metadata
import importlib.util
import re
import sys

#: (module, distribution, minimum version): pyproject.toml's dependencies that the
#: algorithms import (not needed inside QGIS: scikit-learn trains the learned cue, dask runs
#: LiDAR tiles on a cluster, imported only then, tqdm draws the command line's progress bar,
#: threadpoolctl pins BLAS threads where it is installed and is skipped where not).
REQUIREMENTS = [
    ("numpy", "numpy", "1.24"),
    ("scipy", "scipy", "1.10"),
    ("skimage", "scikit-image", "0.19"),
    ("networkx", "networkx", "2.8"),
    ("shapely", "shapely", "2.0"),
    ("geopandas", "geopandas", "0.12"),
    ("pyproj", "pyproj", "3.4"),
    ("rasterio", "rasterio", "1.3"),
    ("pulp", "pulp", "2.6"),
    ("laspy", "laspy", "2.4"),
    ("lazrs", "lazrs", "0.5"),
    ("matplotlib", "matplotlib", "3.6"),
    ("onnxruntime", "onnxruntime", "1.16"),
]


def _release(version: str) -> tuple[int, ...]:
    """The leading numbers of a version ("2.0.1" -> (2, 0, 1), "1.24.2rc1" -> (1, 24, 2))."""
    return tuple(int(part) for part in re.findall(r"\d+", version.split("+")[0])[:3])


def installed_version(module: str, distribution: str) -> str | None:
    """The installed version of a package, None when it is not importable."""
    if importlib.util.find_spec(module) is None:
        return None
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:  # a build without metadata
        try:
            return str(getattr(importlib.import_module(module), "__version__", "0"))
        except Exception:  # noqa: BLE001  (an import that fails is a missing package)
            return None


def missing_requirements(requirements=REQUIREMENTS) -> list[str]:
    """One entry per unmet requirement: ``shapely>=2.0 (found 1.8.5)``, ``laspy>=2.4
    (missing)``; empty when everything is there."""
    missing = []
    for module, distribution, minimum in requirements:
        version = installed_version(module, distribution)
        if version is None:
            missing.append(f"{distribution}>={minimum} (missing)")
        elif _release(version) < _release(minimum):
            missing.append(f"{distribution}>={minimum} (found {version})")
    return missing


class Unmet:
    """Why the algorithms cannot load (``what``) and how to fix it (``fix``): one message,
    ``str()`` of which is the full line the message log gets."""

    def __init__(self, what: str, fix: str):
        self.what, self.fix = what, fix

    def __str__(self):
        return f"gisroads: {self.what} {self.fix}"


def missing_message(missing: list[str]) -> Unmet:
    """What the plugin says when requirements are unmet and no gisroads command is found:
    what, and how to fix it (first: *Set up gisroads*, :mod:`.setup_gisroads`)."""
    from .environment import SetupError, interpreter

    try:
        python = f"{interpreter()} {sys.version.split()[0]}"
    except SetupError:
        python = f"{sys.executable} {sys.version.split()[0]}"
    names = " ".join(f"'{entry.split(' ')[0]}'" for entry in missing)
    return Unmet(
        f"the algorithms need gisroads' own Python environment: QGIS's Python lacks "
        f"{', '.join(missing)}.",
        "Run Set up gisroads (Processing toolbox: gisroads, Set-up; or qgis_process run "
        "gisroads:setupgisroads): it makes that environment once, in the QGIS profile, with "
        f"QGIS's Python ({python}) and pip, and every algorithm then runs through it. Or "
        "name an existing gisroads command in the QGIS setting gisroads/executable or the "
        "GISROADS_EXECUTABLE environment variable. Or, to run the algorithms inside QGIS, "
        "start QGIS from a Python environment that has the packages: "
        f"{python.split()[0]} -m venv --system-site-packages ~/gisroads-venv && "
        f"~/gisroads-venv/bin/pip install --no-binary shapely 'numpy<2' {names} "
        "(shapely built against the system GEOS: its PyPI wheel crashes inside QGIS), "
        "then source ~/gisroads-venv/bin/activate && qgis.")


def load_error_message(error: BaseException) -> Unmet:
    """What the plugin says when the requirements are met but the algorithms still fail to
    import (a package built for another numpy, a broken install)."""
    text = str(error).splitlines()[0] if str(error) else ""
    return Unmet(f"the Processing algorithms are not loaded: importing them failed with "
                 f"{type(error).__name__}: {text}.",
                 "Check that QGIS's Python packages are Debian's builds, or built against "
                 "the system GEOS/GDAL/PROJ, with numpy < 2.")
