"""The house rules of ``gisroads/``, read from the source with ``ast`` (nothing imported):
the core never imports QGIS, no module imports from a floor above its own, and no method
imports another.

Floors, bottom up (a package may import from its own floor and those below):

0. the types and plumbing: ``geo``, ``progress``, ``errors``, ``resources``, ``optimize``,
   ``options`` and the package's ``__init__``;
1. reading and writing, running tasks: ``io``, ``parallel``;
2. the shared stages: ``features``, ``segmentation``, ``vectorize``, ``network``,
   ``synthetic``, ``tiling``;
3. scoring: ``evaluate``;
4. the learned models: ``learn``;
5. the methods: ``lidar``, ``imagery``, ``snakes``, ``update``. They are siblings: none
   imports another (what two of them share lives on a floor below);
6. the whole jobs and the command line: ``jobs``, ``cli``.

In ``cli``, the subcommand modules are siblings: each imports the shared ``options`` and
``report`` but no other subcommand.

Every import counts, also one inside a function: an import that runs only sometimes still
ties the lower floor to the upper one.
"""
import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "gisroads"

FLOORS = [
    {"__init__", "geo", "progress", "errors", "resources", "optimize", "options"},
    {"io", "parallel"},
    {"features", "segmentation", "vectorize", "network", "synthetic", "tiling"},
    {"evaluate"},
    {"learn"},
    {"lidar", "imagery", "snakes", "update"},
    {"jobs", "cli"},
]
METHODS = FLOORS[5]
FLOOR = {name: level for level, names in enumerate(FLOORS) for name in names}


def _modules():
    """``(path, dotted module name, package it resolves relative imports in)``."""
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        # a relative import resolves in the folder: the package itself for an __init__
        yield path, ".".join(parts), parts[:-1]


def _imports(path: Path, package: tuple) -> list[tuple[int, str]]:
    """Every module ``path`` imports, as ``(line, absolute dotted name)``; for ``from X
    import a, b`` also ``X.a`` and ``X.b`` (they may be modules)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(package[:len(package) - node.level + 1])
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            found.append((node.lineno, module))
            found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
    return found


def _floor_of(module: str) -> tuple[str, int] | None:
    """The top-level part of ``gisroads.<part>...`` and its floor; None outside gisroads."""
    parts = module.split(".")
    if parts[0] != "gisroads":
        return None
    part = parts[1] if len(parts) > 1 else "__init__"
    if part not in FLOOR:
        return None  # ``from gisroads import __version__``: a name, not a module
    return part, FLOOR[part]


def test_every_top_level_module_has_a_floor():
    names = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()
             if (p.is_file() and p.suffix == ".py") or (p / "__init__.py").is_file()}
    assert names - set(FLOOR) == set(), "put the new module on a floor in FLOORS"


def test_no_qgis_import_in_the_core():
    found = [f"{path.relative_to(PACKAGE.parent)}:{line}: {module}"
             for path, _, package in _modules()
             for line, module in _imports(path, package)
             if module.split(".")[0] in {"qgis", "processing", "PyQt5", "PyQt6"}]
    assert found == []


def test_no_import_goes_up_a_floor():
    upward = []
    for path, name, package in _modules():
        own = _floor_of(name)
        for line, module in _imports(path, package):
            target = _floor_of(module)
            if target is not None and target[1] > own[1]:
                upward.append(f"{path.relative_to(PACKAGE.parent)}:{line}: "
                              f"{own[0]} (floor {own[1]}) imports {module} "
                              f"(floor {target[1]})")
    assert upward == []


def test_no_method_imports_another():
    found = []
    for path, name, package in _modules():
        own = _floor_of(name)[0]
        if own not in METHODS:
            continue
        for line, module in _imports(path, package):
            target = _floor_of(module)
            if target is not None and target[0] in METHODS and target[0] != own:
                found.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {own} imports "
                             f"{module}")
    assert found == []


def test_no_cli_subcommand_imports_another():
    cli = PACKAGE / "cli"
    shared = {"__init__", "__main__", "app", "options", "report"}
    subcommands = {path.stem for path in cli.glob("*.py")} - shared
    found = [f"{path.relative_to(PACKAGE.parent)}:{line}: {module}"
             for path in sorted(cli.glob("*.py")) if path.stem in subcommands
             for line, module in _imports(path, ("gisroads", "cli"))
             if module.split(".")[:2] == ["gisroads", "cli"] and len(module.split(".")) > 2
             and module.split(".")[2] in subcommands]
    assert found == []


@pytest.mark.parametrize("package, source, expected", [
    (("gisroads", "segmentation"), "from ..imagery.cues import ndvi", "gisroads.imagery.cues"),
    (("gisroads", "vectorize", "sub"), "from ...evaluate import topology",
     "gisroads.evaluate.topology"),
    (("gisroads", "geo"), "import gisroads.lidar.pipeline", "gisroads.lidar.pipeline"),
])
def test_the_check_sees_relative_absolute_and_nested_imports(tmp_path, package, source,
                                                             expected):
    path = tmp_path / "module.py"
    path.write_text(f"def f():\n    {source}\n")
    assert expected in {module for _, module in _imports(path, package)}
