"""Road networks from airborne LiDAR (Zhu & Mordohai 2009).

The entry point is :func:`extract_roads`: a LAS/LAZ file (or several) to a road network,
tile by tile, with the paper's intensity cue or the road evidence of every cue the cloud
carries (:func:`evidence_raster`). The stages are callable alone: multi-level ground
planes (:func:`ground_planes`), intensity images (:func:`intensity_images`), one tile of
Algorithm 1 (:func:`extract_tile`), the road evidence of a cloud (:func:`road_evidence`),
city blocks of a road likelihood (:func:`city_blocks`, section 5), road points classified
back in 3D (:func:`tag_road_points`) and the naive baseline (:func:`baseline_roads`).

The names are imported from their modules on first use, so that ``import gisroads.lidar``
stays cheap.
"""
from typing import TYPE_CHECKING

from .. import _lazy_exports

__all__ = [
    "EvidenceMosaic", "GroundPlanes", "IntensityImages", "LidarOptions", "LidarRoads",
    "TiledRoads", "baseline_roads", "city_blocks", "evidence_raster", "extract_roads",
    "extract_tile", "ground_planes", "image_grid", "intensity_images", "road_evidence",
    "road_likelihood", "tag_road_points", "write_intensity_images",
]

__getattr__, __dir__ = _lazy_exports(__name__, {
    **dict.fromkeys(["EvidenceMosaic", "LidarOptions", "LidarRoads", "TiledRoads",
                     "evidence_raster", "extract_roads", "extract_tile"], ".pipeline"),
    **dict.fromkeys(["city_blocks", "road_likelihood"], ".blocks"),
    **dict.fromkeys(["GroundPlanes", "ground_planes"], ".ground"),
    **dict.fromkeys(["IntensityImages", "image_grid", "intensity_images",
                     "write_intensity_images"], ".intensity"),
    "baseline_roads": ".baseline",
    "road_evidence": ".evidence",
    "tag_road_points": ".tagging",
})

if TYPE_CHECKING:
    from .baseline import baseline_roads
    from .blocks import city_blocks, road_likelihood
    from .evidence import road_evidence
    from .ground import GroundPlanes, ground_planes
    from .intensity import IntensityImages, image_grid, intensity_images, write_intensity_images
    from .pipeline import (EvidenceMosaic, LidarOptions, LidarRoads, TiledRoads,
                           evidence_raster, extract_roads, extract_tile)
    from .tagging import tag_road_points
