"""Files gisroads ships beside its code: the QGIS layer styles and the demo's sample data.

In the repository they sit at the top, ``styles/`` and ``data/demo/``. A wheel and the QGIS
plugin carry a copy inside the package, ``gisroads/_styles`` and ``gisroads/_demo`` (made at
build time by ``setup.py``'s ``build_py`` and by ``scripts/build_plugin.sh``), read here
through :mod:`importlib.resources`. A checkout (an editable install, the tests) has no copy
and reads the repository's folders.
"""
from __future__ import annotations

import tempfile
from functools import cache
from importlib.resources import files
from pathlib import Path

from .errors import MissingFileError

_REPOSITORY = Path(__file__).resolve().parents[1]

STYLES = "_styles"
"""Package data folder of the QGIS styles, one ``<layer name>.qml`` per layer."""
DEMO = "_demo"
"""Package data folder of the demo's sample data (sources and licences in its README.md)."""
_IN_REPOSITORY = {STYLES: _REPOSITORY / "styles", DEMO: _REPOSITORY / "data" / "demo"}


@cache
def resource_dir(name: str) -> Path:
    """The folder of package data ``name`` (:data:`STYLES`, :data:`DEMO`) as a real path.

    The package's copy when it has one, else the repository's folder. A package imported
    from a zip file has its copy extracted once to a temporary folder (GDAL and laspy read
    paths). Raises MissingFileError (a FileNotFoundError), naming both places, when
    neither exists (a broken install), so a styled output is never silently written
    without its styles.
    """
    packaged = files(__package__).joinpath(name)
    if packaged.is_dir():
        if isinstance(packaged, Path):
            return packaged
        return _extracted(packaged, name)
    if _IN_REPOSITORY[name].is_dir():
        return _IN_REPOSITORY[name]
    raise MissingFileError(
        f"gisroads' {name.strip('_')} files are missing: neither {packaged} (package data of "
        f"an installed gisroads) nor {_IN_REPOSITORY[name]} (a checkout) exists; reinstall "
        "gisroads")


def _extracted(folder, name: str) -> Path:
    """Copy a non-file-system resource folder (one level deep) to a temporary folder."""
    target = Path(tempfile.mkdtemp(prefix=f"gisroads{name}."))
    for item in folder.iterdir():
        if item.is_file():
            (target / item.name).write_bytes(item.read_bytes())
    return target


def styles_dir() -> Path:
    """Folder of the QGIS styles (``road_centrelines.qml`` ...)."""
    return resource_dir(STYLES)


def demo_dir() -> Path:
    """Folder of the demo's sample data."""
    return resource_dir(DEMO)

