"""Imagery road network (Grote & Rottensteiner): the whole pipeline from an aerial image."""
from qgis.core import (QgsProcessingOutputString, QgsProcessingParameterBoolean,
                       QgsProcessingParameterEnum, QgsProcessingParameterFile,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterDestination)

from gisroads.geo import CENTRELINES, JUNCTIONS, POLYGONS
from gisroads.imagery.segments import MIN_SEGMENT_PX, SEGMENT_AREA_M2
from gisroads.jobs import image_job

from ..convert import gisroads_errors, progress_callback
from ..loading import load_beneath_on_completion, load_geopackage_on_completion
from .base import GisroadsAlgorithm, network_output
from .imagery_inputs import band_options, imagery_parameters

USE_MODEL_DEFAULT = True
"""Whether the learned road cue is on by default (as ``gisroads image --model``)."""
BUNDLED_MODELS = ("default", "boosted")
"""``gisroads image --model`` of each choice of the *Bundled road model* parameter."""


class ImageryRoadNetwork(GisroadsAlgorithm):
    NAME = "imageryroadnetwork"
    DISPLAY_NAME = "Imagery road network (Grote & Rottensteiner)"
    GROUP = "Imagery"
    HELP = (
        "<p>Extracts the road network of a high-resolution aerial image following Grote "
        "&amp; Rottensteiner: a normalized-cut over-segmentation (colour, intervening "
        "edges and, with a NIR band, an NDVI factor), iterative grouping of segments, road "
        "parts kept by their shape (elongation, convexity, constant width within the road "
        "widths, low height and NDVI, no shadow), linking of road parts across gaps by an "
        "integer program that weighs each gap's geometry and what lies in it (trees, "
        "buildings, shadow), and junction construction with network significance "
        "checks.</p>"
        "<p>Works on RGB, colour-infrared and panchromatic images; a NIR band and a DSM are "
        "used when given, and the road_centrelines record the cues used. Output: a "
        "GeoPackage in the image's CRS with road_centrelines (width_m), road_polygons, "
        "junctions and the QA layers segments (with every shape attribute and the reason a "
        "segment failed), road_parts, gap_edges and junction_connections. The stage "
        "algorithms of this group run the same steps one at a time.</p>"
        "<p><b>Learned road cue</b> (beyond the papers, on by default): a per-pixel road "
        "probability from the bundled convolutional network (a small U-Net trained on 590 "
        "labelled tiles of four sources, applied with onnxruntime), or from a model trained "
        "on your own image with <i>Train road model</i>, goes through the network stage of "
        "<i>Road raster to network</i> at the model's own threshold. The older boosted "
        "trees (adapted to the image and re-scored by the context model) stay selectable. "
        "The probability can be written as a raster to look at. With the cue off, the "
        "papers' pipeline alone.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        params = imagery_parameters(
            self.tr, image_name="INPUT", image_label="Aerial image",
            image="RGB, CIR or panchromatic image in a projected CRS (metres); a geographic "
                  "image is warped to its UTM zone",
            nir_band="optional: the NIR band; enables NDVI in the segmentation, the road-part "
                     "test and the gap context",
            red_band="optional, with a NIR band: the red band for NDVI (default band 1, or 2 "
                     "in a three-band CIR image)",
            dsm_label="Surface model (DSM)",
            dsm="optional: heights in metres; enables the height criteria and buildings as "
                "gap context") + [
            (QgsProcessingParameterNumber("SEGMENTS", self.tr("NCut segments"),
                                          QgsProcessingParameterNumber.Integer, None,
                                          optional=True, minValue=1),
             f"target over-segmentation size; empty: one segment per {SEGMENT_AREA_M2:g} m2 "
             f"of ground (at least {MIN_SEGMENT_PX} pixels each)"),
            (QgsProcessingParameterBoolean("USE_MODEL", self.tr("Use the learned road cue"),
                                           USE_MODEL_DEFAULT),
             "on (default): the learned road probability through the network stage of "
             "Road raster to network, the better path on the benchmark images (QA layers "
             "gap_edges, junction_connections, rejected); off: the papers' pipeline alone "
             "(QA layers segments, road_parts, gap_edges, junction_connections)"),
            (QgsProcessingParameterEnum("BUNDLED_MODEL", self.tr("Bundled road model"),
                                        ["convolutional network", "boosted trees"],
                                        defaultValue=0),
             "the model used when no road model file is given: the convolutional network "
             "(default) or the older boosted trees"),
            (QgsProcessingParameterFile("MODEL", self.tr("Road model file"), optional=True,
                                        fileFilter="Road models (*.onnx *.npz)"),
             "a model file from Train road model (.onnx: the network fine-tuned on your "
             "image; .npz: boosted trees); empty: the bundled road model"),
            (QgsProcessingParameterBoolean("USE_CONTEXT",
                                           self.tr("Re-score with the context model"), True),
             "boosted trees only: on (default), the bundled context model re-scores their "
             "probability from its own shape (long narrow bands) before the network stage; "
             "not applied to the convolutional network, a model from Train road model, nor "
             "in the papers' pipeline"),
            (QgsProcessingParameterRasterDestination(
                "PROBABILITY", self.tr("Road probability"), optional=True,
                createByDefault=False),
             "optional: the learned road probability (0-1, float32 GeoTIFF) on the grid the "
             "image was worked on"),
            (network_output(self.tr, "GeoPackage receiving every layer, in the image's CRS"), None),
        ]
        self.add_parameters(params)
        self.add_network_outputs()
        self.addOutput(QgsProcessingOutputString("CUES", self.tr("Cues used")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        image = self.parameterAsRasterLayer(parameters, "INPUT", context)
        dsm = self.parameterAsRasterLayer(parameters, "DSM", context)
        options = {}
        model = (self.parameterAsFile(parameters, "MODEL", context)
                 or BUNDLED_MODELS[self.parameterAsEnum(parameters, "BUNDLED_MODEL", context)])
        if not self.parameterAsBool(parameters, "USE_MODEL", context):
            model = "none"
        probability = self.parameterAsOutputLayer(parameters, "PROBABILITY", context) or None
        if probability and model == "none":
            feedback.pushWarning(self.tr("the learned road cue is off: no road probability "
                                         "written"))
        if parameters.get("SEGMENTS") not in (None, ""):
            options["n_segments"] = self.parameterAsInt(parameters, "SEGMENTS", context)
        with gisroads_errors(feedback):
            result = image_job(
                image.source(), out,
                **band_options(self, parameters, context),
                dsm_path=dsm.source() if dsm is not None else None, model=model,
                context="default" if self.parameterAsBool(parameters, "USE_CONTEXT", context)
                else "none",
                probability_path=probability if model != "none" else None,
                progress=progress_callback(feedback), **options)
        qa = (("rejected",) if result["method"] == "learned-probability"
              else ("segments", "road_parts"))
        load_geopackage_on_completion(context, out, (
            *qa, "gap_edges", "junction_connections", POLYGONS, CENTRELINES, JUNCTIONS),
            title=image.name())
        load_beneath_on_completion(context, image.source(), "image", title=image.name())
        outputs = {"PROBABILITY": str(result["probability"])} if "probability" in result else {}
        return {"OUTPUT": out, "CUES": result["cues"], **outputs,
                **self.network_outputs(result, feedback, f"; cues: {result['cues']}")}
