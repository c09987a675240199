"""NCut segmentation (imagery): an aerial image over-segmented into polygons (Grote &
Rottensteiner 2010, Sec. 2.1.1)."""
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSink, QgsProcessingParameterNumber)

from gisroads.imagery.segments import (NDVI_THRESHOLD, SEGMENT_AREA_M2, SUPERPIXEL_AREA_M2,
                                       W_NDVI, segment_image, segments_to_frame)

from ..convert import gisroads_errors, progress_callback
from .base import GisroadsAlgorithm
from .imagery_inputs import (IMAGE_HELP, RED_BAND_HELP, band_options, imagery_parameters,
                             read_raster_input, write_segments)


class ImageSegmentation(GisroadsAlgorithm):
    NAME = "imagesegmentation"
    DISPLAY_NAME = "NCut segmentation (imagery)"
    GROUP = "Imagery"
    STAGE = 1
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
        params = imagery_parameters(
            self.tr, image=IMAGE_HELP, red_band=RED_BAND_HELP,
            nir_band="optional: enables the NDVI factor (vegetation / non-vegetation borders)"
        ) + [
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
        with gisroads_errors():
            image = read_raster_input(self, parameters, "IMAGE", context)
            labels = segment_image(
                image, **band_options(self, parameters, context),
                n_segments=self.parameterAsInt(parameters, "N_SEGMENTS", context) or None,
                n_superpixels=self.parameterAsInt(parameters, "N_SUPERPIXELS", context) or None,
                ndvi_threshold=self.parameterAsDouble(parameters, "NDVI_THRESHOLD", context),
                w_ndvi=self.parameterAsDouble(parameters, "W_NDVI", context),
                progress=progress_callback(feedback))
            frame = segments_to_frame(labels, image)
        output = write_segments(self, parameters, "OUTPUT", context, frame, feedback)
        feedback.pushInfo(f"{len(frame)} segments")
        return {"OUTPUT": output, "SEGMENTS": len(frame)}

