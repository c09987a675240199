"""LiDAR stage 5: the minimum cover of the rectangle hypotheses."""
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber, QgsProcessingParameterBoolean,
                       QgsProcessingParameterFeatureSource,
                       QgsProcessingParameterFileDestination, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterLayer)

from ..loading import load_geopackage_on_completion
from .base import JobAlgorithm


class LidarMinCover(JobAlgorithm):
    NAME = "lidarmincover"
    DISPLAY_NAME = "Minimum-cover road rectangles"
    GROUP = "LiDAR"
    STAGE = 4
    JOB = "min_cover_job"
    HELP = (
        "<p>Selects the fewest, most likely rectangles that explain the road likelihood "
        "(Zhu &amp; Mordohai, section 4.4, Algorithm 2): seeds are sampled along the centre "
        "lines of the hypotheses; a rectangle costs A plus the likelihood it leaves "
        "unexplained (Eq. 6-7); the greedy cover repeatedly takes the rectangle of lowest "
        "cost per newly covered seed until that density exceeds D_max, and seeds nobody "
        "covers go to dummy sets (Eq. 8). The exact option solves the same cover as an "
        "integer program (PuLP/CBC) instead, for small inputs.</p>"
        "<p>Inputs: the hypotheses layer and likelihood maps of Road likelihood maps (or a "
        "hand-edited copy of the hypotheses). Writes the selected rectangles (GeoPackage, "
        "with width, length, orientation, cost, density and mean likelihood). Next stage: "
        "Rectangles to centre lines and polygons.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        params = [
            (QgsProcessingParameterFeatureSource("INPUT", self.tr("Hypotheses"),
                                                 [QgsProcessing.TypeVectorPolygon]),
             "the hypotheses layer of Road likelihood maps (fields hyp_id, theta_rad, "
             "width_index, width_m)"),
            (QgsProcessingParameterRasterLayer("LIKELIHOOD", self.tr("Likelihood maps")),
             "the likelihood GeoTIFF of Road likelihood maps"),
            (QgsProcessingParameterNumber("A", self.tr("Rectangle cost A"), double,
                                          self.default("a"), minValue=0.0),
             "fixed cost of every selected rectangle (Eq. 6)"),
            (QgsProcessingParameterNumber("D_MAX", self.tr("Largest cost density D_max"),
                                          double, self.default("d_max"), minValue=0.0),
             "the greedy cover stops when the best cost per new seed exceeds this (Eq. 8)"),
            (QgsProcessingParameterNumber("L_MAX", self.tr("Likelihood cap L_max"), double,
                                          self.default("l_max"), minValue=0.1),
             "the cap used when the maps were made"),
            (QgsProcessingParameterBoolean("EXACT", self.tr("Exact integer program"), False),
             "solve the cover exactly with PuLP (small inputs: minutes for thousands of "
             "hypotheses)"),
            (QgsProcessingParameterFileDestination("OUTPUT", self.tr("Road rectangles"),
                                                   "GeoPackage (*.gpkg)"),
             "GeoPackage with the selected rectangles (layer rectangles)"),
        ]
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputNumber("N_RECTANGLES", self.tr("Rectangles")))
        self.addOutput(QgsProcessingOutputNumber("COVER_COST", self.tr("Cover cost (Eq. 7)")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        exact = self.parameterAsBoolean(parameters, "EXACT", context)
        options = dict(a=self.parameterAsDouble(parameters, "A", context),
                       l_max=self.parameterAsDouble(parameters, "L_MAX", context))
        if not exact:
            options["d_max"] = self.parameterAsDouble(parameters, "D_MAX", context)
        result = self.run_job(dict(
            hypotheses_path=self.source_path(parameters, "INPUT", context, feedback),
            likelihood_path=self.parameterAsRasterLayer(parameters, "LIKELIHOOD",
                                                        context).source(),
            rectangles_path=out, exact=exact, **options), feedback)
        load_geopackage_on_completion(context, out, ("rectangles",))
        feedback.pushInfo(f"{result['n_rectangles']} rectangles, cover cost "
                          f"{result['cover_cost']:.1f}")
        return {"OUTPUT": out, "N_RECTANGLES": result["n_rectangles"],
                "COVER_COST": result["cover_cost"]}
