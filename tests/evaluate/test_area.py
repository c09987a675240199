import math

import geopandas as gpd
import numpy as np
import pytest
from shapely import box

from gisroads.evaluate import area_metrics, area_metrics_from_masks
from gisroads.evaluate.area import roadside


def band(rows, shape=(10, 10)):
    """A road running across the whole grid over the given rows."""
    mask = np.zeros(shape, dtype=bool)
    mask[rows] = True
    return mask


# Reference road on rows 2..5, prediction on rows 3..7 (one row short at the top, two rows of
# spill at the bottom), both across all 10 columns.
REFERENCE = band(slice(2, 6))
PREDICTED = band(slice(3, 8))


def test_roadside_is_the_kerb_not_the_grid_edge():
    # The road runs off the left and right edges: only its top and bottom rows are roadside.
    assert np.array_equal(roadside(REFERENCE), band([2, 5]))
    square = np.zeros((5, 5), dtype=bool)
    square[1:4, 1:4] = True
    expected = square.copy()
    expected[2, 2] = False
    assert np.array_equal(roadside(square), expected)


def test_masks_hand_counted():
    # TP rows 3..5 = 30, FP rows 6..7 = 20, FN row 2 = 10, TN rows 0,1,8,9 = 40.
    # Roadside: reference rows 2 and 5 (20 cells), prediction rows 3 and 7. With 0.5 m cells,
    # row 3 is 1 row (0.5 m) from row 2, row 7 is 2 rows (1.0 m) from row 5:
    # s = (10 * 0.5 + 10 * 1.0) / 20 = 0.75 m. d = (20 - 10) / (20 + 10) = 1/3.
    m = area_metrics_from_masks(PREDICTED, REFERENCE, cell_m=0.5)
    assert (m.tp, m.fp, m.fn, m.tn) == (30, 20, 10, 40)
    assert m.precision == pytest.approx(30 / 50, abs=1e-12)
    assert m.recall == pytest.approx(30 / 40, abs=1e-12)
    assert m.quality == pytest.approx(30 / 60, abs=1e-12)
    assert m.spill_size_m == pytest.approx(0.75, abs=1e-12)
    assert m.spill_direction == pytest.approx(1 / 3, abs=1e-12)


def test_valid_mask_restricts_every_count():
    # Valid rows 0..5: TP 30, FP 0, FN 10, TN 20. Reference roadside rows 2 and 5 count (20);
    # of the predicted roadside only row 3 (0.5 m away) does: s = 10 * 0.5 / 20.
    m = area_metrics_from_masks(PREDICTED, REFERENCE, cell_m=0.5, valid=band(slice(0, 6)))
    assert (m.tp, m.fp, m.fn, m.tn) == (30, 0, 10, 20)
    assert (m.precision, m.recall, m.quality) == pytest.approx((1.0, 0.75, 0.75), abs=1e-12)
    assert m.spill_size_m == pytest.approx(0.25, abs=1e-12)
    assert m.spill_direction == pytest.approx(-1.0, abs=1e-12)


def test_identical_masks():
    m = area_metrics_from_masks(REFERENCE, REFERENCE, cell_m=0.5)
    assert (m.precision, m.recall, m.quality, m.spill_size_m) == (1.0, 1.0, 1.0, 0.0)
    assert math.isnan(m.spill_direction)


def test_empty_prediction():
    m = area_metrics_from_masks(np.zeros((10, 10), bool), REFERENCE, cell_m=0.5)
    assert (m.recall, m.quality, m.spill_size_m, m.spill_direction) == (0.0, 0.0, 0.0, -1.0)
    assert math.isnan(m.precision)


def test_empty_reference_and_shape_mismatch_raise():
    with pytest.raises(ValueError, match="reference"):
        area_metrics_from_masks(REFERENCE, np.zeros((10, 10), bool), cell_m=0.5)
    with pytest.raises(ValueError, match="shape"):
        area_metrics_from_masks(REFERENCE[:5], REFERENCE, cell_m=0.5)


def test_rectangle_shifted_one_metre():
    # Reference 100 m x 10 m, prediction the same 1 m north; 0.5 m cells, centres at
    # multiples of 0.25 m so none is on an edge. The default grid is the union bounds grown by
    # one cell: 202 x 24 cells.
    # Reference: 200 columns x 20 rows (y 0..10), prediction 200 x 20 (y 1..11), overlap
    # 200 x 18: TP 3600, FP 400, FN 400, TN 202 * 24 - 4400 = 448.
    # Roadside: each rectangle's ring of 2 * 200 + 2 * 18 = 436 cells. Distances from the
    # prediction's ring to the reference's: top row all 1.0 m (200 cells); bottom row 0, 0.5,
    # 196 x 1.0, 0.5, 0 (197 m); side columns 17 cells on the reference's sides (0) and one
    # 0.5 m above them on each side (1 m). s = (200 + 197 + 1) / 436.
    ref = gpd.GeoSeries([box(0, 0, 100, 10)], crs="EPSG:32633")
    pred = gpd.GeoSeries([box(0, 1, 100, 11)], crs="EPSG:32633")
    m = area_metrics(pred, ref, cell_m=0.5)
    assert (m.tp, m.fp, m.fn, m.tn) == (3600, 400, 400, 448)
    assert (m.precision, m.recall) == pytest.approx((0.9, 0.9), abs=1e-12)
    assert m.quality == pytest.approx(9 / 11, abs=1e-12)
    assert m.spill_size_m == pytest.approx(398 / 436, abs=1e-12)
    assert m.spill_direction == 0.0


def test_bounds_and_valid_area():
    ref = [box(0, 0, 100, 10)]
    pred = [box(0, 1, 100, 11)]
    # Explicit bounds x 0..50: 100 x 22 cells, no margin.
    m = area_metrics(pred, ref, cell_m=0.5, bounds=(0, 0, 50, 11))
    assert (m.tp, m.fp, m.fn, m.tn) == (1800, 200, 200, 0)
    # Valid area y 0..5 (cell centres 0.25 .. 4.75): only the reference's two bottom rows
    # are missed; nothing is spilt.
    m = area_metrics(pred, ref, cell_m=0.5, valid_area=box(0, 0, 100, 5))
    assert (m.tp, m.fp, m.fn) == (200 * 8, 0, 200 * 2)


def test_polygons_in_geographic_crs_are_measured_in_metres():
    ref = gpd.GeoSeries([box(500000, 5000000, 500100, 5000010)], crs="EPSG:32633")
    pred = gpd.GeoSeries([box(500000, 5000001, 500100, 5000011)], crs="EPSG:32633")
    m = area_metrics(pred, ref.to_crs("EPSG:4326"), cell_m=0.5)
    assert (m.tp, m.fp, m.fn) == (3600, 400, 400)
