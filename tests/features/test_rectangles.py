"""Rotated rectangular road filters on integral images (Zhu & Mordohai Eq. 1-4)."""
import numpy as np
import pytest

from affine import Affine

from gisroads.features.rectangles import (THETA2_RAD, box_sums, boundary_strength, compose,
                                          direction_in_pixels, integral_image,
                                          interior_sign, interior_strength, rotate_to,
                                          rotated_features, rotated_frame, side_step,
                                          sides_on_strongest_edges, valid_fraction)


def _apply(t, u, v):
    return t.a * u + t.b * v + t.c, t.d * u + t.e * v + t.f


def test_integral_image_has_a_zero_border_and_sums_the_top_left_block():
    ii = integral_image([[1, 2], [3, 4]])
    np.testing.assert_array_equal(ii, [[0, 0, 0], [0, 1, 3], [0, 4, 10]])


def test_box_sums_equal_brute_force_sums_of_the_clipped_boxes():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(13, 17))
    ii = integral_image(a)
    r0, r1 = rng.integers(-4, 17, 300), rng.integers(-4, 17, 300)
    c0, c1 = rng.integers(-4, 21, 300), rng.integers(-4, 21, 300)
    brute = [a[max(p, 0):max(q, 0), max(s, 0):max(t, 0)].sum()
             for p, q, s, t in zip(r0, r1, c0, c1)]
    np.testing.assert_allclose(box_sums(ii, r0, c0, r1, c1), brute, atol=1e-12)


def test_direction_follows_the_north_up_counter_clockwise_convention():
    np.testing.assert_allclose(direction_in_pixels(0.0), (1, 0), atol=1e-15)
    np.testing.assert_allclose(direction_in_pixels(np.pi / 2), (0, -1), atol=1e-15)  # north


def test_quarter_turns_resample_whole_pixels():
    a = np.arange(12.0).reshape(3, 4)
    np.testing.assert_array_equal(rotate_to(a, 0.0)[0], a)
    # north becomes +column: the first rotated row is the image's first column, bottom up
    np.testing.assert_array_equal(rotate_to(a, np.pi / 2)[0],
                                  [[8, 4, 0], [9, 5, 1], [10, 6, 2], [11, 7, 3]])
    np.testing.assert_array_equal(rotate_to(a, np.pi)[0], a[::-1, ::-1])
    to_image = rotate_to(a, np.pi / 2)[1]
    assert _apply(to_image, 0, 0) == pytest.approx((0, 3))  # rotated origin: bottom-left


@pytest.mark.parametrize("theta_deg", [0.0, 17.0, 90.0, 137.0, 200.0])
def test_every_rotated_pixel_maps_back_inside_its_source_pixel(theta_deg):
    ids = np.arange(60 * 80, dtype=np.int64).reshape(60, 80)
    rotated, to_image = rotate_to(ids, np.radians(theta_deg), order=0, cval=-1)
    rows, cols = np.nonzero(rotated >= 0)
    source = rotated[rows, cols]
    col, row = _apply(to_image, cols + 0.5, rows + 0.5)
    assert np.abs(col - (source % 80 + 0.5)).max() <= 0.5 + 1e-9
    assert np.abs(row - (source // 80 + 0.5)).max() <= 0.5 + 1e-9
    assert len(source) >= 0.95 * ids.size  # the frame holds the whole image
    # and the inverse mapping returns every source corner to where it was
    back = _apply(~to_image, *_apply(to_image, cols, rows))
    np.testing.assert_allclose(back, (cols, rows), atol=1e-9)


def test_bilinear_rotation_reproduces_a_linear_ramp_at_the_mapped_centres():
    rows, cols = np.mgrid[0:50, 0:70]
    ramp = 3.0 * cols + 7.0 * rows
    rotated, to_image = rotate_to(ramp, 0.5)
    r, c = np.nonzero(np.isfinite(rotated))
    col, row = _apply(to_image, c + 0.5, r + 0.5)
    np.testing.assert_allclose(rotated[r, c], 3.0 * (col - 0.5) + 7.0 * (row - 0.5), atol=1e-8)
    assert len(r) > 0.6 * ramp.size
    assert rotated.shape == rotated_frame(ramp.shape, 0.5)[1]


def test_compose_matches_applying_one_map_after_the_other():
    outer = Affine(0.5, 0.0, 1000.0, 0.0, -0.5, 2000.0)
    inner = rotated_frame((40, 60), 0.7)[0]
    u, v = np.array([0.0, 3.5, 17.0]), np.array([0.0, -2.0, 9.25])
    np.testing.assert_allclose(_apply(compose(outer, inner), u, v),
                               _apply(outer, *_apply(inner, u, v)))


def test_rotation_marks_missing_cells_and_the_outside_as_nan():
    image = np.ones((20, 30))
    image[5, 7] = np.nan
    rotated, to_image = rotate_to(image, np.radians(30))
    assert np.isnan(rotated[0, 0])  # outside the rotated image
    col, row = _apply(~to_image, 7.5, 5.5)
    assert np.isnan(rotated[int(row), int(col)])


def test_interior_filter_weights_eq3():
    window = 0.3
    offsets_deg = np.array([0, 10, 14.9, 15.1, 30, 45, 60, 74.9, 75.1, 90, 105, 166, 180])
    expected = [1, 1, 1, -1, -1, -1, -1, -1, 0, 0, 0, 1, 1]
    edges = np.mod(window + np.radians(offsets_deg), np.pi)
    np.testing.assert_array_equal(interior_sign(edges, window, theta2_rad=THETA2_RAD), expected)
    assert interior_sign(np.nan, window) == 0


def _features(intensity, magnitude=None, orientation=None):
    """Features of the identity rotation, where rotated pixels are image pixels."""
    zeros = np.zeros(np.shape(intensity))
    return rotated_features(intensity, zeros if magnitude is None else magnitude,
                            zeros if orientation is None else orientation, 0.0)


def test_interior_strength_counts_parallel_edges_penalises_oblique_ignores_crosswalks():
    intensity = np.ones((12, 30))
    magnitude = np.zeros((12, 30))
    magnitude[4:8, 5:25] = 0.5  # a 4 x 20 block of edges inside the 6 x 24 window
    window = dict(r0=3, c0=3, width_px=6, length_px=24)
    for orientation, expected in [(0.0, 0.5 * 80 / 144), (np.pi / 4, -0.5 * 80 / 144),
                                  (np.pi / 2, 0.0), (np.radians(80), 0.0)]:
        features = _features(intensity, magnitude, np.full((12, 30), orientation))
        assert interior_strength(features, **window) == pytest.approx(expected)


def _road_rows(rows=12, cols=20):
    """Bright rows 0-3 and 8-11 around a dark road in rows 4-7."""
    image = np.full((rows, cols), 1.0)
    image[4:8] = 0.2
    return image


def test_boundary_strength_is_the_weaker_side_contrast_of_eq1():
    features = _features(_road_rows())
    fit = boundary_strength(features, 4, 2, 4, 16, band_px=2)
    too_wide = boundary_strength(features, 4, 2, 6, 16, band_px=2)  # far side on bright
    bright = boundary_strength(features, 8, 2, 2, 16, band_px=1)  # polarity: inside brighter
    assert fit == pytest.approx(0.8)
    assert too_wide == pytest.approx(0.0)
    assert bright == pytest.approx(-0.8)
    # vectorised over windows, band capped at half the width
    np.testing.assert_allclose(
        boundary_strength(features, [4, 4, 8], [2, 2, 2], [4, 6, 2], [16, 16, 16], band_px=2),
        [0.8, 0.0, -0.8], atol=1e-12)


def test_boundary_strength_averages_valid_cells_only():
    image = _road_rows()
    image[5, 3:9] = np.nan  # a hole inside the road
    image[2, :] = np.nan  # a missing row in the outer band
    features = _features(image)
    assert boundary_strength(features, 4, 2, 4, 16, band_px=2) == pytest.approx(0.8)
    image[0:4] = np.nan  # no data at all in the near outer band
    assert np.isnan(boundary_strength(_features(image), 4, 2, 4, 16, band_px=2))


def test_valid_fraction_and_interior_strength_ignore_missing_cells():
    image = np.ones((10, 10))
    image[:, :5] = np.nan
    magnitude = np.ones((10, 10))
    features = _features(image, magnitude)
    assert valid_fraction(features, 0, 0, 10, 10) == pytest.approx(0.5)
    assert valid_fraction(features, -5, 0, 10, 10) == pytest.approx(0.25)  # half outside
    # the NaN half lends no cells, so the mean signed edge over valid cells stays 1
    assert interior_strength(features, 2, 5, 6, 5) == pytest.approx(1.0, abs=0.05)
    assert np.isnan(interior_strength(features, 2, 0, 6, 3))


def _profile_rows(profile, cols=60):
    """An image whose rows take the values of ``profile``, constant along the columns."""
    return np.repeat(np.asarray(profile, float)[:, None], cols, axis=1)


# grass 0.9 | sidewalk 0.5 (4 rows) | road 0.1 (16 rows) | sidewalk | grass
SIDEWALK_ROAD = [0.9] * 10 + [0.5] * 4 + [0.1] * 16 + [0.5] * 4 + [0.9] * 10


def test_side_step_is_the_thin_band_contrast_with_the_side_polarity():
    features = _features(_profile_rows(SIDEWALK_ROAD))
    # the kerb at row 14: 2 sidewalk rows above (0.5) against 2 road rows below (0.1)
    assert side_step(features, 14, 0, 60, 2, -1) == pytest.approx(0.4)
    assert side_step(features, 10, 0, 60, 2, -1) == pytest.approx(0.4)  # grass-sidewalk
    assert side_step(features, 12, 0, 60, 2, -1) == pytest.approx(0.0)  # mid-sidewalk
    assert side_step(features, 30, 0, 60, 2, 1) == pytest.approx(0.4)  # far kerb, mirrored
    assert side_step(features, 14, 0, 60, 2, 1) == pytest.approx(-0.4)


def test_window_sides_must_be_the_road_edges():
    features = _features(_profile_rows(SIDEWALK_ROAD))
    check = dict(edge_band_px=2, slack_px=1, ratio=0.5, min_step=0.08)
    # on the kerbs (rows 14-30), a row short of a kerb (the slack), and over the sidewalks
    r0 = np.array([14, 14, 10, 10])
    width = np.array([16, 15, 24, 20])
    ok = sides_on_strongest_edges(features, r0, np.zeros(4, int), width, np.full(4, 60),
                                  **check)
    # the last two hold a kerb inside them, as strong a step as their sides
    np.testing.assert_array_equal(ok, [True, True, False, False])
    # inside the road both sides step by nothing: below min_step
    assert not sides_on_strongest_edges(features, 18, 0, 8, 60, **check)


def test_a_window_over_both_carriageways_and_their_median_is_refused():
    # carriageway 0.1 (8 rows) | median 0.9 (6 rows) | carriageway | then grass
    profile = [0.9] * 8 + [0.1] * 8 + [0.9] * 6 + [0.1] * 8 + [0.9] * 8
    features = _features(_profile_rows(profile))
    check = dict(edge_band_px=2, slack_px=1, ratio=0.5)
    both = sides_on_strongest_edges(features, 8, 0, 22, 60, **check)
    each = sides_on_strongest_edges(features, [8, 22], [0, 0], [8, 8], [60, 60], **check)
    assert not both
    assert each.all()


def test_a_tilted_window_is_refused_by_its_ends():
    # a long road, its kerbs on rows 14 and 30 over the first 40 columns and 4 rows lower
    # over the last 40: a window on the first part's kerbs has its far end off them
    image = np.full((50, 120), 0.9)
    image[14:30, :80] = 0.1
    image[18:34, 80:] = 0.1
    features = _features(image)
    check = dict(edge_band_px=2, slack_px=1, ratio=0.5, min_step=0.08)
    assert sides_on_strongest_edges(features, 14, 0, 16, 120, **check)  # whole side: 2/3
    assert not sides_on_strongest_edges(features, 14, 0, 16, 120, end_px=40, **check)
    assert sides_on_strongest_edges(features, 14, 0, 16, 80, end_px=40, **check)
