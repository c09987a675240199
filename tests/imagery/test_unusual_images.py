"""Images as users have them: half of the image without data (NaN), an RGBA GeoTIFF whose
alpha band is the mask, a 16-bit panchromatic band. Each runs through `image_job` with the
convolutional network and with the boosted trees, and the roads stay where the data is."""
import warnings

import numpy as np
import pytest
import rasterio
import rasterio.features
import shapely
from rasterio.enums import ColorInterp

from gisroads.errors import NoRoadFoundWarning
from gisroads.geo import GeoRaster
from gisroads.imagery.baseline import road_colour_mask
from gisroads.io.raster import read_raster
from gisroads.io.vector import read_layer
from gisroads.jobs import image_job
from gisroads.synthetic import make_scene, render_image

TOLERANCE_M = 3.0
"""How far a road line or polygon may reach past the edge of the data, metres."""


@pytest.fixture(scope="module")
def scene():
    """A 300 x 300 m synthetic scene rendered at 1 m (R, G, B, NIR uint8), its roads and
    their polygons rasterised on the image grid."""
    scene = make_scene(seed=0, size_m=(300.0, 300.0))
    image, _ = render_image(scene, pixel_m=1.0)
    road = rasterio.features.rasterize(
        ((g.buffer(w / 2), 1) for g, w in zip(scene.roads.geometry, scene.roads.width_m)),
        out_shape=image.shape, transform=image.transform).astype(bool)
    return scene, image, road


def _write(path, data, image, *, nodata=None, colorinterp=None, **options):
    data = data[None] if data.ndim == 2 else data
    with rasterio.open(path, "w", driver="GTiff", width=data.shape[2], height=data.shape[1],
                       count=data.shape[0], dtype=data.dtype, crs=image.crs,
                       transform=image.transform, nodata=nodata, **options) as dst:
        if colorinterp is not None:
            dst.colorinterp = colorinterp
        dst.write(data)
    return path


def _image_job(*args, **kwargs):
    """image_job, allowing the no-road warning (the bundled network may find none)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NoRoadFoundWarning)
        return image_job(*args, **kwargs)


@pytest.fixture(scope="module")
def half_empty(scene, tmp_path_factory):
    """The scene's R, G, B as float32 with NaN (its nodata) in the left half."""
    _, image, _ = scene
    data = image.data[:3].astype(np.float32)
    data[:, :, :150] = np.nan
    path = tmp_path_factory.mktemp("half") / "half.tif"
    return _write(path, data, image, nodata=float("nan"))


@pytest.mark.parametrize("model", ["default", "boosted"])
def test_a_half_empty_image_gives_roads_only_over_its_data(scene, half_empty, tmp_path,
                                                            model):
    if model == "boosted":
        pytest.importorskip("sklearn")
    truth, image, _ = scene
    xmin, _, xmax, _ = image.bounds
    edge = xmin + 150 * image.pixel_size  # where the data starts
    # the valid half has roads
    right = truth.roads.clip((edge, image.bounds[1], xmax, image.bounds[3]))
    assert right.length.sum() > 200
    result = _image_job(half_empty, tmp_path / "roads.gpkg", model=model,
                        probability_path=tmp_path / "p.tif")
    assert result["model"] == ("boosted" if model == "boosted" else "road_convnet.onnx")
    probability = read_raster(tmp_path / "p.tif").data[0]
    assert probability.shape == image.shape
    assert np.isnan(probability[:, :150]).all()
    assert np.isfinite(probability[:, 150:]).all()
    assert np.nanmin(probability) >= 0 and np.nanmax(probability) <= 1
    lines = read_layer(tmp_path / "roads.gpkg", "road_centrelines")
    assert result["length_m"] == pytest.approx(lines.length.sum(), rel=1e-6, abs=1e-6)
    for layer in ("road_centrelines", "road_polygons", "junctions"):
        frame = read_layer(tmp_path / "roads.gpkg", layer)
        # a road polygon may reach past the data by half its road's width (its end cap)
        reach = TOLERANCE_M + (lines.width_m.max() / 2 if layer == "road_polygons" else 0)
        if len(frame):
            assert frame.total_bounds[0] >= edge - reach, layer
            assert frame.total_bounds[2] <= xmax + reach, layer
    assert result["roads"] > 0 and lines.length.sum() > 100
    # and none is drawn along the edge of the data: only roads that cross it come near it
    along_edge = shapely.box(edge - TOLERANCE_M, image.bounds[1] + 2 * TOLERANCE_M,
                             edge + TOLERANCE_M + 1, image.bounds[3] - 2 * TOLERANCE_M)
    near = shapely.length(shapely.intersection(lines.geometry.values, along_edge)).sum()
    assert near < 0.05 * lines.length.sum()


def test_road_colour_mask_of_a_half_empty_image(scene):
    """NaN pixels used to make the brightness range [nan, nan] ("autodetected range of
    [nan, nan] is not finite")."""
    _, image, road = scene
    data = image.data[:3].astype(np.float32)
    data[:, :, :150] = np.nan
    mask = road_colour_mask(GeoRaster(data, image.transform, image.crs, float("nan")))
    assert mask.dtype == bool and mask.shape == image.shape
    assert not mask[:, :150].any()
    assert mask[:, 150:].any()
    # road colour: the mask's pixels are road far more often than the valid half's
    assert road[:, 150:][mask[:, 150:]].mean() > 2 * road[:, 150:].mean()
    # the same as the valid half on its own, away from the edge (a smoothing's reach)
    alone = road_colour_mask(GeoRaster(data[:, :, 150:], image.transform, image.crs))
    agree = (alone == mask[:, 150:])[5:-5, 5:-5].mean()
    assert agree > 0.97


@pytest.fixture(scope="module")
def rgba(scene, tmp_path_factory):
    """The scene as an RGBA uint8 GeoTIFF, alpha 0 (transparent) on a block and a strip."""
    _, image, _ = scene
    alpha = np.full(image.shape, 255, np.uint8)
    alpha[100:200, 50:120] = 0
    alpha[:, 280:] = 0
    data = np.concatenate([image.data[:3], alpha[None]])
    path = _write(tmp_path_factory.mktemp("rgba") / "rgba.tif", data, image,
                  photometric="RGB",
                  colorinterp=[ColorInterp.red, ColorInterp.green, ColorInterp.blue,
                               ColorInterp.alpha])
    with rasterio.open(path) as src:
        assert src.colorinterp[3] == ColorInterp.alpha and src.count == 4
    return path, alpha


def test_an_alpha_band_is_dropped_and_its_transparent_pixels_are_no_data(scene, rgba):
    _, image, _ = scene
    path, alpha = rgba
    raster = read_raster(path)
    assert raster.data.shape == (3, *image.shape) and raster.data.dtype == np.float32
    transparent = alpha == 0
    np.testing.assert_array_equal(np.isnan(raster.data), np.broadcast_to(
        transparent, raster.data.shape))
    np.testing.assert_array_equal(raster.data[:, ~transparent],
                                  image.data[:3, ~transparent].astype(np.float32))
    assert raster.transform == image.transform and raster.crs == image.crs
    # asked for bands by number, the file is read as it is
    assert read_raster(path, bands=[1, 2, 3, 4]).data.shape[0] == 4


def test_a_fourth_band_marked_alpha_that_is_not_a_mask_is_kept(scene, tmp_path):
    """GDAL marks the fourth band of a 4-band 8-bit GeoTIFF as alpha, a near-infrared band
    too: a band of many values is data, not a mask."""
    _, image, _ = scene
    assert len(np.unique(image.data[3])) > 10
    path = _write(tmp_path / "rgbn.tif", image.data, image, photometric="RGB",
                  colorinterp=[ColorInterp.red, ColorInterp.green, ColorInterp.blue,
                               ColorInterp.alpha])
    raster = read_raster(path)
    assert raster.data.shape == (4, *image.shape)
    np.testing.assert_array_equal(raster.data, image.data)


def test_a_grey_image_with_alpha_is_one_band(scene, tmp_path):
    _, image, _ = scene
    alpha = np.full(image.shape, 255, np.uint8)
    alpha[:, :30] = 0
    path = _write(tmp_path / "la.tif", np.stack([image.data[1], alpha]), image,
                  colorinterp=[ColorInterp.gray, ColorInterp.alpha])
    raster = read_raster(path)
    assert raster.data.shape == (1, *image.shape)
    np.testing.assert_array_equal(np.isnan(raster.data[0]), alpha == 0)


def test_alpha_does_not_change_which_opaque_pixels_are_valid(scene, tmp_path):
    from gisroads.learn.features import valid_pixels

    _, image, _ = scene
    rgb = image.data[:3].copy()
    rgb[0, :5, :5] = 0  # a pure cyan-ish corner: 0 in the red band only
    alpha = np.full((1, *image.shape), 255, np.uint8)
    plain = read_raster(_write(tmp_path / "rgb.tif", rgb, image, nodata=0))
    with_alpha = read_raster(_write(
        tmp_path / "rgba.tif", np.concatenate([rgb, alpha]), image, nodata=0,
        photometric="RGB", colorinterp=[ColorInterp.red, ColorInterp.green,
                                        ColorInterp.blue, ColorInterp.alpha]))
    np.testing.assert_array_equal(valid_pixels(with_alpha), valid_pixels(plain))


@pytest.mark.parametrize("model", ["default", "boosted"])
def test_an_rgba_image_runs_with_no_data_where_it_is_transparent(scene, rgba, tmp_path,
                                                                 model):
    if model == "boosted":
        pytest.importorskip("sklearn")
    _, image, _ = scene
    path, alpha = rgba
    result = _image_job(path, tmp_path / "roads.gpkg", model=model,
                        probability_path=tmp_path / "p.tif")
    assert result["cues"] == "model"
    probability = read_raster(tmp_path / "p.tif").data[0]
    np.testing.assert_array_equal(np.isnan(probability), alpha == 0)
    lines = read_layer(tmp_path / "roads.gpkg", "road_centrelines")
    if len(lines):  # nothing in the transparent strip on the right
        assert lines.total_bounds[2] <= image.bounds[0] + 280 + TOLERANCE_M


@pytest.mark.parametrize("model", ["default", "boosted"])
def test_a_16_bit_panchromatic_image_runs(scene, tmp_path, model):
    if model == "boosted":
        pytest.importorskip("sklearn")
    _, image, _ = scene
    grey = image.data[:3].astype(np.float32).mean(axis=0)
    pan = np.round(grey * 257 * 0.25).astype(np.uint16)  # an 11-14 bit sensor's range
    assert pan.max() > 255
    path = _write(tmp_path / "pan.tif", pan, image)
    assert read_raster(path).data.shape == (1, *image.shape)
    result = _image_job(path, tmp_path / "roads.gpkg", model=model,
                        probability_path=tmp_path / "p.tif")
    assert result["model"] == ("boosted" if model == "boosted" else "road_convnet.onnx")
    probability = read_raster(tmp_path / "p.tif")
    assert probability.data.shape == (1, *image.shape)
    assert probability.data.dtype == np.float32
    assert np.isfinite(probability.data).all()
    assert probability.data.min() >= 0 and probability.data.max() <= 1
    assert (tmp_path / "roads.gpkg").is_file()
    if model == "boosted":
        assert result["roads"] > 0
