# Public targets: demo, test, plugin, bench. Each installs what it needs first (scripts/setup.sh,
# idempotent), so any of them works as the first command on a fresh Debian 12 machine.
SHELL := /bin/bash
VENV := .venv/bin
QVENV := .venv-qgis/bin
QGIS_PROCESS := /usr/bin/qgis_process.bin
export QT_QPA_PLATFORM := offscreen
# 2 cores: OpenBLAS threads thrash under load (an NCut went from 4 s to 29 s)
export OPENBLAS_NUM_THREADS := 1

.PHONY: demo test lint test-core test-core-qgis test-qgis plugin bench bench-city setup setup-core setup-bench

setup:
	@scripts/setup.sh apt venv train qgis

# the demo needs the standalone .venv only: no QGIS, no PostgreSQL
setup-core:
	@scripts/setup.sh python venv

# the benchmarks fine-tune the road network: the train extra (PyTorch) as well
setup-bench:
	@scripts/setup.sh apt venv train

demo: setup-core
	$(VENV)/gisroads demo --out out/demo

## test: the linter, core suite on modern wheels, core suite on Debian's QGIS stack, provider
## suite in QGIS (each part alone: make lint, test-core, test-core-qgis, test-qgis)
test: lint test-core test-core-qgis test-qgis

# ruff, with the checks chosen in pyproject.toml ([tool.ruff]), over the whole tree
lint: setup
	$(VENV)/ruff check .

test-core: setup
	$(VENV)/python -m pytest -q tests --ignore=tests/qgis_provider

test-core-qgis: setup
	$(QVENV)/python -m pytest -q -p no:cacheprovider tests --ignore=tests/qgis_provider

test-qgis: setup plugin
	GISROADS_REQUIRE_QGIS=1 $(QVENV)/python -m pytest -q -p no:cacheprovider tests/qgis_provider

plugin: setup-core dist/gisroads_qgis.zip

dist/gisroads_qgis.zip: scripts/build_plugin.sh metadata.txt $(shell git ls-files -co --exclude-standard gisroads processing_provider styles 2>/dev/null)
	@scripts/build_plugin.sh

bench: setup-bench
	$(VENV)/python bench/run.py --out out/bench

## bench-city: a synthetic city of 1 and 4 km² end to end with 1 and 2 workers (minutes);
## the issue's 9 km² of 166 M points: make bench-city CITY_SIDES_KM=1,3 CITY_DENSITY=17.5
CITY_SIDES_KM ?= 1,2
CITY_DENSITY ?= 10
bench-city: setup-core
	$(VENV)/python bench/run.py --out out/bench-city --city $(CITY_SIDES_KM) --city-density $(CITY_DENSITY)
