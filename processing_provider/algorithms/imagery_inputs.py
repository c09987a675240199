"""What the imagery algorithms (Grote & Rottensteiner) share: the image, segment, band and DSM
inputs, declared in one place and read back in one place, and the segment polygon output.

The declarations import nothing of gisroads (the job algorithms declare their parameters
with them in a QGIS without it); the readers import it when they run."""
from qgis.core import (QgsProcessing, QgsProcessingException, QgsProcessingParameterBand,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterField,
                       QgsProcessingParameterRasterLayer)

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


def read_raster_input(algorithm, parameters, name: str, context):
    """The GeoRaster of raster parameter ``name``, None when an optional one is not given.
    Raises RasterError: read it inside ``gisroads_errors()``."""
    from gisroads.io.raster import read_raster

    layer = algorithm.parameterAsRasterLayer(parameters, name, context)
    return None if layer is None else read_raster(layer.source())


def read_segment_labels(algorithm, parameters, context, feedback, burn) -> tuple:
    """``(image, dsm, labels)``: the IMAGE and DSM rasters (dsm None when not given) and the
    SEGMENTS polygons burnt into labels on the image's grid by ``burn(segments, image,
    id_column=...)`` with their ID_FIELD (segment_id when empty)."""
    from ..convert import gisroads_errors, source_to_frame

    segments = source_to_frame(algorithm.parameterAsSource(parameters, "SEGMENTS", context),
                               feedback)
    id_field = (algorithm.parameterAsFields(parameters, "ID_FIELD", context)
                or ["segment_id"])[0]
    with gisroads_errors():
        image = read_raster_input(algorithm, parameters, "IMAGE", context)
        dsm = read_raster_input(algorithm, parameters, "DSM", context)
        labels = burn(segments, image, id_column=id_field)
    if (labels < 0).all():
        raise QgsProcessingException(algorithm.tr("no segment polygon overlaps the image"))
    return image, dsm, labels


def write_segments(algorithm, parameters, name, context, frame, feedback) -> str:
    """Segments into a polygon sink (one MultiPolygon type for all), styled as segments."""
    import geopandas as gpd
    import shapely

    from ..convert import frame_to_sink, style_on_load

    parts, owner = shapely.get_parts(frame.geometry.values, return_index=True)
    frame = frame.set_geometry(gpd.GeoSeries(shapely.multipolygons(parts, indices=owner),
                                             index=frame.index, crs=frame.crs))
    output = frame_to_sink(algorithm, parameters, name, context, frame, "MultiPolygon",
                           feedback)
    style_on_load(context, output, "segments")
    return output
