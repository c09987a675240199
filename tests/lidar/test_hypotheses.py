"""Rectangle road hypotheses and per-width likelihood maps (Zhu & Mordohai Sec. 4.3, Eq. 5)."""
import numpy as np
import pytest
import rasterio.features
import shapely
from affine import Affine
from pyproj import CRS
from rasterio.enums import MergeAlg
from scipy import ndimage

from gisroads.features.edges import local_energy
from gisroads.features.rectangles import interior_sign
from gisroads.geo import GeoRaster
from gisroads.jobs.common import stage_default
from gisroads.lidar.hypotheses import (DEFAULT_WIDTHS_M, L_MAX, T_BD, HypothesisOptions,
                                       likelihood_maps, road_hypotheses)

CELL_M = 0.5
SIZE_M = 300.0
X0, Y0 = 1000.0, 2000.0
TRANSFORM = Affine(CELL_M, 0, X0, 0, -CELL_M, Y0 + SIZE_M)
CRS_ = CRS.from_epsg(32633)
ROAD_THETA = np.radians(30.0)
ROAD_START = np.array([40.0, 40.0])  # metres from the lower-left corner
ROAD_WIDTH_M, ROAD_LENGTH_M = 10.0, 200.0
LOT = (200.0, 220.0, 40.0)  # lower-left x, y and side of the parking lot, metres
CROSSWALK_S_M = (100.0, 105.0)  # along the road


def _pixel_centres():
    n = int(SIZE_M / CELL_M)
    cols, rows = np.meshgrid(np.arange(n) + 0.5, np.arange(n) + 0.5)
    return cols * CELL_M, SIZE_M - rows * CELL_M  # local x, y


def _road_frame(x, y):
    """Distance along the road and to its left, metres."""
    dx, dy = x - ROAD_START[0], y - ROAD_START[1]
    return (dx * np.cos(ROAD_THETA) + dy * np.sin(ROAD_THETA),
            -dx * np.sin(ROAD_THETA) + dy * np.cos(ROAD_THETA))


def _scene(*, crosswalk=False, seed=0):
    """A dark 10 m road at 30 degrees with two bright dashed lane lines, a dark square
    parking lot, a bright background and noise; intensity in [0, 1]."""
    x, y = _pixel_centres()
    along, left = _road_frame(x, y)
    image = np.full(x.shape, 0.7)
    road = (np.abs(left) <= ROAD_WIDTH_M / 2) & (along >= 0) & (along <= ROAD_LENGTH_M)
    image[road] = 0.2
    for offset in (-1.75, 1.75):
        image[road & (np.abs(left - offset) <= 0.3) & (np.mod(along, 8.0) < 3.0)] = 0.8
    if crosswalk:  # three 1 m bars across the road, 1 m apart
        bars = (road & (along >= CROSSWALK_S_M[0]) & (along < CROSSWALK_S_M[1])
                & (np.mod(along - CROSSWALK_S_M[0], 2.0) < 1.0))
        image[bars] = 0.8
    lot_x, lot_y, side = LOT
    lot = (x >= lot_x) & (x <= lot_x + side) & (y >= lot_y) & (y <= lot_y + side)
    image[lot] = 0.2
    image += 0.05 * np.random.default_rng(seed).standard_normal(image.shape)
    return image.astype(np.float32), road, lot


def _labels(image):
    """A stand-in for the NCut over-segmentation: dark regions and the bright rest."""
    smooth = ndimage.gaussian_filter(np.nan_to_num(image, nan=1.0), 1.0)
    labels = ndimage.label(smooth < 0.45)[0].astype(np.int32)
    labels[np.isnan(image)] = -1
    return labels


def _run(image, **kwargs):
    raster = GeoRaster(image, TRANSFORM, CRS_)
    magnitude, orientation = local_energy(image)
    return raster, road_hypotheses(raster, magnitude, orientation, _labels(image), **kwargs)


def _road_polygon():
    direction = np.array([np.cos(ROAD_THETA), np.sin(ROAD_THETA)])
    normal = np.array([-direction[1], direction[0]]) * ROAD_WIDTH_M / 2
    start = ROAD_START + np.array([X0, Y0])
    end = start + ROAD_LENGTH_M * direction
    return shapely.Polygon([start - normal, end - normal, end + normal, start + normal])


@pytest.fixture(scope="module")
def road_scene():
    image, road, lot = _scene()
    raster, hypotheses = _run(image)
    return raster, hypotheses, road, lot


def test_best_hypothesis_follows_the_road_with_its_width(road_scene):
    _, hypotheses, _, _ = road_scene
    best = hypotheses.iloc[0]
    assert best["score"] == hypotheses["score"].max()
    off = np.degrees(np.mod(best["theta_rad"] - ROAD_THETA + np.pi / 2, np.pi) - np.pi / 2)
    assert abs(off) < 5
    assert 9 <= best["width_m"] <= 12
    inside = shapely.area(shapely.intersection(best.geometry, _road_polygon()))
    assert inside >= 0.8 * best.geometry.area
    # the 10 m road gets better windows at 9-12 m than at 20 m
    by_width = hypotheses.groupby("width_m")["score"].max()
    assert max(by_width.get(9.0, 0), by_width.get(12.0, 0)) > by_width.get(20.0, 0) + 0.1


def test_parking_lot_scores_far_below_the_road(road_scene):
    raster, hypotheses, road, lot = road_scene
    maps = likelihood_maps(hypotheses, raster)
    assert maps.data.shape == (len(DEFAULT_WIDTHS_M),) + raster.shape
    assert maps.data.dtype == np.float32
    best_width = maps.data.max(axis=0)
    assert np.median(best_width[road]) == L_MAX  # the road saturates the cap
    assert best_width[lot].max() <= 0.2 * L_MAX


def test_columns_and_geometry_agree(road_scene):
    _, hypotheses, _, _ = road_scene
    assert list(hypotheses.columns) == ["hyp_id", "x0_m", "y0_m", "theta_rad", "width_m",
                                        "length_m", "s_bd", "s_int", "score", "width_index",
                                        "geometry"]
    assert hypotheses.crs == CRS_
    np.testing.assert_array_equal(hypotheses["hyp_id"], np.arange(len(hypotheses)))
    assert np.all(np.diff(hypotheses["score"].to_numpy()) <= 0)
    np.testing.assert_allclose(hypotheses["score"], hypotheses["s_bd"] + hypotheses["s_int"])
    np.testing.assert_array_equal(np.asarray(DEFAULT_WIDTHS_M)[hypotheses["width_index"]],
                                  hypotheses["width_m"])
    corners = shapely.get_coordinates(hypotheses.geometry.values).reshape(-1, 5, 2)
    theta = hypotheses["theta_rad"].to_numpy()
    direction = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    right = np.stack([np.sin(theta), -np.cos(theta)], axis=1)
    np.testing.assert_allclose(corners[:, 0], hypotheses[["x0_m", "y0_m"]], atol=1e-6)
    np.testing.assert_allclose(corners[:, 1] - corners[:, 0],
                               direction * hypotheses[["length_m"]].to_numpy(), atol=1e-6)
    np.testing.assert_allclose(corners[:, 2] - corners[:, 1],
                               right * hypotheses[["width_m"]].to_numpy(), atol=1e-6)
    assert (hypotheses["s_bd"] >= 0.08).all() and (hypotheses["s_int"] >= 0).all()


def test_likelihood_equals_rasterising_the_rectangles_with_add(road_scene):
    raster, hypotheses, _, _ = road_scene
    sample = hypotheses.sample(n=min(3000, len(hypotheses)), random_state=0)
    maps = likelihood_maps(sample, raster, beta_bd=2.0, beta_int=0.5, l_max=np.inf)
    for k, width_m in enumerate(DEFAULT_WIDTHS_M):
        chosen = sample[sample["width_m"] == width_m]
        expected = np.zeros(raster.shape, np.float32)
        if len(chosen):
            rasterio.features.rasterize(
                zip(chosen.geometry, 2.0 * chosen["s_bd"] + 0.5 * chosen["s_int"]),
                out=expected, transform=raster.transform, merge_alg=MergeAlg.add)
        np.testing.assert_allclose(maps.data[k], expected, atol=1e-3, rtol=1e-5)
    capped = likelihood_maps(sample, raster, l_max=1.5)
    assert capped.data.max() == pytest.approx(1.5)


def test_crosswalk_bars_across_the_road_cost_no_interior_penalty():
    """Fig. 2(b): edges near-orthogonal to the road weigh 0 in F_int (Eq. 3), so the bars
    of a crosswalk add no negative evidence; the window only loses the dashed lines and
    kerb edges the bars hide."""
    x, y = _pixel_centres()
    along, left = _road_frame(x, y)
    window = (np.abs(left) <= ROAD_WIDTH_M / 2) & (np.abs(along - np.mean(CROSSWALK_S_M)) <= 10)
    energy = {}
    for crosswalk in (False, True):
        image, _, _ = _scene(crosswalk=crosswalk)
        magnitude, orientation = local_energy(image)
        weight = interior_sign(orientation, ROAD_THETA)
        energy[crosswalk] = {w: np.where(weight == w, magnitude, 0)[window].mean()
                             for w in (-1, 0, 1)}
        energy[crosswalk]["s_int"] = (weight * magnitude)[window].mean()
    assert energy[True][0] > 10 * energy[False][0]  # the bars' edges, at weight 0
    assert energy[True][-1] <= 1.1 * energy[False][-1]  # no more penalised energy
    assert energy[True]["s_int"] > 0.5 * energy[False]["s_int"] > 0


def test_straight_road_on_the_grid_gives_exact_windows():
    """Noise-free horizontal road, rows 40-59 (10 m): the exact-width windows have the
    full contrast and their left side on the road's north (eastwards) or south edge."""
    image = np.full((100, 400), 0.8, np.float32)
    image[40:60] = 0.2
    labels = (image < 0.5).astype(np.int32)
    raster = GeoRaster(image, TRANSFORM, CRS_)
    zeros = np.zeros(image.shape, np.float32)
    hypotheses = road_hypotheses(raster, zeros, zeros, labels, widths_m=(10.0, 16.0),
                                 lengths_m=(40.0,), orientations_rad=[0.0, np.pi])
    assert set(hypotheses["width_m"]) == {10.0}  # 16 m has no contrast on its far side
    np.testing.assert_allclose(hypotheses["s_bd"], 0.6, atol=1e-6)
    np.testing.assert_allclose(hypotheses["s_int"], 0.0)
    north, south = TRANSFORM.f - 40 * CELL_M, TRANSFORM.f - 60 * CELL_M
    eastwards = np.isclose(hypotheses["theta_rad"], 0.0)
    westwards = np.isclose(hypotheses["theta_rad"], np.pi)
    assert eastwards.any() and westwards.any() and (eastwards | westwards).all()
    np.testing.assert_allclose(hypotheses.loc[eastwards, "y0_m"], north)
    np.testing.assert_allclose(hypotheses.loc[westwards, "y0_m"], south)
    across_road = shapely.box(X0 - 100, south, X0 + 300, north).buffer(1e-6)
    assert shapely.within(hypotheses.geometry.values, across_road).all()
    on_image = shapely.area(shapely.intersection(hypotheses.geometry.values,
                                                 shapely.box(X0, south, X0 + 200, north)))
    assert (on_image >= 0.5 * 400 - 1e-6).all()  # windows lie mostly on data


def test_windows_start_on_the_kerb_where_the_segments_split_at_the_sidewalk():
    """A 10 m road (rows 40-59) with 2 m sidewalks (rows 36-39, 60-63) on grass, segmented
    at the sidewalks' outer lines: the windows snap to the kerbs and take the road's
    width; the 14 m of road and sidewalks, the first thing the segments offer, and windows
    stubbier than three times their width are refused."""
    image = np.full((100, 400), 0.9, np.float32)
    image[36:64] = 0.5
    image[40:60] = 0.1
    labels = (image < 0.7).astype(np.int32)
    raster = GeoRaster(image, TRANSFORM, CRS_)
    zeros = np.zeros(image.shape, np.float32)
    kwargs = dict(widths_m=(10.0, 14.0), lengths_m=(40.0, 80.0), orientations_rad=[0.0])
    hypotheses = road_hypotheses(raster, zeros, zeros, labels, **kwargs)
    assert set(hypotheses["width_m"]) == {10.0}
    north, south = TRANSFORM.f - 40 * CELL_M, TRANSFORM.f - 60 * CELL_M
    bounds = np.array([g.bounds for g in hypotheses.geometry.values])
    np.testing.assert_allclose(bounds[:, [1, 3]], np.tile([south, north], (len(bounds), 1)))
    unsnapped = road_hypotheses(raster, zeros, zeros, labels, snap_m=0.0, edge_ratio=0.0,
                                **kwargs)
    assert 14.0 in set(unsnapped["width_m"])
    stubby = road_hypotheses(raster, zeros, zeros, labels, widths_m=(10.0,),
                             lengths_m=(20.0, 40.0), orientations_rad=[0.0])
    assert set(stubby["length_m"]) == {40.0}
    # the options as one object give what the keywords give
    options = HypothesisOptions(snap_m=0.0, edge_ratio=0.0, **kwargs)
    np.testing.assert_array_equal(
        road_hypotheses(raster, zeros, zeros, labels, options)["width_m"],
        unsnapped["width_m"])


def test_options_are_one_object_with_the_papers_defaults():
    assert stage_default(road_hypotheses, "t_bd") == HypothesisOptions().t_bd == T_BD
    assert stage_default(road_hypotheses, "widths_m") == DEFAULT_WIDTHS_M
    with pytest.raises(KeyError, match="no parameter 'lanes'"):
        stage_default(road_hypotheses, "lanes")
    image = GeoRaster(np.zeros((10, 10), np.float32), TRANSFORM, CRS_)
    with pytest.raises(TypeError, match="lanes"):
        road_hypotheses(image, image.data, image.data, np.zeros((10, 10), np.int32), lanes=2)
    with pytest.raises(AttributeError):
        HypothesisOptions().t_bd = 0.5  # frozen: a default cannot be changed by accident


def test_missing_data_counts_as_missing():
    image, road, _ = _scene(seed=1)
    rng = np.random.default_rng(2)
    rows, cols = np.nonzero(road)
    for i in rng.choice(len(rows), 60, replace=False):  # car-sized holes on the road
        image[rows[i]:rows[i] + 4, cols[i]:cols[i] + 9] = np.nan
    image[:, 200:206] = np.nan  # a scan gap across the road
    image[:, 480:] = np.nan  # no data east of x = 240 m
    raster, hypotheses = _run(image)
    best = hypotheses.iloc[0]
    assert 9 <= best["width_m"] <= 12
    inside = shapely.area(shapely.intersection(best.geometry, _road_polygon()))
    assert inside >= 0.8 * best.geometry.area
    no_data = np.isnan(image)
    for geometry in hypotheses.geometry.values[::max(len(hypotheses) // 200, 1)]:
        covered = rasterio.features.geometry_mask([geometry], raster.shape, TRANSFORM,
                                                  invert=True)
        assert no_data[covered].mean() <= 0.5


def test_no_boundaries_no_hypotheses_and_empty_maps():
    image = np.full((80, 80), 0.5, np.float32)
    raster = GeoRaster(image, TRANSFORM, CRS_)
    zeros = np.zeros(image.shape, np.float32)
    calls = []
    hypotheses = road_hypotheses(raster, zeros, zeros, np.zeros(image.shape, np.int32),
                                 orientations_rad=[0.3, 1.2],
                                 progress=lambda f, m: calls.append(f))
    assert len(hypotheses) == 0 and "score" in hypotheses.columns
    assert calls[0] == 0.0 and calls[-1] == 1.0 and calls == sorted(calls)
    maps = likelihood_maps(hypotheses, raster)
    assert maps.data.shape == (6, 80, 80) and not maps.data.any()


def test_grids_that_are_not_north_up_are_refused():
    image = np.zeros((10, 10), np.float32)
    flipped = GeoRaster(image, Affine(CELL_M, 0, X0, 0, CELL_M, Y0), CRS_)
    with pytest.raises(ValueError, match="north-up"):
        road_hypotheses(flipped, image, image, np.zeros((10, 10), np.int32))
