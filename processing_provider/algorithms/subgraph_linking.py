"""Subgraph linking (integer program): gap hypotheses between road parts, the best kept."""
import math
import tempfile
from pathlib import Path

from qgis.core import (QgsProcessing, QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSink, QgsProcessingParameterFeatureSource,
                       QgsProcessingParameterNumber)

from ..loading import ApplyStyle, on_load, style_path
from .base import JobAlgorithm
from .imagery_inputs import image_arguments, imagery_parameters


class SubgraphLinking(JobAlgorithm):
    NAME = "subgraphlinking"
    JOB = "linking_job"
    DISPLAY_NAME = "Subgraph linking (integer program)"
    GROUP = "Imagery"
    STAGE = 4
    HELP = (
        "<p>Links road parts (centre lines from the road-part shape filtering) into road "
        "strings, following Grote &amp; Rottensteiner (2010, Sec. 2.2).</p>"
        "<p><b>Subgraph generation</b>: every pair of part ends that is close (absolutely "
        "and relative to the parts' lengths), similar in direction and in smooth "
        "continuation (small lateral offset) becomes a gap edge; one end may have several "
        "competing gap edges. <b>Evaluation</b>: each gap edge gets a weight, the product "
        "of linear weights of six features (smoothness, distance, direction difference, "
        "the parts' quality, colour and width differences), combined with what lies in the "
        "gap when rasters are given: a building there (from the DSM) rules the link out "
        "(-10), trees, vehicles and shadow that hide the road support it (occlusion), "
        "asphalt-like surface supports it, a lawn speaks against it; gaps shorter than the "
        "small-gap length ignore their context. An integer program (PuLP) then keeps the "
        "links of greatest total weight with at most one link per part end.</p>"
        "<p>Outputs: <i>gap_edges</i>, every hypothesis with its features, context, weights "
        "and <i>selected</i>, and <i>road_strings</i>, the chained parts with "
        "length-weighted width and quality, the input of junction construction.</p>"
        "<p>To override the program, edit <i>selected</i> in a gap_edges layer (at most "
        "one selected edge per part end) and run again with it as <i>Edited gap edges</i>: "
        "the road strings are then chained from it as it is.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        params = [
            (QgsProcessingParameterFeatureSource("ROAD_PARTS", self.tr("Road parts"),
                                                 [QgsProcessing.TypeVectorLine]),
             "centre lines with part_id, width_m, quality and band means (mean_b1, ...), "
             "in a projected CRS in metres"),
            (QgsProcessingParameterFeatureSource("EDITED_GAP_EDGES",
                                                 self.tr("Edited gap edges"),
                                                 [QgsProcessing.TypeVectorLine], optional=True),
             "optional: a gap_edges layer of an earlier run with selected edited by hand; "
             "when given, the road strings follow it and nothing is recomputed"),
        ] + imagery_parameters(
            self.tr, image_label="Image (context)", image_optional=True,
            image="optional: the image the parts come from, for shadow, asphalt and (RGB) "
                  "vegetation in the gaps",
            nir_band="optional: the image's NIR band; vegetation then comes from the NDVI",
            dsm_label="DSM (context)",
            dsm="optional: surface heights in metres; buildings, vehicles and trees in the "
                "gaps are found in its normalised heights") + [
            (QgsProcessingParameterNumber("MAX_GAP", self.tr("Largest gap (metres)"), double,
                                          self.default("max_gap_m"), minValue=0.0),
             "part ends further apart are never linked"),
            (QgsProcessingParameterNumber("MAX_GAP_RELATIVE",
                                          self.tr("Largest gap relative to the parts' lengths"),
                                          double, self.default("max_gap_relative"), minValue=0.0),
             "the gap may be at most this times the two parts' lengths together"),
            (QgsProcessingParameterNumber("MAX_DIRECTION",
                                          self.tr("Largest direction difference (degrees)"),
                                          double,
                                          math.degrees(self.default("max_direction_diff_rad")),
                                          minValue=0.0, maxValue=180.0),
             "0 for a straight continuation"),
            (QgsProcessingParameterNumber("MAX_LATERAL",
                                          self.tr("Largest lateral offset (metres)"), double,
                                          self.default("max_lateral_offset_m"), minValue=0.0),
             "continuation smoothness: how far an end may lie beside the other part's "
             "extension"),
            (QgsProcessingParameterNumber("MAX_OVERLAP",
                                          self.tr("Largest overlap of linked ends (metres)"),
                                          double, self.default("max_overlap_m"), minValue=0.0),
             "how far two linked ends may reach past each other (touching segments)"),
            (QgsProcessingParameterNumber("SMALL_GAP",
                                          self.tr("Small gap: context ignored below (metres)"),
                                          double, self.default("small_gap_m"), minValue=0.0),
             "the context of shorter gaps is too small to judge"),
            (QgsProcessingParameterFeatureSink("GAP_EDGES", self.tr("Gap edges"),
                                               QgsProcessing.TypeVectorLine),
             "every link hypothesis with features, context, weights and selected"),
            (QgsProcessingParameterFeatureSink("ROAD_STRINGS", self.tr("Road strings"),
                                               QgsProcessing.TypeVectorLine),
             "road parts chained through the selected gap edges"),
        ]
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputNumber("SELECTED", self.tr("Gap edges kept")))
        self.addOutput(QgsProcessingOutputNumber("STRINGS", self.tr("Road strings")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        def number(name):
            return self.parameterAsDouble(parameters, name, context)

        image = self.parameterAsRasterLayer(parameters, "IMAGE", context)
        dsm = self.parameterAsRasterLayer(parameters, "DSM", context)
        edited = self.parameterAsSource(parameters, "EDITED_GAP_EDGES", context)
        with tempfile.TemporaryDirectory(prefix="gisroads-linking-") as folder:
            path = str(Path(folder) / "linked.gpkg")
            bands = image_arguments(self, parameters, context) if image is not None else {}
            result = self.run_job(dict(
                bands, road_parts=self.source_path(parameters, "ROAD_PARTS", context,
                                                   feedback),
                linked_path=path, dsm_path=None if dsm is None else dsm.source(),
                edited_gap_edges=None if edited is None else self.source_path(
                    parameters, "EDITED_GAP_EDGES", context, feedback),
                max_gap_m=number("MAX_GAP"), max_gap_relative=number("MAX_GAP_RELATIVE"),
                max_direction_diff_rad=math.radians(number("MAX_DIRECTION")),
                max_lateral_offset_m=number("MAX_LATERAL"),
                max_overlap_m=number("MAX_OVERLAP"), small_gap_m=number("SMALL_GAP")),
                feedback)
            outputs = {}
            for param, layer in (("GAP_EDGES", "gap_edges"), ("ROAD_STRINGS", "road_strings")):
                outputs[param] = self.layer_to_sink(parameters, param, context, path, layer,
                                                    feedback)
                on_load(context, outputs[param], ApplyStyle(style_path(layer)))
        feedback.pushInfo(f"{result['gap_edges']} gap edges, {result['selected']} kept; "
                          f"{result['road_strings']} road strings")
        return {**outputs, "SELECTED": result["selected"], "STRINGS": result["road_strings"]}
