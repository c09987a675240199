import geopandas as gpd
import numpy as np
import pytest
import shapely

from gisroads.synthetic.perturb import perturb_lines


@pytest.fixture
def grid():
    lines = [shapely.LineString([(0, y), (500, y)]) for y in range(0, 500, 100)]
    return gpd.GeoDataFrame({"width_m": np.full(5, 8.0), "road_id": np.arange(5)},
                            geometry=lines, crs="EPSG:32633")


def test_shift_moves_every_line_by_exactly_the_distance(grid):
    out = perturb_lines(grid, shift_m=3.0, seed=4)
    offsets = shapely.get_coordinates(out.geometry.values) - \
        shapely.get_coordinates(shapely.segmentize(grid.geometry.values, 10.0))
    np.testing.assert_allclose(np.hypot(*offsets.T), 3.0)
    assert out.crs == grid.crs and out.road_id.tolist() == list(range(5))


def test_jitter_drop_and_false_roads(grid):
    out = perturb_lines(grid, jitter_m=0.5, drop_fraction=0.4, false_roads=3,
                        false_length_m=60.0, seed=1)
    kept = out.iloc[:-3]
    assert 1 <= len(kept) < 5
    np.testing.assert_allclose(out.iloc[-3:].length, 60.0)
    assert out.width_m.notna().all()
    y = shapely.get_coordinates(kept.geometry.values)[:, 1]
    deviation = y - np.round(y / 100) * 100
    assert 0.4 < deviation.std() < 0.6
