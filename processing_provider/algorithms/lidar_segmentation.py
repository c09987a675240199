"""LiDAR stage 3: local-energy edges and the NCut over-segmentation of an intensity image."""
from qgis.core import (QgsProcessingOutputNumber, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterDestination,
                       QgsProcessingParameterRasterLayer)

from .base import JobAlgorithm


def level_parameter(tr):
    param = QgsProcessingParameterNumber("LEVEL", tr("Ground level (band - 1)"),
                                         QgsProcessingParameterNumber.Integer, 0,
                                         minValue=0, maxValue=20)
    param.setHelp(tr("which level of the intensity image: 0 is the lowest ground (band 1), "
                     "1 a bridge deck or terrace above it (band 2), ..."))
    return param


class LidarSegmentation(JobAlgorithm):
    NAME = "lidarsegmentation"
    DISPLAY_NAME = "Edges and NCut segmentation (LiDAR)"
    GROUP = "LiDAR"
    STAGE = 2
    JOB = "lidar_segmentation_job"
    HELP = (
        "<p>Edge strength and orientation of one level of a LiDAR intensity image by local "
        "energy (Morrone &amp; Owens: quadrature pairs of oriented filters), and its "
        "over-segmentation into 100-200 regions by a normalized cut (Shi &amp; Malik) over a "
        "graph of fine superpixels, with intensity-similarity affinities as in Zhu &amp; "
        "Mordohai, section 4.3. The same NCut implementation segments aerial images in the "
        "imagery pipeline.</p>"
        "<p>Input: the intensity image of Ground planes and intensity image. Writes the "
        "segment labels (GeoTIFF, -1 = no data) and optionally the edges (bands magnitude "
        "and orientation in radians). Next stage: Road likelihood maps.</p>")

    def initAlgorithm(self, config=None):  # noqa: N802
        params = [
            (QgsProcessingParameterRasterLayer("INPUT", self.tr("Intensity image")),
             "the intensity GeoTIFF of Ground planes and intensity image"),
            (QgsProcessingParameterNumber("SEGMENTS", self.tr("Number of segments"),
                                          QgsProcessingParameterNumber.Integer,
                                          self.default("n_segments"),
                                          minValue=10, maxValue=1000),
             "over-segmentation size (paper: 100-200)"),
            (QgsProcessingParameterRasterDestination("OUTPUT", self.tr("Segments")),
             "GeoTIFF of segment labels"),
            (QgsProcessingParameterRasterDestination("EDGES", self.tr("Edges"), optional=True,
                                                     createByDefault=False),
             "optional GeoTIFF: edge magnitude and orientation (radians, from east)"),
        ]
        self.add_parameters([params[0], (level_parameter(self.tr), None), *params[1:]])
        self.addOutput(QgsProcessingOutputNumber("N_SEGMENTS", self.tr("Segments made")))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.parameterAsOutputLayer(parameters, "OUTPUT", context)
        edges = self.parameterAsOutputLayer(parameters, "EDGES", context) or None
        result = self.run_job(dict(
            intensity_path=self.parameterAsRasterLayer(parameters, "INPUT", context).source(),
            segments_path=out, level=self.parameterAsInt(parameters, "LEVEL", context),
            n_segments=self.parameterAsInt(parameters, "SEGMENTS", context),
            edges_path=edges), feedback)
        feedback.pushInfo(f"{result['n_segments']} segments")
        return {"OUTPUT": out, "EDGES": edges, "N_SEGMENTS": result["n_segments"]}
