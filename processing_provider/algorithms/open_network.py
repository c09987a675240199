"""Open road network GeoPackage: every layer of a gisroads output, styled as stored in it."""
import json

from qgis.core import (QgsProcessingOutputMultipleLayers, QgsProcessingOutputString,
                       QgsProcessingParameterFile, QgsSingleSymbolRenderer,
                       QgsCategorizedSymbolRenderer)

from ..loading import open_geopackage_layers
from .base import GisroadsAlgorithm


def _renderer_summary(layer) -> dict:
    renderer = layer.renderer()
    if isinstance(renderer, QgsSingleSymbolRenderer):
        colors = [renderer.symbol().color().name()]
    elif isinstance(renderer, QgsCategorizedSymbolRenderer):
        colors = [c.symbol().color().name() for c in renderer.categories()]
    else:
        colors = []
    return {"renderer": renderer.type(), "colors": colors}


class OpenRoadNetwork(GisroadsAlgorithm):
    NAME = "openroadnetwork"
    DISPLAY_NAME = "Open road network GeoPackage"
    GROUP = "Evaluation"
    HELP = (
        "<p>Adds every layer of a GeoPackage written by gisroads (road centre lines, road "
        "polygons, junctions and the QA layers) to the project, each with the style stored "
        "in the GeoPackage, polygons below lines below points.</p>"
        "<p>The STYLES output lists, per layer, whether its style came from the file and "
        "how it is drawn.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        param = QgsProcessingParameterFile("INPUT", self.tr("Road network GeoPackage"),
                                           extension="gpkg")
        param.setHelp(self.tr("a .gpkg written by gisroads (or any GeoPackage)"))
        self.addParameter(param)
        self.addOutput(QgsProcessingOutputMultipleLayers("LAYERS", self.tr("Layers")))
        self.addOutput(QgsProcessingOutputString("STYLES", self.tr("Styles per layer (JSON)")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        path = self.parameterAsFile(parameters, "INPUT", context)
        opened = open_geopackage_layers(path)
        # QGIS puts each new layer on top: load polygons (type 2) first, points (0) last
        opened.sort(key=lambda item: -int(item[1].geometryType()))
        styles, ids = {}, []
        for name, layer, styled in opened:
            styles[name] = {"styled_from_file": styled, **_renderer_summary(layer)}
            if not styled:
                feedback.pushWarning(self.tr(f"{name}: no style stored in the GeoPackage"))
            context.temporaryLayerStore().addMapLayer(layer)
            context.addLayerToLoadOnCompletion(
                layer.id(), context.LayerDetails(name, context.project(), name))
            ids.append(layer.id())
        return {"LAYERS": ids, "STYLES": json.dumps(styles)}
