"""Topology metrics: connected components and junctions of centre-line networks.

A network is read as a graph (:func:`gisroads.geo.line_graph`): the lines are noded (split
at every crossing and shared vertex, overlaps dissolved, :func:`gisroads.geo.node_lines`),
every noded line is an edge weighted by its length, and line end points closer than
``snap_m`` are one node. A node's degree is the
number of line ends meeting there; junctions are nodes of degree 3 or more, as in
:func:`gisroads.geo.junctions_from_lines`.
"""
from __future__ import annotations

import numpy as np
import shapely
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..geo import line_graph
from .buffer import align_to_reference, metric_lines, typed_parts


def _match_count(a: np.ndarray, b: np.ndarray, radius_m: float) -> int:
    """Size of the one-to-one matching of point sets ``a`` and ``b`` (``(n, 2)`` arrays).

    Only pairs at most ``radius_m`` apart can match. The matching has the most pairs possible
    and, among those, the least total distance.
    """
    if len(a) == 0 or len(b) == 0:
        return 0
    near = cKDTree(a).sparse_distance_matrix(cKDTree(b), radius_m, output_type="ndarray")
    i, j, d = near["i"], near["j"], near["v"]
    # Points compete only within clusters of mutually reachable points: solve each cluster
    # on its own, so the assignment matrices stay small however large the networks are.
    n = len(a)
    pairs = coo_matrix((np.ones(len(i)), (i, n + j)), shape=(n + len(b),) * 2)
    _, cluster = connected_components(pairs, directed=False)
    cluster = cluster[i]
    size = np.bincount(cluster)
    matches = int(np.count_nonzero(size == 1))
    for label in np.flatnonzero(size > 1):
        member = cluster == label
        rows, row = np.unique(i[member], return_inverse=True)
        cols, col = np.unique(j[member], return_inverse=True)
        # A cost above any sum of in-radius distances makes the assignment maximise the
        # number of in-radius pairs first; pairs at that cost are then dropped.
        out_of_reach = (min(len(rows), len(cols)) + 1) * (radius_m + 1.0)
        cost = np.full((len(rows), len(cols)), out_of_reach)
        cost[row.reshape(-1), col.reshape(-1)] = d[member]
        r, c = linear_sum_assignment(cost)
        matches += int(np.count_nonzero(cost[r, c] < out_of_reach))
    return matches


def _junction_scores(ext_xy: np.ndarray, ref_xy: np.ndarray, radius_m: float) -> dict:
    matches = _match_count(ext_xy, ref_xy, radius_m)
    return {
        "junctions_extracted": int(len(ext_xy)),
        "junctions_reference": int(len(ref_xy)),
        "junction_matches": matches,
        "junction_precision": matches / len(ext_xy) if len(ext_xy) else float("nan"),
        "junction_recall": matches / len(ref_xy) if len(ref_xy) else float("nan"),
        "junction_radius_m": float(radius_m),
    }


def junction_metrics(extracted_points, reference_points, *, radius_m: float = 10.0) -> dict:
    """Precision and recall of extracted junction points against reference junctions.

    Junctions are matched one to one; a pair matches only if at most ``radius_m`` apart. The
    matching has the most pairs possible and, among those, the least total distance (an
    optimal assignment, :func:`scipy.optimize.linear_sum_assignment`, not a greedy one).

    Parameters
    ----------
    extracted_points, reference_points : GeoDataFrame, GeoSeries or sequence of (Multi)Point
        Junction layers; the CRS rules of :mod:`gisroads.evaluate.buffer` apply.
    radius_m : float
        Matching radius in metres.

    Returns
    -------
    dict
        ``junctions_extracted``, ``junctions_reference`` (counts), ``junction_matches``,
        ``junction_precision = matches / junctions_extracted`` (NaN if none extracted),
        ``junction_recall = matches / junctions_reference``, ``junction_radius_m``.
    """
    _, ref, (ext,) = align_to_reference(reference_points, extracted_points)
    point = (shapely.GeometryType.POINT,)
    ext_xy = shapely.get_coordinates(typed_parts(ext, point, layer="extracted"))
    ref_xy = shapely.get_coordinates(typed_parts(ref, point, layer="reference"))
    return _junction_scores(ext_xy, ref_xy, radius_m)


def topology_metrics(extracted, reference, *, junction_radius_m: float = 10.0,
                     reference_junctions=None) -> dict:
    """Connected components and junction agreement of two centre-line networks.

    Parameters
    ----------
    extracted, reference : GeoDataFrame, GeoSeries or sequence of (Multi)LineString
        Centre lines; the input rules of :mod:`gisroads.evaluate.buffer` apply.
    junction_radius_m : float
        Radius for matching junctions, metres (see :func:`junction_metrics`).
    reference_junctions : GeoDataFrame, GeoSeries or sequence of Point, optional
        The reference's own junctions (digitised with it); by default its nodes of degree
        >= 3, which miss the junctions its lines do not share a vertex at.

    Returns
    -------
    dict
        ``components_extracted``, ``components_reference``: connected components of the
        noded networks (0 for an empty network); the keys of :func:`junction_metrics` for
        their junctions (nodes of degree >= 3; the reference's given ones).
        ``junction_recall`` is NaN when the reference has no junction.
    """
    ext, ref, _ = metric_lines(extracted, reference)
    scores = {}
    junctions = {}
    for name, lines in (("extracted", ext), ("reference", ref)):
        graph = line_graph(lines)
        scores[f"components_{name}"] = graph.components()[0]
        junctions[name] = graph.nodes[graph.degree >= 3]
    if reference_junctions is not None:
        _, _, (points,) = align_to_reference(reference, reference_junctions)
        junctions["reference"] = shapely.get_coordinates(typed_parts(
            points, (shapely.GeometryType.POINT,), layer="reference junctions"))
    scores.update(_junction_scores(junctions["extracted"], junctions["reference"],
                                   junction_radius_m))
    return scores
