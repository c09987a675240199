import numpy as np
import pytest
import shapely
from affine import Affine

from gisroads.vectorize.skeleton import skeleton_lines

T = Affine(0.5, 0, 1000.0, 0, -0.5, 2000.0)


def test_straight_band_gives_its_centre_line_and_width():
    mask = np.zeros((60, 300), bool)
    mask[20:40, 10:290] = True  # 10 m wide, 140 m long at 0.5 m cells
    lines = skeleton_lines(mask, T, "EPSG:32633")
    assert len(lines) == 1
    line = lines.geometry.iloc[0]
    y_centre = 2000.0 - 30 * 0.5
    np.testing.assert_allclose(shapely.get_coordinates(line)[:, 1], y_centre, atol=0.5)
    assert 125 < line.length < 141
    assert lines.width_m.iloc[0] == pytest.approx(10.0, abs=1.0)


def test_cross_gives_lines_meeting_at_one_node():
    mask = np.zeros((201, 201), bool)
    mask[95:106, :] = True
    mask[:, 95:106] = True
    lines = skeleton_lines(mask, T, None, min_length_m=5)
    assert len(lines) == 4
    ends = shapely.get_coordinates(shapely.boundary(lines.geometry.values))
    centre = np.array([1000 + 100.5 * 0.5, 2000 - 100.5 * 0.5])
    assert (np.hypot(*(ends - centre).T) < 1.5).sum() == 4


def test_empty_mask():
    assert len(skeleton_lines(np.zeros((10, 10), bool), T, None)) == 0
