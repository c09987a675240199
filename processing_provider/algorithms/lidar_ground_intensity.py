"""LiDAR stages 1-2: multi-level ground planes and the per-level intensity image."""
from qgis.core import (QgsProcessingOutputNumber, QgsProcessingOutputRasterLayer,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterDestination)

from .base import JobAlgorithm, cloud_input, cloud_path


class LidarGroundIntensity(JobAlgorithm):
    NAME = "lidargroundintensity"
    DISPLAY_NAME = "Ground planes and intensity image"
    GROUP = "LiDAR"
    STAGE = 1
    JOB = "ground_intensity_job"
    HELP = (
        "<p>Finds the ground of an airborne LiDAR point cloud on one or more levels and "
        "projects the intensity of each level's ground points to an image (Zhu &amp; "
        "Mordohai, section 4.1): the points are clustered, planar and horizontal clusters "
        "are kept as ground, and ground surfaces stacked over each other (a bridge deck and "
        "the road under it, a cliff top and its foot) become separate levels.</p>"
        "<p>Writes the intensity GeoTIFF (one band per level, 0-1, empty where no ground), "
        "a level-index raster beside it (the highest level seen at each cell) and the "
        "ground height of every level, in the cloud's CRS (metres). Holes narrower than "
        "1.5 m are filled from their neighbours. The whole cloud is read into memory: for "
        "large files run the tiled LiDAR road network algorithm instead. Next stage: "
        "Edges and NCut segmentation (LiDAR).</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        params = [
            (cloud_input(self.tr, "airborne LiDAR with intensity; feet are converted to "
                                  "metres"), None),
            (QgsProcessingParameterNumber("CELL", self.tr("Image cell (metres)"), double,
                                          None, optional=True, minValue=0.1, maxValue=5.0),
             "empty: 0.5 m as in the paper, or the mean point spacing of a sparser cloud"),
            (QgsProcessingParameterNumber("T_PLANAR", self.tr("Planarity threshold T_planar"),
                                          double, self.default("t_planar"),
                                          minValue=0.0001, maxValue=0.3),
             "a cluster is planar when its smallest eigenvalue over the eigenvalue sum is "
             "below this (paper: 0.01)"),
            (QgsProcessingParameterNumber("T_VERT", self.tr("Horizontality threshold T_vert"),
                                          double, self.default("t_vert"),
                                          minValue=0.5, maxValue=1.0),
             "a planar cluster is horizontal when |n . z| exceeds this (paper: 0.98)"),
            (QgsProcessingParameterRasterDestination("OUTPUT", self.tr("Intensity image")),
             "GeoTIFF, one band per ground level; the level index goes beside it"),
            (QgsProcessingParameterRasterDestination("HEIGHTS",
                                                     self.tr("Ground heights per level")),
             "GeoTIFF of each level's ground height (for Tag road points)"),
        ]
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputRasterLayer("LEVEL_INDEX", self.tr("Level index")))
        self.addOutput(QgsProcessingOutputNumber("LEVELS", self.tr("Ground levels")))
        self.addOutput(QgsProcessingOutputNumber("CELL_M", self.tr("Cell size used (metres)")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsOutputLayer(parameters, "OUTPUT", context)
        heights = self.parameterAsOutputLayer(parameters, "HEIGHTS", context)
        result = self.run_job(dict(
            cloud_path=cloud_path(self, parameters, context), intensity_path=out,
            heights_path=heights,
            cell_m=(self.parameterAsDouble(parameters, "CELL", context)
                    if parameters.get("CELL") not in (None, "") else None),
            t_planar=self.parameterAsDouble(parameters, "T_PLANAR", context),
            t_vert=self.parameterAsDouble(parameters, "T_VERT", context)), feedback)
        feedback.pushInfo(f"{result['levels']} ground level(s) from {result['ground_points']} "
                          f"of {result['points']} points, {result['cell_m']:g} m cells")
        return {"OUTPUT": out, "HEIGHTS": heights, "LEVEL_INDEX": str(result["level_index"]),
                "LEVELS": result["levels"], "CELL_M": result["cell_m"]}
