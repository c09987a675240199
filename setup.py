"""Build step of the wheel (the project's metadata is in pyproject.toml).

The repository keeps the QGIS styles and the demo's sample data at its top, ``styles/`` and
``data/demo/``, outside the ``gisroads`` package. ``build_py`` copies them into the built
package as ``gisroads/_styles`` and ``gisroads/_demo``, so a wheel carries them as package
data (read by :mod:`gisroads.resources` through ``importlib.resources``). An editable install
builds no copy: there ``gisroads.resources`` reads the repository's folders. The sdist takes
both folders along (MANIFEST.in), so a wheel built from it has them too.
"""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
PACKAGE_DATA_FOLDERS = {"_styles": ROOT / "styles", "_demo": ROOT / "data" / "demo"}


class BuildPyWithDataFolders(build_py):
    """``build_py`` plus a fresh copy of each of PACKAGE_DATA_FOLDERS in the built package."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for name, source in PACKAGE_DATA_FOLDERS.items():
            if not source.is_dir():
                raise FileNotFoundError(f"{source} is missing: the wheel needs it as "
                                        f"gisroads/{name}")
            target = Path(self.build_lib, "gisroads", name)
            shutil.rmtree(target, ignore_errors=True)  # no stale files from an earlier build
            shutil.copytree(source, target, ignore=shutil.ignore_patterns("__pycache__"))

    def get_outputs(self, include_bytecode=True):
        outputs = super().get_outputs(include_bytecode)
        for name, source in PACKAGE_DATA_FOLDERS.items():
            outputs += [str(Path(self.build_lib, "gisroads", name, p.relative_to(source)))
                        for p in sorted(source.rglob("*")) if p.is_file()]
        return outputs


setup(cmdclass={"build_py": BuildPyWithDataFolders})
