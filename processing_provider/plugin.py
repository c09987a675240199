"""The plugin classes: one registers the Processing provider, nothing else; one registers
the external-tool provider when QGIS's Python lacks the packages (and offers to set up
gisroads' own environment when no gisroads command is found); one stands in when the
algorithms cannot load at all, and says why in one message."""
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
    """The plugin when its algorithms cannot load (the packages are there but do not
    import): registers no provider and says why once, instead of a Python error dialog:
    the whole message in the message log (which qgis_process prints on stderr), what is
    wrong in the desktop's message bar with the fix behind its "Show more"."""

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
    """The plugin in external-tool mode: QGIS's Python lacks the packages; registers the
    provider of the algorithms that run through a ``gisroads`` command (:mod:`.external`).
    Without one found (``executable`` None) the provider holds *Set up gisroads*, the
    message log says how to run it, and the desktop's message bar offers it as a button;
    once it has made the environment the algorithms appear."""

    def __init__(self, iface, unmet, executable: str | None):
        super().__init__(iface, unmet)
        self.executable = executable
        self.provider = None
        self.offer = None  # the message bar item with the set-up button

    def initProcessing(self):  # noqa: N802
        if self.provider is not None:
            return
        from .external import ExternalProvider
        self.provider = ExternalProvider(self.executable, on_ready=self.ready)
        QgsApplication.processingRegistry().addProvider(self.provider)
        if self.executable is None:  # critical: the level qgis_process prints
            QgsMessageLog.logMessage(str(self.unmet), "gisroads", Qgis.Critical)
        else:
            QgsMessageLog.logMessage(self.note(), "gisroads", Qgis.Info)

    def note(self) -> str:
        from .external import EXTERNAL_ALGORITHMS
        names = ", ".join(a.DISPLAY_NAME for a in EXTERNAL_ALGORITHMS)
        return (f"gisroads: {names} run through the external {self.executable}; the other "
                f"algorithms need, in QGIS's Python, "
                f"{self.unmet.what.split(' lacks ', 1)[-1]}")

    def initGui(self):  # noqa: N802
        self.initProcessing()
        bar = self.iface.messageBar()
        if self.executable is not None:
            bar.pushMessage("gisroads", self.note()[len("gisroads: "):], self.unmet.fix,
                            Qgis.Info, 10)
            return
        from qgis.PyQt.QtWidgets import QPushButton
        self.offer = bar.createMessage("gisroads", self.unmet.what)
        button = QPushButton("Set up gisroads…", self.offer)
        button.setToolTip(self.unmet.fix)
        button.clicked.connect(self.open_setup)
        self.offer.layout().addWidget(button)
        bar.pushWidget(self.offer, Qgis.Warning, 0)

    def open_setup(self):
        import processing
        processing.execAlgorithmDialog("gisroads:setupgisroads")

    def ready(self, executable: str):
        """After *Set up gisroads*: the algorithms now run through ``executable``."""
        self.executable = executable
        QgsMessageLog.logMessage(self.note(), "gisroads", Qgis.Info)
        if self.offer is not None:
            self.iface.messageBar().popWidget(self.offer)
            self.offer = None

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
