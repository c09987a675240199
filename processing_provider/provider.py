"""The gisroads Processing provider: one algorithm per module of ``algorithms/``, and the
Processing models of ``models/`` (``.model3`` files chaining those algorithms)."""
import importlib
import pkgutil
from pathlib import Path

from qgis.core import QgsProcessingModelAlgorithm, QgsProcessingProvider

from . import algorithms
from .algorithms.base import GisroadsAlgorithm, show_decimals

MODELS_DIR = Path(__file__).resolve().parent / "models"


def algorithm_classes() -> list[type[GisroadsAlgorithm]]:
    """Every algorithm class defined in ``algorithms/``, in module order."""
    classes = []
    for module_info in sorted(pkgutil.iter_modules(algorithms.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{algorithms.__name__}.{module_info.name}")
        classes += [value for value in vars(module).values()
                    if isinstance(value, type) and issubclass(value, GisroadsAlgorithm)
                    and value.__module__ == module.__name__ and value.NAME]
    return classes


class GisroadsProvider(QgsProcessingProvider):
    def id(self):
        return "gisroads"

    def name(self):
        return "gisroads"

    def longName(self):
        import gisroads
        return f"gisroads {gisroads.__version__}: road networks from LiDAR and imagery"

    def loadAlgorithms(self):  # noqa: N802
        for algorithm_class in algorithm_classes():
            self.addAlgorithm(algorithm_class())
        for path in sorted(MODELS_DIR.glob("*.model3")):
            model = QgsProcessingModelAlgorithm()
            if not model.fromFile(str(path)):
                raise RuntimeError(f"{path}: not a Processing model")
            for parameter in model.parameterDefinitions():
                show_decimals(parameter)  # as the algorithms' own (GisroadsAlgorithm)
            self.addAlgorithm(model)
