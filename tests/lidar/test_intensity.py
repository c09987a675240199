"""Per-level ground intensity images: exact cell values on hand-made points, grid alignment,
normalisation, hole filling, levels, GeoTIFF output, and roads darker than their surroundings."""
import numpy as np
import pytest
import shapely
from pyproj import CRS

from gisroads.io.las import concatenate
from gisroads.io.raster import raster_info, read_raster
from gisroads.lidar.ground import ground_planes
from gisroads.lidar.intensity import (fill_holes, image_grid, intensity_images,
                                      split_share, write_intensity_images)
from gisroads.synthetic import make_scene, render_cloud

RNG = np.random.default_rng(11)
FULL_RANGE = (0.0, 100.0)  # percentiles: min -> 0, max -> 1


def points(xy, z=0.0):
    xy = np.asarray(xy, float)
    return np.column_stack([xy, np.full(len(xy), z)])


def test_cell_values_are_exact_means_of_normalised_intensities():
    # Cells of 1 m over (0, 0)-(3, 2): two points in the top-left cell, one top-right, one
    # bottom-middle.
    xyz = points([(0.2, 1.8), (0.7, 1.1), (2.5, 1.5), (1.5, 0.5)])
    intensity = np.array([100.0, 300.0, 500.0, 200.0])
    images = intensity_images(xyz, intensity, np.zeros(4, int), cell_m=1.0,
                              bounds=(0, 0, 3, 2), percentiles=FULL_RANGE, fill_radius_m=0)
    scale = lambda v: (v - 100.0) / 400.0  # noqa: E731
    expected = np.array([[np.mean([scale(100), scale(300)]), np.nan, scale(500)],
                         [np.nan, scale(200), np.nan]], np.float32)
    np.testing.assert_array_equal(images.image.data[0], expected)
    np.testing.assert_array_equal(images.count[0], [[2, 0, 1], [0, 1, 0]])
    assert images.intensity_range == (100.0, 500.0)
    np.testing.assert_array_equal(images.level_index.data, [[0, -1, 0], [-1, 0, -1]])


def test_grid_is_snapped_outward_and_a_cell_centre_lands_in_its_cell():
    transform, shape = image_grid((10.2, 20.1, 14.9, 24.6), 0.5)
    assert (transform.c, transform.f, transform.a, transform.e) == (10.0, 25.0, 0.5, -0.5)
    assert shape == (10, 10)
    row, col = 3, 7
    centre = (10.0 + (col + 0.5) * 0.5, 25.0 - (row + 0.5) * 0.5)
    images = intensity_images(points([centre]), [7.0], [0], cell_m=0.5,
                              bounds=(10.2, 20.1, 14.9, 24.6), fill_radius_m=0)
    assert images.count[0, row, col] == 1 and images.count.sum() == 1
    assert images.image.transform == transform
    assert images.image.xy_to_rowcol(*centre) == (row, col)


def test_default_bounds_hold_every_ground_point_even_on_grid_lines():
    xyz = points([(2.0, 3.0), (5.0, 6.0), (3.3, 4.4)])
    images = intensity_images(xyz, [1.0, 2.0, 3.0], [0, 0, 0], cell_m=0.5, fill_radius_m=0)
    assert images.image.bounds == (2.0, 2.5, 5.5, 6.0)
    assert images.count.sum() == 3


def test_points_off_the_ground_and_outside_the_bounds_are_ignored():
    xyz = points([(0.5, 0.5), (1.5, 0.5), (9.0, 9.0)])
    images = intensity_images(xyz, [10.0, 1000.0, 20.0], [0, -1, 0], cell_m=1.0,
                              bounds=(0, 0, 2, 1), percentiles=FULL_RANGE, fill_radius_m=0)
    assert images.count.sum() == 1 and images.image.shape == (1, 2)
    assert images.intensity_range == (10.0, 10.0)


def test_normalisation_maps_the_1st_and_99th_percentiles_to_0_and_1():
    n = 2000
    xyz = points(np.column_stack([np.arange(n) + 0.5, np.full(n, 0.5)]))
    intensity = RNG.gamma(2.0, 500.0, n)
    images = intensity_images(xyz, intensity, np.zeros(n, int), cell_m=1.0, fill_radius_m=0)
    lo, hi = np.percentile(intensity, [1, 99])
    assert images.intensity_range == pytest.approx((lo, hi))
    values = images.image.data[0, 0]
    np.testing.assert_allclose(values, np.clip((intensity - lo) / (hi - lo), 0, 1), atol=1e-6)
    assert values.min() == 0.0 and values.max() == 1.0
    assert (values == 0).sum() == pytest.approx(0.01 * n, abs=2)
    assert (values == 1).sum() == pytest.approx(0.01 * n, abs=2)


def test_a_one_cell_hole_gets_the_gaussian_weighted_mean_of_its_neighbours():
    image = RNG.uniform(0, 1, (9, 9)).astype(np.float32)
    image[4, 4] = np.nan
    filled = fill_holes(image, radius_cells=3.0)
    rows, cols = np.mgrid[:9, :9]
    d2 = (rows - 4) ** 2 + (cols - 4) ** 2
    weight = np.where((d2 <= 9) & (d2 > 0), np.exp(-d2 / (2 * 1.5 ** 2)), 0.0)
    assert filled[4, 4] == pytest.approx((weight * np.nan_to_num(image)).sum() / weight.sum(),
                                         rel=1e-5)
    same = np.ones((9, 9), bool)
    same[4, 4] = False
    np.testing.assert_array_equal(filled[same], image[same])


def test_scan_gaps_are_filled_and_a_5m_hole_stays_empty():
    image = np.full((40, 60), 0.25, np.float32)
    image[:, 10:12] = np.nan         # a 1 m scan-line gap at 0.5 m cells
    image[20:30, 30:40] = np.nan     # a 5 m x 5 m hole
    filled = fill_holes(image, radius_cells=1.5 / 0.5)
    assert np.isfinite(filled[:, :25]).all()
    np.testing.assert_allclose(filled[:, 10:12], 0.25, rtol=1e-6)
    assert np.isnan(filled[20:30, 30:40]).all()
    assert np.isfinite(filled[~np.isnan(image)]).all()


def test_outside_of_the_data_is_not_grown():
    image = np.full((20, 20), np.nan, np.float32)
    image[5:15, 5:15] = 0.5
    filled = fill_holes(image, radius_cells=3.0)
    np.testing.assert_array_equal(np.isfinite(filled), np.isfinite(image))


def test_two_overlapping_levels_give_two_bands_with_their_own_values():
    # A road (level 0, dark) under a deck (level 1, bright) over the middle of a 10 m x 4 m grid.
    x, y = np.meshgrid(np.arange(10) + 0.5, np.arange(4) + 0.5)
    road = points(np.column_stack([x.ravel(), y.ravel()]))
    deck_xy = np.column_stack([x.ravel(), y.ravel()])[(x.ravel() > 3) & (x.ravel() < 7)]
    deck = points(deck_xy, z=7.0)
    road = road[(road[:, 0] < 3) | (road[:, 0] > 7)]  # no return under the deck
    xyz = np.vstack([road, deck])
    level = np.r_[np.zeros(len(road), int), np.ones(len(deck), int)]
    intensity = np.r_[np.full(len(road), 100.0), np.full(len(deck), 900.0)]
    images = intensity_images(xyz, intensity, level, cell_m=1.0, bounds=(0, 0, 10, 4),
                              percentiles=FULL_RANGE, fill_radius_m=0)
    assert images.image.data.shape == (2, 4, 10)
    band0, band1 = images.image.data
    np.testing.assert_array_equal(band0[:, [0, 1, 2, 7, 8, 9]], 0.0)
    assert np.isnan(band0[:, 3:7]).all()
    np.testing.assert_array_equal(band1[:, 3:7], 1.0)
    assert np.isnan(band1[:, [0, 1, 2, 7, 8, 9]]).all()
    np.testing.assert_array_equal(images.level_index.data[0], [0, 0, 0, 1, 1, 1, 1, 0, 0, 0])
    # Filling gaps up to 4 m, the road runs on under the 4 m deck in band 0; up to 3 m, not.
    filled = intensity_images(xyz, intensity, level, cell_m=1.0, bounds=(0, 0, 10, 4),
                              percentiles=FULL_RANGE, fill_radius_m=4.0)
    np.testing.assert_allclose(filled.image.data[0], 0.0)
    assert np.isnan(filled.image.data[1][:, [0, 1, 2, 7, 8, 9]]).all()
    unfilled = intensity_images(xyz, intensity, level, cell_m=1.0, bounds=(0, 0, 10, 4),
                                percentiles=FULL_RANGE, fill_radius_m=3.0)
    assert np.isnan(unfilled.image.data[0][:, 3:7]).all()
    np.testing.assert_array_equal(filled.level_index.data[0], [0, 0, 0, 1, 1, 1, 1, 0, 0, 0])


def test_write_intensity_images_round_trip(tmp_path):
    xyz = points([(0.5, 0.5), (1.5, 1.5), (1.5, 0.5)], z=0.0)
    xyz = np.vstack([xyz, points([(0.5, 1.5)], z=6.0)])
    crs = CRS.from_epsg(32633)
    images = intensity_images(xyz, [0.0, 50.0, 100.0, 100.0], [0, 0, 0, 1], cell_m=1.0,
                              crs=crs, percentiles=FULL_RANGE, fill_radius_m=0)
    intensity_path, index_path = write_intensity_images(tmp_path / "tile.tif", images)
    assert index_path == tmp_path / "tile_level_index.tif"
    info = raster_info(intensity_path)
    assert info["band_names"] == ["level_0", "level_1"] and info["epsg"] == 32633
    back = read_raster(intensity_path)
    np.testing.assert_array_equal(back.data, images.image.data)
    assert back.transform == images.image.transform
    index = read_raster(index_path)
    assert index.nodata == -1
    np.testing.assert_array_equal(index.data[0], [[1, 0], [0, 0]])


def test_split_share_is_measured_where_single_and_split_returns_meet():
    # cell 0: single returns 100, 300 and a split return 80 (share 80 / 200 = 0.4);
    # cell 1: the same ground at 0.5; cell 2 holds split returns only and tells nothing
    intensity = np.array([100.0, 300.0, 80.0, 200.0, 100.0, 30.0, 30.0])
    single = np.array([True, True, False, True, False, False, False])
    cell = np.array([0, 0, 0, 1, 1, 2, 2])
    use = np.ones(7, bool)
    assert split_share(intensity, single, use, cell) == pytest.approx(0.45)  # the median
    assert split_share(intensity, np.ones(7, bool), use, cell) == 1.0
    assert split_share(intensity, single, cell != 0, cell) == pytest.approx(0.5)


def test_split_returns_are_brought_to_the_single_return_scale():
    # 1 m cells over (0, 0)-(2, 1): the left cell has single returns of 300 and a split
    # return of 120 (share 0.4); the right one only split returns of 60, i.e. 150
    xyz = points([(0.3, 0.5), (0.6, 0.5), (1.5, 0.5), (1.6, 0.5)])
    intensity = np.array([300.0, 120.0, 60.0, 60.0])
    single = np.array([True, False, False, False])
    level = np.zeros(4, int)
    kwargs = dict(cell_m=1.0, bounds=(0, 0, 2, 1), percentiles=FULL_RANGE, fill_radius_m=0)
    corrected = intensity_images(xyz, intensity, level, single_return=single, **kwargs)
    raw = intensity_images(xyz, intensity, level, **kwargs)
    assert corrected.intensity_range == (150.0, 300.0)
    np.testing.assert_allclose(corrected.image.data[0], [[1.0, 0.0]])
    assert raw.image.data[0, 0, 1] < raw.image.data[0, 0, 0]
    with pytest.raises(ValueError, match="single_return"):
        intensity_images(xyz, intensity, level, single_return=single[:2], **kwargs)


def test_bad_input():
    with pytest.raises(ValueError):
        intensity_images(points([(0, 0)]), [1.0, 2.0], [0])
    with pytest.raises(ValueError):  # no ground and no bounds: no extent
        intensity_images(points([(0, 0)]), [1.0], [-1])
    empty = intensity_images(points([(0, 0)]), [1.0], [-1], bounds=(0, 0, 2, 2), cell_m=1.0)
    assert empty.image.data.shape == (0, 2, 2) and (empty.level_index.data == -1).all()


def test_synthetic_roads_are_darker_than_sidewalks_and_grass():
    scene = make_scene(seed=5, size_m=(300.0, 300.0))
    cloud = concatenate(list(render_cloud(scene, density_per_m2=4.0, seed=1)))
    planes = ground_planes(cloud.xyz)
    images = intensity_images(cloud.xyz, cloud.intensity, planes.level, cell_m=0.5,
                              crs=scene.crs)
    image = images.image.data[0]
    rows, cols = np.mgrid[:image.shape[0], :image.shape[1]]
    transform = images.image.transform
    x, y = transform.c + (cols + 0.5) * 0.5, transform.f - (rows + 0.5) * 0.5
    roads = shapely.union_all(scene.truth.polygons.geometry.values)
    on_road = shapely.contains_xy(roads, x, y) & np.isfinite(image)
    off_road = ~shapely.contains_xy(shapely.buffer(roads, 1.0), x, y) & np.isfinite(image)
    assert on_road.sum() > 10000 and off_road.sum() > 10000
    road, other = np.median(image[on_road]), np.median(image[off_road])
    assert road < 0.5 * other
    assert np.isfinite(image[shapely.contains_xy(roads, x, y)]).mean() > 0.9
