"""The gisroads Processing provider: lists the algorithms."""
from qgis.core import QgsProcessingProvider

from .algorithms.evaluate_network import EvaluateRoadNetwork
from .algorithms.lidar_roads import LidarRoadNetwork
from .algorithms.open_network import OpenRoadNetwork
from .algorithms.synthetic_scene import SyntheticRoadScene
from .algorithms.tag_points import TagRoadPoints


class GisroadsProvider(QgsProcessingProvider):
    def id(self):
        return "gisroads"

    def name(self):
        return "gisroads"

    def longName(self):
        import gisroads
        return f"gisroads {gisroads.__version__}: road networks from LiDAR and imagery"

    def loadAlgorithms(self):  # noqa: N802
        for algorithm in (EvaluateRoadNetwork(), SyntheticRoadScene(), OpenRoadNetwork(),
                          LidarRoadNetwork(), TagRoadPoints()):
            self.addAlgorithm(algorithm)
