"""External-tool mode: the algorithms run a ``gisroads`` executable as a subprocess.

For a QGIS whose Python lacks gisroads' packages (Debian 12's own: shapely 1.8), as QGIS's
GRASS and SAGA providers run their tools: the executable is the ``gisroads`` command of
an environment that has them (a venv, pipx), found in the ``GISROADS_EXECUTABLE``
environment variable, the ``gisroads/executable`` QGIS setting, or on PATH. It reports
progress as JSON lines on stderr (``--progress-json``) and its result as JSON on stdout
(``--json``); a cancel terminates it (SIGTERM: it removes what it was writing).

Standard library and qgis only: this module must import where gisroads cannot. So far one
algorithm runs this way, the whole LiDAR pipeline (its layers loaded as in-process:
:mod:`.loading`); the others need the packages in QGIS.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

from qgis.core import (QgsProcessingAlgorithm, QgsProcessingException,
                       QgsProcessingOutputNumber, QgsProcessingParameterEnum,
                       QgsProcessingParameterFile, QgsProcessingParameterFileDestination,
                       QgsProcessingProvider, QgsSettings)

from .algorithms.base import workers_parameter
from .loading import load_geopackage_on_completion

SETTING = "gisroads/executable"


def find_executable() -> str | None:
    """The external ``gisroads`` (see the module's doc), None when none runs."""
    candidates = [os.environ.get("GISROADS_EXECUTABLE"), QgsSettings().value(SETTING, ""),
                  shutil.which("gisroads")]
    for candidate in filter(None, candidates):
        try:
            done = subprocess.run([candidate, "--version"], capture_output=True, text=True,
                                  timeout=60)
        except (OSError, subprocess.SubprocessError):
            continue
        if done.returncode == 0 and done.stdout.startswith("gisroads"):
            return candidate
    return None


def run_external(executable: str, arguments: list[str], feedback) -> dict:
    """Run ``gisroads ARGUMENTS --json --progress-json``: progress and messages to
    ``feedback``, a cancel terminates it; returns its JSON result or raises
    QgsProcessingException with its one-line error."""
    command = [executable, *arguments, "--json", "--progress-json"]
    feedback.pushCommandInfo(" ".join(command))
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    stop = process.terminate  # one bound method, to disconnect what was connected
    feedback.canceled.connect(stop)
    messages = []
    try:
        for line in process.stderr:
            if line.startswith("{"):
                if feedback.isCanceled():
                    continue  # lines the command wrote before it was stopped
                event = json.loads(line)
                feedback.setProgress(100.0 * event["progress"])
                if event["message"]:
                    feedback.setProgressText(event["message"])
            elif line.strip():
                messages.append(line.strip())
                if line.startswith("gisroads: warning: "):
                    feedback.pushWarning(line.strip()[len("gisroads: warning: "):])
        stdout = process.stdout.read()
        status = process.wait()
    finally:
        feedback.canceled.disconnect(stop)
        if process.poll() is None:
            process.kill()
            process.wait()
        process.stdout.close()
        process.stderr.close()
    if feedback.isCanceled() or status == 130:
        raise QgsProcessingException("cancelled")
    if status != 0:
        errors = [m for m in messages if m.startswith("gisroads: error: ")]
        raise QgsProcessingException(
            errors[-1][len("gisroads: error: "):] if errors
            else f"{executable} failed (exit status {status}): {' '.join(messages[-3:])}")
    return json.loads(stdout)


class ExternalLidarRoadNetwork(QgsProcessingAlgorithm):
    """LiDAR road network (Zhu & Mordohai) through the external ``gisroads lidar``: the
    same id, outputs and defaults as the in-process algorithm, fewer parameters."""

    CUES = ["intensity", "evidence"]

    def __init__(self, executable: str):
        super().__init__()
        self.executable = executable

    def name(self):
        return "lidarroadnetwork"

    def displayName(self):  # noqa: N802
        return "LiDAR road network (Zhu & Mordohai)"

    def group(self):
        return "LiDAR"

    def groupId(self):  # noqa: N802
        return "lidar"

    def shortHelpString(self):  # noqa: N802
        return ("<p>Extracts the road network of an airborne LiDAR point cloud (LAS/LAZ) "
                "(by default every cue the cloud carries; Zhu &amp; Mordohai's intensity cue "
                "alone on request), by running the external gisroads command "
                f"(<code>{self.executable} lidar</code>): QGIS's Python lacks the packages "
                "gisroads needs, so this runs in that command's own environment. Output: a "
                "GeoPackage with road_centrelines, road_polygons, junctions and QA layers, "
                "in the cloud's CRS.</p>")

    def createInstance(self):  # noqa: N802
        return type(self)(self.executable)

    def initAlgorithm(self, config=None):  # noqa: N802
        params = [
            (QgsProcessingParameterFile("INPUT", "Point cloud (LAS/LAZ)",
                                        fileFilter="LAS/LAZ (*.las *.laz *.LAS *.LAZ)"),
             "airborne LiDAR (the intensity cue needs intensity); feet are converted to "
             "metres"),
            (QgsProcessingParameterEnum("CUE", "Road cue", self.CUES,
                                        defaultValue=self.CUES.index("evidence")),
             "evidence (default): the road likelihood of every cue the cloud carries (the "
             "paper's intensity among them), through the network stage; intensity: the "
             "paper's rectangles on the ground intensity alone"),
            (QgsProcessingParameterFileDestination("OUTPUT", "Road network",
                                                   "GeoPackage (*.gpkg)"),
             "GeoPackage receiving every layer, in the cloud's CRS"),
            (workers_parameter(str, "tiles"), None),
        ]
        for parameter, text in params:
            if text is not None:
                parameter.setHelp(text)
            self.addParameter(parameter)
        for name, text in (("ROADS", "number of roads"), ("LENGTH_M", "total road length"),
                           ("JUNCTIONS", "number of junctions")):
            self.addOutput(QgsProcessingOutputNumber(name, text))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        cue = self.CUES[self.parameterAsEnum(parameters, "CUE", context)]
        cloud = self.parameterAsFile(parameters, "INPUT", context)
        result = run_external(self.executable, [
            "lidar", cloud, "-o", out, "--cue", cue,
            "--workers", str(self.parameterAsInt(parameters, "WORKERS", context))], feedback)
        feedback.pushInfo(f"{result['roads']} roads, {result['length_m']:.0f} m, "
                          f"{result['junctions']} junctions")
        load_geopackage_on_completion(context, out, title=Path(cloud).stem)
        return {"OUTPUT": out, "ROADS": result["roads"], "LENGTH_M": result["length_m"],
                "JUNCTIONS": result["junctions"]}


class ExternalProvider(QgsProcessingProvider):
    """The gisroads provider in external-tool mode (same id: models and scripts that name
    ``gisroads:lidarroadnetwork`` work in both modes)."""

    def __init__(self, executable: str):
        super().__init__()
        self.executable = executable

    def id(self):
        return "gisroads"

    def name(self):
        return "gisroads"

    def longName(self):  # noqa: N802
        return f"gisroads (external: {self.executable})"

    def loadAlgorithms(self):  # noqa: N802
        self.addAlgorithm(ExternalLidarRoadNetwork(self.executable))
