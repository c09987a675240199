"""gisroads' error family, read from the source with ``ast`` (nothing imported): every input
or argument gisroads refuses on purpose raises a GisroadsError (a ValueError), so the
command line and the QGIS algorithms can report it as one line and let any other ValueError,
a bug in numpy, shapely or gisroads, keep its traceback (``gisroads.errors.INPUT_ERRORS``).
"""
import ast
from pathlib import Path

from gisroads.errors import INPUT_ERRORS, GisroadsError, MissingFileError

REPO = Path(__file__).resolve().parents[1]

#: The plain ValueErrors that stay, by module and function: each marks a broken invariant
#: of gisroads' own output, where a traceback is what a bug report needs.
PLAIN_VALUE_ERRORS = {
    # RoadNetwork.validate(): a stage wrote layers outside the output contract
    ("gisroads/geo.py", "validate"): 3,
    # the synthetic scene's layout: a street that misses the road it was drawn to
    ("gisroads/synthetic/network.py", "_end_on"): 1,
    # write_classified's classify callback (gisroads' own, from the command line and QGIS)
    # returned the wrong number of classes
    ("gisroads/io/las.py", "write_classified"): 1,
}


def _plain_value_errors(path: Path) -> dict[tuple[str, str], int]:
    found: dict[tuple[str, str], int] = {}
    name = str(path.relative_to(REPO))

    def visit(node, function):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            function = node.name
        if isinstance(node, ast.Raise) and node.exc is not None:
            exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if isinstance(exc, ast.Name) and exc.id == "ValueError":
                found[(name, function)] = found.get((name, function), 0) + 1
        for child in ast.iter_child_nodes(node):
            visit(child, function)

    visit(ast.parse(path.read_text(), str(path)), "<module>")
    return found


def test_gisroads_raises_its_own_errors_not_plain_value_errors():
    found = {}
    for folder in ("gisroads", "processing_provider"):
        for path in sorted((REPO / folder).rglob("*.py")):
            found.update(_plain_value_errors(path))
    unexpected = {k: n for k, n in found.items() if PLAIN_VALUE_ERRORS.get(k) != n}
    assert not unexpected, ("raise GisroadsError (gisroads.errors) for an input or argument "
                            f"gisroads refuses; plain ValueErrors found: {unexpected}")
    gone = sorted(set(PLAIN_VALUE_ERRORS) - set(found))
    assert not gone, f"no plain ValueError left there: drop {gone} from PLAIN_VALUE_ERRORS"


def test_only_gisroads_errors_and_missing_files_are_input_errors():
    assert INPUT_ERRORS == (GisroadsError, FileNotFoundError)
    assert issubclass(GisroadsError, ValueError)  # the stages' contract: "raises ValueError"
    assert issubclass(MissingFileError, INPUT_ERRORS[1])
    assert not isinstance(ValueError("bug"), INPUT_ERRORS)
