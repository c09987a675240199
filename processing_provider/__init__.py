"""QGIS plugin entry point: only ``classFactory`` (QGIS and qgis_process call it)."""
import os
import sys

# In the assembled plugin the core library sits beside this file (gisroads_qgis/gisroads);
# put the plugin folder first on the path so ``import gisroads`` finds that copy.
_PLUGIN_DIR = os.path.dirname(os.path.abspath(__file__))
if os.path.isdir(os.path.join(_PLUGIN_DIR, "gisroads")) and _PLUGIN_DIR not in sys.path:
    sys.path.insert(0, _PLUGIN_DIR)


def classFactory(iface):  # noqa: N802 (QGIS's name)
    """The plugin; when the algorithms' Python packages are missing or do not import, a
    stand-in that says so in one message (no traceback, no provider)."""
    from .dependencies import load_error_message, missing_message, missing_requirements
    from .plugin import GisroadsPlugin, UnavailablePlugin
    missing = missing_requirements()
    if missing:
        from .external import find_executable
        from .plugin import ExternalPlugin
        executable = find_executable()
        if executable is not None:  # external-tool mode
            return ExternalPlugin(iface, missing_message(missing), executable)
        return UnavailablePlugin(iface, missing_message(missing))
    try:
        from . import provider  # noqa: F401: imports gisroads and every dependency
    except Exception as error:  # noqa: BLE001: any import failure is reported, not raised
        return UnavailablePlugin(iface, load_error_message(error))
    return GisroadsPlugin(iface)
