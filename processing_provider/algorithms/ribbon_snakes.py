"""Ribbon-snake road boundaries: the whole map-guided pipeline (Boyko & Funkhouser)."""
from pathlib import Path

from qgis.core import (QgsProcessingParameterFileDestination,
                       QgsProcessingParameterRasterDestination)

from gisroads.jobs import snakes_job, stage_default
from gisroads.parallel import default_workers
from gisroads.snakes.registration import SNAP_M

from ..convert import gisroads_errors, progress_callback, source_to_frame
from ..loading import load_geopackage_on_completion
from .base import GisroadsAlgorithm, cloud_path, network_output, workers_parameter
from .curb_attractor import DETECTORS, map_guided_parameters


def map_guided_arguments(algorithm, parameters, context, feedback) -> tuple:
    """``(cloud path, map lines, options)`` from the ``map_guided_parameters``; options are
    the jobs' ``curb_detector``, ``cell_m`` and ``snap_m``."""
    lines = source_to_frame(algorithm.parameterAsSource(parameters, "MAP", context), feedback)
    options = {
        "curb_detector": DETECTORS[algorithm.parameterAsEnum(parameters, "DETECTOR", context)],
        "cell_m": algorithm.parameterAsDouble(parameters, "CELL", context),
        "snap_m": algorithm.parameterAsDouble(parameters, "SNAP", context)}
    return cloud_path(algorithm, parameters, context), lines, options


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
        params = map_guided_parameters(self.tr, "cell of the attractor map the snakes fit to",
                                       cell_m=stage_default(snakes_job, "cell_m"),
                                       snap_m=SNAP_M) + [
            (network_output(self.tr, "GeoPackage receiving every layer, in the cloud's CRS"),
             None),
            (QgsProcessingParameterFileDestination("TAGGED_LAS",
                                                   self.tr("Cloud with road points (class 11)"),
                                                   "LAZ (*.laz);;LAS (*.las)", optional=True,
                                                   createByDefault=False),
             "optional: the input cloud with the points inside the ribbons classified 11"),
            (QgsProcessingParameterRasterDestination("ATTRACTOR", self.tr("Attractor map"),
                                                     optional=True, createByDefault=False),
             "optional: the attractor maps of the road patches as one GeoTIFF, for QA"),
            (workers_parameter(self.tr, "road patches"), None),
        ]
        self.add_parameters(params)
        self.add_network_outputs()

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        tagged = self.parameterAsFileOutput(parameters, "TAGGED_LAS", context) or None
        attractor = self.parameterAsOutputLayer(parameters, "ATTRACTOR", context) or None
        cloud, lines, options = map_guided_arguments(self, parameters, context, feedback)
        with gisroads_errors(feedback):
            result = snakes_job(
                cloud, lines, out, tagged_las=tagged, attractor_tif=attractor,
                workers=self.parameterAsInt(parameters, "WORKERS", context) or default_workers(),
                progress=progress_callback(feedback), **options)
        load_geopackage_on_completion(context, out, title=Path(cloud).stem)
        return {"OUTPUT": out, "TAGGED_LAS": tagged, "ATTRACTOR": attractor,
                **self.network_outputs(result, feedback, f", {result['converged']} of "
                                       f"{result['patches']} ribbons converged")}
