"""The plugin classes: one registers the Processing provider, nothing else; the other stands
in for it when the algorithms cannot load, and says why in one message."""
from qgis.core import Qgis, QgsApplication, QgsMessageLog


class GisroadsPlugin:
    def __init__(self, iface):
        self.iface = iface
        self.provider = None

    def initProcessing(self):  # noqa: N802 (QGIS's name); qgis_process calls only this
        from .provider import GisroadsProvider
        self.provider = GisroadsProvider()
        QgsApplication.processingRegistry().addProvider(self.provider)

    def initGui(self):  # noqa: N802
        self.initProcessing()

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None


class UnavailablePlugin:
    """The plugin when its algorithms cannot load (missing Python packages): registers no
    provider and shows ``message`` once, instead of a Python error dialog: in the message
    log (which qgis_process prints on stderr) and in the desktop's message bar."""

    def __init__(self, iface, message: str):
        self.iface = iface
        self.message = message
        self.logged = False

    def initProcessing(self):  # noqa: N802
        if self.logged:
            return
        self.logged = True
        QgsMessageLog.logMessage(self.message, "gisroads", Qgis.Critical)

    def initGui(self):  # noqa: N802
        self.initProcessing()
        self.iface.messageBar().pushMessage("gisroads", self.message, level=Qgis.Critical,
                                            duration=0)

    def unload(self):
        pass
