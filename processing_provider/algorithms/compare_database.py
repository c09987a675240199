"""Compare with road database: change layers of an existing road database from an extraction."""
import tempfile
from pathlib import Path

from qgis.core import (QgsFeature, QgsField, QgsFields, QgsProcessing, QgsProcessingException,
                       QgsProcessingOutputNumber, QgsProcessingParameterFeatureSink,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterField,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterLayer,
                       QgsVectorFileWriter)
from qgis.PyQt.QtCore import QVariant

from ..loading import ApplyStyle, on_load, style_path
from .base import JobAlgorithm

FID_FIELD = "gisroads_source_fid"
"""The field that carries the database's feature ids to the job (a copy's own ids are new)."""

#: Output parameter -> (layer name and style, display name, help).
SINKS = {
    "CONFIRMED": ("confirmed", "Confirmed roads",
                  "database roads seen in the data: db_id, matched_share, mean/max offset "
                  "(m), database and measured width, moved and width_changed flags, then the "
                  "database's fields unchanged"),
    "MISSING": ("missing", "Missing roads and stretches",
                "database roads or stretches not seen: db_id, length_m, observable_share "
                "and evidence (not_seen where the data could show the road, not_observable "
                "where it could not, unknown without a coverage), the database's fields (a "
                "road can have several missing stretches)"),
    "NEW": ("new", "New roads",
            "extracted roads absent from the database: road_id, length_m, width_m, score, "
            "and start_db_id/end_db_id, the database roads their ends meet"),
    "MOVED": ("moved", "Moved roads (proposed geometry)",
              "roads whose median offset exceeds the tolerance, with the proposed geometry "
              "(the extracted line), db_id, offsets and the database's fields"),
    "PROPOSED_UPDATE": ("proposed_update", "Proposed database update",
                        "the database with moved geometries and measured widths applied, "
                        "the new roads appended, and a change field (unchanged, moved, "
                        "width, missing, new), ready for review and import"),
}


class CompareWithRoadDatabase(JobAlgorithm):
    NAME = "comparewithroaddatabase"
    JOB = "update_job"
    DISPLAY_NAME = "Compare with road database"
    GROUP = "Road database update"
    HELP = (
        "<p>Compares extracted road centre lines with an existing road database (a "
        "municipal street layer, a topographic database, OpenStreetMap) and writes the "
        "changes: which database roads the new data confirms, which are missing, which "
        "roads are new, which have moved or changed width, and the database with those "
        "updates applied.</p>"
        "<p>Both line sets are sampled every 2 m; a sample matches the nearest line of the "
        "other side within the search distance whose direction differs by less than 30 "
        "degrees, and the match must be mutual (the extracted line there belongs to that "
        "database road). Database roads are judged in stretches of about 15 m, so a road "
        "seen only in part gives missing stretches. A road is confirmed when half of its "
        "length is seen, moved when its median offset exceeds the tolerance.</p>"
        "<p>The database can be any line layer the project has open: PostGIS, GeoPackage, "
        "WFS, Shapefile, in any CRS; it is reprojected to the extraction's CRS for the "
        "matching and every output is in the database's CRS, in 2D. Its feature ids (or "
        "the id field) and all its fields are carried through unchanged; outputs are "
        "feature sinks, so they can be written straight into PostGIS.</p>")

    def groupId(self):  # noqa: N802
        """The group's name itself: the id a Processing model (models/*.model3) has for
        its group, so the model and this algorithm share one group in the toolbox."""
        return self.GROUP

    def initAlgorithm(self, config=None):  # noqa: N802
        lines = [QgsProcessing.TypeVectorLine]
        double = QgsProcessingParameterNumber.Double
        params = [
            (QgsProcessingParameterFeatureSource("EXTRACTED", self.tr("Extracted centre lines"),
                                                 lines),
             "road centre lines of an extraction (a gisroads road_centrelines layer: road_id, "
             "width_m and score are used when present), in a projected CRS"),
            (QgsProcessingParameterFeatureSource("DATABASE", self.tr("Road database"), lines),
             "the road database's line layer, any provider and CRS"),
            (QgsProcessingParameterField("ID_FIELD", self.tr("Database id field"), None,
                                         "DATABASE", optional=True),
             "field holding the database's road ids; empty: the layer's feature ids (a "
             "GeoPackage's fid, a PostGIS primary key)"),
            (QgsProcessingParameterField("WIDTH_FIELD", self.tr("Database width field"), None,
                                         "DATABASE", QgsProcessingParameterField.Numeric,
                                         optional=True),
             "field holding road widths in metres; empty: widths are measured, not compared"),
            (QgsProcessingParameterNumber("TOLERANCE", self.tr("Moved tolerance (metres)"),
                                          double, self.default("tolerance_m"),
                                          minValue=0.1),
             "a road whose median offset from the extraction exceeds this has moved"),
            (QgsProcessingParameterNumber("SEARCH", self.tr("Search distance (metres)"),
                                          double, self.default("search_m"),
                                          minValue=0.5),
             "largest offset at which a database road and an extracted line can still be "
             "the same road: the largest displacement reported as moved"),
            (QgsProcessingParameterNumber("WIDTH_TOLERANCE",
                                          self.tr("Width tolerance (metres)"), double,
                                          self.default("width_tolerance_m"),
                                          minValue=0.0),
             "a measured width differing from the database's by more than this is a change"),
            (QgsProcessingParameterFeatureSource("COVERAGE",
                                                 self.tr("Observable area (polygons)"),
                                                 [QgsProcessing.TypeVectorPolygon],
                                                 optional=True),
             "optional: where the data could show a road (the survey's footprint minus "
             "occlusion by trees and buildings); missing stretches outside it are "
             "not_observable"),
            (QgsProcessingParameterRasterLayer("COVERAGE_RASTER",
                                               self.tr("Observable area (raster)"),
                                               optional=True),
             "optional: the same as a raster, non-zero cells observable (e.g. a ground-point "
             "density or image-coverage mask)"),
        ]
        params += [(QgsProcessingParameterFeatureSink(name, self.tr(title),
                                                      QgsProcessing.TypeVectorLine), text)
                   for name, (_, title, text) in SINKS.items()]
        self.add_parameters(params)
        for name, (layer, _, _) in SINKS.items():
            self.addOutput(QgsProcessingOutputNumber(f"{name}_COUNT",
                                                     self.tr(f"number of {layer} features")))

    def _coverage(self, parameters, context, feedback):
        """The coverage polygons or raster given, as the job reads them, else None."""
        if self.parameterAsSource(parameters, "COVERAGE", context) is not None:
            return self.source_path(parameters, "COVERAGE", context, feedback)
        raster = self.parameterAsRasterLayer(parameters, "COVERAGE_RASTER", context)
        return None if raster is None else raster.source()

    def _database_with_ids(self, parameters, context, feedback, path: str) -> str:
        """The database layer (a file, a selection, a PostGIS or WFS table) copied into a
        GeoPackage with its feature ids in :data:`FID_FIELD`, so the changes name the
        layer's own ids whatever the copy numbers its features."""
        source = self.parameterAsSource(parameters, "DATABASE", context)
        fields = QgsFields(source.fields())
        fields.append(QgsField(FID_FIELD, QVariant.LongLong))
        options = QgsVectorFileWriter.SaveVectorOptions()
        options.driverName, options.layerName = "GPKG", "database"
        writer = QgsVectorFileWriter.create(path, fields, source.wkbType(), source.sourceCrs(),
                                            context.transformContext(), options)
        if writer.hasError():
            raise QgsProcessingException(f"{path}: {writer.errorMessage()}")
        for feature in source.getFeatures():
            if feedback.isCanceled():
                raise QgsProcessingException("cancelled")
            copy = QgsFeature(fields)
            copy.setGeometry(feature.geometry())
            copy.setAttributes(feature.attributes() + [feature.id()])
            writer.addFeature(copy)
        del writer  # closes the file
        return f"{path}|layername=database"

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        if None in (self.parameterAsSource(parameters, "EXTRACTED", context),
                    self.parameterAsSource(parameters, "DATABASE", context)):
            raise QgsProcessingException(self.tr("both line layers are required"))
        feedback.setProgressText(self.tr("reading the layers"))
        with tempfile.TemporaryDirectory(prefix="gisroads-compare-") as folder:
            out = str(Path(folder) / "changes.gpkg")
            result = self.run_job(dict(
                extracted=self.source_path(parameters, "EXTRACTED", context, feedback),
                database=self._database_with_ids(parameters, context, feedback,
                                                 str(Path(folder) / "database.gpkg")),
                out_path=out, fid_field=FID_FIELD,
                id_field=self.parameterAsString(parameters, "ID_FIELD", context) or None,
                width_field=self.parameterAsString(parameters, "WIDTH_FIELD", context) or None,
                tolerance_m=self.parameterAsDouble(parameters, "TOLERANCE", context),
                search_m=self.parameterAsDouble(parameters, "SEARCH", context),
                width_tolerance_m=self.parameterAsDouble(parameters, "WIDTH_TOLERANCE",
                                                         context),
                coverage=self._coverage(parameters, context, feedback)), feedback)
            outputs = {}
            for name, (layer, _, _) in SINKS.items():
                outputs[name] = self.layer_to_sink(parameters, name, context, out, layer,
                                                   feedback)
                outputs[f"{name}_COUNT"] = result[layer]
                on_load(context, outputs[name], ApplyStyle(style_path(layer)))
        feedback.pushInfo(", ".join(f"{count} {change}"
                                    for change, count in result["changes"].items()))
        return outputs
