import time
from pathlib import Path

import numpy as np
import pytest
import shapely
from affine import Affine
from rasterio.features import rasterize
from scipy import ndimage
from scipy.sparse import csr_matrix

from gisroads.geo import GeoRaster
from gisroads.geo import LOCAL_CRS
from gisroads.imagery.datasets import ETH_PIXEL_M
from gisroads.imagery.segments import (default_counts, edge_strength, frame_to_labels,
                                       ndvi_affinity, segment_image, segments_to_frame)
from gisroads.io.raster import read_raster
from gisroads.progress import Cancelled
from gisroads.segmentation.ncut import segment_boundaries
from gisroads.synthetic import make_scene, render_image

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "imagery"
CRS = "EPSG:32633"


def raster(data, pixel_m=0.25):
    rows = np.asarray(data).shape[-2]
    return GeoRaster(np.asarray(data), Affine(pixel_m, 0, 500000.0, 0, -pixel_m,
                                              4500000.0 + rows * pixel_m), CRS)


def boundary_recall(labels, truth_edge, within_px):
    """Share of truth edge pixels within ``within_px`` of a segment boundary."""
    distance = ndimage.distance_transform_edt(~segment_boundaries(labels))
    return float((distance[truth_edge] <= within_px).mean())


def straddling_share(labels, region):
    """Share of pixels in segments that straddle ``region``'s border (minority side)."""
    ids = labels[labels >= 0]
    inside = region[labels >= 0]
    total = np.bincount(ids)
    in_region = np.bincount(ids, inside)
    return float(np.minimum(in_region, total - in_region).sum() / ids.size)


def road_strip_image(seed=0, bands=3):
    """200 x 200 px green background with a grey road strip (rows 80-111) and noise."""
    rng = np.random.default_rng(seed)
    road = np.zeros((200, 200), bool)
    road[80:112] = True
    colour = np.where(road[None], np.array([86, 88, 91, 92.0])[:bands, None, None],
                      np.array([78, 112, 52, 188.0])[:bands, None, None])
    return colour + rng.normal(0, 4, colour.shape), road


def textured_halves(n=192):
    """``(east half, data, rng)``: 4 bands of one blocky texture of +-40 over both halves
    of an n x n image, with noise, so that no colour tells the halves apart."""
    rng = np.random.default_rng(0)
    east = np.zeros((n, n), bool)
    east[:, n // 2:] = True
    texture = np.kron(rng.uniform(-40, 40, (n // 8, n // 8)), np.ones((8, 8)))
    return east, 100.0 + texture[None] + rng.normal(0, 3, (4, n, n)), rng


def test_segment_borders_fall_on_road_edges_of_a_hand_made_strip():
    data, road = road_strip_image()
    labels = segment_image(raster(data.astype(np.float32)), n_segments=24)
    assert labels.dtype == np.int32 and labels.shape == road.shape
    assert labels.min() == 0 and 20 <= labels.max() + 1 <= 40
    assert np.array_equal(np.unique(labels), np.arange(labels.max() + 1))
    edge = road ^ ndimage.binary_erosion(road, border_value=1)
    assert boundary_recall(labels, edge, 1) > 0.95
    assert straddling_share(labels, road) < 0.01
    # every segment one 4-connected region
    assert ndimage.label(labels >= 0)[1] == 1
    assert all(ndimage.label(labels == i)[1] == 1 for i in range(labels.max() + 1))


def test_panchromatic_image_with_nodata_is_segmented_and_nodata_is_minus_one():
    data, road = road_strip_image(bands=2)
    data = data[1].astype(np.float32)  # green: 88 on the road, 112 beside it
    data[:, :30] = np.nan
    labels = segment_image(raster(data), n_segments=20)
    assert (labels[:, :30] == -1).all() and (labels[:, 30:] >= 0).all()
    edge = (road ^ ndimage.binary_erosion(road, border_value=1))
    edge[:, :31] = False
    assert boundary_recall(labels, edge, 1) > 0.9
    nodata = raster(np.where(np.isnan(data), 0, data).astype(np.uint8))
    nodata = GeoRaster(nodata.data, nodata.transform, nodata.crs, nodata=0)
    assert (segment_image(nodata, n_segments=20)[:, :30] == -1).all()


def test_the_ndvi_factor_separates_verge_from_road_of_equal_brightness():
    """Road and verge share the same textured R, G, B; the verge is brighter in NIR only
    by less than the texture's contrast, so colour alone does not prefer their border."""
    verge, data, _ = textured_halves()
    data[3][verge] += 30  # NDVI about 0 on the road, 0.08-0.2 on the verge
    image = raster(np.clip(data, 1, 255).astype(np.float32))
    options = dict(nir_band=4, ndvi_threshold=0.07, n_segments=12, n_superpixels=300)
    without = straddling_share(segment_image(image, w_ndvi=1.0, **options), verge)
    with_ndvi = straddling_share(segment_image(image, **options), verge)
    assert with_ndvi < 0.01 and without > 4 * with_ndvi


def test_the_normalized_cuts_run_with_one_blas_thread():
    """Called alone (a QGIS algorithm does), the cut still pins BLAS: with OpenBLAS's own
    threads an ETH image's segmentation took 21-34 s of CPU instead of 0.5 s on a loaded
    machine."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    data, _ = road_strip_image()
    seen = []

    def progress(fraction, message):
        if message == "normalized cuts" and fraction > 0.4:  # after a patch's cut
            seen.append(max(pool["num_threads"] for pool in threadpoolctl.threadpool_info()))

    with threadpoolctl.threadpool_limits(limits=2):  # what a 2-core machine starts with
        segment_image(raster(data.astype(np.float32)), n_segments=24, progress=progress)
        assert max(pool["num_threads"] for pool in threadpoolctl.threadpool_info()) == 2
    assert seen and max(seen) == 1


def test_the_road_probability_separates_road_from_a_neighbour_of_its_colour():
    """The same textured colours on both sides (a road beside a dark roof): only a learned
    road probability (0.8 against 0.1, with noise) tells them apart; combined with the NDVI
    factor (a NIR band that does not differ) it still does."""
    road, data, rng = textured_halves()
    n = len(road)
    image = raster(np.clip(data, 1, 255).astype(np.float32))
    probability = np.clip(np.where(road, 0.8, 0.1) + rng.normal(0, 0.05, (n, n)), 0, 1)
    options = dict(n_segments=12, n_superpixels=300)
    without = straddling_share(segment_image(image, **options), road)
    with_probability = straddling_share(segment_image(image, probability=probability,
                                                      **options), road)
    # what is left straddles inside superpixels, which follow the colours only
    assert with_probability < 0.02 and without > 5 * with_probability
    both = segment_image(image, probability=probability, nir_band=4, **options)
    assert straddling_share(both, road) < 0.02
    with pytest.raises(ValueError, match="probability"):
        segment_image(image, probability=probability[:10])


def test_a_shared_edge_image_gives_the_same_segments():
    data, _ = road_strip_image(bands=4)
    image = raster(data.astype(np.float32))
    edges = edge_strength(image, nir_band=4)
    assert edges.shape == image.shape and edges[78:82, 50].max() > 2 * np.median(edges)  # road edge
    assert np.array_equal(segment_image(image, nir_band=4, n_segments=20, edge_magnitude=edges),
                          segment_image(image, nir_band=4, n_segments=20))
    with pytest.raises(ValueError, match="edge_magnitude"):
        segment_image(image, edge_magnitude=edges[:10])


def test_ndvi_affinity_marks_only_pairs_across_the_threshold():
    adjacency = csr_matrix(np.array([[0, 2, 0], [2, 0, 3], [0, 3, 0]]))
    factor = ndvi_affinity(adjacency, np.array([0.5, 0.1, 0.05]),
                           ndvi_threshold=0.2, w_ndvi=0.02).toarray()
    np.testing.assert_array_equal(factor, [[0, 0.02, 0], [0.02, 0, 0], [0, 0, 0]])
    with pytest.raises(ValueError, match="w_ndvi"):
        ndvi_affinity(adjacency, np.zeros(3), w_ndvi=0.0)


def test_bad_input_is_refused_with_a_clear_message():
    data, _ = road_strip_image()
    image = raster(data.astype(np.float32))
    with pytest.raises(ValueError, match="NIR band 5"):
        segment_image(image, nir_band=5)
    with pytest.raises(ValueError, match="w_ndvi"):
        segment_image(image, nir_band=1, red_band=2, w_ndvi=0)
    with pytest.raises(ValueError, match="n_segments"):
        segment_image(image, n_segments=0)
    with pytest.raises(ValueError, match="no valid pixel"):
        segment_image(raster(np.full((20, 20), np.nan, np.float32)))

    def cancel(fraction, message):
        if fraction > 0.3:
            raise Cancelled
    with pytest.raises(Cancelled):
        segment_image(image, progress=cancel)


def test_defaults_scale_with_the_pixel_size():
    fine = raster(np.zeros((400, 400), np.uint8), pixel_m=0.1)
    coarse = raster(np.zeros((400, 400), np.uint8), pixel_m=0.3)
    very_coarse = raster(np.zeros((400, 400), np.uint8), pixel_m=1.0)
    assert default_counts(fine) == (round(160000 / 3600), round(160000 / 900))
    assert default_counts(coarse) == (400, 1600)  # 36 m2 = 400 px, 9 m2 = 100 px
    assert default_counts(very_coarse) == (1600, 6400)  # the pixel floors


@pytest.fixture(scope="module")
def scene_image():
    scene = make_scene(seed=1, size_m=(300, 300))
    image, dsm = render_image(scene, pixel_m=0.5)
    road = rasterize([(g, 1) for g in scene.truth.polygons.geometry], out_shape=image.shape,
                     transform=image.transform).astype(bool)
    return image, dsm, road


def test_synthetic_scene_road_edges_are_segment_borders(scene_image):
    image, _, road = scene_image
    labels = segment_image(image, nir_band=4)
    assert labels.min() == 0
    edge = road ^ ndimage.binary_erosion(road, border_value=1)
    recall = boundary_recall(labels, edge, 2)
    random_recall = float((ndimage.distance_transform_edt(~segment_boundaries(labels))
                           <= 2).mean())
    assert recall > 0.85 and recall > random_recall + 0.2
    expected, _ = default_counts(image)
    assert 0.8 * expected <= labels.max() + 1 <= 1.5 * expected


def test_segments_to_frame_and_back_is_exact(scene_image):
    image, _, _ = scene_image
    labels = segment_image(image, n_segments=60)
    labels[:5] = -1
    frame = segments_to_frame(labels, image)
    assert list(frame["segment_id"]) == list(range(labels.max() + 1))
    assert frame.crs == image.crs and frame.geometry.is_valid.all()
    np.testing.assert_allclose(frame.geometry.area, frame["area_px"] * 0.25)
    assert frame["area_px"].sum() == (labels >= 0).sum()
    assert np.array_equal(frame_to_labels(frame, image), labels)
    # an edit: two segments merged by hand come back as one
    merged = frame.copy()
    merged.loc[merged["segment_id"] == 1, "geometry"] = shapely.union(
        merged.geometry[0], merged.geometry[1]) if shapely.touches(
        merged.geometry[0], merged.geometry[1]) else merged.geometry[1]
    merged = merged[merged["segment_id"] != 0]
    back = frame_to_labels(merged, image)
    assert back.max() + 1 == labels.max() + 1 - int(shapely.touches(frame.geometry[0],
                                                                    frame.geometry[1]))


def test_real_eth_image_is_over_segmented_quickly():
    path = sorted((DATA / "eth" / "images").glob("*.png"))[0]
    image = read_raster(path, pixel_size=ETH_PIXEL_M, crs=LOCAL_CRS)
    start = time.process_time()
    labels = segment_image(image)
    seconds = time.process_time() - start
    expected, _ = default_counts(image)
    count = labels.max() + 1
    print(f"{path.name}: {image.shape}, {count} segments (target {expected}), "
          f"{seconds:.2f} s CPU")
    assert (labels >= 0).all() and 0.8 * expected <= count <= 1.5 * expected
    # segments follow colour: the mean within-segment spread is well below the image's
    bands = image.data.astype(float)
    spread = np.mean([ndimage.standard_deviation(b, labels, np.arange(count)).mean()
                      for b in bands])
    assert spread < 0.6 * bands.std(axis=(1, 2)).mean()
    assert seconds < 10
