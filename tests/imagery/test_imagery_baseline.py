"""The naive imagery baseline: road colour, morphology, skeleton."""
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS

from gisroads.evaluate import buffer_metrics
from gisroads.geo import CONTRACT_SCHEMA, GeoRaster
from gisroads.imagery.baseline import METHOD, baseline_roads, road_colour_mask
from gisroads.imagery.datasets import load_eth, load_massachusetts
from gisroads.synthetic import make_scene, render_image

UTM = CRS.from_epsg(32633)


def _grass(rows: int, cols: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    colour = np.array([78, 112, 52], float)[:, None, None]
    return np.clip(colour + 12 * rng.standard_normal((3, rows, cols)), 0, 255).astype(np.uint8)


def test_road_colour_mask_takes_a_grey_road_not_grass_nor_a_white_roof():
    image = _grass(80, 120)
    image[:, 30:40] = 120  # a grey road across, 10 px wide
    image[:, 55:75, 70:90] = 250  # a white roof, among the brightest 5 % of the image
    mask = road_colour_mask(GeoRaster(image, Affine(0.5, 0, 0, 0, -0.5, 40), UTM))
    assert mask[31:39].mean() > 0.95
    assert not mask[61:69, 76:84].any()
    grass = np.ones((80, 120), bool)
    grass[25:45] = False
    grass[48:, 63:97] = False  # the roof and its smoothed border, which does look grey
    assert mask[grass].mean() < 0.01


@pytest.fixture(scope="module")
def synthetic():
    scene = make_scene(seed=3, size_m=(300.0, 300.0))
    image, _ = render_image(scene, pixel_m=0.5)
    return scene, image


def test_baseline_finds_most_roads_of_a_synthetic_image(synthetic):
    scene, image = synthetic
    network = baseline_roads(GeoRaster(image.data[:3], image.transform, image.crs))
    network.validate()
    assert set(network.centrelines["method"]) == {METHOD}
    assert network.crs == image.crs
    scores = buffer_metrics(network.centrelines, scene.truth.centrelines, buffer_m=3.0)
    assert scores.completeness > 0.45  # measured 0.56
    assert scores.correctness > 0.85  # measured 0.97
    width = network.centrelines["width_m"]
    assert width.between(3.0, 25.0).mean() > 0.9


def test_baseline_on_a_panchromatic_image(synthetic):
    scene, image = synthetic
    pan = GeoRaster(image.data[:3].mean(axis=0, keepdims=True).astype(np.uint8),
                    image.transform, image.crs)
    scores = buffer_metrics(baseline_roads(pan).centrelines, scene.truth.centrelines,
                            buffer_m=3.0)
    # brightness alone also takes grey roofs and paving: much weaker, not nothing
    assert scores.completeness > 0.15  # measured 0.21
    assert scores.correctness > 0.12  # measured 0.19


@pytest.mark.parametrize("image", [_grass(200, 200), np.full((3, 200, 200), 128, np.uint8)],
                         ids=["grass", "constant"])
def test_no_road_input_gives_an_empty_valid_network(image):
    network = baseline_roads(GeoRaster(image, Affine(0.5, 0, 0, 0, -0.5, 100), UTM))
    network.validate()
    for name, frame in network.layers().items():
        assert len(frame) == 0
        assert set(CONTRACT_SCHEMA[name]) <= set(frame.columns)
    assert network.crs == UTM


def test_geographic_input_is_refused():
    image = GeoRaster(_grass(10, 10), Affine(2.7e-6, 0, 2.28, 0, -2.7e-6, 48.98),
                      CRS.from_epsg(4326))
    with pytest.raises(ValueError, match="geographic"):
        baseline_roads(image)


def test_baseline_on_a_real_eth_image():
    eth, = load_eth(stems=["satImage_010"])
    scores = buffer_metrics(baseline_roads(eth.image).centrelines, eth.truth,
                            buffer_m=eth.buffer_m, valid_area=eth.valid_area)
    assert scores.completeness > 0.3  # measured 0.39
    assert scores.correctness > 0.45  # measured 0.61


def test_baseline_ignores_massachusetts_white_no_data():
    tile, = load_massachusetts(stems=["10078735_15"])
    tile = tile.crop(0, 600, 900, 900)
    lines = baseline_roads(tile.image).centrelines
    assert lines.length.sum() > 500
    outside = shapely.difference(shapely.union_all(lines.geometry.values), tile.valid_area)
    assert outside.length < 0.02 * lines.length.sum()
