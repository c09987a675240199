"""Curb attractor map: where a road boundary is likely along a road map (Boyko & Funkhouser)."""
from qgis.core import (QgsProcessingParameterEnum, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterDestination)

from .base import JobAlgorithm, cloud_input, cloud_path, road_map_input

DETECTORS = ("exp", "step", "none")


def map_guided_parameters(tr, cell_help: str, *, cell_m: float, snap_m: float) -> list:
    """The inputs both map-guided algorithms share: cloud, map, curb detector, cell and
    intersection snapping (defaults ``cell_m`` and ``snap_m``, metres), as ``(parameter,
    help)`` pairs."""
    return [
        (cloud_input(tr, "the cloud; read chunk by chunk, only along the map"), None),
        (road_map_input(tr), None),
        (QgsProcessingParameterEnum("DETECTOR", tr("Curb detector"),
                                    options=["exp: Gaussian, 15 cm mean (paper's best)",
                                             "step: 10-20 cm", "none: normals only"],
                                    defaultValue=0),
         "how the height step of a neighbourhood weights its normal's tilt"),
        (QgsProcessingParameterNumber("CELL", tr("Attractor cell (metres)"),
                                      QgsProcessingParameterNumber.Double, cell_m,
                                      minValue=0.1, maxValue=5.0), cell_help),
        (QgsProcessingParameterNumber("SNAP", tr("Intersection snapping (metres)"),
                                      QgsProcessingParameterNumber.Double, snap_m,
                                      minValue=0.01, maxValue=50.0),
         "map line ends closer than this are one intersection"),
    ]


class CurbAttractorMap(JobAlgorithm):
    NAME = "curbattractormap"
    DISPLAY_NAME = "Curb attractor map"
    GROUP = "Map-guided snakes"
    STAGE = 2
    JOB = "attractor_job"
    HELP = (
        "<p>Builds the attractor map of Boyko &amp; Funkhouser's map-guided road extraction "
        "(section 2.3) along an approximate road map over a LAS/LAZ point cloud: the map is "
        "registered in 3D, a subcloud is cut around each road (points within 0.5 m of the "
        "road's support plane and 22 m of the road), and every point gets the curb "
        "detector c(p) = f(dh) (1 - (n_p . n_s)^2), from the PCA normal of its 20 nearest "
        "neighbours and the spread dh of their heights; f weights kerb-like steps "
        "(exp: Gaussian of 15 cm mean and 5 cm deviation; step: 10-20 cm; none: 1). The "
        "cell means of c plus 0.2 times the extent term (1 between one and six 3.66 m lanes "
        "from the map line) make the attractor map a = 0.2 e + c.</p>"
        "<p>From the air a kerb only tilts the normals of the neighbourhoods across it, so "
        "the normal term is scaled by that of an ideal 15 cm kerb at the cloud's density. "
        "Output: one GeoTIFF in the cloud's CRS, the largest value where patches overlap; "
        "kerbs show as bright lines, the extent band as a faint 0.2 plateau.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        params = map_guided_parameters(self.tr,
                                       "cell of the attractor map; c is averaged per cell",
                                       cell_m=self.default("cell_m"),
                                       snap_m=self.default("snap_m")) + [
            (QgsProcessingParameterRasterDestination("OUTPUT", self.tr("Attractor map")),
             "GeoTIFF of a = 0.2 e + c in the cloud's CRS"),
        ]
        self.add_parameters(params)

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsOutputLayer(parameters, "OUTPUT", context)
        self.run_job(dict(
            cloud_path=cloud_path(self, parameters, context),
            map_source=self.source_path(parameters, "MAP", context, feedback), out_path=out,
            curb_detector=DETECTORS[self.parameterAsEnum(parameters, "DETECTOR", context)],
            cell_m=self.parameterAsDouble(parameters, "CELL", context),
            snap_m=self.parameterAsDouble(parameters, "SNAP", context)), feedback)
        return {"OUTPUT": out}
