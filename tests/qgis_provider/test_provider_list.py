"""The provider's explicit algorithm list holds every algorithm class of ``algorithms/``,
each once (a new algorithm module not added to the list would never reach the toolbox)."""
import ast
from pathlib import Path

ALGORITHMS_DIR = Path(__file__).resolve().parents[2] / "processing_provider" / "algorithms"


def _defined_algorithms() -> set[str]:
    """Names of the classes in ``algorithms/`` with a non-empty ``NAME``, read with ast."""
    names = set()
    for path in ALGORITHMS_DIR.glob("*.py"):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ClassDef) and any(
                    isinstance(item, ast.Assign) and item.targets[0].id == "NAME"
                    and isinstance(item.value, ast.Constant) and item.value.value
                    for item in node.body if isinstance(item, ast.Assign)
                    and isinstance(item.targets[0], ast.Name)):
                names.add(node.name)
    return names


def test_the_provider_lists_every_algorithm_once(qgis_app):
    from processing_provider.provider import ALGORITHMS
    listed = [cls.__name__ for cls in ALGORITHMS]
    assert len(listed) == len(set(listed))
    assert set(listed) == _defined_algorithms()
    assert len({cls.NAME for cls in ALGORITHMS}) == len(ALGORITHMS)


def test_a_group_has_one_id_in_the_toolbox_in_both_modes(qgis_app):
    """In-process and external algorithms of one group share its id, or the toolbox shows
    the group twice (the desktop's external toolbox did, for Map-guided snakes)."""
    from processing_provider.external import ExternalProvider
    from processing_provider.provider import GisroadsProvider

    for provider in (GisroadsProvider(), ExternalProvider("/opt/gisroads/bin/gisroads")):
        provider.loadAlgorithms()
        ids = {}
        for algorithm in provider.algorithms():
            ids.setdefault(algorithm.group(), set()).add(algorithm.groupId())
        assert len(ids) >= 6
        assert all(len(group_ids) == 1 for group_ids in ids.values()), ids
        assert ids["Map-guided snakes"] == {"map-guidedsnakes"}
