"""Road pieces to the road-network output contract (:class:`gisroads.geo.RoadNetwork`).

:func:`ribbons_to_network` for ribbons given as centre lines with widths: chained, snapped,
noded and partitioned (see :mod:`gisroads.vectorize.ribbons`); :func:`chain_lines` alone
chains pieces (the LiDAR rectangles' mid-lines, :func:`rectangle_centrelines`) for the
network stage.
"""
from .ribbons import (ANGLE_TOL_DEG, JOIN_GAP_M, MIN_LENGTH_M, SMOOTH_M, chain_lines,
                      rectangle_centrelines, ribbon_areas, ribbons_to_network)

__all__ = ["ANGLE_TOL_DEG", "JOIN_GAP_M", "MIN_LENGTH_M", "SMOOTH_M", "chain_lines",
           "rectangle_centrelines", "ribbon_areas", "ribbons_to_network"]
