"""Segment grouping: adjacent segments merged with Grote & Rottensteiner's criteria and fuzzy
rules (2010, Sec. 2.1.2), junction-spanning segments split."""
import tempfile
from pathlib import Path

from qgis.core import (QgsProcessing, QgsProcessingOutputNumber, QgsProcessingParameterBoolean,
                       QgsProcessingParameterFeatureSink, QgsProcessingParameterNumber)

from .base import JobAlgorithm
from .imagery_inputs import imagery_parameters, segment_arguments, segments_to_sink

# criterion: (label, help); each gets a "poor" and a "very good" limit parameter
LIMITS = {
    "colour": ("colour-histogram difference", "0 same colours, 1 disjoint histograms"),
    "edge": ("edge strength along the border",
             "mean local energy along the shared border over the typical border's"),
    "convexity": ("convexity of the merged region", "area / convex-hull area"),
    "border_m": ("shared border length (metres)", "absolute"),
    "border_rel": ("relative shared border", "shared border / shorter segment perimeter"),
    "height_m": ("mean height difference (metres)", "from the DSM; used only with one"),
    "ndvi": ("mean NDVI difference", "used only with a NIR band"),
}


class SegmentGrouping(JobAlgorithm):
    NAME = "segmentgrouping"
    DISPLAY_NAME = "Segment grouping"
    GROUP = "Imagery"
    STAGE = 2
    JOB = "grouping_job"
    HELP = (
        "<p>Merges adjacent segments of an over-segmentation (e.g. from <i>NCut "
        "segmentation (imagery)</i>, possibly edited) into larger segments, following "
        "Grote &amp; Rottensteiner (2010, Sec. 2.1.2).</p>"
        "<p>Criteria per pair of neighbours: difference of the colour histograms, edge "
        "strength along the shared border, convexity of the merged region, shared border "
        "length (absolute and relative to the shorter perimeter), and the mean height "
        "difference from a DSM and the mean NDVI difference when given. Each criterion is "
        "rated between a <i>poor</i> and a <i>very good</i> limit; fuzzy rules make a pair "
        "a candidate when all criteria are good, or when two or three of edge, colour and "
        "convexity are very good (then one border criterion may be poor). Height and NDVI "
        "are never outweighed. In each iteration the best share of candidates (the paper's "
        "10 %) is merged. Finally, segments whose skeleton has three or more long branches "
        "(they span a junction) are split into their arms.</p>"
        "<p>Output: grouped segment polygons with <i>segment_id</i> and <i>area_px</i>, the "
        "input of road-part shape filtering.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        params = imagery_parameters(
            self.tr, image="the image the segments were made from (RGB, CIR or panchromatic)",
            segments="segment polygons in the image's CRS",
            id_field="non-negative integer id of each segment (segment_id when empty)",
            nir_band="optional: adds the NDVI criterion and leaves NIR out of the edges",
            dsm="optional: surface heights in metres; adds the height criterion") + [
            (QgsProcessingParameterNumber("MERGE_FRACTION",
                                          self.tr("Share of candidates merged per iteration"),
                                          double, self.default("merge_fraction"),
                                          minValue=0.001, maxValue=1.0),
             "the paper merges the best 10 % of candidate pairs per iteration"),
            (QgsProcessingParameterNumber("MAX_ITERATIONS", self.tr("Most iterations"),
                                          QgsProcessingParameterNumber.Integer,
                                          self.default("max_iterations"), minValue=1),
             "the grouping stops earlier when no pair is a candidate"),
            (QgsProcessingParameterBoolean("SPLIT", self.tr("Split segments spanning "
                                                            "junctions"),
                                           self.default("split_branches")),
             "cut segments whose skeleton has three or more long branches into their arms"),
            (QgsProcessingParameterNumber("MIN_BRANCH", self.tr("Long branch (metres)"),
                                          double, self.default("min_branch_m"), minValue=0.0),
             "length a skeleton branch must reach beyond the junction to count as an arm"),
        ]
        for criterion, (label, text) in LIMITS.items():
            poor, very_good = self.default("criteria")[criterion]
            for suffix, value, word in (("POOR", poor, "poor"),
                                        ("GOOD", very_good, "very good")):
                params.append((QgsProcessingParameterNumber(
                    f"{criterion.upper()}_{suffix}", self.tr(f"{label.capitalize()}: {word}"),
                    double, value), f"{text}; the value rated {word}"))
        params.append((QgsProcessingParameterFeatureSink("OUTPUT", self.tr("Grouped segments"),
                                                         QgsProcessing.TypeVectorPolygon),
                       "grouped segment polygons with segment_id and area_px"))
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputNumber("SEGMENTS", self.tr("Segments after "
                                                                     "grouping")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        criteria = {c: (self.parameterAsDouble(parameters, f"{c.upper()}_POOR", context),
                        self.parameterAsDouble(parameters, f"{c.upper()}_GOOD", context))
                    for c in LIMITS}
        with tempfile.TemporaryDirectory(prefix="gisroads-grouping-") as folder:
            path = str(Path(folder) / "grouped.gpkg")
            result = self.run_job(dict(
                **segment_arguments(self, parameters, context, feedback),
                grouped_path=path,
                merge_fraction=self.parameterAsDouble(parameters, "MERGE_FRACTION", context),
                max_iterations=self.parameterAsInt(parameters, "MAX_ITERATIONS", context),
                criteria=criteria,
                split_branches=self.parameterAsBoolean(parameters, "SPLIT", context),
                min_branch_m=self.parameterAsDouble(parameters, "MIN_BRANCH", context)),
                feedback)
            output = segments_to_sink(self, parameters, "OUTPUT", context, path, feedback)
        feedback.pushInfo(f"{result['n_input']} segments grouped into {result['n_segments']}")
        return {"OUTPUT": output, "SEGMENTS": result["n_segments"]}
