"""Train road model: the learned road cue trained on the user's image from a road layer."""
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterField,
                       QgsProcessingParameterFileDestination, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterLayer)

from gisroads.jobs import stage_default, train_job

from ..convert import gisroads_errors, progress_callback, source_to_frame
from .base import GisroadsAlgorithm


class TrainRoadModel(GisroadsAlgorithm):
    NAME = "trainroadmodel"
    DISPLAY_NAME = "Train road model"
    GROUP = "Imagery"
    HELP = (
        "<p>Trains the learned road cue on your own aerial image from a road layer over it "
        "(last year's road database, OpenStreetMap), for the imagery road network "
        "algorithm's <i>Road model</i>: how an agency updates its roads from a new "
        "orthophoto.</p>"
        "<p>The roads are rasterised at their width: pixels in the core half of a road are "
        "road samples, pixels beyond the road edge plus the guard band are non-road "
        "samples (the guard absorbs lines a few metres off the road and kerbs); roads "
        "missing from the layer fall among the non-road samples, a few per cent of them, "
        "which the model tolerates. Gradient-boosted trees (scikit-learn) learn from "
        "multiscale colour, texture and line features in metres, so the model holds at the "
        "image's pixel size; its probabilities are calibrated to the share of the image the "
        "roads cover.</p>"
        "<p>Output: a model archive (.npz; plain arrays, nothing executable) with its "
        "training parameters. Needs scikit-learn in QGIS's Python. Cancelling stops between "
        "image tiles; the final fit (seconds) runs to its end.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.add_parameters([
            (QgsProcessingParameterRasterLayer("IMAGE", self.tr("Aerial image")),
             "RGB or panchromatic image in a projected CRS (metres); a geographic image is "
             "warped to its UTM zone; bands 1-3 are taken as red, green, blue"),
            (QgsProcessingParameterFeatureSource("ROADS", self.tr("Road layer"),
                                                 [QgsProcessing.TypeVectorLine]),
             "road centre lines over the image, any CRS (reprojected to the image's); they "
             "need not be complete"),
            (QgsProcessingParameterField("WIDTH_FIELD", self.tr("Road width field"), None,
                                         "ROADS", QgsProcessingParameterField.Numeric,
                                         optional=True),
             "field holding each road's width in metres; empty fields, non-positive values "
             "and no field take the road width below"),
            (QgsProcessingParameterNumber("WIDTH", self.tr("Road width (metres)"),
                                          QgsProcessingParameterNumber.Double,
                                          stage_default(train_job, "width_m"),
                                          minValue=0.5, maxValue=100.0),
             "width of the roads without a width field value"),
            (QgsProcessingParameterNumber("GUARD", self.tr("Guard band (metres)"),
                                          QgsProcessingParameterNumber.Double,
                                          stage_default(train_job, "guard_m"),
                                          minValue=0.0, maxValue=50.0),
             "no non-road sample within this distance of a road's edge: OpenStreetMap lines "
             "are often 2-5 m off the road"),
            (QgsProcessingParameterNumber("SAMPLES", self.tr("Samples"),
                                          QgsProcessingParameterNumber.Integer,
                                          stage_default(train_job, "samples"),
                                          minValue=1000),
             "pixels sampled from the image, half of them road; more samples, slower "
             "training"),
            (QgsProcessingParameterFileDestination("OUTPUT", self.tr("Road model"),
                                                   self.tr("Road model (*.npz)")),
             "the model archive (.npz) to give to the imagery road network algorithm"),
        ])
        self.addOutput(QgsProcessingOutputNumber("SAMPLES_USED", self.tr("Samples used")))
        self.addOutput(QgsProcessingOutputNumber("ROAD_SHARE",
                                                 self.tr("Road share calibrated to")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        if not out.lower().endswith(".npz"):
            out += ".npz"
        roads = source_to_frame(self.parameterAsSource(parameters, "ROADS", context), feedback)
        field = self.parameterAsString(parameters, "WIDTH_FIELD", context) or None
        with gisroads_errors(feedback):
            result = train_job(
                self.parameterAsRasterLayer(parameters, "IMAGE", context).source(), roads,
                out, width_field=field,
                width_m=self.parameterAsDouble(parameters, "WIDTH", context),
                guard_m=self.parameterAsDouble(parameters, "GUARD", context),
                samples=self.parameterAsInt(parameters, "SAMPLES", context),
                progress=progress_callback(feedback))
        feedback.pushInfo(f"model of {result['trees']} trees from {result['samples']} "
                          f"samples, calibrated to a road share of {result['road_share']:.3f}")
        return {"OUTPUT": str(result["model"]), "SAMPLES_USED": result["samples"],
                "ROAD_SHARE": result["road_share"]}
