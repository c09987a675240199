"""The convolutional road model at run time (onnxruntime, no torch): the bundled network
loads, its probability is the same tiled or not, on the image grid, NaN exactly where the
image has no data, the same for a grey band as for that band three times and for 8- and
16-bit values; bad images and bad model files are refused; progress and cancel per tile.

Only properties are asserted here, never probability values: the bundled model may be
replaced by another training run at any time."""
import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from gisroads.geo import GeoRaster
from gisroads.learn.convnet import (DEFAULT_CONVNET_PATH, ConvNet, _windows,
                                    convnet_probability, is_convnet_file, load_convnet,
                                    network_input, normalisation)
from gisroads.progress import Cancelled
from gisroads.synthetic import make_scene, render_image

UTM = CRS.from_epsg(32633)
PIXEL_M = 0.75


@pytest.fixture(scope="module")
def bundled() -> ConvNet:
    if not DEFAULT_CONVNET_PATH.is_file():
        pytest.skip(f"the bundled road network {DEFAULT_CONVNET_PATH} is missing "
                    "(scripts/train_road_cnn.py writes it)")
    return load_convnet()


@pytest.fixture(scope="module")
def scene_rgb() -> GeoRaster:
    """A 300 x 300 m synthetic scene at 0.75 m: 400 x 400 uint8 R, G, B in UTM 33N."""
    image, _ = render_image(make_scene(seed=0, size_m=(300.0, 300.0)), pixel_m=PIXEL_M)
    assert image.shape == (400, 400) and image.crs.to_epsg() == 32633
    return GeoRaster(image.data[:3].copy(), image.transform, image.crs)


@pytest.fixture(scope="module")
def default_probability(bundled, scene_rgb) -> GeoRaster:
    return convnet_probability(scene_rgb, bundled)


def _like(image: GeoRaster, data, nodata=None) -> GeoRaster:
    return GeoRaster(data, image.transform, image.crs, nodata)


def _tiles_per_axis(n: int, tile: int, overlap: int) -> int:
    """Tiles of ``tile`` pixels overlapping by ``overlap`` that cover ``n`` pixels, the
    last one flush with the end; an axis shorter than a tile takes one window, or two
    when it is no multiple of 32."""
    if n < tile:
        return 1 if n % 32 == 0 else 2
    return int(np.ceil((n - tile) / (tile - overlap))) + 1


@pytest.mark.parametrize("n", [1, 31, 32, 200, 240, 512, 1000, 1024, 1500, 3000])
def test_windows_lie_inside_the_image_and_cover_it(n):
    windows = _windows(n, 1024, 64)
    assert len(windows) == _tiles_per_axis(n, 1024, 64) or n < 32
    covered = np.zeros(max(n, 32), bool)
    for start, size in windows:
        assert size % 32 == 0 and start >= 0
        assert start + size <= n or (n < 32 and (start, size) == (0, 32))
        covered[start:start + size] = True
    assert covered[:n].all()


def test_bundled_model_loads_with_its_working_pixel_and_threshold(bundled):
    assert bundled.path == DEFAULT_CONVNET_PATH
    assert 0.5 <= bundled.pixel_m <= 1.0
    assert 0.0 < bundled.threshold < 1.0
    assert bundled.metadata["pixel_m"] == bundled.pixel_m
    inputs = [i.name for i in bundled.session.get_inputs()]
    outputs = [o.name for o in bundled.session.get_outputs()]
    assert inputs == ["image"] and outputs == ["logit"]
    assert is_convnet_file(DEFAULT_CONVNET_PATH) and is_convnet_file("x/Model.ONNX")
    assert not is_convnet_file("model.npz")


def test_probability_is_on_the_image_grid_in_0_1(default_probability, scene_rgb):
    p = default_probability
    assert p.data.dtype == np.float32 and p.data.shape == scene_rgb.shape
    assert p.transform == scene_rgb.transform and p.crs == scene_rgb.crs
    assert np.isnan(p.nodata)
    assert np.isfinite(p.data).all()
    assert p.data.min() >= 0.0 and p.data.max() <= 1.0


def test_small_tiles_give_the_same_probability_as_large_ones(bundled, scene_rgb,
                                                             default_probability):
    rows, cols = (int(round(n * PIXEL_M / bundled.pixel_m)) for n in scene_rgb.shape)
    # the default is one tile for this image, 256-pixel tiles are several per axis
    assert _tiles_per_axis(rows, 256, 96) >= 2 and _tiles_per_axis(cols, 256, 96) >= 2
    tiled = convnet_probability(scene_rgb, bundled, tile_px=256, overlap_px=96)
    assert tiled.data.shape == default_probability.data.shape
    np.testing.assert_array_equal(np.isnan(tiled.data), np.isnan(default_probability.data))
    # the network sees about 300 working pixels around a pixel: a 256-pixel tile cuts some
    # of that context off (measured mean difference 0.030)
    assert np.nanmean(np.abs(tiled.data - default_probability.data)) < 0.05


def test_tiling_keeps_the_nan_pattern_of_a_partly_empty_image(bundled, scene_rgb):
    data = scene_rgb.data.astype(np.float32)
    data[:, 30:170, 250:390] = np.nan  # larger than a working tile's overlap
    data[:, 300:, :40] = np.nan
    image = _like(scene_rgb, data)
    whole = convnet_probability(image, bundled)
    tiled = convnet_probability(image, bundled, tile_px=256, overlap_px=96)
    empty = np.isnan(data).any(axis=0)
    np.testing.assert_array_equal(np.isnan(whole.data), empty)
    np.testing.assert_array_equal(np.isnan(tiled.data), empty)
    assert np.nanmean(np.abs(tiled.data - whole.data)) < 0.05


def test_half_empty_image_is_nan_exactly_where_it_has_no_data(bundled, scene_rgb):
    data = scene_rgb.data.astype(np.float32)
    data[:, :, :200] = np.nan
    p = convnet_probability(_like(scene_rgb, data, nodata=float("nan")), bundled)
    assert p.data.shape == scene_rgb.shape
    assert np.isnan(p.data[:, :200]).all()
    valid = p.data[:, 200:]
    assert np.isfinite(valid).all()
    assert valid.min() >= 0.0 and valid.max() <= 1.0


def test_a_declared_nodata_value_is_no_data(bundled, scene_rgb):
    data = scene_rgb.data.copy()
    data[:, 250:, 100:300] = 0  # black in every band: the nodata value
    data[0, :50, :50] = 0  # black in one band only: data
    p = convnet_probability(_like(scene_rgb, data, nodata=0), bundled)
    expected = np.zeros(scene_rgb.shape, bool)
    expected[250:, 100:300] = True
    np.testing.assert_array_equal(np.isnan(p.data), expected)


def test_a_single_band_is_the_same_as_that_band_three_times(bundled, scene_rgb):
    grey = scene_rgb.data[1]
    single = convnet_probability(_like(scene_rgb, grey[None].copy()), bundled)
    flat = convnet_probability(_like(scene_rgb, grey.copy()), bundled)  # (rows, cols)
    triple = convnet_probability(_like(scene_rgb, np.repeat(grey[None], 3, axis=0)), bundled)
    np.testing.assert_allclose(single.data, triple.data, rtol=0, atol=1e-6)
    np.testing.assert_allclose(flat.data, triple.data, rtol=0, atol=1e-6)


def test_extra_bands_after_the_third_are_ignored(bundled, scene_rgb, default_probability):
    rng = np.random.default_rng(0)
    nir = rng.integers(0, 256, scene_rgb.shape, dtype=np.uint8)
    four = np.concatenate([scene_rgb.data, nir[None]])
    p = convnet_probability(_like(scene_rgb, four), bundled)
    np.testing.assert_array_equal(p.data, default_probability.data)


def test_8_and_16_bit_values_of_one_image_give_the_same_probability(bundled, scene_rgb,
                                                                    default_probability):
    wide = scene_rgb.data.astype(np.uint16) * np.uint16(257)  # 255 -> 65535
    assert wide.dtype == np.uint16 and wide.max() > 255
    p16 = convnet_probability(_like(scene_rgb, wide), bundled)
    np.testing.assert_allclose(p16.data, default_probability.data, rtol=0, atol=1e-4)
    # and reflectance-like floats in [0, 1]
    reflectance = scene_rgb.data.astype(np.float32) / np.float32(255.0)
    pf = convnet_probability(_like(scene_rgb, reflectance), bundled)
    np.testing.assert_allclose(pf.data, default_probability.data, rtol=0, atol=1e-4)


@pytest.mark.parametrize("pixel_m", [0.3, 2.0])
def test_other_pixel_sizes_come_back_on_their_own_grid(bundled, pixel_m):
    """A finer image is shrunk to the working grid, a coarser one enlarged; the probability
    is on the image's own grid either way, NaN exactly where it has no data."""
    image, _ = render_image(make_scene(seed=2, size_m=(300.0, 300.0)), pixel_m=pixel_m)
    data = image.data[:3].astype(np.float32)
    rows, cols = image.shape
    data[:, :rows // 3, : cols // 4] = np.nan
    p = convnet_probability(_like(image, data), bundled)
    assert p.data.shape == (rows, cols) and p.transform == image.transform
    np.testing.assert_array_equal(np.isnan(p.data), np.isnan(data).any(axis=0))
    assert np.nanmin(p.data) >= 0.0 and np.nanmax(p.data) <= 1.0


@pytest.fixture(scope="module")
def scene_at_working_pixel() -> GeoRaster:
    """320 x 320 pixels at the working 1 m: one tile, no resampling, no padding."""
    image, _ = render_image(make_scene(seed=3, size_m=(320.0, 320.0)), pixel_m=1.0)
    assert image.shape == (320, 320)
    return GeoRaster(image.data[:3].copy(), image.transform, image.crs)


@pytest.mark.parametrize("views, turns", [(2, [(True, True)]),
                                          (4, [(True, True), (True, False), (False, True)])])
def test_averaged_views_make_the_probability_turn_with_the_image(bundled,
                                                                 scene_at_working_pixel,
                                                                 views, turns):
    image = scene_at_working_pixel
    alone = convnet_probability(image, bundled, views=1).data
    averaged = convnet_probability(image, bundled, views=views).data
    for flip_rows, flip_cols in turns:
        def turn(array, flip_rows=flip_rows, flip_cols=flip_cols):
            return array[..., ::-1 if flip_rows else 1, ::-1 if flip_cols else 1]
        turned = _like(image, np.ascontiguousarray(turn(image.data)))
        # the network alone is not equivariant; the average over the views is
        assert np.abs(turn(convnet_probability(turned, bundled, views=1).data)
                      - alone).max() > 1e-3
        np.testing.assert_allclose(turn(convnet_probability(turned, bundled,
                                                            views=views).data),
                                   averaged, atol=1e-5)
    with pytest.raises(ValueError, match="views"):
        convnet_probability(image, bundled, views=3)


def test_images_the_model_cannot_measure_are_refused(bundled, scene_rgb):
    geographic = GeoRaster(scene_rgb.data, Affine(1e-5, 0, 15.0, 0, -1e-5, 45.0),
                           CRS.from_epsg(4326))
    with pytest.raises(ValueError, match="projected metre CRS"):
        convnet_probability(geographic, bundled)
    with pytest.raises(ValueError, match="2"):
        convnet_probability(_like(scene_rgb, scene_rgb.data[:2].copy()), bundled)
    with pytest.raises(ValueError, match="no CRS"):
        convnet_probability(GeoRaster(scene_rgb.data, scene_rgb.transform, None), bundled)
    rotated = GeoRaster(scene_rgb.data, Affine(0.75, 0.1, 500000.0, 0.1, -0.75, 4500000.0),
                        UTM)
    with pytest.raises(ValueError, match="north-up"):
        convnet_probability(rotated, bundled)
    empty = np.full((3, 64, 64), np.nan, np.float32)
    with pytest.raises(ValueError, match="no valid pixel"):
        convnet_probability(_like(scene_rgb, empty), bundled)
    with pytest.raises(ValueError, match="overlap"):
        convnet_probability(scene_rgb, bundled, tile_px=128, overlap_px=64)


def test_files_that_are_not_road_networks_are_refused(tmp_path):
    with pytest.raises(ValueError, match="no such road model file"):
        load_convnet(tmp_path / "missing.onnx")
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(np.random.default_rng(0).bytes(4096))
    with pytest.raises(ValueError, match="not a readable ONNX model"):
        load_convnet(junk)
    text = tmp_path / "model.onnx"
    text.write_text("this is not a model\n")
    with pytest.raises(ValueError):
        load_convnet(text)


def test_an_onnx_model_without_gisroads_metadata_is_refused(tmp_path):
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Identity", ["image"], ["logit"])], "identity",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 32, 32])],
        [helper.make_tensor_value_info("logit", TensorProto.FLOAT, [1, 3, 32, 32])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    path = tmp_path / "identity.onnx"
    onnx.save(model, str(path))
    with pytest.raises(ValueError, match="without gisroads metadata"):
        load_convnet(path)
    entry = model.metadata_props.add()
    entry.key, entry.value = "gisroads", '{"threshold": 0.5}'
    onnx.save(model, str(path))
    with pytest.raises(ValueError, match="no pixel_m"):
        load_convnet(path)


def test_progress_is_reported_once_per_tile_and_ends_at_1(bundled, scene_rgb):
    calls = []
    convnet_probability(scene_rgb, bundled, tile_px=128, overlap_px=32,
                        progress=lambda fraction, message: calls.append((fraction, message)))
    rows, cols = (int(round(n * PIXEL_M / bundled.pixel_m)) for n in scene_rgb.shape)
    tiles = _tiles_per_axis(rows, 128, 32) * _tiles_per_axis(cols, 128, 32)
    assert len(calls) == tiles
    fractions = [f for f, _ in calls]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert 0.0 < fractions[0] < 1.0
    assert calls[-1][1].endswith(f"tile {tiles} of {tiles}")
    # the default tiles: a 300 x 300 px working grid, shorter than a tile and no multiple
    # of 32, takes two windows along each axis
    calls.clear()
    convnet_probability(scene_rgb, bundled,
                        progress=lambda fraction, message: calls.append(fraction))
    assert calls == [0.25, 0.5, 0.75, 1.0]


def test_cancel_from_the_progress_callback_stops_the_run(bundled, scene_rgb):
    calls = []

    def cancel_at_the_second_tile(fraction, message):
        calls.append(fraction)
        if len(calls) == 2:
            raise Cancelled

    with pytest.raises(Cancelled):
        convnet_probability(scene_rgb, bundled, tile_px=128, overlap_px=32,
                            progress=cancel_at_the_second_tile)
    assert len(calls) == 2 and calls[-1] < 1.0


def test_normalisation_maps_percentiles_to_plus_minus_a_half():
    rng = np.random.default_rng(0)
    bands = rng.uniform(0, 1000, (3, 50, 60)).astype(np.float32)
    valid = np.ones((50, 60), bool)
    valid[:, :10] = False
    bands[:, :, :10] = 1e9  # outside the valid pixels: must not count
    low, high = normalisation(bands, valid)
    expected = np.percentile(bands[:, valid].ravel(), (1.0, 99.0))
    assert (low, high) == pytest.approx(tuple(expected))
    x = network_input(bands, valid, low, high)
    assert x.dtype == np.float32 and x.shape == (3, 50, 60)
    assert (x[:, :, :10] == 0).all()
    assert x.min() >= -1.5 and x.max() <= 1.5
    inside = x[:, valid]
    assert np.mean(inside < -0.5) == pytest.approx(0.01, abs=0.005)
    assert np.mean(inside > 0.5) == pytest.approx(0.01, abs=0.005)
    # a single band becomes three equal channels; NaN becomes 0, not NaN
    grey = bands[:1].copy()
    grey[0, 0, 20] = np.nan
    valid[0, 20] = False
    single = network_input(grey, valid, low, high)
    assert single.shape == (3, 50, 60) and np.isfinite(single).all()
    np.testing.assert_array_equal(single[0], single[2])
    # a constant image does not divide by zero
    flat_low, flat_high = normalisation(np.full((3, 4, 4), 7.0), np.ones((4, 4), bool))
    assert flat_high > flat_low == 7.0
    with pytest.raises(ValueError, match="no valid pixel"):
        normalisation(bands, np.zeros((50, 60), bool))


def test_probabilities_are_the_same_in_both_environments(bundled):
    """Pinned to 1e-5: the same values in .venv (PyPI's numpy 2 and scipy) and .venv-qgis
    (Debian's numpy 1.24 and scipy 1.10), onnxruntime the same wheel in both."""
    scene = make_scene(seed=0, size_m=(300.0, 300.0))
    image, _ = render_image(scene, pixel_m=0.75)
    p = convnet_probability(GeoRaster(image.data[:3], image.transform, image.crs), bundled).data
    pixels = ([50, 100, 200, 300, 350, 189], [60, 200, 140, 390, 20, 184])
    np.testing.assert_allclose(p[pixels], [0.152651, 0.000272, 0.001424, 0.002407, 0.007825,
                                           0.999492], atol=1e-5)
    assert float(np.nanmean(p)) == pytest.approx(0.222203, abs=1e-5)
