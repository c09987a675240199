"""The plugin class: registers the Processing provider, nothing else."""
from qgis.core import QgsApplication

from .provider import GisroadsProvider


class GisroadsPlugin:
    def __init__(self, iface):
        self.iface = iface
        self.provider = None

    def initProcessing(self):  # noqa: N802 (QGIS's name); qgis_process calls only this
        self.provider = GisroadsProvider()
        QgsApplication.processingRegistry().addProvider(self.provider)

    def initGui(self):  # noqa: N802
        self.initProcessing()

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
