"""NCut over-segmentation of an aerial image (Grote & Rottensteiner 2010, Sec. 2.1.1)."""
import tempfile
from pathlib import Path

from qgis.core import (QgsProcessing, QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSink, QgsProcessingParameterNumber)

from .base import JobAlgorithm
from .imagery_inputs import (IMAGE_HELP, RED_BAND_HELP, image_arguments, imagery_parameters,
                             segments_to_sink)


class ImageSegmentation(JobAlgorithm):
    NAME = "imagesegmentation"
    DISPLAY_NAME = "NCut segmentation (imagery)"
    GROUP = "Imagery"
    STAGE = 1
    JOB = "segmentation_job"
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
             "target over-segmentation size; 0: about one segment per road width squared "
             "of ground (at least 100 pixels each)"),
            (QgsProcessingParameterNumber("N_SUPERPIXELS",
                                          self.tr("Number of superpixels (0: auto)"),
                                          integer, 0, minValue=0),
             "graph nodes of the cut; 0: a quarter of a segment's ground each (at least "
             "25 pixels), at least twice the segments"),
            (QgsProcessingParameterNumber("NDVI_THRESHOLD", self.tr("NDVI threshold"), double,
                                          self.default("ndvi_threshold"), minValue=-1.0,
                                          maxValue=1.0),
             "NDVI between vegetation and the rest (with a NIR band only); the paper adapts "
             "it per data set"),
            (QgsProcessingParameterNumber("W_NDVI", self.tr("NDVI factor w_NDVI"), double,
                                          self.default("w_ndvi"), minValue=1e-6, maxValue=1.0),
             "affinity factor across the NDVI threshold, 0 < w_NDVI << 1; 1 turns it off"),
            (QgsProcessingParameterFeatureSink("OUTPUT", self.tr("Segments"),
                                               QgsProcessing.TypeVectorPolygon),
             "segment polygons with segment_id and area_px"),
        ]
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputNumber("SEGMENTS", self.tr("Segments made")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        with tempfile.TemporaryDirectory(prefix="gisroads-segments-") as folder:
            path = str(Path(folder) / "segments.gpkg")
            result = self.run_job(dict(
                **image_arguments(self, parameters, context), segments_path=path,
                n_segments=self.parameterAsInt(parameters, "N_SEGMENTS", context),
                n_superpixels=self.parameterAsInt(parameters, "N_SUPERPIXELS", context),
                ndvi_threshold=self.parameterAsDouble(parameters, "NDVI_THRESHOLD", context),
                w_ndvi=self.parameterAsDouble(parameters, "W_NDVI", context)), feedback)
            output = segments_to_sink(self, parameters, "OUTPUT", context, path, feedback)
        feedback.pushInfo(f"{result['n_segments']} segments")
        return {"OUTPUT": output, "SEGMENTS": result["n_segments"]}
