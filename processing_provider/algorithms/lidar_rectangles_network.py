"""LiDAR stage 6: road rectangles to centre lines, road polygons and junctions."""
from qgis.core import QgsProcessing, QgsProcessingParameterFeatureSource

from ..loading import load_geopackage_on_completion
from .base import JobAlgorithm, network_output


class RectanglesToNetwork(JobAlgorithm):
    NAME = "rectanglestonetwork"
    DISPLAY_NAME = "Rectangles to centre lines and polygons"
    GROUP = "LiDAR"
    STAGE = 5
    JOB = "rectangles_network_job"
    HELP = (
        "<p>Turns road rectangles into a road network: each rectangle's mid-line is its "
        "centre line; centre lines of overlapping or abutting rectangles that continue each "
        "other are chained and smoothed (a curved road becomes one line), then go through "
        "the network stage every method ends in (Road raster to network): gaps bridged by "
        "the integer program, T, X and Y junctions built, lines split where roads meet, "
        "duplicates and isolated short pieces removed; a junction connection far outside "
        "the rectangles is refused. Road polygons follow the centre lines at their "
        "widths.</p>"
        "<p>Input: the rectangles of Minimum-cover road rectangles, or any polygon layer with "
        "the fields width_m (metres) and theta_rad (road direction, radians counter-clockwise "
        "from east), e.g. rectangles edited by hand. Writes a GeoPackage with "
        "road_centrelines (width_m), road_polygons, junctions and the rectangles.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        params = [
            (QgsProcessingParameterFeatureSource("INPUT", self.tr("Road rectangles"),
                                                 [QgsProcessing.TypeVectorPolygon]),
             "rectangles with fields width_m and theta_rad"),
            (network_output(self.tr, "GeoPackage receiving the road network layers"), None),
        ]
        self.add_parameters(params)
        self.add_network_outputs()

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        result = self.run_job(dict(
            rectangles_path=self.source_path(parameters, "INPUT", context, feedback),
            out_path=out), feedback)
        load_geopackage_on_completion(context, out, ("rectangles", "road_polygons",
                                                     "road_centrelines", "junctions"),
                                      group="roads")
        return {"OUTPUT": out, **self.network_outputs(result, feedback)}
