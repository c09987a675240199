"""Ribbon snakes on hand-made attractor maps with known corridors."""
import numpy as np
import pytest
from affine import Affine

from gisroads.geo import GeoRaster
from gisroads.snakes.gvf import gradient_vector_flow
from gisroads.snakes.ribbon import (initial_ribbon, internal_matrix, resample_line,
                                    ribbon_snake)

CELL = 0.5


def corridor(left_x=4.0, right_x=-4.0, *, gap=None, size=(120.0, 60.0)):
    """Attractor map of two kerb ridges (Gaussian, 0.4 m) along y at x = left_x and right_x,
    optionally with a gap (y0, y1) in the left one."""
    height, width = size
    transform = Affine(CELL, 0, -width / 2, 0, -CELL, height / 2)
    rows, cols = int(height / CELL), int(width / CELL)
    x = transform.c + (np.arange(cols) + 0.5) * CELL
    y = transform.f - (np.arange(rows) + 0.5) * CELL
    left = np.exp(-(x - left_x) ** 2 / (2 * 0.4 ** 2))[None, :] * np.ones((rows, 1))
    if gap is not None:
        left[(y > gap[0]) & (y < gap[1])] = 0.0
    right = np.exp(-(x - right_x) ** 2 / (2 * 0.4 ** 2))[None, :] * np.ones((rows, 1))
    return GeoRaster(left + right, transform, None), x, y


def map_line(x0=3.0):
    """The map: a south-to-north line at x = x0 (left normal points west)."""
    return np.array([[x0, -50.0], [x0, 50.0]])


def test_internal_matrix_is_pentadiagonal_and_ignores_shifts_and_slopes():
    a = internal_matrix(10, alpha=0.0, beta=1.0).toarray()
    assert np.allclose(a, a.T) and np.allclose(a[np.abs(np.subtract.outer(
        np.arange(10), np.arange(10))) > 2], 0)
    assert np.allclose(a @ np.ones(10), 0) and np.allclose(a @ np.arange(10.0), 0)
    assert np.allclose(a[4, 2:7], [1, -4, 6, -4, 1])


def test_resample_line_every_metre_with_left_normals():
    points, normals = resample_line([[0, 0], [10, 0]], 1.0)
    assert len(points) == 11 and np.allclose(normals, [0, 1])
    with pytest.raises(ValueError, match="two distinct"):
        resample_line([[1, 1], [1, 1]])


def test_a_ribbon_started_3_m_off_an_8_m_corridor_converges_to_it():
    attractor, _, _ = corridor()
    u, v = gradient_vector_flow(attractor.data)
    # map line 3 m east of the corridor centre: the centre lies 3 m to its left (west)
    centre, half, converged = ribbon_snake(u, v, attractor.transform, map_line(3.0),
                                           width0_m=8.0)
    assert converged
    assert np.abs(centre[:, 0] - 0.0).max() < 0.5
    assert np.abs(2 * half - 8.0).max() < 0.5
    assert np.allclose(centre[:, 1], np.linspace(-50, 50, 101))


def test_initial_ribbon_finds_the_corridor_from_a_one_lane_start_where_gvf_alone_fails():
    attractor, _, _ = corridor()
    u, v = gradient_vector_flow(attractor.data)
    line = map_line(3.0)
    # the paper's start (1 lane wide on the map line): both sides fall to the near kerb
    _, half, _ = ribbon_snake(u, v, attractor.transform, line, width0_m=3.66)
    assert np.median(2 * half) < 4.0
    shift, half0 = initial_ribbon(attractor, line)
    assert np.allclose(shift, 3.0, atol=0.5)   # centre 3 m to the line's left (west)
    assert np.allclose(2 * half0, 8.0, atol=0.5)
    centre, half, converged = ribbon_snake(u, v, attractor.transform, line,
                                           width0_m=2 * half0, shift0_m=shift)
    assert converged
    assert np.abs(centre[:, 0]).max() < 0.5 and np.abs(2 * half - 8.0).max() < 0.5


@pytest.mark.parametrize("gap_m", [6.0, 12.0])
def test_rigidity_bridges_a_gap_in_one_kerb(gap_m):
    attractor, _, _ = corridor(gap=(-gap_m / 2, gap_m / 2))
    u, v = gradient_vector_flow(attractor.data)
    centre, half, _ = ribbon_snake(u, v, attractor.transform, map_line(1.0), width0_m=7.0)
    west, east = centre[:, 0] - half, centre[:, 0] + half
    assert np.abs(east - 4.0).max() < 0.6 and np.abs(west + 4.0).max() < 0.6


def test_an_attractor_free_field_leaves_the_ribbon_where_it_started():
    empty = np.zeros((100, 100))
    transform = Affine(CELL, 0, -25, 0, -CELL, 25)
    centre, half, converged = ribbon_snake(empty, empty, transform, [[0, -20], [0, 20]],
                                           width0_m=6.0, shift0_m=1.0)
    assert converged and np.allclose(centre[:, 0], -1.0) and np.allclose(half, 3.0)


def test_ribbon_snake_refuses_bad_input():
    z = np.zeros((10, 10))
    with pytest.raises(ValueError, match="2-D"):
        ribbon_snake(z, np.zeros((10, 11)), Affine.identity(), [[0, 0], [5, 0]], width0_m=3)
    with pytest.raises(ValueError, match="width0_m"):
        ribbon_snake(z, z, Affine.identity(), [[0, 0], [5, 0]], width0_m=-1)
