"""Synthetic road scene: a point cloud, an orthoimage and DSM, with their exact road truth."""
from gisroads.jobs import stage_default, synth_job

from ..convert import gisroads_errors, progress_callback
from ..loading import load_scene_on_completion
from .base import GisroadsAlgorithm, add_scene_parameters


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
        add_scene_parameters(self, stage_default(synth_job, "size_m"),
                             stage_default(synth_job, "density_per_m2"),
                             stage_default(synth_job, "pixel_m"))

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
        return load_scene_on_completion(context, paths, folder)
