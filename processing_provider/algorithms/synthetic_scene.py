"""Synthetic road scene: a point cloud, an orthoimage and DSM, with their exact road truth."""
from qgis.core import (QgsProcessingOutputFile, QgsProcessingOutputRasterLayer,
                       QgsProcessingOutputVectorLayer, QgsProcessingParameterBoolean,
                       QgsProcessingParameterFolderDestination, QgsProcessingParameterNumber,
                       QgsProcessingContext)

from gisroads.geo import CENTRELINES, JUNCTIONS, POLYGONS
from gisroads.jobs import stage_default, synth_job

from ..convert import gisroads_errors, progress_callback
from ..loading import load_geopackage_on_completion
from .base import GisroadsAlgorithm


class SyntheticRoadScene(GisroadsAlgorithm):
    NAME = "syntheticroadscene"
    DISPLAY_NAME = "Synthetic road scene"
    GROUP = "Test data"
    HELP = (
        "<p>Generates a suburban scene with exact ground truth, to try the road extraction "
        "algorithms and to measure them: straight and curved roads 4-25 m wide, a dual "
        "carriageway, T, X, Y and oblique junctions, dead ends, kerbs, parking lots, "
        "buildings, trees over roads, cars, lane markings and zebra crossings, a road on a "
        "cliff top above another and a bridge over a road.</p>"
        "<p>Writes into the output folder: <i>truth.gpkg</i> (road_centrelines with width_m, "
        "road_polygons, junctions and the scene's objects), <i>cloud.laz</i> (airborne "
        "point cloud with intensity and returns), <i>image.tif</i> (red, green, blue, "
        "near-infrared) and <i>dsm.tif</i> (surface heights, metres). Same seed, same "
        "scene.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        size = stage_default(synth_job, "size_m")
        params = [
            QgsProcessingParameterNumber("WIDTH", self.tr("Scene width (metres)"), double,
                                         size[0], minValue=300.0, maxValue=5000.0),
            QgsProcessingParameterNumber("HEIGHT", self.tr("Scene height (metres)"), double,
                                         size[1], minValue=300.0, maxValue=5000.0),
            QgsProcessingParameterNumber("SEED", self.tr("Random seed"),
                                         QgsProcessingParameterNumber.Integer, 0, minValue=0),
            QgsProcessingParameterNumber("DENSITY", self.tr("Point density (points/m²)"),
                                         double, stage_default(synth_job, "density_per_m2"),
                                         minValue=0.1, maxValue=200.0),
            QgsProcessingParameterNumber("PIXEL", self.tr("Image pixel size (metres)"),
                                         double, stage_default(synth_job, "pixel_m"),
                                         minValue=0.05, maxValue=5.0),
            QgsProcessingParameterBoolean("WRITE_CLOUD", self.tr("Write the point cloud"), True),
            QgsProcessingParameterBoolean("WRITE_IMAGE", self.tr("Write the image and DSM"),
                                          True),
            QgsProcessingParameterFolderDestination("OUTPUT_FOLDER", self.tr("Output folder")),
        ]
        helps = ["east-west extent of the scene", "north-south extent of the scene",
                 "the same seed always gives the same scene",
                 "mean number of LiDAR points per square metre",
                 "ground size of an orthoimage and DSM pixel",
                 "cloud.laz, LAS 1.4 point format 6, in the scene's CRS",
                 "image.tif (R, G, B, NIR, 8 bit) and dsm.tif (float, metres)",
                 "folder that receives truth.gpkg, cloud.laz, image.tif and dsm.tif"]
        for param, text in zip(params, helps):
            param.setHelp(self.tr(text))
            self.addParameter(param)
        self.addOutput(QgsProcessingOutputVectorLayer("TRUTH_CENTRELINES",
                                                      self.tr("Truth road centre lines")))
        self.addOutput(QgsProcessingOutputFile("TRUTH", self.tr("Truth GeoPackage")))
        self.addOutput(QgsProcessingOutputFile("CLOUD", self.tr("Point cloud (LAZ)")))
        self.addOutput(QgsProcessingOutputRasterLayer("IMAGE", self.tr("Orthoimage")))
        self.addOutput(QgsProcessingOutputRasterLayer("DSM", self.tr("Surface model")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        folder = self.parameterAsString(parameters, "OUTPUT_FOLDER", context)
        with gisroads_errors():
            paths = synth_job(
                folder,
                size_m=(self.parameterAsDouble(parameters, "WIDTH", context),
                        self.parameterAsDouble(parameters, "HEIGHT", context)),
                seed=self.parameterAsInt(parameters, "SEED", context),
                density_per_m2=self.parameterAsDouble(parameters, "DENSITY", context),
                pixel_m=self.parameterAsDouble(parameters, "PIXEL", context),
                cloud=self.parameterAsBool(parameters, "WRITE_CLOUD", context),
                image=self.parameterAsBool(parameters, "WRITE_IMAGE", context),
                progress=progress_callback(feedback))
        truth = str(paths["truth"])
        load_geopackage_on_completion(context, truth, (POLYGONS, CENTRELINES, JUNCTIONS),
                                      group="truth")
        outputs = {"TRUTH": truth, "TRUTH_CENTRELINES": f"{truth}|layername={CENTRELINES}",
                   "CLOUD": str(paths.get("cloud", "")), "OUTPUT_FOLDER": folder}
        for key in ("IMAGE", "DSM"):
            if key.lower() in paths:
                outputs[key] = str(paths[key.lower()])
                context.addLayerToLoadOnCompletion(
                    outputs[key], QgsProcessingContext.LayerDetails(key.lower(),
                                                                    context.project(), key))
        return outputs
