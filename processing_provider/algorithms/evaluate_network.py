"""Evaluate road network: buffer, topology, path-length and area scores against a reference."""
import json
import tempfile
from pathlib import Path

from qgis.core import (QgsProcessing, QgsProcessingOutputNumber, QgsProcessingOutputString,
                       QgsProcessingParameterFeatureSink, QgsProcessingParameterFeatureSource,
                       QgsProcessingParameterNumber)

from ..loading import ApplyStyle, on_load, style_path
from .base import JobAlgorithm

HEADLINE = {"COMPLETENESS": ("buffer", "completeness"), "CORRECTNESS": ("buffer", "correctness"),
            "QUALITY": ("buffer", "quality"), "RMS_M": ("buffer", "rms_m"),
            "APLS": ("apls", "apls")}


class EvaluateRoadNetwork(JobAlgorithm):
    NAME = "evaluateroadnetwork"
    JOB = "evaluate_job"
    DISPLAY_NAME = "Evaluate road network"
    GROUP = "Evaluation"
    HELP = (
        "<p>Scores extracted road centre lines against reference centre lines.</p>"
        "<p><b>Buffer scores</b> (Wiedemann et al. 1998): <i>completeness</i> is the share of "
        "the reference length lying within the buffer of the extraction, <i>correctness</i> "
        "the share of the extracted length within the buffer of the reference, "
        "<i>quality</i> = matched extracted length / (extracted length + unmatched "
        "reference length), <i>RMS</i> the root-mean-square distance of matched extracted "
        "lines to the reference.</p>"
        "<p><b>Topology</b>: connected components, junction precision and recall. "
        "<b>APLS</b>: a path-length similarity in [0, 1] (1 = same shortest routes). "
        "<b>Area scores</b> (Boyko &amp; Funkhouser 2011), when road polygons are given on "
        "both sides: precision, recall, quality on a grid, average spill size and "
        "prevailing spill direction (positive: the extraction spills outwards).</p>"
        "<p>Outputs: the extracted and reference lines cut into matched (TP), false (FP) "
        "and missed (FN) pieces, and the scores as numbers and as a JSON report.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        lines = [QgsProcessing.TypeVectorLine]
        polygons = [QgsProcessing.TypeVectorPolygon]
        self.addParameter(QgsProcessingParameterFeatureSource(
            "EXTRACTED", self.tr("Extracted road centre lines"), lines))
        self.addParameter(QgsProcessingParameterFeatureSource(
            "REFERENCE", self.tr("Reference road centre lines"), lines))
        # metres in any CRS (the scores work in metres), so numbers, not distances in the
        # layer's units, which QGIS shows as "<unknown>" until a layer is chosen
        double = QgsProcessingParameterNumber.Double
        self.addParameter(QgsProcessingParameterNumber(
            "BUFFER", self.tr("Buffer width (metres; about half a carriageway)"), double,
            self.default("buffer_m"), minValue=0.01))
        self.addParameter(QgsProcessingParameterNumber(
            "JUNCTION_RADIUS", self.tr("Junction matching radius (metres)"), double,
            self.default("junction_radius_m"), minValue=0.01))
        self.addParameter(QgsProcessingParameterFeatureSource(
            "EXTRACTED_POLYGONS", self.tr("Extracted road polygons (for area scores)"),
            polygons, optional=True))
        self.addParameter(QgsProcessingParameterFeatureSource(
            "REFERENCE_POLYGONS", self.tr("Reference road polygons (for area scores)"),
            polygons, optional=True))
        self.addParameter(QgsProcessingParameterNumber(
            "CELL", self.tr("Grid cell for area scores (metres)"),
            QgsProcessingParameterNumber.Double, self.default("cell_m"), minValue=0.05))
        self.addParameter(QgsProcessingParameterFeatureSource(
            "VALID_AREA", self.tr("Valid area: score only inside these polygons"),
            polygons, optional=True))
        self.addParameter(QgsProcessingParameterFeatureSource(
            "REFERENCE_JUNCTIONS", self.tr("Reference junctions (points)"),
            [QgsProcessing.TypeVectorPoint], optional=True))
        self.addParameter(QgsProcessingParameterFeatureSink(
            "EXTRACTED_QA", self.tr("Extracted pieces (TP/FP)"), QgsProcessing.TypeVectorLine))
        self.addParameter(QgsProcessingParameterFeatureSink(
            "REFERENCE_QA", self.tr("Reference pieces (TP/FN)"), QgsProcessing.TypeVectorLine))
        for name in HEADLINE:
            self.addOutput(QgsProcessingOutputNumber(name, self.tr(name.replace("_", " ").lower())))
        self.addOutput(QgsProcessingOutputString("REPORT", self.tr("All scores (JSON)")))

        for name, text in (("EXTRACTED", "the centre lines to score"),
                           ("REFERENCE", "the reference (ground truth) centre lines"),
                           ("BUFFER", "lines closer than this count as matched; metres"),
                           ("JUNCTION_RADIUS", "junctions closer than this match; metres"),
                           ("EXTRACTED_POLYGONS", "road area of the extraction, optional"),
                           ("REFERENCE_POLYGONS", "reference road area, optional"),
                           ("CELL", "cell size of the grid the areas are compared on"),
                           ("VALID_AREA", "e.g. the surveyed area; optional"),
                           ("REFERENCE_JUNCTIONS", "digitised junctions of the reference; "
                            "optional (default: the nodes its lines share)"),
                           ("EXTRACTED_QA", "extracted lines cut at the buffer, status TP/FP"),
                           ("REFERENCE_QA", "reference lines cut at the buffer, status TP/FN")):
            self.parameterDefinition(name).setHelp(self.tr(text))

    def _path(self, parameters, name, context, feedback):
        if self.parameterAsSource(parameters, name, context) is None:
            return None
        return self.source_path(parameters, name, context, feedback)

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        with tempfile.TemporaryDirectory(prefix="gisroads-evaluate-") as folder:
            qa_path = str(Path(folder) / "qa.gpkg")
            results = self.run_job(dict(
                extracted=self._path(parameters, "EXTRACTED", context, feedback),
                reference=self._path(parameters, "REFERENCE", context, feedback),
                buffer_m=self.parameterAsDouble(parameters, "BUFFER", context),
                cell_m=self.parameterAsDouble(parameters, "CELL", context),
                junction_radius_m=self.parameterAsDouble(parameters, "JUNCTION_RADIUS",
                                                         context),
                extracted_polygons=self._path(parameters, "EXTRACTED_POLYGONS", context,
                                              feedback),
                reference_polygons=self._path(parameters, "REFERENCE_POLYGONS", context,
                                              feedback),
                valid_area=self._path(parameters, "VALID_AREA", context, feedback),
                reference_junctions=self._path(parameters, "REFERENCE_JUNCTIONS", context,
                                               feedback),
                qa_path=qa_path), feedback)
            outputs = {name: results[group][key] for name, (group, key) in HEADLINE.items()}
            for param, layer in (("EXTRACTED_QA", "eval_extracted"),
                                 ("REFERENCE_QA", "eval_reference")):
                outputs[param] = self.layer_to_sink(parameters, param, context, qa_path,
                                                    layer, feedback)
                on_load(context, outputs[param], ApplyStyle(style_path(layer)))
        feedback.pushInfo(self.tr(_summary(results)))
        outputs["REPORT"] = json.dumps(results)
        feedback.setProgress(100)
        return outputs


def _summary(results: dict) -> str:
    buffer = results["buffer"]
    return (f"completeness {buffer['completeness']:.3f}, correctness "
            f"{buffer['correctness']:.3f}, quality {buffer['quality']:.3f}, RMS "
            f"{buffer['rms_m']:.2f} m")
