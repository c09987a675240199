"""What every gisroads algorithm shares: group, translation hook, instance creation, help."""
import re

from qgis.core import (QgsProcessing, QgsProcessingAlgorithm, QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterFile,
                       QgsProcessingParameterFileDestination)
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

    def add_parameters(self, params) -> None:
        """Add ``(parameter, help text)`` pairs; a help of None leaves the parameter's own."""
        for param, text in params:
            if text is not None:
                param.setHelp(self.tr(text))
            self.addParameter(param)

    def add_network_outputs(self) -> None:
        """The numbers every road-network algorithm reports."""
        for name, text in (("ROADS", "number of roads"), ("LENGTH_M", "total road length"),
                           ("JUNCTIONS", "number of junctions")):
            self.addOutput(QgsProcessingOutputNumber(name, self.tr(text)))

    @staticmethod
    def network_outputs(result: dict, feedback, detail: str = "") -> dict:
        """Report a road network job's figures and return them as the algorithm's outputs."""
        feedback.pushInfo(f"{result['roads']} roads, {result['length_m']:.0f} m, "
                          f"{result['junctions']} junctions{detail}")
        return {"ROADS": result["roads"], "LENGTH_M": result["length_m"],
                "JUNCTIONS": result["junctions"]}


def cloud_input(tr, text: str) -> QgsProcessingParameterFile:
    """The LAS/LAZ point cloud parameter ``INPUT``."""
    param = QgsProcessingParameterFile("INPUT", tr("Point cloud (LAS/LAZ)"),
                                       fileFilter="LAS/LAZ (*.las *.laz *.LAS *.LAZ)")
    param.setHelp(tr(text))
    return param


def road_map_input(tr) -> QgsProcessingParameterFeatureSource:
    """The approximate road map parameter ``MAP`` of the map-guided algorithms."""
    param = QgsProcessingParameterFeatureSource("MAP", tr("Road map lines"),
                                                [QgsProcessing.TypeVectorLine])
    param.setHelp(tr("approximate road centre lines in any CRS (reprojected to the cloud's)"))
    return param


def network_output(tr, text: str) -> QgsProcessingParameterFileDestination:
    """The road-network GeoPackage parameter ``OUTPUT``."""
    param = QgsProcessingParameterFileDestination("OUTPUT", tr("Road network"),
                                                  "GeoPackage (*.gpkg)")
    param.setHelp(tr(text))
    return param
