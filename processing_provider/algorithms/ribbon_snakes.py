"""Ribbon-snake road boundaries: the whole map-guided pipeline (Boyko & Funkhouser)."""
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber, QgsProcessingParameterEnum,
                       QgsProcessingParameterFile, QgsProcessingParameterFeatureSource,
                       QgsProcessingParameterFileDestination, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterDestination)

from gisroads.geo import CENTRELINES, JUNCTIONS, POLYGONS
from gisroads.jobs import snakes_job

from ..convert import (gisroads_errors, load_geopackage_on_completion, progress_callback,
                       source_to_frame)
from .base import GisroadsAlgorithm
from .curb_attractor import DETECTORS


class RibbonSnakeRoads(GisroadsAlgorithm):
    NAME = "ribbonsnakeroads"
    DISPLAY_NAME = "Ribbon-snake road boundaries"
    GROUP = "Map-guided snakes"
    HELP = (
        "<p>Fits the roads of an approximate road map (OpenStreetMap, an old digitised "
        "network; any CRS) to a LAS/LAZ point cloud from kerb to kerb, following Boyko "
        "&amp; Funkhouser: the map is registered in 3D, a subcloud is cut around each road "
        "(bridges and the roads under them apart), a curb attractor map is built per road "
        "(see Curb attractor map), its gradient vector flow spreads the kerbs' pull, and a "
        "ribbon snake (a centre line and a width along the map line, free to shift "
        "sideways as a whole, rigid against bending) settles on the kerbs.</p>"
        "<p>Output GeoPackage in the cloud's CRS: road_centrelines (the ribbons' centre "
        "lines, width_m), road_polygons (kerb to kerb, with their level: a bridge and the "
        "road below overlap), junctions from the map's topology (a bridge crossing is "
        "none), and the QA layers ribbon_patches (one ribbon per road, converged or not) "
        "and registered_map. Optionally the cloud with the points inside the ribbons, on "
        "their own level, classified 11, and the attractor map as a GeoTIFF.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        params = [
            (QgsProcessingParameterFile("INPUT", self.tr("Point cloud (LAS/LAZ)"),
                                        fileFilter="LAS/LAZ (*.las *.laz *.LAS *.LAZ)"),
             "the cloud; read chunk by chunk, only along the map"),
            (QgsProcessingParameterFeatureSource("MAP", self.tr("Road map lines"),
                                                 [QgsProcessing.TypeVectorLine]),
             "approximate road centre lines in any CRS (reprojected to the cloud's)"),
            (QgsProcessingParameterEnum("DETECTOR", self.tr("Curb detector"),
                                        options=["exp: Gaussian, 15 cm mean (paper's best)",
                                                 "step: 10-20 cm", "none: normals only"],
                                        defaultValue=0),
             "how the height step of a neighbourhood weights its normal's tilt"),
            (QgsProcessingParameterNumber("CELL", self.tr("Attractor cell (metres)"),
                                          QgsProcessingParameterNumber.Double, 0.5,
                                          minValue=0.1, maxValue=5.0),
             "cell of the attractor map the snakes fit to"),
            (QgsProcessingParameterNumber("SNAP", self.tr("Intersection snapping (metres)"),
                                          QgsProcessingParameterNumber.Double, 2.0,
                                          minValue=0.01, maxValue=50.0),
             "map line ends closer than this are one intersection"),
            (QgsProcessingParameterFileDestination("OUTPUT", self.tr("Road network"),
                                                   "GeoPackage (*.gpkg)"),
             "GeoPackage receiving every layer, in the cloud's CRS"),
            (QgsProcessingParameterFileDestination("TAGGED_LAS",
                                                   self.tr("Cloud with road points (class 11)"),
                                                   "LAZ (*.laz);;LAS (*.las)", optional=True,
                                                   createByDefault=False),
             "optional: the input cloud with the points inside the ribbons classified 11"),
            (QgsProcessingParameterRasterDestination("ATTRACTOR", self.tr("Attractor map"),
                                                     optional=True, createByDefault=False),
             "optional: the attractor maps of the road patches as one GeoTIFF, for QA"),
        ]
        for param, text in params:
            param.setHelp(self.tr(text))
            self.addParameter(param)
        for name, text in (("ROADS", "number of roads"), ("LENGTH_M", "total road length"),
                           ("JUNCTIONS", "number of junctions")):
            self.addOutput(QgsProcessingOutputNumber(name, self.tr(text)))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        tagged = self.parameterAsFileOutput(parameters, "TAGGED_LAS", context) or None
        attractor = self.parameterAsOutputLayer(parameters, "ATTRACTOR", context) or None
        lines = source_to_frame(self.parameterAsSource(parameters, "MAP", context), feedback)
        with gisroads_errors():
            result = snakes_job(
                self.parameterAsFile(parameters, "INPUT", context), lines, out,
                curb_detector=DETECTORS[self.parameterAsEnum(parameters, "DETECTOR", context)],
                tagged_las=tagged, attractor_tif=attractor,
                cell_m=self.parameterAsDouble(parameters, "CELL", context),
                snap_m=self.parameterAsDouble(parameters, "SNAP", context),
                progress=progress_callback(feedback))
        load_geopackage_on_completion(context, out, ("ribbon_patches", POLYGONS, CENTRELINES,
                                                     JUNCTIONS), group="roads")
        feedback.pushInfo(f"{result['roads']} roads, {result['length_m']:.0f} m, "
                          f"{result['junctions']} junctions, {result['converged']} of "
                          f"{result['patches']} ribbons converged")
        return {"OUTPUT": out, "TAGGED_LAS": tagged, "ATTRACTOR": attractor,
                "ROADS": result["roads"], "LENGTH_M": result["length_m"],
                "JUNCTIONS": result["junctions"]}
