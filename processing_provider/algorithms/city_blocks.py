"""City blocks (normalized cut): Zhu & Mordohai's block segmentation of a road-likelihood map."""
from qgis.core import QgsProcessingOutputNumber

from gisroads.errors import GisroadsError
from gisroads.lidar.blocks import MAX_EDGE_M, SAMPLE_SPACING_M
from gisroads.jobs import blocks_job

from ..convert import gisroads_errors, progress_callback
from ..loading import load_geopackage_on_completion
from .base import GisroadsAlgorithm, city_blocks_parameters


class CityBlocks(GisroadsAlgorithm):
    NAME = "cityblocks"
    DISPLAY_NAME = "City blocks (normalized cut)"
    GROUP = "LiDAR"
    HELP = (
        "<p>Segments a city into blocks bounded by roads, from a road-likelihood raster, "
        "following Zhu &amp; Mordohai (section 5).</p>"
        "<p>Places off the roads are the nodes of a graph; nodes within 80 m are joined, "
        "and the weight of an edge is exp(-L), L the highest road likelihood on the "
        "straight segment between the two nodes (an <i>intervening contour</i>). A "
        "normalized cut of this graph gives the blocks: where the road extraction missed "
        "a stretch of road, the two blocks it bounds are still separated, because the "
        "cheapest cut runs through the gap. The number of blocks is the largest eigengap "
        "of the graph unless given. Every non-road cell then takes the block of its "
        "nearest node reached without crossing a road.</p>"
        "<p>Input: a likelihood GeoTIFF from the LiDAR road network's raster folder "
        "(<i>*_likelihood_level_*.tif</i>; the maximum over its width bands is used) or any "
        "road-probability raster with values in [0, 1], in a projected CRS. Output: the "
        "city_blocks layer (block_id, segment, area_m2, perimeter_m) in a GeoPackage.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.add_parameters(city_blocks_parameters(self.tr, SAMPLE_SPACING_M, MAX_EDGE_M))
        self.addOutput(QgsProcessingOutputNumber("N_BLOCKS", self.tr("Number of blocks")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        raster = self.parameterAsRasterLayer(parameters, "INPUT", context)
        blocks = (self.parameterAsInt(parameters, "BLOCKS", context)
                  if parameters.get("BLOCKS") not in (None, "") else None)
        with gisroads_errors():
            if raster is None:
                raise GisroadsError("the likelihood raster could not be loaded")
            result = blocks_job(
                raster.source(), out,
                points_path=self.parameterAsFile(parameters, "POINTS", context) or None,
                n_blocks=blocks, progress=progress_callback(feedback),
                sample_spacing_m=self.parameterAsDouble(parameters, "SPACING", context),
                max_edge_m=self.parameterAsDouble(parameters, "MAX_EDGE", context))
        load_geopackage_on_completion(context, out, ("city_blocks",))
        feedback.pushInfo(f"{result['blocks']} city blocks, {result['area_m2']:.0f} m²")
        return {"OUTPUT": out, "N_BLOCKS": result["blocks"]}
