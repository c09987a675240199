"""Train road model: the learned road cue trained on the user's image from a road layer."""
from qgis.core import QgsProcessingOutputNumber

from gisroads.jobs import stage_default, train_job
from gisroads.learn.convnet import CHECK_SHARE, FINE_TUNE_STEPS

from ..convert import gisroads_errors, progress_callback, source_to_frame
from .base import GisroadsAlgorithm, train_parameters


class TrainRoadModel(GisroadsAlgorithm):
    NAME = "trainroadmodel"
    DISPLAY_NAME = "Train road model"
    GROUP = "Imagery"
    HELP = (
        "<p>Trains the learned road cue on your own aerial image from a road layer over it "
        "(last year's road database, OpenStreetMap), for the imagery road network "
        "algorithm's <i>Road model file</i>: how an agency updates its roads from a new "
        "orthophoto.</p>"
        "<p>The roads are rasterised at their width: pixels in the core half of a road are "
        "road, pixels beyond the road edge plus the guard band are non-road (the guard "
        "absorbs lines a few metres off the road and kerbs); roads missing from the layer "
        "fall among the non-road pixels, a few per cent of them, which the model "
        "tolerates.</p>"
        "<p>An output ending in <b>.onnx</b> (the default) fine-tunes the bundled "
        "convolutional network on the image (a few minutes for a 1500 x 1500 tile; needs "
        "PyTorch in the Python that runs gisroads: pip install 'gisroads[train]'). An "
        "output ending in <b>.npz</b> trains gradient-boosted trees (scikit-learn) on "
        "multiscale colour, texture and line features in metres, calibrated to the share of "
        "the image the roads cover (a model archive of plain arrays). Cancelling stops "
        "between steps.</p>"
        "<p>The network is checked before it is written: a share of the layer's road length "
        "(a fifth by default) is left out of the fine-tuning, and where the bundled network "
        "finds more of those roads than the fine-tuned one, the bundled network is written "
        "(with a warning): fine-tuning then did not help on this image.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.add_parameters(train_parameters(
            self.tr, stage_default(train_job, "default_width_m"),
            stage_default(train_job, "guard_m"), stage_default(train_job, "samples"),
            FINE_TUNE_STEPS, CHECK_SHARE))
        self.addOutput(QgsProcessingOutputNumber("SAMPLES_USED",
                                                 self.tr("Samples used (boosted trees)")))
        self.addOutput(QgsProcessingOutputNumber("ROAD_SHARE",
                                                 self.tr("Road share of the layer")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        if not out.lower().endswith((".npz", ".onnx")):
            out += ".onnx"
        roads = source_to_frame(self.parameterAsSource(parameters, "ROADS", context), feedback)
        field = self.parameterAsString(parameters, "WIDTH_FIELD", context) or None
        with gisroads_errors(feedback):
            result = train_job(
                self.parameterAsRasterLayer(parameters, "IMAGE", context).source(), roads,
                out, width_field=field,
                default_width_m=self.parameterAsDouble(parameters, "WIDTH", context),
                guard_m=self.parameterAsDouble(parameters, "GUARD", context),
                samples=self.parameterAsInt(parameters, "SAMPLES", context),
                steps=self.parameterAsInt(parameters, "STEPS", context),
                check_share=self.parameterAsDouble(parameters, "CHECK", context),
                progress=progress_callback(feedback))
        if "trees" in result:
            feedback.pushInfo(f"model of {result['trees']} trees from {result['samples']} "
                              f"samples, calibrated to a road share of "
                              f"{result['road_share']:.3f}")
        elif (result.get("check") or {}).get("kept") == "base":
            feedback.pushInfo("the base network was written: it found more of the roads "
                              "left out to check the fine-tuning")
        else:
            feedback.pushInfo(f"network fine-tuned for {result['steps']} steps; the layer's "
                              f"roads cover {result['road_share']:.3f} of the image")
        return {"OUTPUT": str(result["model"]), "SAMPLES_USED": result.get("samples", 0),
                "ROAD_SHARE": result["road_share"]}
