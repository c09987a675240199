"""Set up gisroads: make gisroads' own Python environment in the QGIS profile
(:mod:`.environment`), so that every algorithm runs through its ``gisroads`` command.

Standard library and qgis only, like :mod:`.external`: it is there when gisroads cannot
import in QGIS's Python.
"""
from __future__ import annotations

from pathlib import Path

from qgis.core import (QgsApplication, QgsProcessingAlgorithm, QgsProcessingException,
                       QgsProcessingOutputString, QgsProcessingParameterFile)

from .environment import FOLDER, SetupError, bundled_wheel, create_environment, interpreter

PLUGIN_FOLDER = Path(__file__).resolve().parent


def private_environment_folder() -> Path:
    """Where the set-up puts the environment: inside the current QGIS profile."""
    return Path(QgsApplication.qgisSettingsDirPath()) / FOLDER


class SetUpGisroads(QgsProcessingAlgorithm):
    """Make the private environment; afterwards ``on_ready(executable)`` (the provider
    reloads its algorithms through the new command)."""

    def __init__(self, on_ready=None):
        super().__init__()
        self.on_ready = on_ready
        self.executable = None

    def name(self):
        return "setupgisroads"

    def displayName(self):  # noqa: N802
        return "Set up gisroads"

    def group(self):
        return "Set-up"

    def groupId(self):  # noqa: N802
        return "setup"

    def shortHelpString(self):  # noqa: N802
        return (f"<p>QGIS's Python lacks packages that gisroads needs (shapely 2, laspy, "
                f"onnxruntime…), so gisroads runs as its own command in its own Python "
                f"environment. This makes that environment once: a virtual environment of "
                f"QGIS's Python ({_interpreter_name()}) in the QGIS profile "
                f"(<code>{private_environment_folder()}</code>), into which pip installs the "
                "gisroads wheel that this plugin carries, with its dependencies (about "
                "1 GB installed) from the package index that your pip is configured for "
                "(pip.conf, PIP_INDEX_URL, a proxy in HTTPS_PROXY). Afterwards every gisroads "
                "algorithm runs through it. To use a gisroads command installed elsewhere "
                "instead, name it in the QGIS setting <code>gisroads/executable</code>.</p>")

    def createInstance(self):  # noqa: N802
        return type(self)(self.on_ready)

    def initAlgorithm(self, config=None):  # noqa: N802
        wheel = QgsProcessingParameterFile(
            "WHEEL", "gisroads wheel", fileFilter="Python wheel (*.whl)", optional=True)
        wheel.setFlags(wheel.flags() | wheel.FlagAdvanced)
        wheel.setHelp("the gisroads wheel to install; by default the one the plugin carries")
        self.addParameter(wheel)
        self.addOutput(QgsProcessingOutputString("EXECUTABLE", "gisroads command"))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        wheel = self.parameterAsFile(parameters, "WHEEL", context) or bundled_wheel(
            PLUGIN_FOLDER)
        if not wheel:
            raise QgsProcessingException(
                f"the plugin in {PLUGIN_FOLDER} carries no gisroads wheel: reinstall it from "
                "its ZIP")

        def progress(fraction, message):
            feedback.setProgress(100.0 * fraction)
            feedback.pushInfo(message)

        try:
            self.executable = create_environment(
                private_environment_folder(), wheel, progress=progress,
                cancelled=feedback.isCanceled)
        except SetupError as error:
            raise QgsProcessingException(str(error)) from None
        return {"EXECUTABLE": self.executable}

    def postProcessAlgorithm(self, context, feedback):  # noqa: N802
        if self.executable is not None and self.on_ready is not None:
            self.on_ready(self.executable)
        return {"EXECUTABLE": self.executable}


def _interpreter_name() -> str:
    try:
        return str(interpreter())
    except SetupError:
        return "not found"
