"""APLS: the Average Path Length Similarity of two road networks (Van Etten et al., 2018).

What is computed
----------------
Each network is read as a graph (:func:`gisroads.geo.line_graph`): noded lines
are edges weighted by their length, line ends are nodes.

One half, ``APLS(S → T)``, scores a target network ``T`` against a source network ``S``:

1. Control points on ``S``: every node of ``S``, plus the points cutting each edge of length
   ``L`` into ``ceil(L / node_spacing_m)`` equal parts (so they are at most
   ``node_spacing_m`` apart along every edge).
2. Pairs: every pair of control points that are connected in ``S`` (same connected
   component). When there are more than ``max_pairs``, a uniform random sample of
   ``max_pairs`` distinct pairs is drawn with ``numpy.random.default_rng(seed)``.
3. ``L_S``: the shortest-path length between the two points in ``S``.
4. Snapping: each control point is moved to the nearest point on the lines of ``T`` if that
   is at most ``snap_m`` away; otherwise it is unsnapped. ``L_T`` is the shortest-path length
   between the two snapped points in ``T``, along the edges they lie on and then through the
   graph of ``T`` (exact: a point on an edge may leave it through either end, and two points on
   one edge may also go straight along it).
5. ``term = min(1, |L_S - L_T| / L_S)``, and ``term = 1`` when a point is unsnapped or ``T``
   has no path between them.
6. ``APLS(S → T) = 1 - mean(term)``, and 0 when ``S`` has no pair (an empty network).

``apls_reference_to_extracted`` is ``APLS(reference → extracted)`` (SpaceNet's
"gt → prop": missing roads and broken connections cost), ``apls_extracted_to_reference`` is
``APLS(extracted → reference)`` ("prop → gt": spurious roads and shortcuts cost), and
``apls`` is their harmonic mean (0 when both are 0).

Where this may differ from SpaceNet's own code: control points divide each edge equally
(at most ``node_spacing_m`` apart) instead of being laid from one end; snapped points are
located on the target's lines rather than inserted into its graph as new nodes, which gives
the same path lengths; beyond ``max_pairs`` pairs are sampled, to bound the run time.

References
----------
Van Etten, A., Lindenbaum, D., Bacastow, T. M. (2018). SpaceNet: A Remote Sensing Dataset and
Challenge Series. arXiv:1807.01232.
"""
from __future__ import annotations

import numpy as np
import shapely
from scipy.sparse.csgraph import dijkstra

from ..geo import LineGraph, line_graph
from .buffer import metric_lines, nearest_on_lines, pieces_needed

#: Most entries of one block of the shortest-path matrix (sources x nodes) held at once.
_MAX_DISTANCE_ENTRIES = 1 << 24


def _control_points(graph: LineGraph, spacing_m: float):
    """Edge index, distance along the edge and ``(x, y)`` of every control point."""
    # Each node is represented by its first line end: that edge, at its start or its end.
    _, first_end = np.unique(graph.edges.ravel(), return_index=True)
    node_edge = first_end // 2
    node_along = (first_end % 2) * graph.lengths[node_edge]

    parts = pieces_needed(graph.lengths, spacing_m)
    inner = parts - 1
    inner_edge = np.repeat(np.arange(len(parts)), inner)
    rank = 1 + np.arange(inner.sum()) - np.repeat(np.cumsum(inner) - inner, inner)
    inner_along = rank * (graph.lengths / parts)[inner_edge]
    inner_xy = shapely.get_coordinates(
        shapely.line_interpolate_point(graph.lines[inner_edge], inner_along))

    return (np.concatenate([node_edge, inner_edge]),
            np.concatenate([node_along, inner_along]),
            np.concatenate([graph.nodes, inner_xy]))


def _connected_pairs(component: np.ndarray, max_pairs: int, rng: np.random.Generator):
    """Index pairs ``(i, j)``, ``i != j``, of points sharing a component: all of them, or a
    uniform sample of ``max_pairs`` distinct ones."""
    order = np.argsort(component, kind="stable")
    label = component[order]
    # Pairs are numbered point by point (in component order) over the later points of the
    # same component, so a pair number decodes to its two points without listing them all.
    later = np.searchsorted(label, label, side="right") - np.arange(len(label)) - 1
    total = int(later.sum())
    number = (np.arange(total) if total <= max_pairs
              else np.sort(rng.choice(total, size=max_pairs, replace=False)))
    upto = np.cumsum(later)
    first = np.searchsorted(upto, number, side="right")
    second = first + 1 + number - (upto - later)[first]
    return order[first], order[second]


def _node_distances(graph: LineGraph, sources: np.ndarray, rows: np.ndarray,
                    cols: np.ndarray) -> np.ndarray:
    """``dist[rows, cols]`` of the shortest-path matrix from node ``sources`` to all nodes,
    computed a block of sources at a time to bound memory."""
    adjacency = graph.adjacency()
    block = max(1, _MAX_DISTANCE_ENTRIES // max(len(graph.nodes), 1))
    out = np.empty(rows.shape)
    for start in range(0, len(sources), block):
        dist = dijkstra(adjacency, directed=False, indices=sources[start:start + block])
        inside = (rows >= start) & (rows < start + block)
        out[inside] = dist[rows[inside] - start, cols[inside]]
    return out


def _path_lengths(graph: LineGraph, edge_a, along_a, edge_b, along_b) -> np.ndarray:
    """Shortest-path lengths between points given as (edge, distance along it); inf if none."""
    ends_a, ends_b = graph.edges[edge_a], graph.edges[edge_b]
    to_ends_a = np.stack([along_a, graph.lengths[edge_a] - along_a], axis=1)
    to_ends_b = np.stack([along_b, graph.lengths[edge_b] - along_b], axis=1)
    sources, row = np.unique(ends_a, return_inverse=True)
    row = row.reshape(ends_a.shape)
    # The four routes: (start|end of a's edge) to (start|end of b's edge).
    between = _node_distances(graph, sources, np.repeat(row, 2, axis=1), np.tile(ends_b, 2))
    length = (np.repeat(to_ends_a, 2, axis=1) + between + np.tile(to_ends_b, 2)).min(axis=1)
    same = edge_a == edge_b
    length[same] = np.minimum(length[same], np.abs(along_a - along_b)[same])
    return length


def _one_way(source: LineGraph, target: LineGraph, *, node_spacing_m: float, snap_m: float,
             max_pairs: int, seed: int) -> tuple[float, int]:
    """``APLS(source → target)`` and the number of pairs it averages."""
    if len(source.lines) == 0:
        return 0.0, 0
    edge, along, xy = _control_points(source, node_spacing_m)
    _, component = source.components()
    first, second = _connected_pairs(component[source.edges[edge, 0]], max_pairs,
                                     np.random.default_rng(seed))
    if len(first) == 0:
        return 0.0, 0
    source_length = _path_lengths(source, edge[first], along[first], edge[second],
                                  along[second])
    target_length = np.full(len(first), np.inf)
    if len(target.lines):
        snap_edge, snap_along, _ = nearest_on_lines(shapely.points(xy), target.lines,
                                                    max_distance=snap_m)
        snapped = (snap_edge[first] >= 0) & (snap_edge[second] >= 0)
        a, b = first[snapped], second[snapped]
        target_length[snapped] = _path_lengths(target, snap_edge[a], snap_along[a],
                                               snap_edge[b], snap_along[b])
    # An unsnapped point or a missing path leaves target_length at inf, hence a term of 1.
    term = np.minimum(1.0, np.abs(source_length - target_length) / source_length)
    return float(1.0 - term.mean()), int(len(first))


def apls_score(extracted, reference, *, node_spacing_m: float = 50.0, snap_m: float = 4.0,
                 max_pairs: int = 2000, seed: int = 0) -> dict:
    """APLS of extracted centre lines against reference ones (see the module docstring).

    Parameters
    ----------
    extracted, reference : GeoDataFrame, GeoSeries or sequence of (Multi)LineString
        Centre lines; the input rules of :mod:`gisroads.evaluate.buffer` apply.
    node_spacing_m : float
        Largest spacing of control points along an edge, metres (SpaceNet: 50 m).
    snap_m : float
        Largest distance a control point may move to land on the other network, metres
        (SpaceNet's 4 m buffer).
    max_pairs : int
        Most pairs averaged per direction; beyond it pairs are sampled.
    seed : int
        Seed of the pair sample, so results repeat.

    Returns
    -------
    dict
        ``apls`` (harmonic mean of the two halves), ``apls_reference_to_extracted``,
        ``apls_extracted_to_reference``, ``pairs_reference``, ``pairs_extracted`` (pairs
        averaged in each half), ``node_spacing_m``, ``snap_m``. Scores are in [0, 1]; an
        empty extracted network scores 0.
    """
    ext, ref, _ = metric_lines(extracted, reference)
    ext_graph, ref_graph = line_graph(ext), line_graph(ref)
    options = dict(node_spacing_m=node_spacing_m, snap_m=snap_m, max_pairs=max_pairs,
                   seed=seed)
    to_ext, pairs_ref = _one_way(ref_graph, ext_graph, **options)
    to_ref, pairs_ext = _one_way(ext_graph, ref_graph, **options)
    mean = 2 * to_ext * to_ref / (to_ext + to_ref) if to_ext + to_ref > 0 else 0.0
    return {"apls": float(mean), "apls_reference_to_extracted": to_ext,
            "apls_extracted_to_reference": to_ref, "pairs_reference": pairs_ref,
            "pairs_extracted": pairs_ext, "node_spacing_m": float(node_spacing_m),
            "snap_m": float(snap_m)}
