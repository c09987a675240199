#!/usr/bin/env bash
# Assembles the QGIS plugin folder gisroads_qgis/ (processing_provider/ at its root, plus
# metadata.txt and the gisroads core with styles/ as its package data gisroads/_styles, as
# in a wheel: see setup.py) and zips it into dist/gisroads_qgis.zip, the form QGIS's
# "Install from ZIP" and a profile's plugin folder take. The plugin also carries the
# gisroads wheel (wheels/), which "Set up gisroads" installs where QGIS's Python lacks the
# packages. PYTHON (default .venv/bin/python) builds it, from a clean copy of the sources.
set -euo pipefail
cd "$(dirname "$0")/.."
build=$(mktemp -d)
trap 'rm -rf "$build"' EXIT
plugin="$build/gisroads_qgis"
mkdir -p "$plugin"
cp -r processing_provider/. "$plugin/"
cp metadata.txt "$plugin/"
cp -r gisroads "$plugin/"
rm -rf "$plugin/gisroads/_styles" "$plugin/gisroads/_demo"
cp -r styles "$plugin/gisroads/_styles"
src="$build/src"
mkdir -p "$src/data"
cp -r gisroads styles setup.py pyproject.toml MANIFEST.in README.md "$src/"
cp -r data/demo "$src/data/"
rm -rf "$src/gisroads/_styles" "$src/gisroads/_demo"
find "$src" "$plugin" -name "__pycache__" -prune -exec rm -rf {} +
"${PYTHON:-.venv/bin/python}" -m pip wheel --quiet --no-deps --no-build-isolation \
  --wheel-dir "$plugin/wheels" "$src" 2>"$build/wheel.log" || { cat "$build/wheel.log" >&2; exit 1; }
mkdir -p dist
# a private temporary name: two builds running at once each rename a whole zip into place
(cd "$build" && python3 -m zipfile -c "$build/gisroads_qgis.zip" gisroads_qgis)
mv "$build/gisroads_qgis.zip" dist/gisroads_qgis.zip.$$
mv dist/gisroads_qgis.zip.$$ dist/gisroads_qgis.zip
echo "built dist/gisroads_qgis.zip"
