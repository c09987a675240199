"""Train LiDAR road model: the evidence cue learned from the area's road layer."""
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterField,
                       QgsProcessingParameterFileDestination, QgsProcessingParameterNumber)

from .base import JobAlgorithm, cloud_input, cloud_path


class TrainLidarRoadModel(JobAlgorithm):
    NAME = "trainlidarroadmodel"
    JOB = "train_lidar_job"
    DISPLAY_NAME = "Train LiDAR road model"
    GROUP = "LiDAR"
    HELP = (
        "<p>Learns what the roads of an area look like in its point cloud from the area's "
        "existing road layer (last year's road database, OpenStreetMap), for the "
        "<i>Road model of the area</i> of <i>LiDAR road network</i>: how an agency updates "
        "its roads from a new survey (beyond the paper).</p>"
        "<p>Each cell of the cloud's lowest surface gets the evidence cue's likelihood, the "
        "raw measure of every cue (height, density, pulses, roughness, slope, intensity, "
        "returns, classification, kerbs) and three of them averaged over 2-4 m. The middle "
        "half of each road of the layer is road, cells beyond its edge and the guard band "
        "are not; the layer's errors are left out: a road of the layer that the cloud shows "
        "bare (a fake, a misregistered line) and a road the layer lacks are not taught. "
        "Boosted trees (scikit-learn) fitted on those cells give a road probability that "
        "replaces the evidence cue's rule. Training takes seconds for a square kilometre "
        "at a few points per square metre.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        self.add_parameters([
            (cloud_input(self.tr, "the area's cloud; the same kind of survey as the clouds "
                                  "the model is for"), None),
            (QgsProcessingParameterFeatureSource("ROADS", self.tr("Road layer"),
                                                 [QgsProcessing.TypeVectorLine]),
             "the area's road centre lines, any CRS (reprojected to the cloud's)"),
            (QgsProcessingParameterField("WIDTH_FIELD", self.tr("Road width field"), None,
                                         "ROADS", QgsProcessingParameterField.Numeric,
                                         optional=True),
             "field holding each road's width in metres; empty: the width below for all"),
            (QgsProcessingParameterNumber("WIDTH", self.tr("Road width (metres)"), double,
                                          self.default("width_m"), minValue=1.0),
             "width of the roads without a width field"),
            (QgsProcessingParameterNumber("GUARD", self.tr("Guard band (metres)"), double,
                                          self.default("guard_m"), minValue=0.0),
             "cells this far beyond a road's edge are neither road nor background: it "
             "absorbs lines a few metres off their road"),
            (QgsProcessingParameterFileDestination("OUTPUT", self.tr("Road model"),
                                                   "Road model (*.npz)"),
             "the model file (.npz), for LiDAR road network's Road model of the area"),
        ])
        for name, text in (("ROAD_CELLS", "cells of the layer's roads taught"),
                           ("OTHER_CELLS", "other cells taught"), ("TREES", "trees")):
            self.addOutput(QgsProcessingOutputNumber(name, self.tr(text)))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        if not out.lower().endswith(".npz"):
            out += ".npz"
        result = self.run_job(dict(
            cloud_path=cloud_path(self, parameters, context),
            roads_path=self.source_path(parameters, "ROADS", context, feedback),
            out_path=out,
            width_field=self.parameterAsString(parameters, "WIDTH_FIELD", context) or None,
            width_m=self.parameterAsDouble(parameters, "WIDTH", context),
            guard_m=self.parameterAsDouble(parameters, "GUARD", context)), feedback)
        feedback.pushInfo(f"{result['trees']} trees from {result['road_cells']} road and "
                          f"{result['other_cells']} other cells of {result['cell_m']:g} m")
        return {"OUTPUT": result["model"], "ROAD_CELLS": result["road_cells"],
                "OTHER_CELLS": result["other_cells"], "TREES": result["trees"]}
