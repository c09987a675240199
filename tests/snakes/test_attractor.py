"""Attractor map: curb detector, extent term and their sum on a grid (Boyko & Funkhouser 2.3)."""
import numpy as np
import pytest

from gisroads.snakes.attractor import (LANE_M, attractor_map, curb_response, drop_off_edges,
                                       extent_term, pca_normals, step_weight)


def kerb_cloud(step_m=0.15, noise_m=0.0, spacing_m=0.2, seed=0):
    """A 20 x 20 m patch of points, flat road for y < 0, raised by ``step_m`` for y >= 0."""
    rng = np.random.default_rng(seed)
    g = np.arange(-10, 10, spacing_m)
    x, y = np.meshgrid(g, g)
    x = x.ravel() + rng.uniform(-0.05, 0.05, x.size)
    y = y.ravel() + rng.uniform(-0.05, 0.05, y.size)
    z = np.where(y >= 0, step_m, 0.0) + rng.normal(0, noise_m, x.size) if noise_m else \
        np.where(y >= 0, step_m, 0.0)
    return np.column_stack([x, y, z])


def test_pca_normals_of_a_tilted_plane_are_exact():
    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 5, (300, 2))
    xyz = np.column_stack([xy, 0.5 * xy[:, 0]])       # z = x / 2
    normals, neighbours = pca_normals(xyz)
    expected = np.array([-0.5, 0.0, 1.0]) / np.sqrt(1.25)
    assert neighbours.shape == (300, 20)
    assert np.allclose(normals, expected, atol=1e-9)


def test_step_weights_follow_equations_2_to_4():
    dh = np.array([0.05, 0.10, 0.15, 0.20, 0.25])
    assert np.array_equal(step_weight(dh, "none"), np.ones(5))
    assert np.array_equal(step_weight(dh, "step"), [0, 1, 1, 1, 0])
    assert np.allclose(step_weight(dh, "exp"), np.exp(-(dh - 0.15) ** 2 / (2 * 0.05 ** 2)))
    with pytest.raises(ValueError, match="curb detector"):
        step_weight(dh, "sobel")


@pytest.mark.parametrize("detector", ["exp", "step", "none"])
def test_a_15_cm_kerb_fires_on_the_kerb_line_and_not_on_flat_road(detector):
    xyz = kerb_cloud(noise_m=0.01)
    c = curb_response(xyz, detector=detector)
    on_kerb = np.abs(xyz[:, 1]) < 0.25
    flat = np.abs(xyz[:, 1]) > 2.0
    assert c[on_kerb].mean() > 0.5
    assert c[flat].mean() < 0.05
    assert c.min() >= 0 and c.max() <= 1


def test_the_step_detector_ignores_a_40_cm_wall_foot_and_the_exp_detector_downweights_it():
    xyz = kerb_cloud(step_m=0.40)
    on_step = np.abs(xyz[:, 1]) < 0.25
    assert curb_response(xyz, detector="step")[on_step].mean() < 0.05
    exp = curb_response(xyz, detector="exp")[on_step].mean()
    kerb = curb_response(kerb_cloud(step_m=0.15), detector="exp")[on_step].mean()
    assert exp < 0.5 * kerb


def test_the_raw_normal_term_is_small_from_the_air_and_scaling_restores_it():
    xyz = kerb_cloud(noise_m=0.01)
    on_kerb = np.abs(xyz[:, 1]) < 0.25
    raw = curb_response(xyz, detector="none", scale_tilt=False)[on_kerb].mean()
    assert 0.005 < raw < 0.2
    assert curb_response(xyz, detector="none")[on_kerb].mean() > 3 * raw


def test_curb_response_rejects_bad_input():
    with pytest.raises(ValueError, match="shape"):
        curb_response(np.zeros((30, 2)))
    with pytest.raises(ValueError, match="at least"):
        curb_response(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="curb detector"):
        curb_response(kerb_cloud(), detector="canny")


def test_extent_term_is_one_between_one_and_six_lanes():
    line = np.array([[0.0, -100.0], [0.0, 100.0]])
    x = np.array([0.0, 3.0, 3.7, 10.0, -21.9, 22.0, 40.0])
    assert np.array_equal(extent_term(x, np.zeros_like(x), line), [0, 0, 1, 1, 1, 0, 0])
    assert LANE_M == 3.66


def test_attractor_map_peaks_on_the_kerb_and_carries_the_extent_term():
    xyz = kerb_cloud(noise_m=0.01)
    xyz[:, 1] += 5.0                                   # kerb at y = 5, map line at y = 0
    line = np.array([[-10.0, 0.0], [10.0, 0.0]])
    a = attractor_map(xyz, line, cell_m=0.5, crs="EPSG:32633", drop_off_weight=0.0)
    assert a.pixel_size == 0.5 and a.crs is not None
    rows, cols = a.shape
    y = a.transform.f + (np.arange(rows) + 0.5) * a.transform.e
    x = a.transform.c + (np.arange(cols) + 0.5) * a.transform.a
    inner = (x > -8) & (x < 8)
    profile = a.data[:, inner].mean(axis=1)
    assert abs(y[np.argmax(profile)] - 5.0) <= 0.5
    assert profile.max() > 0.2 + 0.4
    flat = (y > 6.5) & (y < 9.5)      # raised flat sidewalk inside the extent band
    assert np.allclose(profile[flat], 0.2, atol=0.05)
    near = np.abs(y) < 3.5            # closer than a lane: e = 0, flat road: c = 0
    assert profile[near].max() < 0.05


def test_drop_off_edges_outline_a_deck_and_ignore_a_parked_car():
    counts = np.zeros((40, 60), int)
    counts[10:30, :] = 1                 # an 8 m deck (0.4 m cells) across the grid
    counts[12:16, 20:25] = 0             # a 1.6 x 2 m car: no point under it
    counts[::3, ::2] = 0                 # sparse sampling
    edges = drop_off_edges(counts, 0.4)
    assert edges[10].all() and edges[29].all()          # both deck edges
    assert not edges[11:29].any()                       # nothing inside, car included
    assert not edges[:10].any() and not edges[30:].any()


def test_attractor_map_marks_a_kerbless_deck_edge_but_not_the_subclouds_reach():
    rng = np.random.default_rng(3)
    xy = rng.uniform([-30, -4], [30, 4], (6000, 2))      # an 8 m deck, flat, no kerb
    xyz = np.column_stack([xy, np.full(len(xy), 7.0)])
    line = np.array([[-30.0, 2.0], [30.0, 2.0]])          # map 2 m off the deck's middle
    a = attractor_map(xyz, line, cell_m=0.5)
    rows, cols = a.shape
    y = a.transform.f + (np.arange(rows) + 0.5) * a.transform.e
    x = a.transform.c + (np.arange(cols) + 0.5) * a.transform.a
    profile = a.data[:, (x > -20) & (x < 20)].mean(axis=1)
    assert abs(y[np.argmax(np.where(y > 0, profile, 0))] - 4.0) <= 0.5
    assert abs(y[np.argmax(np.where(y < 0, profile, 0))] + 4.0) <= 0.5
    assert profile[np.abs(y) < 3].max() < 0.3
    plain = attractor_map(xyz, line, cell_m=0.5, drop_off_weight=0.0)
    assert plain.data.max() <= 0.2 + 1e-6 + 0.05


def test_sparse_kerb_is_found_by_the_ground_step_where_the_normals_barely_see_it():
    """At an airborne density (about 4 points/m2, 2 cm noise) a 15 cm kerb tilts the point
    normals little; the lowest point per cell steps up across it, and the curb term takes
    that step (kerbs=True), at the kerb and not on the flat road or sidewalk beside it."""
    xyz = kerb_cloud(noise_m=0.02, spacing_m=0.5, seed=3)
    xyz[:, 1] += 5.0                                   # kerb at y = 5, map line at y = 0
    line = np.array([[-10.0, 0.0], [10.0, 0.0]])

    def profile(kerbs):
        a = attractor_map(xyz, line, cell_m=0.5, drop_off_weight=0.0, kerbs=kerbs,
                          k_neighbours=20)
        y = a.transform.f + (np.arange(a.shape[0]) + 0.5) * a.transform.e
        x = a.transform.c + (np.arange(a.shape[1]) + 0.5) * a.transform.a
        return y, a.data[:, (x > -8) & (x < 8)].mean(axis=1)

    y, with_kerbs = profile(True)
    _, paper = profile(False)
    at_kerb = np.abs(y - 5.0) <= 0.5
    assert with_kerbs[at_kerb].max() > 0.2 + 0.8
    assert with_kerbs[at_kerb].max() > paper[at_kerb].max() + 0.2
    away = (np.abs(y - 5.0) > 2.5) & (np.abs(y) < 9)  # flat road and sidewalk, inside the data
    assert with_kerbs[away].max() < 0.2 + 0.15
