"""Road networks from aerial imagery (Grote & Rottensteiner): segments, road parts, subgraphs.

The entry point is :func:`extract_image_roads`: an image (RGB, CIR or panchromatic, NIR
and a DSM optional) to a road network, through the papers' stages or the learned road
probability (:func:`road_probability`) and the shared network stage. The naive baseline
(:func:`baseline_roads`) and its road-colour cue (:func:`road_colour_mask`) measure it.

The names are imported from their modules on first use, so that ``import gisroads.imagery``
stays cheap.
"""
from typing import TYPE_CHECKING

from .. import _lazy_exports

__all__ = [
    "ImageOptions", "ImageRoads", "baseline_roads", "extract_image_roads", "road_colour_mask",
    "road_probability",
]

__getattr__, __dir__ = _lazy_exports(__name__, {
    **dict.fromkeys(["ImageOptions", "ImageRoads", "extract_image_roads", "road_probability"],
                    ".pipeline"),
    **dict.fromkeys(["baseline_roads", "road_colour_mask"], ".baseline"),
})

if TYPE_CHECKING:
    from .baseline import baseline_roads, road_colour_mask
    from .pipeline import ImageOptions, ImageRoads, extract_image_roads, road_probability
