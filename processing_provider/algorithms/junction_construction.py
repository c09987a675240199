"""Junction construction and network generation: road strings to the road-network GeoPackage."""
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber, QgsProcessingParameterExtent,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterNumber)

from ..loading import load_geopackage_on_completion
from .base import JobAlgorithm, network_output

CONNECTIONS = "junction_connections"


class JunctionConstruction(JobAlgorithm):
    NAME = "junctionconstruction"
    JOB = "junctions_job"
    DISPLAY_NAME = "Junction construction and network generation"
    GROUP = "Imagery"
    STAGE = 5
    HELP = (
        "<p>Connects road strings (the output of subgraph linking, or any line layer) into "
        "a road network, following Grote &amp; Rottensteiner (2010, Sec. 2.3).</p>"
        "<p>Each string's centre line is approximated by a polygon (Douglas-Peucker) and "
        "carries its average width. Of two close parallel roads the better one is kept; "
        "roads mostly covered by other roads are deleted. A semicircle ahead of each road "
        "end, larger for better roads, is searched for other roads: collinear roads "
        "pointing at each other are joined end to end, others where the end's extension "
        "meets the other road, or by the short polygon through the intersection of both "
        "extensions; crossing roads meet where they cross. Each road end keeps one "
        "junction connection, the shortest (continuations first). Connected components "
        "whose junction connections are longer than their roads, or which are shorter than "
        "the minimum length, are dropped, unless two of their open ends lie near the "
        "border of the given extent.</p>"
        "<p>Input fields <i>width_m</i> (metres) and <i>quality</i> (0..1) are used when "
        "present, the defaults below otherwise. Output: a GeoPackage with road_centrelines "
        "(split at junctions, width_m, score = quality), road_polygons, junctions and "
        "junction_connections (every hypothesis with its kind and whether it was "
        "verified and kept).</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        params = [
            (QgsProcessingParameterFeatureSource("ROAD_STRINGS", self.tr("Road strings"),
                                                 [QgsProcessing.TypeVectorLine]),
             "road centre lines in a projected CRS in metres, optionally with width_m and "
             "quality fields"),
            (QgsProcessingParameterExtent("EXTENT", self.tr("Image extent"), optional=True),
             "optional: the extent of the image the strings come from; components reaching "
             "its border with two open ends are kept however short"),
            (QgsProcessingParameterNumber("DEFAULT_WIDTH",
                                          self.tr("Width where none is given (metres)"),
                                          double, self.default("width_m"), minValue=0.1),
             "used for lines without a width_m value"),
            (QgsProcessingParameterNumber("DEFAULT_QUALITY",
                                          self.tr("Quality where none is given (0-1)"),
                                          double, self.default("quality"), minValue=0.0,
                                          maxValue=1.0),
             "used for lines without a quality value; sets their search radius"),
            (QgsProcessingParameterNumber("TOLERANCE",
                                          self.tr("Polygon approximation tolerance (metres)"),
                                          double, self.default("tolerance_m"), minValue=0.0),
             "largest distance of a string's vertices from its approximated centre line"),
            (QgsProcessingParameterNumber("MIN_RADIUS",
                                          self.tr("Search radius at quality 0 (metres)"),
                                          double, self.default("min_search_radius_m"),
                                          minValue=0.1),
             "radius of the semicircle searched ahead of a road end of the worst quality"),
            (QgsProcessingParameterNumber("MAX_RADIUS",
                                          self.tr("Search radius at quality 1 (metres)"),
                                          double, self.default("max_search_radius_m"),
                                          minValue=0.1),
             "radius for the best roads; linear in quality in between"),
            (QgsProcessingParameterNumber("COLLINEAR",
                                          self.tr("Collinear roads: largest direction "
                                                  "difference (degrees)"),
                                          double, self.default("collinear_deg"), minValue=0.0,
                                          maxValue=89.0),
             "roads closer in direction are joined end to end, never through an "
             "intersection"),
            (QgsProcessingParameterNumber("OVERLAP", self.tr("Overlap share that deletes a "
                                                             "road"),
                                          double, self.default("overlap_share"), minValue=0.0,
                                          maxValue=1.0),
             "a road whose area is covered by other roads for more than this share goes"),
            (QgsProcessingParameterNumber("MIN_LENGTH",
                                          self.tr("Minimum length of a component (metres)"),
                                          double, self.default("min_total_length_m"),
                                          minValue=0.0),
             "shorter isolated networks (roads and junction connections) are dropped"),
            (QgsProcessingParameterNumber("BORDER", self.tr("Near the border (metres)"),
                                          double, self.default("border_m"), minValue=0.0),
             "open ends this close to the extent's border count as leaving the image"),
            (network_output(self.tr, "GeoPackage receiving road_centrelines, road_polygons, "
                                     "junctions and junction_connections"), None),
        ]
        self.add_parameters(params)
        self.add_network_outputs()
        self.addOutput(QgsProcessingOutputNumber("CONNECTIONS",
                                                 self.tr("junction connections kept")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        source = self.parameterAsSource(parameters, "ROAD_STRINGS", context)
        extent = None
        if parameters.get("EXTENT") not in (None, ""):
            box = self.parameterAsExtent(parameters, "EXTENT", context, source.sourceCrs())
            extent = [box.xMinimum(), box.yMinimum(), box.xMaximum(), box.yMaximum()]
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)

        def number(name):
            return self.parameterAsDouble(parameters, name, context)

        result = self.run_job(dict(
            lines=self.source_path(parameters, "ROAD_STRINGS", context, feedback),
            out_path=out, extent=extent, width_m=number("DEFAULT_WIDTH"),
            quality=number("DEFAULT_QUALITY"), tolerance_m=number("TOLERANCE"),
            min_search_radius_m=number("MIN_RADIUS"), max_search_radius_m=number("MAX_RADIUS"),
            collinear_deg=number("COLLINEAR"), overlap_share=number("OVERLAP"),
            min_total_length_m=number("MIN_LENGTH"), border_m=number("BORDER")), feedback)
        load_geopackage_on_completion(context, out, ("road_polygons", CONNECTIONS,
                                                     "road_centrelines", "junctions"),
                                      group="roads")
        kept = result["connections"]
        return {"OUTPUT": out, "CONNECTIONS": kept,
                **self.network_outputs(result, feedback, f", {kept} junction connections")}
