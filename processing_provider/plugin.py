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
    provider and says why once, instead of a Python error dialog: the whole message in the
    message log (which qgis_process prints on stderr), what is wrong in the desktop's
    message bar with the fix behind its "Show more"."""

    def __init__(self, iface, unmet):
        self.iface = iface
        self.unmet = unmet  # dependencies.Unmet
        self.logged = False

    def initProcessing(self):  # noqa: N802
        if self.logged:
            return
        self.logged = True
        QgsMessageLog.logMessage(str(self.unmet), "gisroads", Qgis.Critical)

    def initGui(self):  # noqa: N802
        self.initProcessing()
        self.iface.messageBar().pushMessage("gisroads", self.unmet.what, self.unmet.fix,
                                            Qgis.Critical, 0)

    def unload(self):
        pass


class ExternalPlugin(UnavailablePlugin):
    """The plugin in external-tool mode: QGIS's Python lacks the packages, but a
    ``gisroads`` command runs elsewhere; registers the provider of the algorithms that run
    through it (:mod:`.external`) and says so once, as information."""

    def __init__(self, iface, unmet, executable: str):
        super().__init__(iface, unmet)
        self.executable = executable
        self.provider = None

    def initProcessing(self):  # noqa: N802
        if self.provider is not None:
            return
        from .external import ExternalProvider
        self.provider = ExternalProvider(self.executable)
        QgsApplication.processingRegistry().addProvider(self.provider)
        QgsMessageLog.logMessage(self.note(), "gisroads", Qgis.Info)

    def note(self) -> str:
        return (f"gisroads: the LiDAR road network runs through the external "
                f"{self.executable}; the other algorithms need, in QGIS's Python, "
                f"{self.unmet.what.split(' lacks ', 1)[-1]}")

    def initGui(self):  # noqa: N802
        self.initProcessing()
        self.iface.messageBar().pushMessage("gisroads", self.note()[len("gisroads: "):],
                                            self.unmet.fix, Qgis.Info, 10)

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
