"""NCut segmentation (imagery): an aerial image over-segmented into polygons (Grote &
Rottensteiner 2010, Sec. 2.1.1)."""
import geopandas as gpd
import shapely
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber, QgsProcessingParameterBand,
                       QgsProcessingParameterFeatureSink, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterLayer)

from gisroads.imagery.segments import (NDVI_THRESHOLD, SEGMENT_AREA_M2, SUPERPIXEL_AREA_M2,
                                       W_NDVI, segment_image, segments_to_frame)
from gisroads.io.raster import read_raster

from ..convert import frame_to_sink, gisroads_errors, progress_callback, style_on_load
from .base import GisroadsAlgorithm


class ImageSegmentation(GisroadsAlgorithm):
    NAME = "imagesegmentation"
    DISPLAY_NAME = "NCut segmentation (imagery)"
    GROUP = "Imagery"
    HELP = (
        "<p>Over-segments an aerial image with normalized cuts, the first stage of Grote "
        "&amp; Rottensteiner's road extraction (2010, Sec. 2.1.1): segment borders should "
        "fall on road borders, so the image is cut into many small segments that "
        "<i>Segment grouping</i> merges again.</p>"
        "<p>The affinity of neighbouring regions combines colour similarity (every band, "
        "stretched between its 1st and 99th percentiles), the strength of edges between "
        "them (local energy of the intensity) and, when a near-infrared band is given, a "
        "factor w_NDVI much smaller than 1 between regions on opposite sides of the NDVI "
        "threshold, which separates roads from vegetation. To be tractable the cut runs on "
        "a graph of SLIC superpixels, patch by patch.</p>"
        "<p>Works on RGB, CIR and panchromatic images in a projected CRS. The output "
        "polygons carry <i>segment_id</i> and <i>area_px</i>; they can be edited (merged, "
        "split, redrawn) before the grouping or the road-part filtering.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        integer = QgsProcessingParameterNumber.Integer
        params = [
            (QgsProcessingParameterRasterLayer("IMAGE", self.tr("Image")),
             "RGB, CIR or panchromatic image (8 or 16 bit) in a projected CRS in metres"),
            (QgsProcessingParameterBand("NIR_BAND", self.tr("Near-infrared band"), None,
                                        "IMAGE", optional=True),
             "optional: enables the NDVI factor (vegetation / non-vegetation borders)"),
            (QgsProcessingParameterBand("RED_BAND", self.tr("Red band"), None, "IMAGE",
                                        optional=True),
             "red band for the NDVI; by default band 2 when NIR is band 1 (CIR), else 1"),
            (QgsProcessingParameterNumber("N_SEGMENTS", self.tr("Number of segments (0: auto)"),
                                          integer, 0, minValue=0),
             f"target over-segmentation size; 0: one segment per {SEGMENT_AREA_M2:g} m2 of "
             "image (at least 100 pixels each)"),
            (QgsProcessingParameterNumber("N_SUPERPIXELS",
                                          self.tr("Number of superpixels (0: auto)"),
                                          integer, 0, minValue=0),
             f"graph nodes of the cut; 0: one per {SUPERPIXEL_AREA_M2:g} m2 (at least 25 "
             "pixels each), at least twice the segments"),
            (QgsProcessingParameterNumber("NDVI_THRESHOLD", self.tr("NDVI threshold"), double,
                                          NDVI_THRESHOLD, minValue=-1.0, maxValue=1.0),
             "NDVI between vegetation and the rest (with a NIR band only); the paper adapts "
             "it per data set"),
            (QgsProcessingParameterNumber("W_NDVI", self.tr("NDVI factor w_NDVI"), double,
                                          W_NDVI, minValue=1e-6, maxValue=1.0),
             "affinity factor across the NDVI threshold, 0 < w_NDVI << 1; 1 turns it off"),
            (QgsProcessingParameterFeatureSink("OUTPUT", self.tr("Segments"),
                                               QgsProcessing.TypeVectorPolygon),
             "segment polygons with segment_id and area_px"),
        ]
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputNumber("SEGMENTS", self.tr("Segments made")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        image_layer = self.parameterAsRasterLayer(parameters, "IMAGE", context)
        nir = self.parameterAsInt(parameters, "NIR_BAND", context) or None
        red = self.parameterAsInt(parameters, "RED_BAND", context) or None
        with gisroads_errors():
            image = read_raster(image_layer.source())
            labels = segment_image(
                image, nir_band=nir, red_band=red,
                n_segments=self.parameterAsInt(parameters, "N_SEGMENTS", context) or None,
                n_superpixels=self.parameterAsInt(parameters, "N_SUPERPIXELS", context) or None,
                ndvi_threshold=self.parameterAsDouble(parameters, "NDVI_THRESHOLD", context),
                w_ndvi=self.parameterAsDouble(parameters, "W_NDVI", context),
                progress=progress_callback(feedback))
            frame = segments_to_frame(labels, image)
        output = write_segments(self, parameters, "OUTPUT", context, frame, feedback)
        feedback.pushInfo(f"{len(frame)} segments")
        return {"OUTPUT": output, "SEGMENTS": len(frame)}


def write_segments(algorithm, parameters, name, context, frame, feedback) -> str:
    """Segments into a polygon sink (one MultiPolygon type for all), styled as segments."""
    parts, owner = shapely.get_parts(frame.geometry.values, return_index=True)
    frame = frame.set_geometry(gpd.GeoSeries(shapely.multipolygons(parts, indices=owner),
                                             index=frame.index, crs=frame.crs))
    output = frame_to_sink(algorithm, parameters, name, context, frame, "MultiPolygon",
                           feedback)
    style_on_load(context, output, "segments")
    return output
