"""Road-part shape filtering (Grote & Rottensteiner): segments in, road-part centre lines out."""
import math
import tempfile
from pathlib import Path

from qgis.core import (QgsProcessing, QgsProcessingOutputNumber, QgsProcessingOutputString,
                       QgsProcessingParameterBoolean, QgsProcessingParameterFeatureSink,
                       QgsProcessingParameterNumber)

from ..loading import ApplyStyle, on_load, style_path
from .base import JobAlgorithm
from .imagery_inputs import (IMAGE_HELP, RED_BAND_HELP, imagery_parameters, segment_arguments,
                             segments_to_sink)

# parameter: (label, criteria key and index for (min, max) pairs, help)
THRESHOLDS = {
    "MIN_WIDTH": ("Smallest road width (metres)", ("width_range_m", 0),
                  "mean width of a road part, twice the mean distance from its centre line "
                  "to its border (paper: 3 m)"),
    "MAX_WIDTH": ("Largest road width (metres)", ("width_range_m", 1),
                  "wider segments are squares, lots or blocks (paper: 16 m)"),
    "MIN_LENGTH": ("Shortest road part (metres)", ("min_length_m", None),
                   "length of the centre line"),
    "ELONGATION": ("Smallest elongation", ("elongation_min", None),
                   "squared perimeter / area: 16 for a square, 25 for a 4:1 rectangle, 68 "
                   "for an 8 x 120 m strip"),
    "CONVEXITY": ("Smallest convexity", ("convexity_min", None),
                  "area / convex-hull area needed at the smallest elongation"),
    "ELONGATION_CURVED": ("Elongation of curved parts", ("elongation_curved_min", None),
                          "from this elongation on (paper: 70) the smallest convexity of "
                          "curved parts applies; in between the convexity needed falls "
                          "linearly"),
    "CONVEXITY_CURVED": ("Smallest convexity of curved parts", ("convexity_curved_min", None),
                         "convexity needed by very elongated parts; set it to the smallest "
                         "convexity to turn the relaxation for curves off"),
    "WIDTH_CONSTANCY": ("Smallest width constancy", ("width_constancy_min", None),
                        "mean / standard deviation of the width along the centre line "
                        "(paper: 1.7)"),
    "MAX_HEIGHT": ("Largest height above ground (metres)", ("height_max_m", None),
                   "mean of the normalised DSM over the segment; used only with a DSM"),
    "MAX_NDVI": ("Largest NDVI", ("ndvi_max", None),
                 "mean NDVI; used only with a NIR band (paper: adapted per data set)"),
    "MAX_EXCESS_GREEN": ("Largest excess green (RGB without NIR)",
                         ("excess_green_max", None),
                         "mean (2G - R - B) / (R + G + B): the vegetation test of RGB images "
                         "without a NIR band; lawns and trees are above 0.1"),
    "MAX_SATURATION": ("Largest colour saturation (RGB without NIR)",
                       ("saturation_max", None),
                       "mean HSV saturation (max - min) / max of bands 1-3: roads are grey "
                       "(about 0.1), soil, tiles, coloured roofs and leaf-off forest are "
                       "not; 1 turns the test off"),
    "MIN_INTENSITY": ("Smallest intensity (0-1)", ("intensity_range", 0),
                      "darker segments are shadows; intensity is the mean of the bands "
                      "stretched between their 1st and 99th percentiles"),
    "MAX_INTENSITY": ("Largest intensity (0-1)", ("intensity_range", 1),
                      "brighter segments are white roofs or paint"),
    "MAX_INTENSITY_STD": ("Largest intensity standard deviation (0-1)",
                          ("intensity_std_max", None),
                          "roads are homogeneous; gardens, roofs with structure are not"),
    "MIN_EDGE_CONTRAST": ("Smallest border edge contrast", ("edge_contrast_min", None),
                          "mean edge strength on the segment's border over that inside it: "
                          "a road part is a homogeneous region bounded by edges, while "
                          "regions cut out of texture (forest, fields) are not; 0 (the "
                          "default) turns the test off, about 1.1-1.2 on textured scenes"),
    "ROAD_WIDTH": ("Typical road width (metres)", ("road_width_m", None),
                   "the width the quality measure rewards most"),
}


class RoadPartFiltering(JobAlgorithm):
    NAME = "roadparts"
    DISPLAY_NAME = "Road-part shape filtering"
    GROUP = "Imagery"
    STAGE = 3
    JOB = "road_parts_job"
    HELP = (
        "<p>Tests every segment of an image segmentation against the road-part criteria of "
        "Grote &amp; Rottensteiner (2010, Sec. 2.1.3) with the parameters of Grote et al. "
        "(2009, Table 1) and keeps the road parts as centre lines.</p>"
        "<p><b>Shape</b>: elongation (squared perimeter / area) and convexity (area / "
        "convex-hull area), where very elongated curved parts may be less convex; mean width "
        "within a road-width range and nearly constant along the centre line; a minimum "
        "length. <b>Radiometry</b>: intensity neither very low (shadow) nor very high, low "
        "intensity standard deviation, low NDVI when a NIR band is given (else, for RGB, a "
        "low excess green and a low colour saturation: roads are grey), low height above "
        "ground when a DSM is given. Adjacent road "
        "parts with similar directions are merged when the merged region still passes. "
        "Each part gets a quality in 0-1 from its "
        "elongation, width, width constancy, length and NDVI.</p>"
        "<p>Outputs: <i>segments</i>, every segment with its measurements, <i>passed</i>, "
        "<i>reason</i> (the first failing test) and <i>failures</i> (all of them), so the "
        "thresholds can be tuned by looking at the map; and <i>road_parts</i>, the centre "
        "lines with width, length, quality and band means, the input of subgraph "
        "linking. The segments may come from the segmentation and grouping stages or be "
        "drawn by hand.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        double = QgsProcessingParameterNumber.Double
        params = imagery_parameters(
            self.tr, image=IMAGE_HELP, red_band=RED_BAND_HELP,
            segments="segment polygons in the image's CRS, e.g. from segment grouping",
            id_field="non-negative integer id of each segment (segment_id when empty); "
                     "polygons with the same id are one segment",
            nir_band="optional: adds the NDVI test and leaves NIR out of the intensity",
            dsm="optional: surface heights in metres; adds the height test (normalised DSM)")
        for name, (label, (key, index), text) in THRESHOLDS.items():
            params.append((QgsProcessingParameterNumber(
                name, self.tr(label), double, self._default(key, index),
                minValue=-1.0 if name in ("MAX_NDVI", "MAX_EXCESS_GREEN") else 0.0), text))
        params += [
            (QgsProcessingParameterBoolean("MERGE", self.tr("Merge adjacent road parts"),
                                           self.default("merge")),
             "merge touching parts of similar direction when the union still passes"),
            (QgsProcessingParameterNumber("MAX_DIRECTION",
                                          self.tr("Largest direction difference to merge "
                                                  "(degrees)"), double,
                                          math.degrees(self.default("max_direction_diff_rad")),
                                          minValue=0.0, maxValue=90.0),
             "main directions of two parts to merge differ by at most this"),
            (QgsProcessingParameterFeatureSink("OUTPUT_SEGMENTS", self.tr("Segments tested"),
                                               QgsProcessing.TypeVectorPolygon),
             "every segment with its measurements, passed, reason and failures"),
            (QgsProcessingParameterFeatureSink("ROAD_PARTS", self.tr("Road parts"),
                                               QgsProcessing.TypeVectorLine),
             "centre lines of the road parts: part_id, segment_id, width_m, length_m, "
             "quality, band means"),
        ]
        self.add_parameters(params)
        self.addOutput(QgsProcessingOutputNumber("PARTS", self.tr("Road parts found")))
        self.addOutput(QgsProcessingOutputString("CUES", self.tr("Cues used")))

    def _default(self, key, index):
        value = self.default("criteria")[key]
        return float(value if index is None else value[index])

    def _criteria(self, parameters, context) -> dict:
        criteria = {}
        for name, (_, (key, index), _) in THRESHOLDS.items():
            value = self.parameterAsDouble(parameters, name, context)
            if index is None:
                criteria[key] = value
            else:
                criteria.setdefault(key, list(self.default("criteria")[key]))[index] = value
        return criteria

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        with tempfile.TemporaryDirectory(prefix="gisroads-roadparts-") as folder:
            path = str(Path(folder) / "road_parts.gpkg")
            result = self.run_job(dict(
                **segment_arguments(self, parameters, context, feedback),
                road_parts_path=path,
                criteria=self._criteria(parameters, context),
                merge=self.parameterAsBoolean(parameters, "MERGE", context),
                max_direction_diff_rad=math.radians(
                    self.parameterAsDouble(parameters, "MAX_DIRECTION", context))), feedback)
            outputs = {
                "OUTPUT_SEGMENTS": segments_to_sink(self, parameters, "OUTPUT_SEGMENTS",
                                                    context, path, feedback),
                "ROAD_PARTS": self.layer_to_sink(parameters, "ROAD_PARTS", context, path,
                                                 "road_parts", feedback)}
        on_load(context, outputs["ROAD_PARTS"], ApplyStyle(style_path("road_parts")))
        feedback.pushInfo(f"{result['n_passed']} road parts among {result['n_segments']} "
                          f"segments; cues: {result['cues']}")
        return {**outputs, "PARTS": result["n_parts"], "CUES": result["cues"]}
