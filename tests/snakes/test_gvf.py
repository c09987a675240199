"""Gradient vector flow (Xu & Prince 1997) of simple edge maps."""
import numpy as np
import pytest

from gisroads.snakes.gvf import gradient_vector_flow


def test_the_flow_of_a_single_edge_points_towards_it_from_both_sides():
    edge = np.zeros((40, 81))
    edge[:, 40] = 1.0
    u, v = gradient_vector_flow(edge, iterations=400)
    assert np.all(u[:, 25:40] > 0)          # left of the edge: pointing right
    assert np.all(u[:, 41:56] < 0)          # right of it: pointing left
    assert np.allclose(u[:, :40], -u[:, 80:40:-1], atol=1e-9)   # mirror symmetric
    assert np.abs(v).max() < 1e-9
    # the flow reaches beyond the 1-pixel reach of the plain gradient, fading with distance
    assert abs(u[20, 30]) > abs(u[20, 20]) > 0


def test_more_iterations_widen_the_reach_until_the_field_converges():
    edge = np.zeros((3, 61))
    edge[:, 30] = 1.0
    short, _ = gradient_vector_flow(edge, iterations=20)
    long_, _ = gradient_vector_flow(edge, iterations=400)
    assert abs(long_[1, 15]) > 10 * abs(short[1, 15])
    converged, _ = gradient_vector_flow(edge, iterations=20000, tolerance=1e-7)
    again, _ = gradient_vector_flow(edge, iterations=40000, tolerance=1e-8)
    assert np.allclose(converged, again, atol=1e-3)


def test_a_vertical_edge_gives_a_row_flow():
    edge = np.zeros((61, 20))
    edge[30, :] = 1.0
    u, v = gradient_vector_flow(edge)
    assert np.all(v[20:30] > 0) and np.all(v[31:41] < 0) and np.abs(u).max() < 1e-9


def test_a_constant_map_has_no_flow_and_bad_input_is_refused():
    u, v = gradient_vector_flow(np.full((10, 10), 3.0))
    assert not u.any() and not v.any()
    with pytest.raises(ValueError, match="2-D"):
        gradient_vector_flow(np.zeros(10))
    with pytest.raises(ValueError, match="NaN"):
        gradient_vector_flow(np.array([[0.0, np.nan], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="mu"):
        gradient_vector_flow(np.zeros((5, 5)), mu=0.5)
