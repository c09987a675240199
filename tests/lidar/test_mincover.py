import math

import geopandas as gpd
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS
from scipy.ndimage import gaussian_filter
from shapely import box

from gisroads.geo import GeoRaster
from gisroads.lidar.mincover import (cover_cost, cover_seeds, exact_min_cover,
                                     greedy_min_cover, seed_likelihood)

UTM = CRS.from_epsg(32633)


def hypotheses(boxes, *, width_index=None, theta_rad=None):
    """Hypothesis frame of rectangles (default: along x, width index 0)."""
    boxes = list(boxes)
    n = len(boxes)
    theta = np.zeros(n) if theta_rad is None else np.asarray(theta_rad, float)
    bounds = shapely.bounds(boxes)
    return gpd.GeoDataFrame(
        {"hyp_id": np.arange(100, 100 + n), "x0_m": bounds[:, 0], "y0_m": bounds[:, 1],
         "theta_rad": theta, "width_m": bounds[:, 3] - bounds[:, 1],
         "length_m": bounds[:, 2] - bounds[:, 0], "s_bd": 1.0, "s_int": 1.0, "score": 1.0,
         "width_index": np.zeros(n, np.int64) if width_index is None else width_index},
        geometry=boxes, crs=UTM)


def raster(bands, *, x0=-2.0, y_top=12.0, cell=1.0):
    """GeoRaster of (K, rows, cols) values, upper-left corner (x0, y_top)."""
    data = np.asarray(bands, np.float32)
    return GeoRaster(data, Affine(cell, 0, x0, 0, -cell, y_top), UTM)


def along_x(values_by_x, *, x0=-2.0, x1=302.0, y0=-12.0, y1=12.0, cell=1.0):
    """One band, constant across y, given by a function of pixel-centre x."""
    x = np.arange(x0, x1, cell) + cell / 2
    rows = int(round((y1 - y0) / cell))
    return np.tile(values_by_x(x), (rows, 1)), dict(x0=x0, y_top=y1, cell=cell)


def test_seeds_are_shared_where_centre_lines_overlap():
    # R0 x 0..4 -> samples x = 1, 3; R1 x 2..6 -> x = 3, 5; x = 3 is one seed.
    seeds, membership = cover_seeds(hypotheses([box(0, -2, 4, 2), box(2, -2, 6, 2)]))
    np.testing.assert_allclose(seeds, [[1, 0], [3, 0], [5, 0]], atol=1e-12)
    assert membership.dtype == bool
    np.testing.assert_array_equal(membership.toarray(), [[1, 1, 0], [0, 1, 1]])


def test_seeds_of_a_rotated_rectangle_lie_on_its_axis_and_inside_it():
    rect = shapely.affinity.rotate(box(0, -3, 20, 3), 30, origin=(0, 0))
    seeds, membership = cover_seeds(hypotheses([rect], theta_rad=[math.radians(30)]))
    assert len(seeds) == 10
    u = np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    np.testing.assert_allclose(seeds @ u, np.arange(1, 20, 2), atol=1e-9)
    np.testing.assert_allclose(seeds @ [-u[1], u[0]], 0, atol=1e-9)
    assert membership.toarray().all()


def test_seed_likelihood_reads_every_band_and_nan_without_data():
    bands = np.stack([np.full((4, 4), 2.0), np.full((4, 4), 5.0)])
    bands[1, 0, 0] = np.nan
    values = seed_likelihood([[0.5, 3.5], [1.5, 1.5], [10, 10]], raster(bands, x0=0, y_top=4))
    np.testing.assert_array_equal(values, [[2, 2, np.nan], [np.nan, 5, np.nan]])


def test_seeds_off_the_maps_cost_nothing():
    # The rectangle runs 0..40 m; the maps end at x = 20 (L = L_max there). Only the 10
    # seeds on the maps count: Cost = 0 + A, and nothing is missed.
    hyp = hypotheses([box(0, -2, 40, 2)])
    band, where = along_x(lambda x: np.ones_like(x), x0=0, x1=20, y0=-3, y1=3)
    lik = raster([band], **where)
    greedy = greedy_min_cover(hyp, lik, l_max=1.0, a=3.0)
    assert greedy["density"].tolist() == pytest.approx([0.3])
    assert greedy.attrs["cover_cost"] == pytest.approx(3.0)


@pytest.fixture
def three_seeds():
    # seeds x = 1, 3, 5 with L = 10, 10, 2 (l_max 10): C = 0, 0, 0.8; dummy 1, 1, 0.2.
    hyp = hypotheses([box(0, -2, 4, 2), box(2, -2, 6, 2)])
    band, where = along_x(lambda x: np.where(x < 4, 10.0, 2.0), x1=8, y0=-3, y1=3)
    return hyp, raster([band], **where)


def test_three_seeds_greedy_and_exact_take_the_cheap_rectangle(three_seeds):
    # Cost(R0) = 0 + 0 + A = 0.5, Cost(R1) = 0 + 0.8 + 0.5 = 1.3. Eq. 7:
    # {} 2.2, {R0} 0.5 + 0.2 = 0.7, {R1} 1.3 + 1 = 2.3, {R0, R1} 1.8.
    hyp, lik = three_seeds
    greedy = greedy_min_cover(hyp, lik, l_max=10, a=0.5)
    exact = exact_min_cover(hyp, lik, l_max=10, a=0.5)
    for frame in (greedy, exact):
        assert frame["hyp_id"].tolist() == [100]
        assert frame.attrs["cover_cost"] == pytest.approx(0.7, abs=1e-9)
        assert frame["cost"].tolist() == pytest.approx([0.5], abs=1e-9)
        assert frame["density"].tolist() == pytest.approx([0.25], abs=1e-9)
        assert frame["mean_likelihood"].tolist() == pytest.approx([10.0], abs=1e-6)
    assert exact.attrs["optimal"]
    for ids, cost in [([], 2.2), ([100], 0.7), ([101], 2.3), ([100, 101], 1.8)]:
        assert cover_cost(ids, hyp, lik, l_max=10, a=0.5) == pytest.approx(cost, abs=1e-9)


def test_d_max_stops_the_greedy(three_seeds):
    # After R0, R1 would cover seed x = 5 alone at density (0.8 + 0.5) / 1 = 1.3.
    hyp, lik = three_seeds
    greedy = greedy_min_cover(hyp, lik, l_max=10, a=0.5, d_max=2.0)
    assert greedy["hyp_id"].tolist() == [100, 101]
    assert greedy["density"].tolist() == pytest.approx([0.25, 1.3], abs=1e-9)
    assert greedy["order"].tolist() == [0, 1]
    assert greedy.attrs["cover_cost"] == pytest.approx(1.8, abs=1e-9)


def test_greedy_takes_the_big_set_first_exact_does_not():
    # Six seeds x = 1..11, all L = L_max (C = 0), A = 1. Rc (4 seeds, density 1/4) goes first,
    # then Ra and Rb for one seed each: cost 3. The optimum is Ra + Rb: cost 2.
    hyp = hypotheses([box(0, -1, 6, 1), box(6, -1, 12, 1), box(2, -1, 10, 1)])
    band, where = along_x(lambda x: np.ones_like(x), x1=14, y0=-2, y1=2)
    lik = raster([band], **where)
    greedy = greedy_min_cover(hyp, lik, l_max=1, a=1.0, d_max=2.0)
    exact = exact_min_cover(hyp, lik, l_max=1, a=1.0)
    assert greedy["hyp_id"].tolist() == [102, 100, 101]
    assert greedy.attrs["cover_cost"] == pytest.approx(3.0, abs=1e-9)
    assert sorted(exact["hyp_id"]) == [100, 101]
    assert exact.attrs["cover_cost"] == pytest.approx(2.0, abs=1e-9)


@pytest.mark.parametrize("band_20m, band_10m, expected", [
    (1.0, 0.6, [100]),          # one 20 m road: the 20 m rectangle wins (Fig. 3, case 3)
    (0.6, 1.0, [101, 102]),     # two 10 m carriageways: the two 10 m rectangles win
])
def test_width_competition(band_20m, band_10m, expected):
    hyp = hypotheses([box(0, -10, 100, 10), box(0, 0, 100, 10), box(0, -10, 100, 0)],
                     width_index=[1, 0, 0])
    def road(level):
        return lambda x: np.where((x > 0) & (x < 100), level, 0.0)

    b20, where = along_x(road(band_20m), x1=102)
    b10, _ = along_x(road(band_10m), x1=102)
    lik = raster([b10, b20], **where)
    greedy = greedy_min_cover(hyp, lik, l_max=1.0)
    exact = exact_min_cover(hyp, lik, l_max=1.0)
    assert sorted(greedy["hyp_id"]) == expected
    assert sorted(exact["hyp_id"]) == expected
    assert greedy.attrs["cover_cost"] == pytest.approx(exact.attrs["cover_cost"], abs=1e-9)


def gap_instance(gap_m):
    """A 300 m road (10 m wide) with L = 0 over a central gap; hypotheses: the whole road
    and the two pieces either side of the gap."""
    half = 150 - gap_m / 2
    hyp = hypotheses([box(0, -5, 300, 5), box(0, -5, half, 5), box(300 - half, -5, 300, 5)])
    band, where = along_x(lambda x: np.where(np.abs(x - 150) < gap_m / 2, 0.0, 1.0))
    return hyp, raster([band], **where)


@pytest.mark.parametrize("gap_m, a, expected", [
    (8, 10.0, [100]),           # 4 gap seeds: (4 + A) / 150 beats A / 73, one rectangle
    (60, 10.0, [101, 102]),     # 30 gap seeds: covering them costs more than a second A
    (8, 1.0, [101, 102]),       # a small A does not bridge even a short gap
])
def test_occlusion_gap_bridged_when_a_pays_for_it(gap_m, a, expected):
    hyp, lik = gap_instance(gap_m)
    greedy = greedy_min_cover(hyp, lik, l_max=1.0, a=a)
    exact = exact_min_cover(hyp, lik, l_max=1.0, a=a)
    assert sorted(greedy["hyp_id"]) == expected
    assert sorted(exact["hyp_id"]) == expected


def test_progress_reaches_one_and_empty_input_gives_empty_frame():
    hyp, lik = gap_instance(8)
    calls = []
    greedy_min_cover(hyp, lik, l_max=1.0, progress=lambda f, m: calls.append(f))
    assert calls[-1] == 1.0 and all(0 <= f <= 1 for f in calls)
    empty = greedy_min_cover(hyp.iloc[:0], lik, l_max=1.0)
    assert len(empty) == 0 and "order" in empty and empty.attrs["cover_cost"] == 0.0


def random_instance(seed):
    """12 random rectangles (6 or 10 m wide, 10-40 m long, any direction) over two smooth
    random likelihood maps in a 60 m square."""
    rng = np.random.default_rng(seed)
    n = 12
    width_index = rng.integers(0, 2, n)
    width = np.array([6.0, 10.0])[width_index]
    length = rng.uniform(10, 40, n)
    theta = rng.uniform(0, np.pi, n)
    centre = rng.uniform(10, 50, (n, 2))
    rects = [shapely.affinity.rotate(box(c[0] - ln / 2, c[1] - w / 2, c[0] + ln / 2,
                                         c[1] + w / 2), t, origin=tuple(c), use_radians=True)
             for c, ln, w, t in zip(centre, length, width, theta)]
    hyp = hypotheses(rects, width_index=width_index, theta_rad=theta)
    bands = np.stack([gaussian_filter(rng.random((60, 60)), 3) for _ in range(2)])
    bands = (bands - bands.min()) / (bands.max() - bands.min())
    return hyp, raster(bands, x0=0, y_top=60)


def test_greedy_within_the_harmonic_bound_of_the_optimum_on_random_instances():
    ratios = []
    for seed in range(20):
        hyp, lik = random_instance(seed)
        greedy = greedy_min_cover(hyp, lik, l_max=1.0, a=2.0)
        exact = exact_min_cover(hyp, lik, l_max=1.0, a=2.0)
        _, membership = cover_seeds(hyp)
        largest = int(membership.sum(axis=1).max())
        harmonic = sum(1.0 / k for k in range(1, largest + 1))
        g, e = greedy.attrs["cover_cost"], exact.attrs["cover_cost"]
        assert exact.attrs["optimal"]
        assert e <= g + 1e-9
        assert g <= harmonic * e + 1e-9
        assert cover_cost(greedy["hyp_id"], hyp, lik, l_max=1.0, a=2.0) == pytest.approx(g)
        ratios.append(g / e)
    print(f"greedy/exact over 20 instances: median {np.median(ratios):.4f}, "
          f"max {np.max(ratios):.4f}")
