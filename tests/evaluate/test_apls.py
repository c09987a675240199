import numpy as np
import pytest
from shapely import LineString

from gisroads.evaluate import apls_score
from gisroads.evaluate.apls import _connected_pairs, _path_lengths
from gisroads.evaluate.topology import line_graph


def grid(n=4, spacing=100.0):
    span = (n - 1) * spacing
    return ([LineString([(0, k * spacing), (span, k * spacing)]) for k in range(n)]
            + [LineString([(k * spacing, 0), (k * spacing, span)]) for k in range(n)])


def test_identical_networks_score_one():
    m = apls_score(grid(), grid())
    assert m["apls"] == pytest.approx(1.0, abs=1e-9)
    assert m["apls_reference_to_extracted"] == pytest.approx(1.0, abs=1e-9)
    assert m["apls_extracted_to_reference"] == pytest.approx(1.0, abs=1e-9)


def test_gap_in_a_straight_road_by_hand():
    # Reference: x = 0..200, one edge cut into 4 parts of 50 m -> control points at
    # x = 0, 50, 100, 150, 200, all 10 pairs connected. The proposal has a gap x = 90..110.
    # Reference -> proposal: x = 100 is 10 m from the proposal (> 4 m snap), so its 4 pairs
    # score term 1; of the other 6 pairs, (0, 50) and (150, 200) are exact (term 0) and the
    # 4 crossing the gap have no path (term 1): 1 - 8/10 = 0.2.
    # Proposal -> reference: two 90 m edges of 2 parts each, control points 0, 45, 90 and
    # 110, 155, 200; 3 + 3 connected pairs, all exact in the reference: 1.0.
    # APLS = 2 * 0.2 * 1 / 1.2 = 1/3.
    proposal = [LineString([(0, 0), (90, 0)]), LineString([(110, 0), (200, 0)])]
    m = apls_score(proposal, [LineString([(0, 0), (200, 0)])])
    assert m["pairs_reference"] == 10 and m["pairs_extracted"] == 6
    assert m["apls_reference_to_extracted"] == pytest.approx(0.2, abs=1e-9)
    assert m["apls_extracted_to_reference"] == pytest.approx(1.0, abs=1e-9)
    assert m["apls"] == pytest.approx(1 / 3, abs=1e-9)


def test_longer_detour_by_hand():
    # Reference: the 100 m straight road A(0, 0) - B(100, 0) -> control points A, B and the
    # midpoint: pairs A-mid, mid-B (50 m), A-B (100 m).
    # Proposal: the same road through a bend, one 141.42 m edge A - (50, 50) - B. A and B snap
    # to themselves; the midpoint is 35.36 m from the proposal and does not snap.
    # Reference -> proposal: terms 1, 1 (unsnapped) and |100 - 141.42| / 100:
    # 1 - (2 + 0.4142) / 3.
    # Proposal -> reference: the edge is cut into 3 parts of 47.14 m -> control points A, B,
    # (33.3, 33.3), (66.7, 33.3); the inner two are > 4 m from the road and do not snap, so of
    # the 6 pairs only A-B scores, |141.42 - 100| / 141.42; the other 5 are 1.
    reference = [LineString([(0, 0), (100, 0)])]
    proposal = [LineString([(0, 0), (50, 50), (100, 0)])]
    m = apls_score(proposal, reference)
    bent = 100 * np.sqrt(2)
    assert m["apls_reference_to_extracted"] == pytest.approx(
        1 - (2 + (bent - 100) / 100) / 3, abs=1e-9)
    assert m["apls_extracted_to_reference"] == pytest.approx(
        1 - (5 + (bent - 100) / bent) / 6, abs=1e-9)


def test_removing_a_bridge_edge_lowers_the_score():
    reference = [LineString([(0, 0), (300, 0)]), LineString([(300, 0), (600, 0)]),
                 LineString([(600, 0), (900, 0)])]
    m = apls_score([reference[0], reference[2]], reference)
    assert 0.1 < m["apls"] < 0.9
    assert m["apls_extracted_to_reference"] == pytest.approx(1.0, abs=1e-9)


def test_empty_proposal_scores_zero():
    m = apls_score([], grid())
    assert m["apls"] == m["apls_reference_to_extracted"] == 0.0
    assert m["apls_extracted_to_reference"] == 0.0 and m["pairs_extracted"] == 0


def test_pairs_are_sampled_reproducibly():
    a = apls_score(grid(), grid(), max_pairs=50, seed=3)
    b = apls_score(grid(), grid(), max_pairs=50, seed=3)
    assert a == b and a["pairs_reference"] == 50


def test_connected_pairs_enumerate_and_sample():
    component = np.array([0, 0, 1, 0, 1])
    first, second = _connected_pairs(component, 100, np.random.default_rng(0))
    assert sorted(zip(first.tolist(), second.tolist())) == [(0, 1), (0, 3), (1, 3), (2, 4)]
    first, second = _connected_pairs(component, 3, np.random.default_rng(0))
    pairs = set(zip(first.tolist(), second.tolist()))
    assert len(pairs) == 3 and pairs <= {(0, 1), (0, 3), (1, 3), (2, 4)}


def test_path_lengths_take_the_shorter_way_round():
    # A 300 m arc and a 100 m chord between the same nodes: two points 10 m from either end
    # of the arc are 280 m apart along it but 10 + 100 + 10 = 120 m via the chord.
    arc = LineString([(0, 0), (0, 100), (100, 100), (100, 0)])
    chord = LineString([(0, 0), (100, 0)])
    graph = line_graph([arc, chord])
    on_arc = int(np.flatnonzero(graph.lengths == 300)[0])
    edge = np.array([on_arc])
    assert _path_lengths(graph, edge, np.array([10.0]), edge, np.array([290.0])) == [120.0]
    assert _path_lengths(graph, edge, np.array([10.0]), edge, np.array([60.0])) == [50.0]
