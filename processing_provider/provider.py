"""The gisroads Processing provider: the algorithms of ``algorithms/`` (listed in
:data:`ALGORITHMS`, method by method in pipeline order), and the Processing models of
``models/`` (``.model3`` files chaining those algorithms)."""
from pathlib import Path

from qgis.core import QgsProcessingModelAlgorithm, QgsProcessingProvider

from .algorithms.base import GisroadsAlgorithm, show_decimals
from .algorithms.city_blocks import CityBlocks
from .algorithms.compare_database import CompareWithRoadDatabase
from .algorithms.curb_attractor import CurbAttractorMap
from .algorithms.evaluate_network import EvaluateRoadNetwork
from .algorithms.image_segmentation import ImageSegmentation
from .algorithms.imagery_roads import ImageryRoadNetwork
from .algorithms.junction_construction import JunctionConstruction
from .algorithms.lidar_evidence import LidarRoadEvidence
from .algorithms.lidar_ground_intensity import LidarGroundIntensity
from .algorithms.lidar_likelihood import LidarLikelihood
from .algorithms.lidar_min_cover import LidarMinCover
from .algorithms.lidar_rectangles_network import RectanglesToNetwork
from .algorithms.lidar_roads import LidarRoadNetwork
from .algorithms.lidar_segmentation import LidarSegmentation
from .algorithms.open_network import OpenRoadNetwork
from .algorithms.raster_network import RoadRasterToNetwork
from .algorithms.register_map import RegisterRoadMap
from .algorithms.ribbon_snakes import RibbonSnakeRoads
from .algorithms.road_parts import RoadPartFiltering
from .algorithms.segment_grouping import SegmentGrouping
from .algorithms.subgraph_linking import SubgraphLinking
from .algorithms.synthetic_scene import SyntheticRoadScene
from .algorithms.tag_points import TagRoadPoints
from .algorithms.train_lidar_model import TrainLidarRoadModel
from .algorithms.train_road_model import TrainRoadModel

MODELS_DIR = Path(__file__).resolve().parent / "models"

ALGORITHMS: tuple[type[GisroadsAlgorithm], ...] = (
    # LiDAR (Zhu & Mordohai): the whole pipeline, its stages, the evidence cue, city blocks
    LidarRoadNetwork, LidarGroundIntensity, LidarSegmentation, LidarLikelihood, LidarMinCover,
    RectanglesToNetwork, TagRoadPoints, LidarRoadEvidence, CityBlocks, TrainLidarRoadModel,
    # imagery (Grote & Rottensteiner, with the learned cue): the pipeline and its stages
    ImageryRoadNetwork, ImageSegmentation, SegmentGrouping, RoadPartFiltering,
    SubgraphLinking, JunctionConstruction, TrainRoadModel,
    # map-guided snakes (Boyko & Funkhouser)
    RibbonSnakeRoads, RegisterRoadMap, CurbAttractorMap,
    # any road raster to a network; the road database update
    RoadRasterToNetwork, CompareWithRoadDatabase,
    # scenes, scores, loading
    SyntheticRoadScene, EvaluateRoadNetwork, OpenRoadNetwork,
)
"""Every algorithm the provider offers; a new one is added here."""


def algorithm_classes() -> list[type[GisroadsAlgorithm]]:
    """Every algorithm class the provider offers (:data:`ALGORITHMS`)."""
    return list(ALGORITHMS)


class GisroadsProvider(QgsProcessingProvider):
    def id(self):
        return "gisroads"

    def name(self):
        return "gisroads"

    def longName(self):
        import gisroads
        return f"gisroads {gisroads.__version__}: road networks from LiDAR and imagery"

    def loadAlgorithms(self):  # noqa: N802
        for algorithm_class in ALGORITHMS:
            self.addAlgorithm(algorithm_class())
        for path in sorted(MODELS_DIR.glob("*.model3")):
            model = QgsProcessingModelAlgorithm()
            if not model.fromFile(str(path)):
                raise RuntimeError(f"{path}: not a Processing model")
            for parameter in model.parameterDefinitions():
                show_decimals(parameter)  # as the algorithms' own (GisroadsAlgorithm)
            self.addAlgorithm(model)
