"""External-tool mode: the algorithms run a ``gisroads`` executable as a subprocess.

For a QGIS whose Python lacks gisroads' packages (Debian 12's own: shapely 1.8), as QGIS's
GRASS and SAGA providers run their tools: the executable is the ``gisroads`` command of
an environment that has them, found in this order whatever PATH holds: the
``GISROADS_EXECUTABLE`` environment variable, the ``gisroads/executable`` QGIS setting,
the private environment that *Set up gisroads* makes in the QGIS profile
(:mod:`.setup_gisroads`), then PATH. It reports progress as JSON lines on stderr
(``--progress-json``) and its result as JSON on stdout (``--json``); a cancel terminates it
(SIGTERM: it removes what it was writing).

Standard library and qgis only: this module must import where gisroads cannot. The whole
pipelines (LiDAR, imagery, map-guided snakes), the network stage and a few tools have an
external twin here (:data:`EXTERNAL_ALGORITHMS`, their layers loaded as in-process:
:mod:`.loading`); the stages that are one job of :mod:`gisroads.jobs` are one class for
both modes (:data:`JOB_ALGORITHMS`); *Open road network GeoPackage* needs QGIS alone.
"""
from __future__ import annotations

from pathlib import Path

from qgis.core import (QgsProcessing, QgsProcessingAlgorithm, QgsProcessingOutputNumber,
                       QgsProcessingParameterBoolean,
                       QgsProcessingParameterEnum, QgsProcessingParameterFeatureSource,
                       QgsProcessingParameterFile, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterLayer,
                       QgsProcessingProvider)

from .algorithms.base import (add_scene_parameters, background_output, city_blocks_parameters,
                              group_id, lidar_model_input, train_parameters,
                              workers_parameter)
from .algorithms.compare_database import CompareWithRoadDatabase
from .algorithms.curb_attractor import CurbAttractorMap
from .algorithms.evaluate_network import EvaluateRoadNetwork
from .algorithms.image_segmentation import ImageSegmentation
from .algorithms.junction_construction import JunctionConstruction
from .algorithms.lidar_evidence import LidarRoadEvidence
from .algorithms.lidar_ground_intensity import LidarGroundIntensity
from .algorithms.lidar_likelihood import LidarLikelihood
from .algorithms.lidar_min_cover import LidarMinCover
from .algorithms.lidar_rectangles_network import RectanglesToNetwork
from .algorithms.lidar_segmentation import LidarSegmentation
from .algorithms.open_network import OpenRoadNetwork
from .algorithms.register_map import RegisterRoadMap
from .algorithms.road_parts import RoadPartFiltering
from .algorithms.segment_grouping import SegmentGrouping
from .algorithms.subgraph_linking import SubgraphLinking
from .algorithms.tag_points import TagRoadPoints
from .algorithms.train_lidar_model import TrainLidarRoadModel
from .loading import (load_beneath_on_completion, load_geopackage_on_completion,
                      load_scene_on_completion)
from .runner import external_defaults, run_external
from .setup_gisroads import SetUpGisroads


class _ExternalAlgorithm(QgsProcessingAlgorithm):
    """An algorithm run through the external ``gisroads SUBCOMMAND``: the same id, outputs
    and defaults as the in-process algorithm (a test compares them), fewer parameters."""

    NAME = DISPLAY_NAME = GROUP = SUBCOMMAND = HELP = OUTPUT_HELP = ""

    def __init__(self, executable: str):
        super().__init__()
        self.executable = executable

    def name(self):
        return self.NAME

    def displayName(self):  # noqa: N802
        return self.DISPLAY_NAME

    def group(self):
        return self.GROUP

    def groupId(self):  # noqa: N802
        return group_id(self.GROUP)

    def shortHelpString(self):  # noqa: N802
        return (f"<p>{self.HELP}, by running the external gisroads command "
                f"(<code>{self.executable} {self.SUBCOMMAND}</code>): QGIS's Python lacks the "
                "packages gisroads needs, so this runs in that command's own environment. "
                f"{self.OUTPUT_HELP}</p>")

    def createInstance(self):  # noqa: N802
        return type(self)(self.executable)

    def parameters(self) -> list:
        """``(parameter, help text)`` of the algorithm (a road network's OUTPUT excepted)."""
        raise NotImplementedError

    def initAlgorithm(self, config=None):  # noqa: N802
        for parameter, text in self.parameters():
            if text is not None:
                parameter.setHelp(text)
            self.addParameter(parameter)


class _ExternalRoadNetwork(_ExternalAlgorithm):
    """A road network through the external ``gisroads``: its GeoPackage is loaded as
    in-process (:mod:`.loading`)."""

    OUTPUT_HELP = ("Output: a GeoPackage with road_centrelines, road_polygons, junctions and "
                   "QA layers, in the input's CRS, added to the project named after the "
                   "input.")

    def arguments(self, parameters, context, feedback) -> tuple[str, list[str]]:
        """The input's path and the subcommand's other arguments."""
        raise NotImplementedError

    def initAlgorithm(self, config=None):  # noqa: N802
        super().initAlgorithm(config)
        output = QgsProcessingParameterFileDestination("OUTPUT", "Road network",
                                                       "GeoPackage (*.gpkg)")
        output.setHelp("GeoPackage receiving every layer, in the input's CRS")
        self.addParameter(output)
        for name, text in (("ROADS", "number of roads"), ("LENGTH_M", "total road length"),
                           ("JUNCTIONS", "number of junctions")):
            self.addOutput(QgsProcessingOutputNumber(name, text))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        source, arguments = self.arguments(parameters, context, feedback)
        result = run_external(self.executable,
                              [self.SUBCOMMAND, source, "-o", out, *arguments], feedback)
        feedback.pushInfo(f"{result['roads']} roads, {result['length_m']:.0f} m, "
                          f"{result['junctions']} junctions")
        title = self.title(parameters, context)
        load_geopackage_on_completion(context, out, title=title)
        beneath = self.beneath(parameters, context, result)
        if beneath is not None:
            load_beneath_on_completion(context, *beneath, title=title)
        return {"OUTPUT": out, "ROADS": result["roads"], "LENGTH_M": result["length_m"],
                "JUNCTIONS": result["junctions"],
                **({"BACKGROUND": result["background"]} if "background" in result else {})}

    def beneath(self, parameters, context, result) -> tuple[str, str] | None:
        """The raster to add beneath the roads and what it is, None for none."""
        return None

    def title(self, parameters, context) -> str:
        """What the loaded layers are named after: the input's name."""
        return Path(self.parameterAsFile(parameters, "INPUT", context)).stem


class ExternalLidarRoadNetwork(_ExternalRoadNetwork):
    """LiDAR road network through ``gisroads lidar``."""

    NAME, DISPLAY_NAME, GROUP = ("lidarroadnetwork", "LiDAR road network (Zhu & Mordohai)",
                                 "LiDAR")
    SUBCOMMAND = "lidar"
    HELP = ("Extracts the road network of an airborne LiDAR point cloud (LAS/LAZ) (by default "
            "every cue the cloud carries; Zhu &amp; Mordohai's intensity cue alone on "
            "request)")
    CUES = ["intensity", "evidence"]

    def parameters(self):
        return [
            (QgsProcessingParameterFile("INPUT", "Point cloud (LAS/LAZ)",
                                        fileFilter="LAS/LAZ (*.las *.laz *.LAS *.LAZ)"),
             "airborne LiDAR (the intensity cue needs intensity); feet are converted to "
             "metres"),
            (QgsProcessingParameterEnum("CUE", "Road cue", self.CUES,
                                        defaultValue=self.CUES.index("evidence")),
             "evidence (default): the road likelihood of every cue the cloud carries (the "
             "paper's intensity among them), through the network stage; intensity: the "
             "paper's rectangles on the ground intensity alone"),
            (lidar_model_input(str), None),
            (workers_parameter(str, "tiles"), None),
            (background_output(str), None),
        ]

    def arguments(self, parameters, context, feedback):
        background = self.parameterAsFileOutput(parameters, "BACKGROUND", context)
        model = self.parameterAsFile(parameters, "MODEL", context)
        return (self.parameterAsFile(parameters, "INPUT", context),
                ["--cue", self.CUES[self.parameterAsEnum(parameters, "CUE", context)],
                 *(["--model", model] if model else []),
                 "--workers", str(self.parameterAsInt(parameters, "WORKERS", context)),
                 *(["--background", background] if background else [])])

    def beneath(self, parameters, context, result):
        if "background" not in result:
            return None
        return result["background"], result["background_kind"]


class ExternalImageryRoadNetwork(_ExternalRoadNetwork):
    """Imagery road network through ``gisroads image``: the bundled road network's
    probability through the network stage, the default of the in-process algorithm."""

    NAME, DISPLAY_NAME, GROUP = ("imageryroadnetwork",
                                 "Imagery road network (Grote & Rottensteiner)", "Imagery")
    SUBCOMMAND = "image"
    HELP = ("Extracts the road network of an aerial image (GeoTIFF: RGB, CIR, panchromatic; "
            "a geographic image is warped to its UTM zone) with the bundled convolutional "
            "road model and the network stage")

    def parameters(self):
        return [
            (QgsProcessingParameterRasterLayer("INPUT", "Aerial image"),
             "a raster layer of the project or a file; the layer's file is what is read"),
            (QgsProcessingParameterRasterLayer("DSM", "Digital surface model", optional=True),
             "optional: a DSM in metres on the image's area"),
        ]

    def arguments(self, parameters, context, feedback):
        image = self.parameterAsRasterLayer(parameters, "INPUT", context)
        dsm = self.parameterAsRasterLayer(parameters, "DSM", context)
        return image.source(), (["--dsm", dsm.source()] if dsm is not None else [])

    def title(self, parameters, context):
        return self.parameterAsRasterLayer(parameters, "INPUT", context).name()

    def beneath(self, parameters, context, result):
        return self.parameterAsRasterLayer(parameters, "INPUT", context).source(), "image"


class ExternalRoadRasterToNetwork(_ExternalRoadNetwork):
    """Road raster to network through ``gisroads vectorize``."""

    NAME, DISPLAY_NAME, GROUP = ("roadrastertonetwork", "Road raster to network",
                                 "Road network")
    SUBCOMMAND = "vectorize"
    HELP = ("Turns any road raster (a mask, or a probability 0-1 or 0-255) into a clean, "
            "connected road network, the network stage every gisroads method ends in")

    def parameters(self):
        return [
            (QgsProcessingParameterRasterLayer("INPUT", "Road raster"),
             "road mask or probability raster, projected or geographic; the layer's file is "
             "what is read"),
            (QgsProcessingParameterNumber("BAND", "Band", QgsProcessingParameterNumber.Integer,
                                          1, minValue=1),
             "1-based band holding the road mask or probability"),
            (QgsProcessingParameterNumber("THRESHOLD", "Road threshold",
                                          QgsProcessingParameterNumber.Double, 0.5,
                                          minValue=0.0, maxValue=1.0),
             "pixels whose smoothed probability reaches this are road (0-1; a 0-255 raster "
             "is scaled to 0-1 first)"),
            (QgsProcessingParameterBoolean("WIDE_AREAS", "Roads through car parks and plazas",
                                           False),
             "car parks, plazas and other wide paved areas give the roads that cross them, "
             "not their outlines and aisles (the imagery algorithm's own rule)"),
        ]

    def arguments(self, parameters, context, feedback):
        raster = self.parameterAsRasterLayer(parameters, "INPUT", context)
        return raster.source(), [
            "--band", str(self.parameterAsInt(parameters, "BAND", context)),
            "--threshold", str(self.parameterAsDouble(parameters, "THRESHOLD", context)),
            *(["--wide-areas"] if self.parameterAsBool(parameters, "WIDE_AREAS", context)
              else [])]

    def title(self, parameters, context):
        return self.parameterAsRasterLayer(parameters, "INPUT", context).name()


class ExternalRibbonSnakeRoads(_ExternalRoadNetwork):
    """Ribbon-snake road boundaries through ``gisroads snakes``; the road map, any layer of
    the project (a selection, PostGIS, WFS), goes to it as a temporary GeoPackage."""

    NAME, DISPLAY_NAME, GROUP = ("ribbonsnakeroads", "Ribbon-snake road boundaries",
                                 "Map-guided snakes")
    SUBCOMMAND = "snakes"
    HELP = ("Fits the roads of an approximate road map to a LAS/LAZ point cloud from kerb to "
            "kerb (Boyko &amp; Funkhouser: the map registered in 3D, a curb attractor map "
            "per road, ribbon snakes)")
    DETECTORS = ["exp", "step", "none"]

    def parameters(self):
        return [
            (QgsProcessingParameterFile("INPUT", "Point cloud (LAS/LAZ)",
                                        fileFilter="LAS/LAZ (*.las *.laz *.LAS *.LAZ)"),
             "the cloud; read chunk by chunk, only along the map"),
            (QgsProcessingParameterFeatureSource("MAP", "Road map lines",
                                                 [QgsProcessing.TypeVectorLine]),
             "approximate road centre lines in any CRS (reprojected to the cloud's)"),
            (QgsProcessingParameterEnum("DETECTOR", "Curb detector",
                                        options=["exp: Gaussian, 15 cm mean (paper's best)",
                                                 "step: 10-20 cm", "none: normals only"],
                                        defaultValue=0),
             "how the height step of a neighbourhood weights its normal's tilt"),
            (workers_parameter(str, "road patches"), None),
        ]

    def arguments(self, parameters, context, feedback):
        road_map = self.parameterAsCompatibleSourceLayerPath(
            parameters, "MAP", context, ["gpkg"], "gpkg", feedback)
        return self.parameterAsFile(parameters, "INPUT", context), [
            road_map,
            "--curb-detector", self.DETECTORS[self.parameterAsEnum(parameters, "DETECTOR",
                                                                     context)],
            "--workers", str(self.parameterAsInt(parameters, "WORKERS", context))]


class ExternalSyntheticScene(_ExternalAlgorithm):
    """Synthetic road scene through ``gisroads synth``."""

    NAME, DISPLAY_NAME, GROUP = "syntheticroadscene", "Synthetic road scene", "Test data"
    SUBCOMMAND = "synth"
    HELP = ("Generates a suburban scene with exact ground truth (roads 4-25 m wide, junctions "
            "of every kind, kerbs, parking lots, buildings, trees, cars, a bridge), to try "
            "and measure the road extraction algorithms")
    OUTPUT_HELP = ("Output folder: truth.gpkg, cloud.laz, image.tif and dsm.tif; the truth, "
                   "image and DSM are added to the project.")
    #: ``gisroads synth``'s defaults (a test compares them with the in-process algorithm's).
    SIZE_M, DENSITY_PER_M2, PIXEL_M = (400.0, 400.0), 10.0, 0.25

    def initAlgorithm(self, config=None):  # noqa: N802
        add_scene_parameters(self, self.SIZE_M, self.DENSITY_PER_M2, self.PIXEL_M)

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        folder = self.parameterAsString(parameters, "OUTPUT_FOLDER", context)

        def number(name):
            return f"{self.parameterAsDouble(parameters, name, context):g}"

        paths = run_external(self.executable, [
            self.SUBCOMMAND, "-o", folder,
            "--size", f"{number('WIDTH')}x{number('HEIGHT')}",
            "--seed", str(self.parameterAsInt(parameters, "SEED", context)),
            "--density", number("DENSITY"), "--pixel", number("PIXEL"),
            *([] if self.parameterAsBool(parameters, "WRITE_CLOUD", context)
              else ["--no-cloud"]),
            *([] if self.parameterAsBool(parameters, "WRITE_IMAGE", context)
              else ["--no-image"])], feedback)
        return load_scene_on_completion(context, paths, folder)


class ExternalTrainRoadModel(_ExternalAlgorithm):
    """Train road model through ``gisroads train``; the road layer, any layer of the
    project, goes to it as a temporary GeoPackage."""

    NAME, DISPLAY_NAME, GROUP = "trainroadmodel", "Train road model", "Imagery"
    SUBCOMMAND = "train"
    HELP = ("Trains the imagery road model on your image with your road layer as labels "
            "(.npz: boosted trees; .onnx: fine-tunes the convolutional network, which needs "
            "the command's environment to have PyTorch: pip install 'gisroads[train]')")
    OUTPUT_HELP = "Output: the model file, for the Imagery road network's model."
    #: ``gisroads train``'s defaults (a test compares them with the in-process algorithm's).
    WIDTH_M, GUARD_M, SAMPLES, STEPS, CHECK = 6.0, 5.0, 100000, 150, 0.2

    def parameters(self):
        return train_parameters(str, self.WIDTH_M, self.GUARD_M, self.SAMPLES, self.STEPS,
                                self.CHECK)

    def initAlgorithm(self, config=None):  # noqa: N802
        super().initAlgorithm(config)
        self.addOutput(QgsProcessingOutputNumber("SAMPLES_USED", "Samples used (boosted trees)"))
        self.addOutput(QgsProcessingOutputNumber("ROAD_SHARE", "Road share of the layer"))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        if not out.lower().endswith((".npz", ".onnx")):
            out += ".onnx"
        roads = self.parameterAsCompatibleSourceLayerPath(parameters, "ROADS", context,
                                                          ["gpkg"], "gpkg", feedback)
        field = self.parameterAsString(parameters, "WIDTH_FIELD", context)
        result = run_external(self.executable, [
            self.SUBCOMMAND, self.parameterAsRasterLayer(parameters, "IMAGE", context).source(),
            roads, "-o", out, *(["--width-field", field] if field else []),
            "--width", str(self.parameterAsDouble(parameters, "WIDTH", context)),
            "--guard", str(self.parameterAsDouble(parameters, "GUARD", context)),
            "--samples", str(self.parameterAsInt(parameters, "SAMPLES", context)),
            "--steps", str(self.parameterAsInt(parameters, "STEPS", context)),
            "--check", str(self.parameterAsDouble(parameters, "CHECK", context))], feedback)
        return {"OUTPUT": result["model"], "SAMPLES_USED": result.get("samples", 0),
                "ROAD_SHARE": result["road_share"]}


class ExternalCityBlocks(_ExternalAlgorithm):
    """City blocks (normalized cut) through ``gisroads blocks``."""

    NAME, DISPLAY_NAME, GROUP = "cityblocks", "City blocks (normalized cut)", "LiDAR"
    SUBCOMMAND = "blocks"
    HELP = ("Segments a city into blocks bounded by roads (Zhu &amp; Mordohai, section 5): a "
            "normalized cut of a graph over the non-road places, its edges weighted by the "
            "highest road likelihood between their nodes")
    OUTPUT_HELP = "Output: a GeoPackage with the city_blocks layer, in the raster's CRS."
    #: ``gisroads blocks``'s defaults (a test compares them with the in-process algorithm's).
    SPACING_M, MAX_EDGE_M = 10.0, 80.0

    def parameters(self):
        return city_blocks_parameters(str, self.SPACING_M, self.MAX_EDGE_M)

    def initAlgorithm(self, config=None):  # noqa: N802
        super().initAlgorithm(config)
        self.addOutput(QgsProcessingOutputNumber("N_BLOCKS", "Number of blocks"))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        points = self.parameterAsFile(parameters, "POINTS", context)
        blocks = parameters.get("BLOCKS")
        result = run_external(self.executable, [
            self.SUBCOMMAND, self.parameterAsRasterLayer(parameters, "INPUT", context).source(),
            "-o", out, *(["--points", points] if points else []),
            *(["--blocks", str(self.parameterAsInt(parameters, "BLOCKS", context))]
              if blocks not in (None, "") else []),
            "--spacing", str(self.parameterAsDouble(parameters, "SPACING", context)),
            "--max-edge", str(self.parameterAsDouble(parameters, "MAX_EDGE", context))],
            feedback)
        load_geopackage_on_completion(context, out, ("city_blocks",))
        feedback.pushInfo(f"{result['blocks']} city blocks, {result['area_m2']:.0f} m²")
        return {"OUTPUT": out, "N_BLOCKS": result["blocks"]}


class ExternalProvider(QgsProcessingProvider):
    """The gisroads provider in external-tool mode (same id: models and scripts that name
    ``gisroads:lidarroadnetwork`` work in both modes). Without an executable it holds *Set
    up gisroads* alone, and the algorithms once that has made one."""

    def __init__(self, executable: str | None, on_ready=None):
        super().__init__()
        self.executable = executable
        self.on_ready = on_ready

    def id(self):
        return "gisroads"

    def name(self):
        return "gisroads"

    def longName(self):  # noqa: N802
        return f"gisroads (external: {self.executable or 'not set up yet'})"

    def loadAlgorithms(self):  # noqa: N802
        self.addAlgorithm(SetUpGisroads(on_ready=self.use))
        if self.executable is not None:
            for algorithm in EXTERNAL_ALGORITHMS:
                self.addAlgorithm(algorithm(self.executable))
            self.addAlgorithm(OpenRoadNetwork())  # QGIS alone: nothing to run
            # the stages need a gisroads that reports its jobs' defaults
            if external_defaults(self.executable) is not None:
                for algorithm in JOB_ALGORITHMS:
                    self.addAlgorithm(algorithm(self.executable))

    def use(self, executable: str):
        """Run the algorithms through ``executable`` from now on."""
        self.executable = executable
        self.refreshAlgorithms()
        if self.on_ready is not None:
            self.on_ready(executable)


EXTERNAL_ALGORITHMS = (ExternalLidarRoadNetwork, ExternalImageryRoadNetwork,
                       ExternalRoadRasterToNetwork, ExternalRibbonSnakeRoads,
                       ExternalSyntheticScene, ExternalTrainRoadModel, ExternalCityBlocks)
"""The algorithms that run through the external ``gisroads``: same ids as in-process."""

JOB_ALGORITHMS = (LidarGroundIntensity, LidarSegmentation, LidarLikelihood, LidarMinCover,
                  RectanglesToNetwork, LidarRoadEvidence, TagRoadPoints, RegisterRoadMap,
                  CurbAttractorMap, EvaluateRoadNetwork, TrainLidarRoadModel,
                  ImageSegmentation, SegmentGrouping, RoadPartFiltering, SubgraphLinking,
                  JunctionConstruction, CompareWithRoadDatabase)
"""The algorithms whose one class runs in both modes (:class:`.algorithms.base.JobAlgorithm`):
given the executable, through ``gisroads job``."""
