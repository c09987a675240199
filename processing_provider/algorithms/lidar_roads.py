"""LiDAR road network (Zhu & Mordohai): the whole pipeline from a LAS/LAZ file."""
from pathlib import Path

from qgis.core import (QgsProcessingParameterEnum, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterFolderDestination, QgsProcessingParameterNumber,
                       QgsProcessingParameterString)

from gisroads.geo import CENTRELINES, JUNCTIONS, POLYGONS, SERVICE_CENTRELINES
from gisroads.jobs import lidar_job, parse_metres, stage_default
from gisroads.lidar.pipeline import CUES, DEFAULT_LENGTHS_M, DEFAULT_WIDTHS_M, EVIDENCE_THRESHOLD
from gisroads.parallel import default_workers

from ..convert import gisroads_errors, progress_callback
from ..loading import load_beneath_on_completion, load_geopackage_on_completion
from .base import (GisroadsAlgorithm, background_output, cloud_input, cloud_path,
                   lidar_model_input, network_output, workers_parameter)


class LidarRoadNetwork(GisroadsAlgorithm):
    NAME = "lidarroadnetwork"
    DISPLAY_NAME = "LiDAR road network (Zhu & Mordohai)"
    GROUP = "LiDAR"
    HELP = (
        "<p>Extracts the road network of an airborne LiDAR point cloud (LAS/LAZ). By "
        "default (the <i>evidence</i> cue, beyond the paper) the road likelihood of every "
        "cue the cloud carries (ground intensity, height above the terrain, density, "
        "roughness, slope, returns, the file's classification, kerbs) goes through the "
        "network stage (Road raster to network): gaps are bridged, junctions built and "
        "curved roads followed; shores are left out, and car-park aisles (known by the "
        "rows of cars along them) go to their own layer, service_centrelines. The QA "
        "layers are gap_edges, junction_connections and rejected, and the raster folder "
        "receives road_evidence.tif.</p>"
        "<p>The <i>intensity</i> cue follows Zhu &amp; Mordohai alone (the cloud needs "
        "intensity): ground planes on several levels (a road under a bridge and the bridge "
        "are both found), a 0.5 m intensity image per level, local-energy edges and a "
        "normalized-cut segmentation, rectangle road hypotheses scored by boundary and "
        "interior filters, likelihood maps per road width, and a minimum cover that picks "
        "the fewest rectangles explaining them; its QA layers are rectangles (selected) and "
        "hypotheses (all valid windows).</p>"
        "<p>The cloud is read once into overlapping tiles, which run in parallel (one "
        "worker process per core by default); roads are joined across tile seams. Output: "
        "a GeoPackage in the cloud's CRS with road_centrelines (width_m), road_polygons and "
        "junctions.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        widths = ",".join(f"{w:g}" for w in DEFAULT_WIDTHS_M)
        lengths = ",".join(f"{v:g}" for v in DEFAULT_LENGTHS_M)
        params = [
            (cloud_input(self.tr, "airborne LiDAR (the intensity cue needs intensity); feet "
                                  "are converted to metres"), None),
            (QgsProcessingParameterEnum("CUE", self.tr("Road cue"), list(CUES),
                                        defaultValue=CUES.index(stage_default(lidar_job, "cue"))),
             "evidence (default): the road likelihood of every cue the cloud carries (the "
             "paper's intensity among them), through the network stage; intensity: the "
             "paper's rectangles on the ground intensity alone"),
            (QgsProcessingParameterNumber("THRESHOLD", self.tr("Evidence threshold"), double,
                                          EVIDENCE_THRESHOLD, minValue=0.0, maxValue=1.0),
             "evidence cue only: road likelihood at which a cell is road"),
            (lidar_model_input(self.tr), None),
            (QgsProcessingParameterNumber("CELL", self.tr("Intensity image cell (metres)"),
                                          double, None, optional=True, minValue=0.1,
                                          maxValue=5.0),
             "empty: 0.5 m as in the paper, or the mean point spacing of a sparser cloud"),
            (QgsProcessingParameterString("WIDTHS", self.tr("Road widths to try (metres)"),
                                          widths),
             "comma-separated; the paper's 10-25 m suit arterials, suburbs need 6-12 m"),
            (QgsProcessingParameterString("LENGTHS", self.tr("Rectangle lengths (metres)"),
                                          lengths), "comma-separated (paper: 40-300 m)"),
            (QgsProcessingParameterNumber("TILE", self.tr("Tile side (metres)"), double,
                                          stage_default(lidar_job, "tile_m"), minValue=50.0),
             "the cloud is processed in tiles of this side (paper: 300 m)"),
            (QgsProcessingParameterNumber("OVERLAP", self.tr("Tile overlap (metres)"), double,
                                          stage_default(lidar_job, "overlap_m"), minValue=0.0),
             "overlap with each neighbouring tile (paper: 100 m)"),
            (QgsProcessingParameterNumber("SEGMENTS", self.tr("NCut segments per tile"),
                                          QgsProcessingParameterNumber.Integer,
                                          stage_default(lidar_job, "n_segments"),
                                          minValue=10, maxValue=1000),
             "over-segmentation size (paper: 100-200)"),
            (workers_parameter(self.tr, "tiles"), None),
            (network_output(self.tr, "GeoPackage receiving every layer, in the cloud's CRS"), None),
            (background_output(self.tr), None),
            (QgsProcessingParameterFileDestination("TAGGED_LAS",
                                                   self.tr("Cloud with road points (class 11)"),
                                                   "LAZ (*.laz);;LAS (*.las)", optional=True,
                                                   createByDefault=False),
             "optional: the input cloud with road-surface points classified 11"),
            (QgsProcessingParameterFolderDestination("RASTERS", self.tr("Raster folder"),
                                                     optional=True, createByDefault=False),
             "optional: intensity, likelihood and ground-height GeoTIFFs for QA"),
        ]
        self.add_parameters(params)
        self.add_network_outputs()

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        tagged = self.parameterAsFileOutput(parameters, "TAGGED_LAS", context) or None
        rasters = self.parameterAsString(parameters, "RASTERS", context) or None
        background = self.parameterAsFileOutput(parameters, "BACKGROUND", context) or None
        cloud = cloud_path(self, parameters, context)
        with gisroads_errors(feedback):
            result = lidar_job(
                cloud, out, tagged_las=tagged, rasters_dir=rasters, background=background,
                progress=progress_callback(feedback),
                cue=CUES[self.parameterAsEnum(parameters, "CUE", context)],
                model=self.parameterAsFile(parameters, "MODEL", context) or None,
                threshold=self.parameterAsDouble(parameters, "THRESHOLD", context),
                cell_m=(self.parameterAsDouble(parameters, "CELL", context)
                        if parameters.get("CELL") not in (None, "") else None),
                widths_m=parse_metres(self.parameterAsString(parameters, "WIDTHS", context),
                                      "widths"),
                lengths_m=parse_metres(self.parameterAsString(parameters, "LENGTHS", context),
                                       "lengths"),
                tile_m=self.parameterAsDouble(parameters, "TILE", context),
                overlap_m=self.parameterAsDouble(parameters, "OVERLAP", context),
                n_segments=self.parameterAsInt(parameters, "SEGMENTS", context),
                workers=self.parameterAsInt(parameters, "WORKERS", context) or default_workers())
        qa = (("hypotheses", "rectangles") if result["cue"] == "intensity"
              else ("rejected", "gap_edges", "junction_connections", SERVICE_CENTRELINES))
        load_geopackage_on_completion(context, out, (*qa, POLYGONS, CENTRELINES, JUNCTIONS),
                                      title=Path(cloud).stem)
        if "background" in result:
            load_beneath_on_completion(context, str(result["background"]),
                                       result["background_kind"], title=Path(cloud).stem)
        return {"OUTPUT": out, "TAGGED_LAS": tagged, "RASTERS": rasters,
                "BACKGROUND": str(result["background"]) if "background" in result else None,
                **self.network_outputs(result, feedback)}
