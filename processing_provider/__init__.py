"""QGIS plugin entry point: only ``classFactory`` (QGIS and qgis_process call it)."""
import os
import sys

# In the assembled plugin the core library sits beside this file (gisroads_qgis/gisroads);
# put the plugin folder first on the path so ``import gisroads`` finds that copy.
_PLUGIN_DIR = os.path.dirname(os.path.abspath(__file__))
if os.path.isdir(os.path.join(_PLUGIN_DIR, "gisroads")) and _PLUGIN_DIR not in sys.path:
    sys.path.insert(0, _PLUGIN_DIR)


def classFactory(iface):  # noqa: N802 (QGIS's name)
    """The plugin: in-process when QGIS's Python has the algorithms' packages; in
    external-tool mode when it lacks them; a stand-in that says why in one message (no
    traceback, no provider) when they are there but do not import."""
    from .dependencies import load_error_message, missing_message, missing_requirements
    from .plugin import GisroadsPlugin, UnavailablePlugin
    missing = missing_requirements()
    if missing:
        from .runner import find_executable
        from .plugin import ExternalPlugin
        # external-tool mode; without a gisroads command, Set up gisroads makes one
        return ExternalPlugin(iface, missing_message(missing), find_executable())
    try:
        from . import provider  # noqa: F401  (imports gisroads and every dependency)
    except Exception as error:  # noqa: BLE001  (any import failure is reported, not raised)
        return UnavailablePlugin(iface, load_error_message(error))
    return GisroadsPlugin(iface)
