"""The road-network floor shared by every method: evidence in, a clean connected network out.

Below the methods and above the vectorisers, so no method imports another:

:mod:`gisroads.network.subgraph`
    Gap edges between road-part ends, their weights, and the integer program that keeps one
    link per end (Grote & Rottensteiner 2010, Sec. 2.2), chaining parts into road strings.
:mod:`gisroads.network.junctions`
    Road strings to a network: approximation, duplicates, junction construction and
    significance (Sec. 2.3).
:mod:`gisroads.network.cuts`
    Cuts across roads closed in a road mask before its skeleton: two road ends of the same
    width facing each other across open ground.
:mod:`gisroads.network.rasters`
    Any road raster (a mask or a probability map) to road parts and, through the two stages
    above, to the network contract.

The entry point is :func:`raster_to_network`; its stages, the network generation and their
options objects are importable from here too, each from its module on first use, so that
``import gisroads.network`` stays cheap.
"""
from typing import TYPE_CHECKING

from .. import _lazy_exports

__all__ = [
    "ContextOptions", "GapOptions", "NetworkOptions", "PartOptions", "WeightOptions",
    "link_gaps", "link_road_parts", "parts_to_network", "raster_to_network", "road_mask",
    "road_probability", "skeleton_parts", "strings_to_network", "with_missing_roads",
]

__getattr__, __dir__ = _lazy_exports(__name__, {
    **dict.fromkeys(["PartOptions", "link_gaps", "parts_to_network", "raster_to_network",
                     "road_mask", "road_probability", "skeleton_parts",
                     "with_missing_roads"], ".rasters"),
    **dict.fromkeys(["ContextOptions", "GapOptions", "WeightOptions", "link_road_parts"],
                    ".subgraph"),
    **dict.fromkeys(["NetworkOptions", "strings_to_network"], ".junctions"),
})

if TYPE_CHECKING:
    from .junctions import NetworkOptions, strings_to_network
    from .rasters import (PartOptions, link_gaps, parts_to_network, raster_to_network,
                          road_mask, road_probability, skeleton_parts)
    from .subgraph import ContextOptions, GapOptions, WeightOptions, link_road_parts
