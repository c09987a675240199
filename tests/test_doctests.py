"""The numpydoc Examples of the entry points, run as doctests (issue 26, item 2).

Each example builds a small synthetic scene (:mod:`gisroads.synthetic`) and prints counts,
booleans or coarsely rounded values, so it passes as written in both environments (PyPI's
numpy 2 and Debian's numpy 1.24). An example runs in a namespace of its own, not its
module's, so that it imports what it uses, as a reader copying it must; it writes files
only into temporary folders (and runs in an empty one, so a slip leaves nothing behind).

One test per example, named after the function (``pytest --durations`` shows each one's
time); the examples of a module not listed in ``MODULES`` are not run, so add the module
when you write its first example.
"""
import doctest
import importlib

import pytest

MODULES = [
    "gisroads.evaluate.buffer",
    "gisroads.evaluate.report",
    "gisroads.features.kerbs",
    "gisroads.imagery.pipeline",
    "gisroads.io.raster",
    "gisroads.jobs.common",
    "gisroads.network.areas",
    "gisroads.network.branches",
    "gisroads.io.vector",
    "gisroads.lidar.blocks",
    "gisroads.lidar.intensity",
    "gisroads.lidar.pipeline",
    "gisroads.network.rasters",
    "gisroads.options",
    "gisroads.snakes.pipeline",
    "gisroads.synthetic.canal",
    "gisroads.synthetic.cloud",
    "gisroads.synthetic.image",
    "gisroads.synthetic.network",
    "gisroads.synthetic.perturb",
    "gisroads.synthetic.rural",
    "gisroads.update.conflate",
]
OPTIONS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
MIN_EXAMPLES = 10


def _examples() -> list[doctest.DocTest]:
    finder = doctest.DocTestFinder()
    found = []
    for name in MODULES:
        module = importlib.import_module(name)
        found += [test for test in finder.find(module, name) if test.examples]
    return sorted(found, key=lambda test: test.name)


EXAMPLES = _examples()


def test_the_entry_points_have_examples():
    assert len(EXAMPLES) >= MIN_EXAMPLES, [test.name for test in EXAMPLES]


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda test: test.name)
def test_example(example, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    example.globs = {"__name__": example.name}  # its own imports only
    output = []
    runner = doctest.DocTestRunner(optionflags=OPTIONS)
    result = runner.run(example, out=output.append, clear_globs=True)
    assert result.failed == 0, "".join(output)
