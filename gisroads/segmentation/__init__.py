"""Image and graph segmentation.

- :mod:`.ncut`: normalized cuts (Shi & Malik 2000) with Yu & Shi's discretisation, on any
  sparse affinity graph (:func:`.ncut.ncut`) and, over SLIC superpixels, on images
  (intensity, bands, intervening edges, extra pairwise factors).

The grouping of an image's segments (Grote & Rottensteiner 2010, 2.1.2) is an imagery
stage: :mod:`gisroads.imagery.grouping`.

The graph function ``ncut`` is not re-exported here, so that ``gisroads.segmentation.ncut``
stays the module.
"""
from .ncut import (intervening_edge_strength, ncut_segmentation, segment_boundaries,
                   superpixel_graph)

__all__ = ["intervening_edge_strength", "ncut_segmentation", "segment_boundaries",
           "superpixel_graph"]
