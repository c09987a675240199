"""QGIS plugin entry point: only ``classFactory`` (QGIS and qgis_process call it)."""
import os
import sys

# In the assembled plugin the core library sits beside this file (gisroads_qgis/gisroads);
# put the plugin folder first on the path so ``import gisroads`` finds that copy.
_PLUGIN_DIR = os.path.dirname(os.path.abspath(__file__))
if os.path.isdir(os.path.join(_PLUGIN_DIR, "gisroads")) and _PLUGIN_DIR not in sys.path:
    sys.path.insert(0, _PLUGIN_DIR)


def classFactory(iface):  # noqa: N802 (QGIS's name)
    from .plugin import GisroadsPlugin
    return GisroadsPlugin(iface)
