#!/usr/bin/env bash
# Installs everything gisroads needs on Debian 12, idempotently:
#   python  Debian's venv and pip: all the standalone .venv needs from Debian (make demo)
#   apt   Debian's QGIS and the Debian Python stack QGIS embeds, PostGIS for the update
#         tests (docs/environments.md), and what `python` installs
#   venv  .venv: the standalone environment, modern wheels from PyPI
#   train .venv gains the train extra (PyTorch, CPU build, and onnx) for the training tests
#   qgis  .venv-qgis: Debian's Python with system site-packages, numpy pinned to Debian's,
#         shapely 2 built from source against the system GEOS
# Each step leaves a stamp keyed on the files it depends on, so a second run is quick.
set -euo pipefail
cd "$(dirname "$0")/.."
STAMPS=.stamps
mkdir -p "$STAMPS"

# the standalone .venv takes everything else as PyPI wheels (GEOS, GDAL, PROJ and CBC inside)
VENV_APT_PACKAGES=(python3-venv python3-pip)

APT_PACKAGES=("${VENV_APT_PACKAGES[@]}" qgis python3-qgis qgis-providers python3-skimage python3-geopandas python3-rasterio
  python3-sklearn python3-pulp python3-pytest python3-pip python3-venv coinor-cbc libgeos-dev build-essential
  python3-dev proj-data python3-tqdm
  # BLAS/OpenMP threads pinned inside the library (gisroads.imagery.pipeline.pinned_threads)
  python3-threadpoolctl
  # the QGIS desktop in a virtual display, for the plugin's start-up test
  xvfb xauth
  # tiles as tasks on Dask (gisroads.parallel)
  python3-dask python3-distributed
  # a throwaway PostGIS database for the road-database update tests (setup.sh installs
  # without recommends: the extension itself is postgresql-15-postgis-3), loaded by ogr2ogr
  postgresql postgis postgresql-15-postgis-3 gdal-bin)

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

install_missing() {
  local missing=()
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return
  echo "setup: installing Debian packages: ${missing[*]}"
  as_root apt-get update -qq
  DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

step_python() { install_missing "${VENV_APT_PACKAGES[@]}"; }

step_apt() { install_missing "${APT_PACKAGES[@]}"; }

stamp_for() { echo "$STAMPS/$1-$(cat "${@:2}" | sha1sum | cut -c1-12)"; }

step_venv() {
  local stamp; stamp=$(stamp_for venv pyproject.toml scripts/setup.sh)
  [ -f "$stamp" ] && [ -x .venv/bin/python ] && return
  echo "setup: building .venv (standalone, PyPI wheels)"
  rm -rf .venv
  /usr/bin/python3 -m venv .venv
  # wheel: the plugin build (pip wheel --no-build-isolation) needs it beside setuptools < 70.1
  .venv/bin/pip install -q --upgrade pip wheel
  .venv/bin/pip install -q -e '.[test]'
  rm -f "$STAMPS"/venv-*; touch "$stamp"
}

step_train() {
  local stamp; stamp=$(stamp_for train pyproject.toml scripts/setup.sh)
  [ -f "$stamp" ] && .venv/bin/python -c "import torch, onnx" 2>/dev/null && return
  echo "setup: adding the train extra to .venv (PyTorch CPU build, onnx)"
  # the CPU build by its exact version: a bare 'torch' would bring a CUDA build of several GB
  .venv/bin/pip install -q "torch==2.13.0" && .venv/bin/pip install -q -e '.[test,train]'
  rm -f "$STAMPS"/train-*; touch "$stamp"
}

step_qgis() {
  local stamp; stamp=$(stamp_for qgis pyproject.toml scripts/setup.sh qgis-constraints.txt)
  [ -f "$stamp" ] && [ -x .venv-qgis/bin/python ] && return
  echo "setup: building .venv-qgis (Debian's QGIS Python stack + shapely 2 from source)"
  rm -rf .venv-qgis
  /usr/bin/python3 -m venv --system-site-packages .venv-qgis
  # Debian's pyproj finds PROJ's data under sys.prefix, which a venv moves away from /usr.
  mkdir -p .venv-qgis/share && ln -s /usr/share/proj .venv-qgis/share/proj
  # Only packages Debian lacks come from PyPI; everything linking GEOS/GDAL/PROJ is Debian's,
  # except shapely 2, compiled here against the system GEOS.
  .venv-qgis/bin/pip install -q -c qgis-constraints.txt --no-binary shapely \
    "shapely>=2" laspy lazrs pytest-qgis onnxruntime
  .venv-qgis/bin/pip install -q --no-deps --no-build-isolation -e .
  .venv-qgis/bin/python -c "import numpy, shapely, geopandas, rasterio, skimage, qgis.core; \
assert numpy.__version__.startswith('1.'), numpy.__version__"
  rm -f "$STAMPS"/qgis-*; touch "$stamp"
}

for step in "${@:-apt venv train qgis}"; do
  for s in $step; do "step_$s"; done
done
