"""Subgraph linking (integer program): gap hypotheses between road parts, the best kept."""
import numpy as np
from qgis.core import (QgsProcessing, QgsProcessingException, QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSink, QgsProcessingParameterFeatureSource,
                       QgsProcessingParameterNumber)

from gisroads.imagery.cues import context_rasters, image_cues, normalised_dsm
from gisroads.network.subgraph import (MAX_DIRECTION_DIFF_RAD, MAX_GAP_M, MAX_GAP_RELATIVE,
                                       MAX_LATERAL_OFFSET_M, MAX_OVERLAP_M, SMALL_GAP_M,
                                       link_road_parts, road_strings)

from ..convert import (frame_to_sink, gisroads_errors, progress_callback, source_to_frame,
                       style_on_load)
from .base import GisroadsAlgorithm
from .imagery_inputs import band_options, imagery_parameters, read_raster_input


class SubgraphLinking(GisroadsAlgorithm):
    NAME = "subgraphlinking"
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
                                          MAX_GAP_M, minValue=0.0),
             "part ends further apart are never linked"),
            (QgsProcessingParameterNumber("MAX_GAP_RELATIVE",
                                          self.tr("Largest gap relative to the parts' lengths"),
                                          double, MAX_GAP_RELATIVE, minValue=0.0),
             "the gap may be at most this times the two parts' lengths together"),
            (QgsProcessingParameterNumber("MAX_DIRECTION",
                                          self.tr("Largest direction difference (degrees)"),
                                          double, float(np.degrees(MAX_DIRECTION_DIFF_RAD)),
                                          minValue=0.0, maxValue=180.0),
             "0 for a straight continuation"),
            (QgsProcessingParameterNumber("MAX_LATERAL",
                                          self.tr("Largest lateral offset (metres)"), double,
                                          MAX_LATERAL_OFFSET_M, minValue=0.0),
             "continuation smoothness: how far an end may lie beside the other part's "
             "extension"),
            (QgsProcessingParameterNumber("MAX_OVERLAP",
                                          self.tr("Largest overlap of linked ends (metres)"),
                                          double, MAX_OVERLAP_M, minValue=0.0),
             "how far two linked ends may reach past each other (touching segments)"),
            (QgsProcessingParameterNumber("SMALL_GAP",
                                          self.tr("Small gap: context ignored below (metres)"),
                                          double, SMALL_GAP_M, minValue=0.0),
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

    def _context(self, parameters, context, crs):
        """Keyword arguments of link_road_parts for the optional rasters."""
        image = read_raster_input(self, parameters, "IMAGE", context)
        dsm = read_raster_input(self, parameters, "DSM", context)
        for raster, name in ((image, "image"), (dsm, "DSM")):
            if raster is not None and None not in (raster.crs, crs) and raster.crs != crs:
                raise QgsProcessingException(
                    self.tr(f"the {name} is in another CRS than the road parts; reproject it"))
        if image is None and dsm is None:
            return {}
        if image is None:
            return {"transform": dsm.transform, "ndsm": normalised_dsm(dsm, dsm)}
        cues = image_cues(image, **band_options(self, parameters, context), dsm=dsm)
        return {"transform": image.transform, **context_rasters(cues)}

    def _link(self, parts, parameters, context, feedback):
        """Generation, context, weights and the integer program with the parameters."""
        def number(name):
            return self.parameterAsDouble(parameters, name, context)

        return link_road_parts(
            parts, **self._context(parameters, context, parts.crs),
            progress=progress_callback(feedback),
            gap_options={"max_gap_m": number("MAX_GAP"),
                         "max_gap_relative": number("MAX_GAP_RELATIVE"),
                         "max_direction_diff_rad": np.radians(number("MAX_DIRECTION")),
                         "max_lateral_offset_m": number("MAX_LATERAL"),
                         "max_overlap_m": number("MAX_OVERLAP")},
            weight_options={"small_gap_m": number("SMALL_GAP")})

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        parts = source_to_frame(self.parameterAsSource(parameters, "ROAD_PARTS", context),
                                feedback)
        edited = self.parameterAsSource(parameters, "EDITED_GAP_EDGES", context)
        with gisroads_errors():
            if edited is not None:
                gaps = source_to_frame(edited, feedback)
                strings = road_strings(parts, gaps)
            else:
                gaps, strings = self._link(parts, parameters, context, feedback)
        outputs = {}
        for param, layer, frame in (("GAP_EDGES", "gap_edges", gaps),
                                    ("ROAD_STRINGS", "road_strings", strings)):
            outputs[param] = frame_to_sink(self, parameters, param, context, frame,
                                           "LineString", feedback)
            style_on_load(context, outputs[param], layer)
        selected = int(gaps["selected"].fillna(False).astype(bool).sum())
        feedback.pushInfo(f"{len(gaps)} gap edges, {selected} kept; {len(strings)} road "
                          "strings")
        return {**outputs, "SELECTED": selected, "STRINGS": len(strings)}
