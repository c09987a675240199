"""Screenshots of a gisroads algorithm dialog in the QGIS desktop, before and after a run.

Run by ``scripts/qgis_dialog_screenshot.sh`` inside ``qgis --code`` under Xvfb (a QGIS started
the usual way: the system Python, the plugin from its zip in a throwaway profile), so what a
user sees can be looked at on a machine without a display. Settings come from the
environment: ``SHOT_ALGORITHM`` (e.g. ``gisroads:lidarroadnetwork``), ``SHOT_PARAMETERS`` (a
JSON object), ``SHOT_SCRIPTS`` (this folder) and ``SHOT_DIR``, where ``toolbox.png`` (the
Processing toolbox filtered to gisroads, every group open), ``dialog.png``,
``window_before_run.png`` (the main window with its message bar), ``dialog_after_run.png``,
``window_after_run.png`` (the main window: the layers the run loaded, on the map and in the
layer tree) and ``shot.log`` go.
"""
import json
import os
import sys
from pathlib import Path

import processing
from qgis.core import QgsApplication, QgsProject
from qgis.PyQt.QtCore import QTimer
from qgis.utils import iface

sys.path.insert(0, os.environ["SHOT_SCRIPTS"])  # qgis --code runs this without __file__
from qgis_toolbox import show_gisroads_toolbox, toolbox_rows  # noqa: E402

OUT = Path(os.environ["SHOT_DIR"])
ALGORITHM = os.environ["SHOT_ALGORITHM"]
PARAMETERS = json.loads(os.environ.get("SHOT_PARAMETERS", "{}"))


def _log(text: str) -> None:
    with open(OUT / "shot.log", "a") as log:
        log.write(text + "\n")


def _show_toolbox() -> None:
    toolbox = show_gisroads_toolbox()

    def grab() -> None:
        _log("toolbox: " + json.dumps(toolbox_rows(toolbox.algorithmTree)))
        toolbox.grab().save(str(OUT / "toolbox.png"))
        toolbox.hide()
        _open_dialog()

    QTimer.singleShot(1500, grab)


def _open_dialog() -> None:
    registry = QgsApplication.processingRegistry()
    algorithm = registry.algorithmById(ALGORITHM)
    _log(f"algorithm: {type(algorithm).__name__ if algorithm else None}")
    if algorithm is None:
        _log("providers: " + ", ".join(p.id() for p in registry.providers()))
        QgsApplication.exit(1)
        return
    dialog = processing.createAlgorithmDialog(ALGORITHM, PARAMETERS)
    dialog.show()

    def after_run(successful: bool, results: dict) -> None:
        _log(f"finished: {successful}, results: {results}")
        # let the dialog show the end of its log first, then the map its layers
        QTimer.singleShot(1000, lambda: dialog.grab().save(str(OUT / "dialog_after_run.png")))

        def window() -> None:
            dialog.close()
            layers = QgsProject.instance().layerTreeRoot().findLayers()
            _log("layers: " + json.dumps([[n.name(), n.itemVisibilityChecked()]
                                          for n in layers]))
            iface.mapCanvas().zoomToFullExtent()
            iface.mapCanvas().refreshAllLayers()
            QTimer.singleShot(3000, lambda: (
                iface.mainWindow().grab().save(str(OUT / "window_after_run.png")),
                QgsApplication.exit(0 if successful else 1)))

        QTimer.singleShot(2000, window)

    def run() -> None:
        dialog.grab().save(str(OUT / "dialog.png"))
        iface.mainWindow().grab().save(str(OUT / "window_before_run.png"))
        dialog.algorithmFinished.connect(after_run)
        dialog.runAlgorithm()

    QTimer.singleShot(2000, run)


# after QGIS has loaded its plugins and providers
QTimer.singleShot(8000, _show_toolbox)
