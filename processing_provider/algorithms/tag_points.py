"""Tag road points: classify the road-surface points of a cloud (class 11), level by level."""
from qgis.core import (QgsProcessingOutputNumber, QgsProcessingParameterFile,
                       QgsProcessingParameterFileDestination, QgsProcessingParameterNumber)

from .base import JobAlgorithm, cloud_input, cloud_path


class TagRoadPoints(JobAlgorithm):
    NAME = "tagroadpoints"
    JOB = "tag_job"
    DISPLAY_NAME = "Tag road points"
    GROUP = "LiDAR"
    STAGE = 6
    HELP = (
        "<p>Writes a copy of a LAS/LAZ point cloud whose road-surface points are classified "
        "11 (road surface), every other attribute unchanged.</p>"
        "<p>A point is road when it lies inside a road polygon and within a height "
        "tolerance of the ground surface of that polygon's level: on a bridge, the deck "
        "points belong to the deck road and the points of the road below to that road, "
        "never each other. The road polygons come from a gisroads road network (their "
        "<i>level</i> field; level 0 where it is missing): from the LiDAR road network, the "
        "ribbon snakes or drawn by hand. The level surfaces come from the ground_heights.tif "
        "the LiDAR algorithms write or, when none is given, from the cloud's own ground "
        "planes (the whole cloud is then read into memory).</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        params = [
            (cloud_input(self.tr, "the cloud the road network was extracted from"), None),
            (QgsProcessingParameterFile("POLYGONS", self.tr("Road polygons"),
                                        fileFilter="Vector (*.gpkg *.geojson *.shp)"),
             "a gisroads GeoPackage (its road_polygons layer) or any polygon file with "
             "a level field"),
            (QgsProcessingParameterFile("HEIGHTS", self.tr("Ground heights per level"),
                                        fileFilter="GeoTIFF (*.tif *.tiff)", optional=True),
             "optional: ground_heights.tif from the LiDAR road network's raster folder (or "
             "Ground planes and intensity image); empty: computed from the cloud"),
            (QgsProcessingParameterNumber("TOLERANCE", self.tr("Height tolerance (metres)"),
                                          QgsProcessingParameterNumber.Double,
                                          self.default("tolerance_m"),
                                          minValue=0.01, maxValue=5.0),
             "largest height difference between a point and its level's surface"),
            (QgsProcessingParameterFileDestination("OUTPUT", self.tr("Tagged cloud"),
                                                   "LAZ (*.laz);;LAS (*.las)"),
             "the copy with road points in class 11"),
        ]
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputNumber("TAGGED", self.tr("Road points tagged")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        result = self.run_job(dict(
            cloud_path=cloud_path(self, parameters, context),
            polygons_path=self.parameterAsFile(parameters, "POLYGONS", context), out_path=out,
            heights_path=self.parameterAsFile(parameters, "HEIGHTS", context) or None,
            tolerance_m=self.parameterAsDouble(parameters, "TOLERANCE", context)), feedback)
        feedback.pushInfo(f"{result['tagged_points']} road points tagged")
        return {"OUTPUT": out, "TAGGED": result["tagged_points"]}
