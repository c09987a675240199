"""Branches of a road network that lead only into an area (beyond the papers).

A car park's access is paved, kerbed and as wide as a street, so nothing along it tells it
from a road; where it leads does. Cut the network at a bridge (a line whose removal splits
it) and the smaller side is a branch: a driveway, a cul-de-sac, a car park's entrance with
its island and aisles. A branch is a service way when it ends only in the area (a car park
known by its rows of parked cars): every line end of the branch that meets no other line
lies in the area. A branch with an end elsewhere (a street going on past the data, a
cul-de-sac) stays.
"""
from __future__ import annotations

import numpy as np
import shapely

from ..geo import _end_nodes


def branches_into(lines, area, *, snap_m: float = 0.5) -> np.ndarray:
    """Which lines belong to a branch of the network that leads only into ``area``.

    Parameters
    ----------
    lines : array_like of LineString
        The network's centre lines, noded at their junctions (a line runs from junction or
        end to junction or end, as :func:`gisroads.network.raster_to_network` gives them).
    area : shapely geometry
        Where a branch may end (e.g. the car parks around the aisles taken out of a network).
    snap_m : float
        Line ends closer than this are one node, metres.

    Returns
    -------
    ndarray of bool
        One per line: it lies in such a branch or is the bridge that joins one.

    Examples
    --------
    A street with a drive into a car park and a side street:

    >>> from shapely import LineString, box
    >>> from gisroads.network.branches import branches_into
    >>> lines = [LineString([(0, 0), (20, 0)]), LineString([(20, 0), (50, 0)]),
    ...          LineString([(50, 0), (100, 0)]), LineString([(50, 0), (50, 30)]),
    ...          LineString([(20, 0), (20, -40)])]
    >>> car_park = box(40, 25, 70, 50)
    >>> [bool(b) for b in branches_into(lines, car_park)]
    [False, False, False, True, False]
    """
    import networkx as nx  # a graph library is a cost only the car-park rule should pay

    lines = np.asarray(lines, dtype=object)
    taken = np.zeros(len(lines), dtype=bool)
    if len(lines) == 0 or area is None or area.is_empty:
        return taken
    nodes, node_of_end = _end_nodes(lines, snap_m)
    edges = node_of_end.reshape(2, -1).T
    points = shapely.points(nodes)
    free = np.bincount(edges.ravel(), minlength=len(nodes)) == 1
    in_area = shapely.intersects(points, area)
    graph = nx.MultiGraph()
    graph.add_nodes_from(range(len(nodes)))
    graph.add_edges_from(edges.tolist())
    index_of = {pair: i for i, pair in enumerate(map(tuple, np.sort(edges, axis=1).tolist()))}
    bridges = np.array(sorted(index_of[tuple(sorted(pair))] for pair in nx.bridges(graph)),
                       dtype=np.int64)
    if len(bridges) == 0:
        return taken
    # the pieces the bridges join, and the forest of pieces they make
    inner = np.ones(len(lines), dtype=bool)
    inner[bridges] = False
    pieces = nx.Graph()
    pieces.add_nodes_from(range(len(nodes)))
    pieces.add_edges_from(edges[inner].tolist())
    piece = np.empty(len(nodes), dtype=np.int64)
    for label, members in enumerate(nx.connected_components(pieces)):
        piece[list(members)] = label
    count = piece.max() + 1
    line_piece = piece[edges[:, 0]]
    line_piece[bridges] = -1
    lengths = shapely.length(lines)
    # per piece: free ends in the area, free ends elsewhere, lines that touch the area, length
    own = np.stack([np.bincount(piece, weights=free & in_area, minlength=count),
                    np.bincount(piece, weights=free & ~in_area, minlength=count),
                    np.bincount(line_piece[inner], weights=shapely.intersects(
                        lines[inner], area), minlength=count),
                    np.bincount(line_piece[inner], weights=lengths[inner], minlength=count)],
                   axis=1)
    bridge_own = np.stack([np.zeros(len(lines)), np.zeros(len(lines)),
                           shapely.intersects(lines, area), lengths], axis=1)
    forest = nx.Graph()
    forest.add_nodes_from(range(count))
    for line in bridges.tolist():
        forest.add_edge(*piece[edges[line]].tolist(), line=line)
    beneath = own.copy()   # a piece and all below it, the bridges down to them included
    for members in nx.connected_components(forest):
        root = min(members)
        below = nx.dfs_tree(forest, root)
        for child in nx.dfs_postorder_nodes(below, root):
            for grandchild in below.successors(child):
                beneath[child] += beneath[grandchild] + bridge_own[
                    forest.edges[child, grandchild]["line"]]
        whole = beneath[root]
        for parent, child in below.edges():
            line = forest.edges[parent, child]["line"]
            above = whole - beneath[child] - bridge_own[line]
            child_side = beneath[child][3] <= above[3]
            ends_in, ends_elsewhere, touched, _ = beneath[child] if child_side else above
            if ends_in and not ends_elsewhere and touched + bridge_own[line][2]:
                under = nx.descendants(below, child) | {child}
                side = under if child_side else set(members) - under
                lines_of = np.isin(line_piece, list(side))
                lines_of[[data["line"] for a, b, data in forest.edges(side, data=True)
                          if a in side and b in side]] = True
                taken |= lines_of
                taken[line] = True
    return taken
