"""Local-energy edges: positions, the orientation convention, histograms, no-data cells."""
import numpy as np
import pytest

from gisroads.features.edges import (dominant_orientations, fill_nearest, local_energy,
                                     orientation_histogram)


def angle_error_deg(measured_rad, expected_rad):
    """Signed difference of line orientations (period pi), degrees."""
    return np.degrees(np.angle(np.exp(2j * (np.asarray(measured_rad) - expected_rad))) / 2)


def line_image(theta_deg, size=101, width_px=1.0):
    """A thin bright line through the centre along (d_col, d_row) = (cos, -sin) of theta."""
    rows, cols = np.mgrid[:size, :size] - size // 2
    theta = np.radians(theta_deg)
    distance = cols * np.sin(theta) + rows * np.cos(theta)
    return np.exp(-distance ** 2 / (2 * width_px ** 2)).astype(np.float32), np.abs(distance)


def test_fill_nearest_copies_the_nearest_valid_value():
    image = np.array([[1.0, np.nan, np.nan, 4.0]])
    filled = fill_nearest(image, np.isfinite(image))
    np.testing.assert_array_equal(filled, [[1.0, 1.0, 4.0, 4.0]])


def test_vertical_step_peaks_on_the_step_with_orientation_half_pi():
    image = np.zeros((64, 64), np.float32)
    image[:, 32:] = 1.0
    magnitude, orientation = local_energy(image)
    assert magnitude.dtype == np.float32 and orientation.dtype == np.float32
    assert magnitude.shape == orientation.shape == image.shape
    peak_cols = magnitude.argmax(axis=1)
    assert set(peak_cols) <= {31, 32}  # the step lies between columns 31 and 32
    on_step = orientation[np.arange(64), peak_cols]
    assert np.abs(angle_error_deg(on_step, np.pi / 2)).max() < 3
    # far from the step, nothing
    assert magnitude[:, :8].max() < 0.05 * magnitude.max()


def test_horizontal_step_has_orientation_zero():
    image = np.zeros((64, 64), np.float32)
    image[32:, :] = 1.0
    magnitude, orientation = local_energy(image)
    peak_rows = magnitude.argmax(axis=0)
    assert set(peak_rows) <= {31, 32}
    assert np.abs(angle_error_deg(orientation[peak_rows, np.arange(64)], 0.0)).max() < 3
    assert ((orientation >= 0) & (orientation < np.pi)).all()


@pytest.mark.parametrize("theta_deg", [30, 150, 100])
def test_line_orientation_is_counter_clockwise_from_east_with_north_up(theta_deg):
    image, distance = line_image(theta_deg)
    magnitude, orientation = local_energy(image)
    rows, cols = np.mgrid[:101, :101] - 50
    on_line = (distance < 0.5) & (np.abs(rows) < 30) & (np.abs(cols) < 30)
    errors = angle_error_deg(orientation[on_line], np.radians(theta_deg))
    assert np.abs(errors).max() < 3
    # the energy ridge is on the line
    assert magnitude[on_line].mean() > 5 * magnitude[distance > 12].mean()


def test_a_30_degree_line_rises_to_the_right_on_the_displayed_image():
    image = np.zeros((61, 61), np.float32)
    steps = np.arange(-25, 26)
    # from the centre, 30 deg up-right: columns grow, rows shrink (a jagged 1-pixel line)
    line_rows = np.round(30 - steps * np.sin(np.radians(30))).astype(int)
    line_cols = np.round(30 + steps * np.cos(np.radians(30))).astype(int)
    image[line_rows, line_cols] = 1.0
    magnitude, orientation = local_energy(image)
    central = np.abs(steps) < 15
    errors = angle_error_deg(orientation[line_rows[central], line_cols[central]],
                             np.radians(30))
    assert abs(np.median(errors)) < 3


def test_dominant_orientations_of_a_road_grid():
    rng = np.random.default_rng(1)
    rows, cols = np.mgrid[:300, :300].astype(float)
    road = np.zeros((300, 300), bool)
    for k in (60, 160, 250):
        road |= np.abs(rows - k) < 5  # east-west roads: 0 deg
    for k in (40, 140, 230):
        road |= np.abs(cols - k) < 5  # north-south roads: 90 deg
    theta = np.radians(40)
    road |= np.abs((cols - 150) * np.sin(theta) + (rows - 150) * np.cos(theta)) < 5
    image = np.where(road, 0.2, 1.0) + rng.normal(0, 0.1, road.shape)
    magnitude, orientation = local_energy(image)
    found = dominant_orientations(magnitude, orientation)
    assert len(found) == 3
    expected = np.radians([0, 40, 90])
    errors = angle_error_deg(found[:, None], expected[None, :])
    assert np.abs(errors).min(axis=0).max() < 3  # every road direction found
    assert np.abs(errors).min(axis=1).max() < 3  # and nothing else


def test_orientation_histogram_splits_votes_between_nearest_centres():
    magnitude = np.array([1.0, 2.0, 4.0, 0.0, np.nan, 8.0])
    orientation = np.array([0.0, np.pi / 8, 7 * np.pi / 8, 1.0, 1.0, np.nan])
    centres, weights = orientation_histogram(magnitude, orientation, n_bins=4, smooth_bins=0)
    np.testing.assert_allclose(centres, [0, np.pi / 4, np.pi / 2, 3 * np.pi / 4])
    # 0 -> bin 0; pi/8 halfway between bins 0 and 1; 7pi/8 halfway between bin 3 and pi = 0;
    # zero, NaN magnitudes and NaN orientations count nothing
    np.testing.assert_allclose(weights, [1 + 1 + 2, 1, 0, 2])


def test_orientation_histogram_smoothing_is_circular_and_keeps_the_total():
    _, weights = orientation_histogram([1.0], [0.0], n_bins=12, smooth_bins=1)
    assert weights.sum() == pytest.approx(1.0)
    assert weights[1] == pytest.approx(weights[11])  # wraps around pi
    assert weights.argmax() == 0


def test_dominant_orientations_order_share_and_count():
    centres = np.radians([30, 120, 75])  # bin centres of 12 bins of 15 deg
    magnitude = np.array([10.0, 5.0, 0.5])
    found = dominant_orientations(magnitude, centres, n_bins=12, smooth_bins=0)
    np.testing.assert_allclose(found, np.radians([30, 120]))  # 0.5/15.5 < min_share
    found = dominant_orientations(magnitude, centres, n_bins=12, smooth_bins=0, min_share=0.01)
    np.testing.assert_allclose(found, np.radians([30, 120, 75]))
    found = dominant_orientations(magnitude, centres, n_bins=12, smooth_bins=0, max_peaks=1)
    np.testing.assert_allclose(found, np.radians([30]))
    assert dominant_orientations(np.zeros(3), centres).size == 0


def test_nan_and_masked_cells_get_zero_magnitude_and_make_no_edge():
    rng = np.random.default_rng(0)
    image = 5.0 + rng.normal(0, 0.01, (80, 80))
    image[20:40, 30:60] = np.nan
    magnitude, orientation = local_energy(image)
    assert np.isfinite(magnitude).all() and np.isfinite(orientation).all()
    assert (magnitude[20:40, 30:60] == 0).all() and (orientation[20:40, 30:60] == 0).all()
    # the rim of the hole is no edge: the fill continues the data
    assert magnitude.max() < 0.05
    mask = np.zeros(image.shape, bool)
    mask[60:70, 10:20] = True
    masked, _ = local_energy(image, mask=mask)
    assert (masked[mask] == 0).all()
    all_nan, _ = local_energy(np.full((10, 10), np.nan))
    assert (all_nan == 0).all()


def test_step_next_to_a_hole_is_still_found():
    image = np.zeros((64, 64))
    image[:, 32:] = 1.0
    image[:, 40:50] = np.nan
    magnitude, orientation = local_energy(image)
    assert set(magnitude[:, :36].argmax(axis=1)) <= {31, 32}
