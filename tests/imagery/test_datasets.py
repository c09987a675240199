"""The real imagery benchmark loads in metres, with its truth where the roads are."""
import geopandas as gpd
import numpy as np
import pytest
import rasterio
import shapely
from affine import Affine

from gisroads.geo import GeoRaster
from gisroads.vectorize.skeleton import skeleton_lines
from gisroads.imagery.datasets import DATA_DIR, benchmark_images, mask_centrelines, prune_spurs

# pixel sizes stated in ../shared/data/README.md
README_PIXEL_M = {"spacenet_vegas": 0.3, "spacenet_paris": 0.3, "massachusetts": 1.0,
                  "deepglobe": 0.5, "eth": 0.6}
README_COUNTS = {"spacenet_vegas": 1, "spacenet_paris": 1, "massachusetts": 5,
                 "deepglobe": 2, "eth": 5}


@pytest.fixture(scope="module")
def images():
    return benchmark_images()


def test_every_image_loads_in_metres_with_the_readme_pixel_size(images):
    datasets = [record.dataset for record in images]
    assert {name: datasets.count(name) for name in README_COUNTS} == README_COUNTS
    for record in images:
        crs = record.image.crs
        assert not crs.is_geographic, record.name
        assert all(axis.unit_name == "metre" for axis in crs.axis_info[:2]), record.name
        expected = README_PIXEL_M[record.dataset]
        assert abs(record.image.pixel_size - expected) <= 0.1 * expected, record.name
        assert abs(record.image.transform.e) == pytest.approx(record.image.pixel_size)
        assert record.truth.crs == crs
        assert record.buffer_m == (4.0 if record.dataset == "massachusetts" else 3.0)
        assert record.source and record.image.data.ndim == 3


def test_truth_lines_lie_inside_the_image_and_its_valid_area(images):
    for record in images:
        frame = shapely.box(*record.image.bounds).buffer(1e-6)
        assert frame.contains(record.valid_area.buffer(-1e-6)), record.name
        if not record.scored:
            continue
        lines = shapely.union_all(record.truth.geometry.values)
        assert record.truth.length.sum() > 300, record.name
        assert set(record.truth.geom_type) == {"LineString"}
        assert record.valid_area.buffer(1e-6).contains(lines), record.name


def test_spacenet_tiles_are_warped_into_their_utm_zone(images):
    zones = {record.dataset: record.image.crs.to_epsg() for record in images
             if record.dataset.startswith("spacenet")}
    assert zones == {"spacenet_vegas": 32611, "spacenet_paris": 32631}


def test_vegas_labels_fall_on_the_warped_road_mask(images):
    vegas = next(record for record in images if record.dataset == "spacenet_vegas")
    lines = vegas.truth.geometry.values
    points = shapely.line_interpolate_point(
        np.repeat(lines, 200), np.tile(np.linspace(0.02, 0.98, 200), len(lines)),
        normalized=True)
    x, y = shapely.get_coordinates(points).T
    row, col = vegas.truth_mask.xy_to_rowcol(x, y)
    on_road = vegas.truth_mask.data[row, col]
    assert on_road.mean() > 0.95
    # the image was warped like the mask: its valid pixels cover the labels too
    assert (vegas.image.data[0][row, col] > 0).all()
    # and a shift of 10 m would leave the narrow label mask
    row, col = vegas.truth_mask.xy_to_rowcol(x + 10.0, y + 10.0)
    inside = (row < vegas.image.shape[0]) & (col < vegas.image.shape[1])
    assert vegas.truth_mask.data[row[inside], col[inside]].mean() < 0.5


@pytest.mark.filterwarnings("ignore::rasterio.errors.NotGeoreferencedWarning")
def test_massachusetts_white_no_data_is_outside_the_valid_area(images):
    tiles = {record.name.split("/")[1]: record for record in images
             if record.dataset == "massachusetts"}
    tile = tiles["10078735_15"]
    white = (tile.image.data == 255).all(axis=0)
    rows, cols = np.nonzero(white)
    sample = slice(None, None, 97)
    t = tile.image.transform
    x, y = t.c + (cols[sample] + 0.5) * t.a, t.f + (rows[sample] + 0.5) * t.e
    inside = shapely.contains_xy(tile.valid_area, x, y)
    assert white.mean() > 0.6 and inside.mean() < 0.01
    assert tile.valid_area.area / 1500 ** 2 == pytest.approx(1 - white.mean(), abs=0.02)
    # the edge case: every road of 10078750 lies in no-data, so there is nothing to score
    edge = tiles["10078750_15"]
    with rasterio.open(DATA_DIR / "massachusetts" / "masks" / "10078750_15.png") as src:
        assert (src.read(1) > 0).sum() > 10_000
    assert not edge.scored and len(edge.truth) == 0
    assert all(record.scored for name, record in tiles.items() if name != "10078750_15")


def test_crop_keeps_the_georeferencing_and_clips_the_truth(images):
    eth = next(record for record in images if record.dataset == "eth")
    part = eth.crop(100, 50, 200, 300)
    assert part.image.shape == (200, 300)
    assert part.image.transform.c == pytest.approx(eth.image.transform.c + 50 * 0.6)
    assert part.image.transform.f == pytest.approx(eth.image.transform.f - 100 * 0.6)
    np.testing.assert_array_equal(part.image.data, eth.image.data[:, 100:300, 50:350])
    assert shapely.box(*part.image.bounds).buffer(1e-6).contains(
        shapely.union_all(part.truth.geometry.values))
    assert 0 < part.truth.length.sum() < eth.truth.length.sum()
    with pytest.raises(ValueError, match="outside"):
        eth.crop(400, 0, 10, 10)


def test_prune_spurs_drops_short_end_branches_only():
    def frame(*coords):
        return gpd.GeoDataFrame({"width_m": np.full(len(coords), 6.0)},
                                geometry=[shapely.LineString(c) for c in coords])
    west, east = [(0, 0), (50, 0)], [(50, 0), (100, 0)]
    pruned = prune_spurs(frame(west, east, [(50, 0), (50, 4)]), spur_m=10.0)
    assert len(pruned) == 1 and pruned.length.iloc[0] == pytest.approx(100.0)
    assert pruned["width_m"].iloc[0] == pytest.approx(6.0)
    kept = prune_spurs(frame(west, east, [(50, 0), (50, 40)]), spur_m=10.0)
    assert sorted(kept.length.round(6)) == [40.0, 50.0, 50.0]


def test_mask_centrelines_of_a_band_and_a_cross():
    transform = Affine(1.0, 0, 0, 0, -1.0, 60.0)
    band = np.zeros((60, 100), bool)
    band[20:27] = True
    lines = mask_centrelines(GeoRaster(band, transform, None))
    assert len(lines) == 1
    y = shapely.get_coordinates(lines.geometry.iloc[0])[:, 1]
    assert np.abs(y - (60 - 23.5)).max() <= 1.0  # the middle row, give or take the ends
    # pixel centres 0.5 to 99.5, less up to half the width at each end (skeleton ends)
    assert 99.0 - 7.0 <= lines.length.iloc[0] <= 99.0
    assert lines["width_m"].iloc[0] == pytest.approx(7.0, abs=1.5)
    cross = np.zeros((100, 100), bool)
    cross[45:56] = True
    cross[:, 45:56] = True
    arms = mask_centrelines(GeoRaster(cross, Affine(1.0, 0, 0, 0, -1.0, 100.0), None))
    # four arms from the middle towards the borders
    assert len(arms) == 4
    assert ((arms.length > 49.5 - 7.0) & (arms.length <= 50.5)).all()


def test_mask_centrelines_prune_the_spurs_of_border_bumps():
    band = np.zeros((60, 200), bool)
    band[25:40] = True
    for col in range(10, 190, 20):
        band[20:25, col:col + 5] = True  # driveway-like bumps of 5 x 5 m
    transform = Affine(1.0, 0, 0, 0, -1.0, 60.0)
    raw = skeleton_lines(band, transform, None)
    assert len(raw) > 10  # a spur towards every bump
    lines = mask_centrelines(GeoRaster(band, transform, None))
    assert len(lines) == 1 and lines.length.iloc[0] > 170.0
    y = shapely.get_coordinates(lines.geometry.iloc[0])[:, 1]
    assert np.abs(y - (60 - 32.5)).max() <= 1.0  # along the band's middle row


def test_bad_requests_are_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown datasets"):
        benchmark_images(datasets=["vegas"])
    with pytest.raises(FileNotFoundError):
        benchmark_images(tmp_path / "nowhere")
