"""Image features for road extraction.

- :mod:`.edges`: edge magnitude and edge-line orientation from local energy (Morrone & Owens
  1987), orientation histograms and dominant road orientations (Zhu & Mordohai 2009, 4.2-4.3);
- :mod:`.rectangles`: the rectangular boundary and interior road filters (Zhu & Mordohai 2009,
  section 4.2).
"""
from .edges import dominant_orientations, fill_nearest, local_energy, orientation_histogram

__all__ = ["dominant_orientations", "fill_nearest", "local_energy", "orientation_histogram"]
