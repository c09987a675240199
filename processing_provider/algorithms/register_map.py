"""Register road map to point cloud: a 2D road map lifted onto a LAS/LAZ cloud in 3D."""
from qgis.core import (QgsProcessingOutputNumber, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber)

from ..loading import load_geopackage_on_completion
from .base import JobAlgorithm, cloud_input, cloud_path, road_map_input


class RegisterRoadMap(JobAlgorithm):
    NAME = "registerroadmap"
    JOB = "register_job"
    DISPLAY_NAME = "Register road map to point cloud"
    GROUP = "Map-guided snakes"
    STAGE = 1
    HELP = (
        "<p>Lifts an approximate 2D road map (OpenStreetMap lines, a digitised network; any "
        "CRS, reprojected to the cloud's) onto a LAS/LAZ point cloud, as the first step of "
        "Boyko &amp; Funkhouser's map-guided road extraction.</p>"
        "<p>Intersections are the lines' shared end points (within the snapping "
        "tolerance) and ends lying on another line; lines crossing without a shared vertex "
        "stay apart, so a bridge over a road is no intersection. A Cardinal spline with "
        "control vertices at the intersections (shared by the roads meeting there) and "
        "every 15 m is fitted to the elevations of the points within 15 cm of its samples "
        "(one every metre), all roads at once; each sample then takes its closest point's "
        "elevation and inclines above 35 % are clamped. Points of other levels (a deck "
        "over the road, cars, tree crowns) are told apart by the continuity of the road "
        "along its length.</p>"
        "<p>Only heights are registered: the lines keep the map's horizontal positions. "
        "Output: the registered_map layer (LineString Z) in the cloud's CRS, with "
        "road_id, length_m, seen_fraction (share of samples with a point of the road's "
        "level nearby), the intersections at both ends and the map's attributes.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        params = [
            (cloud_input(self.tr, "the cloud to register the map on; read chunk by chunk, "
                                  "only along the map"), None),
            (road_map_input(self.tr), None),
            (QgsProcessingParameterNumber("SNAP", self.tr("Intersection snapping (metres)"),
                                          double, self.default("snap_m"),
                                          minValue=0.01, maxValue=50.0),
             "line ends closer than this are one intersection; an end this close to "
             "another line makes a T junction"),
            (QgsProcessingParameterNumber("CONTROL_SPACING",
                                          self.tr("Control vertex spacing (metres)"),
                                          double,
                                          self.default("control_spacing_m"),
                                          minValue=1.0, maxValue=200.0),
             "spline control vertices along the roads (paper: 15 m)"),
            (QgsProcessingParameterNumber("SUPPORT_RADIUS",
                                          self.tr("Support radius (metres)"),
                                          double, self.default("support_radius_m"),
                                          minValue=0.01, maxValue=5.0),
             "points within this distance of a sample fit its elevation (paper: 15 cm); "
             "an airborne cloud of a few points per square metre sees one sample in two"),
            (QgsProcessingParameterNumber("MAX_INCLINE", self.tr("Maximum incline"),
                                          double, self.default("max_incline"),
                                          minValue=0.01, maxValue=2.0),
             "steepest road, rise over run (paper: 0.35)"),
            (QgsProcessingParameterFileDestination("OUTPUT", self.tr("Registered map"),
                                                   "GeoPackage (*.gpkg)"),
             "GeoPackage receiving the registered_map layer"),
        ]
        self.add_parameters(params)
        for name, text in (("ROADS", "number of roads"), ("LENGTH_M", "total road length"),
                           ("SEEN_FRACTION", "share of samples seeing the road")):
            self.addOutput(QgsProcessingOutputNumber(name, self.tr(text)))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        result = self.run_job(dict(
            cloud_path=cloud_path(self, parameters, context),
            map_source=self.source_path(parameters, "MAP", context, feedback), out_path=out,
            snap_m=self.parameterAsDouble(parameters, "SNAP", context),
            control_spacing_m=self.parameterAsDouble(parameters, "CONTROL_SPACING", context),
            support_radius_m=self.parameterAsDouble(parameters, "SUPPORT_RADIUS", context),
            max_incline=self.parameterAsDouble(parameters, "MAX_INCLINE", context)), feedback)
        load_geopackage_on_completion(context, out, ("registered_map",), group="snakes")
        feedback.pushInfo(f"{result['roads']} roads, {result['length_m']:.0f} m, "
                          f"{100 * result['seen_fraction']:.0f} % of the samples seen")
        return {"OUTPUT": out, "ROADS": result["roads"], "LENGTH_M": result["length_m"],
                "SEEN_FRACTION": result["seen_fraction"]}
