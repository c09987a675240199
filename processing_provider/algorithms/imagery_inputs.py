"""What the imagery algorithms (Grote & Rottensteiner) share: the image, segment, band and DSM
inputs, declared in one place and read back in one place, and the segment polygon output.
QGIS alone: the stages run in a QGIS without gisroads' packages too."""
from qgis.core import (QgsProcessing, QgsProcessingParameterBand,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterField,
                       QgsProcessingParameterRasterLayer)

from ..loading import ApplyStyle, on_load, style_path

# band parameter: keyword of the gisroads functions that take it
BANDS = {"NIR_BAND": "nir_band", "RED_BAND": "red_band"}
# help texts the stages share
IMAGE_HELP = "RGB, CIR or panchromatic image (8 or 16 bit) in a projected CRS in metres"
RED_BAND_HELP = "red band for the NDVI; by default band 2 when NIR is band 1 (CIR), else 1"


def imagery_parameters(tr, *, image: str, nir_band: str, red_band: str | None = None,
                       segments: str | None = None, id_field: str | None = None,
                       dsm: str | None = None, image_name: str = "IMAGE",
                       image_label: str = "Image", image_optional: bool = False,
                       dsm_label: str = "DSM") -> list:
    """The imagery inputs as ``(parameter, help)`` pairs, in this order: the image
    (``image_name``), the SEGMENTS polygons and their ID_FIELD, the image's NIR_BAND and
    RED_BAND, the DSM.

    ``image``, ``segments``, ``id_field``, ``nir_band``, ``red_band`` and ``dsm`` are the help
    texts of their parameters; a parameter whose help is None is left out.
    """
    pairs = [
        (QgsProcessingParameterRasterLayer(image_name, tr(image_label),
                                           optional=image_optional), image),
        (QgsProcessingParameterFeatureSource("SEGMENTS", tr("Segments"),
                                             [QgsProcessing.TypeVectorPolygon]), segments),
        (QgsProcessingParameterField("ID_FIELD", tr("Segment id field"), "segment_id",
                                     "SEGMENTS", QgsProcessingParameterField.Numeric,
                                     optional=True), id_field),
        (QgsProcessingParameterBand("NIR_BAND", tr("Near-infrared band"), None, image_name,
                                    optional=True), nir_band),
        (QgsProcessingParameterBand("RED_BAND", tr("Red band"), None, image_name,
                                    optional=True), red_band),
        (QgsProcessingParameterRasterLayer("DSM", tr(dsm_label), optional=True), dsm),
    ]
    return [(param, text) for param, text in pairs if text is not None]


def band_options(algorithm, parameters, context) -> dict:
    """``nir_band`` and ``red_band`` keyword arguments (1-based, None when not given) from the
    band parameters ``algorithm`` declares."""
    return {keyword: algorithm.parameterAsInt(parameters, name, context) or None
            for name, keyword in BANDS.items()
            if algorithm.parameterDefinition(name) is not None}


def image_arguments(algorithm, parameters, context) -> dict:
    """The IMAGE's path and its ``nir_band`` / ``red_band``, as a stage's job takes them."""
    return {"image_path": algorithm.parameterAsRasterLayer(parameters, "IMAGE",
                                                           context).source(),
            **band_options(algorithm, parameters, context)}


def segment_arguments(algorithm, parameters, context, feedback) -> dict:
    """The image (:func:`image_arguments`), the SEGMENTS as a file with their ID_FIELD and
    the DSM's path, as the grouping and road-part stages' jobs take them."""
    dsm = algorithm.parameterAsRasterLayer(parameters, "DSM", context)
    return {**image_arguments(algorithm, parameters, context),
            "segments": algorithm.source_path(parameters, "SEGMENTS", context, feedback),
            "id_field": (algorithm.parameterAsFields(parameters, "ID_FIELD", context)
                         or ["segment_id"])[0],
            "dsm_path": None if dsm is None else dsm.source()}


def segments_to_sink(algorithm, parameters, name: str, context, path: str, feedback) -> str:
    """The ``segments`` layer a stage's job wrote to ``path`` into the sink ``name``,
    styled as segments."""
    output = algorithm.layer_to_sink(parameters, name, context, path, "segments", feedback)
    on_load(context, output, ApplyStyle(style_path("segments")))
    return output
