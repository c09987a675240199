"""Road raster to network: any road mask or probability raster to a clean, connected network."""
from qgis.core import QgsProcessingOutputNumber, QgsProcessingParameterBoolean, \
    QgsProcessingParameterNumber, QgsProcessingParameterRasterLayer

from gisroads.geo import CENTRELINES, JUNCTIONS, POLYGONS
from gisroads.jobs import vectorize_job
from gisroads.network.rasters import THRESHOLD

from ..convert import gisroads_errors, progress_callback
from ..loading import load_geopackage_on_completion
from .base import GisroadsAlgorithm, network_output


class RoadRasterToNetwork(GisroadsAlgorithm):
    NAME = "roadrastertonetwork"
    DISPLAY_NAME = "Road raster to network"
    GROUP = "Road network"
    HELP = (
        "<p>Turns any road raster into a clean, connected vector road network: a binary "
        "mask or a road probability (0-1, or 0-255 in an 8-bit raster) from a deep-learning "
        "segmentation, a classified land-cover map or a thresholded index, in any CRS "
        "(a geographic raster is worked in its UTM zone); no-data is never road.</p>"
        "<p>The probability is smoothed, thresholded and cleaned (small holes filled, "
        "specks dropped), skeletonised tile by tile with the tiles stitched, spurs shorter "
        "than the local half width plus 5 m pruned, junction pixel clusters contracted into "
        "one node at the crossing, branch ends straightened; gaps between dead ends (a "
        "tree, a car, a bridge shadow across the road) are bridged by the integer program "
        "of the imagery method when the continuation is smooth; junctions are built and "
        "insignificant pieces dropped. This is the network stage every gisroads method "
        "ends in.</p>"
        "<p>Output: a GeoPackage with road_centrelines (width_m from the raster, score = "
        "mean probability), road_polygons, junctions and the QA layers gap_edges (weights "
        "and selected), junction_connections and rejected.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.add_parameters([
            (QgsProcessingParameterRasterLayer("INPUT", self.tr("Road raster")),
             "road mask or probability raster (0-1 or 0-255), projected or geographic"),
            (QgsProcessingParameterNumber("BAND", self.tr("Band"),
                                          QgsProcessingParameterNumber.Integer, 1,
                                          minValue=1),
             "1-based band holding the road mask or probability"),
            (QgsProcessingParameterNumber("THRESHOLD", self.tr("Road threshold"),
                                          QgsProcessingParameterNumber.Double, THRESHOLD,
                                          minValue=0.0, maxValue=1.0),
             "pixels whose smoothed probability reaches this are road (0-1; a 0-255 raster "
             "is scaled to 0-1 first)"),
            (QgsProcessingParameterBoolean("WIDE_AREAS", self.tr("Roads through car parks and "
                                                                 "plazas"), False),
             "car parks, plazas and other wide paved areas give the roads that cross them, "
             "not their outlines and aisles (the imagery algorithm's own rule)"),
            (network_output(self.tr, "GeoPackage receiving every layer, in the raster's CRS"),
             None),
        ])
        self.add_network_outputs()
        self.addOutput(QgsProcessingOutputNumber("GAPS_BRIDGED",
                                                 self.tr("Gaps bridged")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        raster = self.parameterAsRasterLayer(parameters, "INPUT", context)
        with gisroads_errors(feedback):
            result = vectorize_job(
                raster.source(), out,
                band=self.parameterAsInt(parameters, "BAND", context),
                threshold=self.parameterAsDouble(parameters, "THRESHOLD", context),
                wide_areas=self.parameterAsBool(parameters, "WIDE_AREAS", context),
                progress=progress_callback(feedback))
        load_geopackage_on_completion(context, out, (
            "rejected", "gap_edges", "junction_connections", POLYGONS, CENTRELINES,
            JUNCTIONS), title=raster.name())
        return {"OUTPUT": out, "GAPS_BRIDGED": result["gaps_bridged"],
                **self.network_outputs(result, feedback,
                                       f"; {result['gaps_bridged']} gaps bridged")}
