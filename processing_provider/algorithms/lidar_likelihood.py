"""LiDAR stage 4: rectangle road hypotheses and the per-width likelihood maps."""
from qgis.core import (QgsProcessingOutputNumber, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterDestination,
                       QgsProcessingParameterRasterLayer, QgsProcessingParameterString)

from ..loading import load_geopackage_on_completion
from .base import JobAlgorithm
from .lidar_segmentation import level_parameter


class LidarLikelihood(JobAlgorithm):
    NAME = "lidarlikelihood"
    DISPLAY_NAME = "Road likelihood maps"
    GROUP = "LiDAR"
    STAGE = 3
    JOB = "likelihood_job"
    HELP = (
        "<p>Rectangular road hypotheses on one level of a LiDAR intensity image and the road "
        "likelihood map of every window width (Zhu &amp; Mordohai, section 4.3, Eq. 5). "
        "Window corners are sampled on long straight boundaries of the segmentation, "
        "orientations come from the peaks of the edge-orientation histogram; a window is "
        "kept when its long sides lie on edges (boundary filter, road darker or brighter "
        "than its surroundings) and its inside has no edge across the road (interior "
        "filter). Each valid window adds its scores to the pixels it covers in its width's "
        "map, capped at L_max.</p>"
        "<p>Inputs: the intensity image and the segments of the previous stages (same grid). "
        "Writes the likelihood GeoTIFF (one band per width) and the hypotheses layer "
        "(GeoPackage). Next stage: Minimum-cover road rectangles.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        params = [
            (QgsProcessingParameterRasterLayer("INPUT", self.tr("Intensity image")),
             "the intensity GeoTIFF of Ground planes and intensity image"),
            (level_parameter(self.tr), None),
            (QgsProcessingParameterRasterLayer("SEGMENTS", self.tr("Segments")),
             "the segments GeoTIFF of Edges and NCut segmentation, for the same level"),
            (QgsProcessingParameterString("WIDTHS", self.tr("Road widths to try (metres)"),
                                          ",".join(f"{w:g}" for w in self.default("widths_m"))),
             "comma-separated; one likelihood band per width (paper: 10-25 m for arterials)"),
            (QgsProcessingParameterString("LENGTHS", self.tr("Window lengths (metres)"),
                                          ",".join(f"{v:g}" for v in self.default("lengths_m"))),
             "comma-separated (paper: 40-300 m)"),
            (QgsProcessingParameterNumber("T_BD", self.tr("Boundary threshold T_bd"), double,
                                          self.default("t_bd"), minValue=0.0, maxValue=1.0),
             "least boundary-filter score of a valid window"),
            (QgsProcessingParameterNumber("T_INT", self.tr("Interior threshold T_int"),
                                          double, self.default("t_int"), minValue=-1.0,
                                          maxValue=1.0),
             "least interior-filter score of a valid window"),
            (QgsProcessingParameterNumber("L_MAX", self.tr("Likelihood cap L_max"), double,
                                          self.default("l_max"), minValue=0.1),
             "likelihood above which a pixel is surely road"),
            (QgsProcessingParameterRasterDestination("OUTPUT", self.tr("Likelihood maps")),
             "GeoTIFF, one band per width"),
            (QgsProcessingParameterFileDestination("HYPOTHESES", self.tr("Hypotheses"),
                                                   "GeoPackage (*.gpkg)"),
             "GeoPackage with the valid windows (layer hypotheses)"),
        ]
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputNumber("N_HYPOTHESES", self.tr("Valid windows")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsOutputLayer(parameters, "OUTPUT", context)
        hypotheses = self.parameterAsFileOutput(parameters, "HYPOTHESES", context)
        result = self.run_job(dict(
            intensity_path=self.parameterAsRasterLayer(parameters, "INPUT", context).source(),
            segments_path=self.parameterAsRasterLayer(parameters, "SEGMENTS", context).source(),
            likelihood_path=out, hypotheses_path=hypotheses,
            level=self.parameterAsInt(parameters, "LEVEL", context),
            widths_m=self.parameterAsString(parameters, "WIDTHS", context),
            lengths_m=self.parameterAsString(parameters, "LENGTHS", context),
            t_bd=self.parameterAsDouble(parameters, "T_BD", context),
            t_int=self.parameterAsDouble(parameters, "T_INT", context),
            l_max=self.parameterAsDouble(parameters, "L_MAX", context)), feedback)
        load_geopackage_on_completion(context, hypotheses, ("hypotheses",))
        feedback.pushInfo(f"{result['n_hypotheses']} valid windows")
        return {"OUTPUT": out, "HYPOTHESES": hypotheses,
                "N_HYPOTHESES": result["n_hypotheses"]}
