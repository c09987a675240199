"""LiDAR road evidence: the road likelihood of every cue a point cloud carries (beyond the
paper)."""
from qgis.core import (QgsProcessingOutputNumber, QgsProcessingOutputString,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterDestination)

from .base import JobAlgorithm, cloud_input, cloud_path


class LidarRoadEvidence(JobAlgorithm):
    NAME = "lidarroadevidence"
    DISPLAY_NAME = "Road evidence raster (LiDAR)"
    GROUP = "LiDAR"
    JOB = "evidence_job"
    HELP = (
        "<p>Measures, per cell of the lowest surface of an airborne LiDAR point cloud, how "
        "road-like it is by everything the cloud carries, and combines the cues into one "
        "road likelihood (0-1): the ground intensity (asphalt is dark at 1064 nm, grass "
        "bright), the height of the lowest return above the terrain (roofs, cars), the "
        "density of ground returns (buildings and water leave holes), the roughness and "
        "slope of the ground, the share of multi-return pulses (vegetation) and the file's "
        "own classification when it has one (ground, road surface, bridge deck; vegetation, "
        "buildings and water rule a cell out). This goes beyond Zhu &amp; Mordohai, whose "
        "method reads the intensity alone; the cues used and those the file lacks are "
        "reported.</p>"
        "<p>Output: a one-band GeoTIFF in the cloud's CRS (metres), NaN outside the data. "
        "Next: Road raster to network turns it into centre lines, polygons and junctions, "
        "as the LiDAR road network algorithm does with its evidence cue.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        self.add_parameters([
            (cloud_input(self.tr, "airborne LiDAR; intensity, returns and classes are used "
                                  "when present; feet are converted to metres"), None),
            (QgsProcessingParameterNumber("CELL", self.tr("Cell (metres)"), double, None,
                                          optional=True, minValue=0.1, maxValue=5.0),
             "empty: 0.5 m, or the mean point spacing of a sparser cloud"),
            (QgsProcessingParameterNumber("TILE", self.tr("Tile side (metres)"), double,
                                          self.default("tile_m"), minValue=50.0),
             "the cloud is read and measured tile by tile, normalised alike"),
            (QgsProcessingParameterNumber("OVERLAP", self.tr("Tile overlap (metres)"), double,
                                          self.default("overlap_m"),
                                          minValue=0.0),
             "overlap with each neighbouring tile; each cell comes from one tile's core"),
            (QgsProcessingParameterRasterDestination("OUTPUT", self.tr("Road evidence")),
             "GeoTIFF of road likelihood, 0-1"),
        ])
        self.addOutput(QgsProcessingOutputString("CUES", self.tr("Cues used")))
        self.addOutput(QgsProcessingOutputString("MISSING", self.tr("Cues missing")))
        self.addOutput(QgsProcessingOutputNumber("CELL_M", self.tr("Cell size used (metres)")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsOutputLayer(parameters, "OUTPUT", context)
        result = self.run_job(dict(
            cloud_path=cloud_path(self, parameters, context), out_path=out,
            cell_m=(self.parameterAsDouble(parameters, "CELL", context)
                    if parameters.get("CELL") not in (None, "") else None),
            tile_m=self.parameterAsDouble(parameters, "TILE", context),
            overlap_m=self.parameterAsDouble(parameters, "OVERLAP", context)), feedback)
        feedback.pushInfo(f"cues used: {result['cues']}; missing: {result['missing'] or '-'}")
        return {"OUTPUT": out, "CUES": result["cues"], "MISSING": result["missing"],
                "CELL_M": result["cell_m"]}
