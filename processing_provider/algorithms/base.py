"""What every gisroads algorithm shares: group, translation hook, instance creation, help,
stage numbers in the toolbox and the decimals of number parameters."""
import json
import math
import re

from qgis.core import (QgsFeatureSink, QgsProcessing, QgsProcessingAlgorithm,
                       QgsProcessingException, QgsProcessingOutputFile,
                       QgsProcessingOutputNumber, QgsProcessingOutputRasterLayer,
                       QgsProcessingOutputVectorLayer, QgsProcessingParameterBoolean,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterField,
                       QgsProcessingParameterFile, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterFolderDestination, QgsProcessingParameterNumber,
                       QgsProcessingParameterPointCloudLayer,
                       QgsProcessingParameterRasterLayer, QgsProviderRegistry, QgsVectorLayer)
from qgis.PyQt.QtCore import QCoreApplication



def group_id(group: str) -> str:
    """The toolbox group id of a group name: one per name, in-process and external, or the
    toolbox shows a group twice."""
    return group.lower().replace(" ", "")

class GisroadsAlgorithm(QgsProcessingAlgorithm):
    """Subclasses set ``NAME``, ``DISPLAY_NAME``, ``GROUP`` and ``HELP`` (HTML), and a
    stage of a method's pipeline its ``STAGE``."""

    NAME = ""
    DISPLAY_NAME = ""
    GROUP = ""
    HELP = ""
    STAGE = 0
    """Place of a stage algorithm in its group's pipeline (1, 2, ...), put before its display
    name ("1 Ground planes and intensity image"): the toolbox sorts by name, so the stages
    show in pipeline order, ahead of the whole pipelines and tools (0: no number). The
    algorithm's id (``NAME``) carries no number and never changes."""

    def tr(self, text):
        return QCoreApplication.translate("gisroads", text)

    def name(self):
        return self.NAME

    def displayName(self):  # noqa: N802
        name = self.tr(self.DISPLAY_NAME)
        return f"{self.STAGE} {name}" if self.STAGE else name

    def group(self):
        return self.tr(self.GROUP)

    def groupId(self):  # noqa: N802
        return group_id(self.GROUP)

    def shortHelpString(self):  # noqa: N802
        return self.tr(self.HELP)

    def shortDescription(self):  # noqa: N802
        """The help's first paragraph as plain text (the toolbox tooltip)."""
        first = self.HELP.split("</p>")[0]
        return self.tr(re.sub(r"<[^>]+>", "", first).replace("&amp;", "&"))

    def createInstance(self):  # noqa: N802
        return type(self)()

    def addParameter(self, parameter, createOutput=True):  # noqa: N802
        """QGIS's addParameter; a decimal number parameter first gets the decimals its
        values need (:func:`show_decimals`)."""
        show_decimals(parameter)
        return super().addParameter(parameter, createOutput)

    def add_parameters(self, params) -> None:
        """Add ``(parameter, help text)`` pairs; a help of None leaves the parameter's own."""
        for param, text in params:
            if text is not None:
                param.setHelp(self.tr(text))
            self.addParameter(param)

    def add_network_outputs(self) -> None:
        """The numbers every road-network algorithm reports."""
        for name, text in (("ROADS", "number of roads"), ("LENGTH_M", "total road length"),
                           ("JUNCTIONS", "number of junctions")):
            self.addOutput(QgsProcessingOutputNumber(name, self.tr(text)))

    @staticmethod
    def network_outputs(result: dict, feedback, detail: str = "") -> dict:
        """Report a road network job's figures and return them as the algorithm's outputs."""
        feedback.pushInfo(f"{result['roads']} roads, {result['length_m']:.0f} m, "
                          f"{result['junctions']} junctions{detail}")
        return {"ROADS": result["roads"], "LENGTH_M": result["length_m"],
                "JUNCTIONS": result["junctions"]}


class JobAlgorithm(GisroadsAlgorithm):
    """An algorithm whose work is one job of :mod:`gisroads.jobs` (``JOB``), called with
    plain values: paths, numbers, strings. The same class runs in two modes: in-process
    (QGIS's Python has gisroads' packages) it calls the job; given the external
    ``gisroads`` command (``executable``, external-tool mode) it runs ``gisroads job JOB
    ARGUMENTS``. The defaults of its parameters are the job's, read from gisroads in
    either mode (``gisroads job --defaults`` in the external one), so they are written
    once. The module of such an algorithm imports nothing of gisroads at its top."""

    JOB = ""

    def __init__(self, executable: str | None = None):
        super().__init__()
        self.executable = executable

    def createInstance(self):  # noqa: N802
        return type(self)(self.executable)

    def default(self, parameter: str):
        """The job's default of its keyword argument ``parameter``."""
        if self.executable is None:
            from gisroads.jobs import job_defaults
            return job_defaults(self.JOB)[parameter]
        from ..runner import external_defaults
        return (external_defaults(self.executable) or {})[self.JOB][parameter]

    def source_path(self, parameters, name: str, context, feedback) -> str:
        """A vector input as the job reads it: the layer's own file when the job can read
        it (``path|layername=...`` for a GeoPackage layer), else a temporary GeoPackage of
        what QGIS holds (a selection, a PostGIS table, a memory layer)."""
        path, layer = self.parameterAsCompatibleSourceLayerPathAndLayerName(
            parameters, name, context, ["gpkg"], "gpkg", feedback)
        return f"{path}|layername={layer}" if layer else path

    def layer_to_sink(self, parameters, name: str, context, path: str, layer_name: str,
                      feedback) -> str:
        """Copy the layer ``layer_name`` of the GeoPackage a job wrote into the feature sink
        parameter ``name`` (a file, a database table, a temporary layer: whatever the user
        chose); returns its destination id."""
        layer = QgsVectorLayer(f"{path}|layername={layer_name}", layer_name, "ogr")
        if not layer.isValid():
            raise QgsProcessingException(f"{path}: no layer {layer_name}")
        sink, dest_id = self.parameterAsSink(parameters, name, context, layer.fields(),
                                             layer.wkbType(), layer.crs())
        if sink is None:
            raise QgsProcessingException(self.invalidSinkError(parameters, name))
        if not sink.addFeatures(layer.getFeatures(), QgsFeatureSink.FastInsert):
            raise QgsProcessingException(f"{name}: {sink.lastError()}")
        if feedback.isCanceled():
            raise QgsProcessingException("cancelled")
        return dest_id

    def run_job(self, arguments: dict, feedback) -> dict:
        """The job's result, as JSON gives it (paths as strings) in both modes."""
        if self.executable is not None:
            from ..runner import run_external
            return run_external(self.executable, ["job", self.JOB, json.dumps(arguments)],
                                feedback)
        from gisroads.jobs import run_job
        from gisroads.progress import to_json

        from ..convert import gisroads_errors, progress_callback
        with gisroads_errors(feedback):
            result = run_job(self.JOB, arguments, progress_callback(feedback))
        return json.loads(to_json(result))


def _decimals(value: float) -> int:
    """Decimals ``value`` needs, up to 6 (29.999999999999996 needs none)."""
    return len(f"{value:.6f}".rstrip("0").split(".")[1])


def number_decimals(parameter: QgsProcessingParameterNumber) -> int:
    """Decimals a number parameter's spin box shows: as many as its default, minimum and
    maximum need, at least 1, and at least 2 for values below 1 (shares, thresholds,
    cells) so they can be tuned by hundredths; at most 6."""
    values = [float(v) for v in (parameter.defaultValue(), parameter.minimum(),
                                 parameter.maximum())
              if isinstance(v, (int, float)) and math.isfinite(v) and abs(v) < 1e15]
    needed = max((_decimals(v) for v in values), default=0)
    return min(6, max(needed, 2 if any(0 < abs(v) < 1 for v in values) else 1))


def show_decimals(parameter) -> None:
    """Set the decimals a decimal number parameter shows in the algorithm dialog (QGIS's
    ``widget_wrapper`` metadata; QGIS shows 6 by default: "300.000000"), unless set."""
    if not isinstance(parameter, QgsProcessingParameterNumber) \
            or parameter.dataType() != QgsProcessingParameterNumber.Double:
        return
    metadata = parameter.metadata()
    wrapper = dict(metadata.get("widget_wrapper") or {})
    if "decimals" not in wrapper:
        wrapper["decimals"] = number_decimals(parameter)
        metadata["widget_wrapper"] = wrapper
        parameter.setMetadata(metadata)


def reads_point_clouds() -> bool:
    """Whether this QGIS opens LAS/LAZ files as point-cloud layers (its PDAL provider;
    Debian's QGIS 3.22 is built without it)."""
    return "pdal" in QgsProviderRegistry.instance().providerList()


def cloud_input(tr, text: str):
    """The LAS/LAZ point cloud parameter ``INPUT``: a point-cloud layer of the project
    where QGIS can open one (:func:`reads_point_clouds`), a file otherwise."""
    if reads_point_clouds():
        param = QgsProcessingParameterPointCloudLayer("INPUT", tr("Point cloud (LAS/LAZ)"))
    else:
        param = QgsProcessingParameterFile("INPUT", tr("Point cloud (LAS/LAZ)"),
                                           fileFilter="LAS/LAZ (*.las *.laz *.LAS *.LAZ)")
    param.setHelp(tr(text))
    return param


def cloud_path(algorithm, parameters, context) -> str:
    """The file of the point cloud ``INPUT`` (:func:`cloud_input`), a layer's or a path's."""
    if isinstance(algorithm.parameterDefinition("INPUT"), QgsProcessingParameterFile):
        return algorithm.parameterAsFile(parameters, "INPUT", context)
    layer = algorithm.parameterAsPointCloudLayer(parameters, "INPUT", context)
    if layer is None:
        raise QgsProcessingException(f"INPUT: {parameters.get('INPUT')!r} is no point "
                                     "cloud that this QGIS can open")
    if not layer.source().lower().endswith((".las", ".laz")):
        raise QgsProcessingException(f"{layer.name()}: gisroads reads LAS and LAZ files; "
                                     f"this layer is {layer.source()}")
    return layer.source()


def road_map_input(tr) -> QgsProcessingParameterFeatureSource:
    """The approximate road map parameter ``MAP`` of the map-guided algorithms."""
    param = QgsProcessingParameterFeatureSource("MAP", tr("Road map lines"),
                                                [QgsProcessing.TypeVectorLine])
    param.setHelp(tr("approximate road centre lines in any CRS (reprojected to the cloud's)"))
    return param


def workers_parameter(tr, what: str) -> QgsProcessingParameterNumber:
    """The parameter ``WORKERS``: ``what`` (tiles, road patches) as parallel tasks; 0, the
    default, is one worker per core."""
    param = QgsProcessingParameterNumber("WORKERS", tr("Parallel workers"),
                                         QgsProcessingParameterNumber.Integer, 0, minValue=0)
    param.setHelp(tr(f"the {what} run as tasks on this many worker processes started beside "
                     f"QGIS (Dask), each with one {what.rstrip('s')} in memory at a time; 0: "
                     "one per core; 1: one after another inside QGIS"))
    return param


def lidar_model_input(tr) -> QgsProcessingParameterFile:
    """The optional parameter ``MODEL`` of a LiDAR road network: a road model of the area
    learned from its road layer (``gisroads train CLOUD ROADS -o model.npz``)."""
    param = QgsProcessingParameterFile("MODEL", tr("Road model of the area (.npz)"),
                                       fileFilter="Road model (*.npz)", optional=True)
    param.setHelp(tr("optional: boosted trees learned from the area's road layer by "
                     "Train LiDAR road model (or 'gisroads train CLOUD ROADS -o "
                     "model.npz'; the road-database update); they replace the evidence "
                     "cue's rule (the evidence cue only)"))
    return param


def network_output(tr, text: str) -> QgsProcessingParameterFileDestination:
    """The road-network GeoPackage parameter ``OUTPUT``."""
    param = QgsProcessingParameterFileDestination("OUTPUT", tr("Road network"),
                                                  "GeoPackage (*.gpkg)")
    param.setHelp(tr(text))
    return param


def background_output(tr) -> QgsProcessingParameterFileDestination:
    """The parameter ``BACKGROUND`` of a LiDAR road network: the GeoTIFF to see the roads
    over, loaded beneath them (a temporary file by default)."""
    param = QgsProcessingParameterFileDestination("BACKGROUND", tr("Background raster"),
                                                  "GeoTIFF (*.tif)", optional=True,
                                                  createByDefault=True)
    param.setHelp(tr("the cloud's ground intensity image (its road evidence where the file "
                     "records no intensity), added to the project beneath the roads; a "
                     "temporary file unless saved"))
    return param


def add_scene_parameters(algorithm, size_m, density_per_m2: float, pixel_m: float) -> None:
    """The parameters and outputs of *Synthetic road scene* (in-process and external), with
    the defaults of ``gisroads synth``."""
    tr = QCoreApplication.translate
    double = QgsProcessingParameterNumber.Double
    params = [
        (QgsProcessingParameterNumber("WIDTH", tr("gisroads", "Scene width (metres)"), double,
                                      size_m[0], minValue=300.0, maxValue=5000.0),
         "east-west extent of the scene"),
        (QgsProcessingParameterNumber("HEIGHT", tr("gisroads", "Scene height (metres)"), double,
                                      size_m[1], minValue=300.0, maxValue=5000.0),
         "north-south extent of the scene"),
        (QgsProcessingParameterNumber("SEED", tr("gisroads", "Random seed"),
                                      QgsProcessingParameterNumber.Integer, 0, minValue=0),
         "the same seed always gives the same scene"),
        (QgsProcessingParameterNumber("DENSITY", tr("gisroads", "Point density (points/m²)"),
                                      double, density_per_m2, minValue=0.1, maxValue=200.0),
         "mean number of LiDAR points per square metre"),
        (QgsProcessingParameterNumber("PIXEL", tr("gisroads", "Image pixel size (metres)"),
                                      double, pixel_m, minValue=0.05, maxValue=5.0),
         "ground size of an orthoimage and DSM pixel"),
        (QgsProcessingParameterBoolean("WRITE_CLOUD", tr("gisroads", "Write the point cloud"),
                                       True),
         "cloud.laz, LAS 1.4 point format 6, in the scene's CRS"),
        (QgsProcessingParameterBoolean("WRITE_IMAGE",
                                       tr("gisroads", "Write the image and DSM"), True),
         "image.tif (R, G, B, NIR, 8 bit) and dsm.tif (float, metres)"),
        (QgsProcessingParameterFolderDestination("OUTPUT_FOLDER",
                                                 tr("gisroads", "Output folder")),
         "folder that receives truth.gpkg, cloud.laz, image.tif and dsm.tif"),
    ]
    for param, text in params:
        param.setHelp(tr("gisroads", text))
        algorithm.addParameter(param)
    for output in (QgsProcessingOutputVectorLayer("TRUTH_CENTRELINES",
                                                  tr("gisroads", "Truth road centre lines")),
                   QgsProcessingOutputFile("TRUTH", tr("gisroads", "Truth GeoPackage")),
                   QgsProcessingOutputFile("CLOUD", tr("gisroads", "Point cloud (LAZ)")),
                   QgsProcessingOutputRasterLayer("IMAGE", tr("gisroads", "Orthoimage")),
                   QgsProcessingOutputRasterLayer("DSM", tr("gisroads", "Surface model"))):
        algorithm.addOutput(output)

def city_blocks_parameters(tr, spacing_m: float, max_edge_m: float) -> list:
    """``(parameter, help)`` of *City blocks* (in-process and external), with the defaults
    of ``gisroads blocks``."""
    double = QgsProcessingParameterNumber.Double
    return [
        (QgsProcessingParameterRasterLayer("INPUT", tr("Road likelihood raster")),
         "likelihood GeoTIFF of the LiDAR road network (0-25) or a road probability "
         "(0-1), projected CRS"),
        (QgsProcessingParameterFile("POINTS", tr("Ground points (LAS/LAZ)"),
                                    fileFilter="LAS/LAZ (*.las *.laz *.LAS *.LAZ)",
                                    optional=True),
         "optional: the cloud whose ground points (class 2) are the graph's nodes, as "
         "in the paper; empty: a regular sample of the raster"),
        (QgsProcessingParameterNumber("BLOCKS", tr("Number of blocks"),
                                      QgsProcessingParameterNumber.Integer, None,
                                      optional=True, minValue=1, maxValue=10000),
         "normalized-cut segments; empty: chosen by the largest eigengap"),
        (QgsProcessingParameterNumber("SPACING", tr("Node spacing (metres)"), double,
                                      spacing_m, minValue=1.0, maxValue=100.0),
         "distance between graph nodes; smaller is finer and slower"),
        (QgsProcessingParameterNumber("MAX_EDGE", tr("Longest edge (metres)"),
                                      double, max_edge_m, minValue=5.0, maxValue=500.0),
         "nodes closer than this are joined (paper: 80 m)"),
        (QgsProcessingParameterFileDestination("OUTPUT", tr("City blocks"),
                                               "GeoPackage (*.gpkg)"),
         "GeoPackage receiving the city_blocks layer, in the raster's CRS"),
    ]


def train_parameters(tr, width_m: float, guard_m: float, samples: int, steps: int,
                     check_share: float) -> list:
    """``(parameter, help)`` of *Train road model* (in-process and external), with the
    defaults of ``gisroads train``."""
    return [
        (QgsProcessingParameterRasterLayer("IMAGE", tr("Aerial image")),
         "RGB or panchromatic image in a projected CRS (metres); a geographic image is "
         "warped to its UTM zone; bands 1-3 are taken as red, green, blue"),
        (QgsProcessingParameterFeatureSource("ROADS", tr("Road layer"),
                                             [QgsProcessing.TypeVectorLine]),
         "road centre lines over the image, any CRS (reprojected to the image's); they "
         "need not be complete"),
        (QgsProcessingParameterField("WIDTH_FIELD", tr("Road width field"), None,
                                     "ROADS", QgsProcessingParameterField.Numeric,
                                     optional=True),
         "field holding each road's width in metres; empty fields, non-positive values "
         "and no field take the road width below"),
        (QgsProcessingParameterNumber("WIDTH", tr("Road width (metres)"),
                                      QgsProcessingParameterNumber.Double, width_m,
                                      minValue=0.5, maxValue=100.0),
         "width of the roads without a width field value"),
        (QgsProcessingParameterNumber("GUARD", tr("Guard band (metres)"),
                                      QgsProcessingParameterNumber.Double, guard_m,
                                      minValue=0.0, maxValue=50.0),
         "no non-road sample within this distance of a road's edge: OpenStreetMap lines "
         "are often 2-5 m off the road"),
        (QgsProcessingParameterNumber("SAMPLES", tr("Samples"),
                                      QgsProcessingParameterNumber.Integer, samples,
                                      minValue=1000),
         "boosted trees (.npz) only: pixels sampled from the image, half of them road; "
         "more samples, slower training"),
        (QgsProcessingParameterNumber("STEPS", tr("Fine-tuning steps"),
                                      QgsProcessingParameterNumber.Integer,
                                      steps, minValue=1),
         "network (.onnx) only: optimiser steps of 8 crops; more steps, longer training"),
        (QgsProcessingParameterNumber("CHECK", tr("Share of roads left out to check"),
                                      QgsProcessingParameterNumber.Double, check_share,
                                      minValue=0.0, maxValue=0.9),
         "network (.onnx) only: this share of the layer's road length (whole roads) is "
         "left out of the fine-tuning; the fine-tuned and the bundled network are compared "
         "on it and the one that finds more of it is written; 0: every road is trained on, "
         "no check"),
        (QgsProcessingParameterFileDestination(
            "OUTPUT", tr("Road model"),
            tr("Road network (*.onnx);;Boosted trees (*.npz)")),
         "the model to give to the imagery road network algorithm: .onnx fine-tunes the "
         "convolutional network, .npz trains boosted trees"),
    ]
