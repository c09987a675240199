"""What every gisroads algorithm shares: group, translation hook, instance creation, help."""
import re

from qgis.core import QgsProcessingAlgorithm
from qgis.PyQt.QtCore import QCoreApplication


class GisroadsAlgorithm(QgsProcessingAlgorithm):
    """Subclasses set ``NAME``, ``DISPLAY_NAME``, ``GROUP`` and ``HELP`` (HTML)."""

    NAME = ""
    DISPLAY_NAME = ""
    GROUP = ""
    HELP = ""

    def tr(self, text):
        return QCoreApplication.translate("gisroads", text)

    def name(self):
        return self.NAME

    def displayName(self):  # noqa: N802
        return self.tr(self.DISPLAY_NAME)

    def group(self):
        return self.tr(self.GROUP)

    def groupId(self):  # noqa: N802
        return self.GROUP.lower().replace(" ", "")

    def shortHelpString(self):  # noqa: N802
        return self.tr(self.HELP)

    def shortDescription(self):  # noqa: N802
        """The help's first paragraph as plain text (the toolbox tooltip)."""
        first = self.HELP.split("</p>")[0]
        return self.tr(re.sub(r"<[^>]+>", "", first).replace("&amp;", "&"))

    def createInstance(self):  # noqa: N802
        return type(self)()
