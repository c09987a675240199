"""Road pieces to the road-network output contract (:class:`gisroads.geo.RoadNetwork`).

:func:`rectangles_to_network` for Zhu & Mordohai's road rectangles, :func:`ribbons_to_network`
for ribbons given as centre lines with widths; both chain, snap, node and partition the same
way (see :mod:`gisroads.vectorize.ribbons`).
"""
from .ribbons import (ANGLE_TOL_DEG, JOIN_GAP_M, MIN_LENGTH_M, SMOOTH_M, rectangle_centrelines,
                      rectangles_to_network, ribbon_areas, ribbons_to_network)

__all__ = ["ANGLE_TOL_DEG", "JOIN_GAP_M", "MIN_LENGTH_M", "SMOOTH_M", "rectangle_centrelines",
           "rectangles_to_network", "ribbon_areas", "ribbons_to_network"]
