import time
from pathlib import Path

import numpy as np
import pytest
from affine import Affine
from rasterio.features import rasterize
from scipy import ndimage

from gisroads.geo import GeoRaster
from gisroads.geo import LOCAL_CRS
from gisroads.imagery.datasets import ETH_PIXEL_M
from gisroads.imagery.segments import segment_image
from gisroads.io.raster import read_raster
from gisroads.progress import Cancelled
from gisroads.imagery.grouping import (CRITERIA, group_segments, merge_strength,
                                            split_branching_segments)
from gisroads.synthetic import make_scene, render_image

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "imagery"
PX = 0.25
ROAD = (86, 88, 91)
GRASS = (78, 112, 52)


def raster(data, pixel_m=PX):
    rows = np.asarray(data).shape[-2]
    return GeoRaster(np.asarray(data, np.float32),
                     Affine(pixel_m, 0, 500000.0, 0, -pixel_m, 4500000.0 + rows * pixel_m),
                     "EPSG:32633")


def paint(classes, colours, seed=0):
    rng = np.random.default_rng(seed)
    image = np.asarray(colours, float)[classes].transpose(2, 0, 1)
    return image + rng.normal(0, 4, image.shape)


def grid_labels(shape, step_rows, step_cols, offset=0):
    rows, cols = np.mgrid[:shape[0], :shape[1]]
    return ((rows - offset) // step_rows) * 1000 + cols // step_cols


def segments_in(labels, region):
    return np.unique(labels[region])


def test_pieces_of_a_road_merge_without_taking_the_verge():
    road = np.zeros((200, 200), bool)
    road[80:112] = True  # 8 m wide
    image = raster(paint(road.astype(int), [GRASS, ROAD]))
    # the road cut into six pieces along its length, the verges into 40 px blocks
    labels = np.where(road, 10_000 + np.arange(200)[None, :] // 34, grid_labels(road.shape,
                                                                                 40, 40))
    labels = np.where(road | (np.arange(200)[:, None] < 80), labels, labels + 500)
    grouped = group_segments(labels, image)
    assert grouped.dtype == np.int32 and (grouped >= 0).all()
    assert len(segments_in(grouped, road)) <= 2 < 6
    for segment in segments_in(grouped, road):  # no road segment took verge pixels
        assert road[grouped == segment].all()
    assert len(np.unique(grouped)) < len(np.unique(labels)) / 3


def test_a_height_step_blocks_a_merge_that_colour_alone_allows():
    halves = np.zeros((120, 160), int)
    halves[:, 80:] = 1
    image = raster(paint(halves, [ROAD, ROAD]))  # a grey roof as grey as the road
    labels = grid_labels(halves.shape, 40, 40)
    dsm = raster(np.where(halves == 1, 5.0, 0.0))
    without = group_segments(labels, image)
    with_dsm = group_segments(labels, image, dsm=dsm)
    assert len(np.unique(without)) == 1
    assert len(np.unique(with_dsm)) == 2
    assert np.array_equal(with_dsm[:, :80] == with_dsm[0, 0], np.ones((120, 80), bool))


def test_ndvi_difference_blocks_a_merge():
    halves = np.zeros((120, 160), int)
    halves[:, 80:] = 1
    image = raster(paint(halves, [ROAD, ROAD]))
    ndvi = np.where(halves == 1, 0.4, 0.0)
    labels = grid_labels(halves.shape, 40, 40)
    assert len(np.unique(group_segments(labels, image, ndvi=ndvi))) == 2


def test_a_road_probability_difference_blocks_a_merge():
    halves = np.zeros((120, 160), int)
    halves[:, 80:] = 1
    image = raster(paint(halves, [ROAD, ROAD]))  # a dark roof as grey as the road
    labels = grid_labels(halves.shape, 40, 40)
    rng = np.random.default_rng(0)
    probability = np.clip(np.where(halves == 0, 0.8, 0.1) + rng.normal(0, 0.05, halves.shape),
                          0, 1)
    assert len(np.unique(group_segments(labels, image))) == 1
    grouped = group_segments(labels, image, probability=probability)
    assert len(np.unique(grouped)) == 2
    assert np.array_equal(grouped[:, :80] == grouped[0, 0], np.ones((120, 80), bool))
    with pytest.raises(ValueError, match="probability"):
        group_segments(labels, image, probability=probability[:10])


def test_fuzzy_rules_let_very_good_criteria_outweigh_a_poor_one():
    names = ["colour", "edge", "convexity", "border_m", "border_rel"]

    def strength(**goodness):
        values = {n: np.array([goodness.get(n, 0.6)]) for n in names}
        values.update({k: np.array([v]) for k, v in goodness.items() if k not in names})
        return float(merge_strength(values)[0])

    assert strength() >= 0.5  # everything good
    assert strength(border_rel=0.0) < 0.5  # one poor, nothing very good
    assert strength(colour=1, edge=1, border_rel=0.0) >= 0.5  # the paper's example
    assert strength(colour=1, edge=1, convexity=0.1, border_rel=0.0) < 0.5
    assert strength(colour=1, edge=1, convexity=1, border_m=0.0) >= 0.5
    assert strength(colour=1, edge=1, convexity=1, border_m=0.0, border_rel=0.0) < 0.5
    assert strength(colour=1, edge=1, convexity=1, height_m=0.0) < 0.5  # never outweighed
    assert strength(colour=1, edge=1, convexity=1, ndvi=0.0) < 0.5
    assert strength(colour=1, edge=1, convexity=1, probability=0.0) < 0.5


def test_one_iteration_merges_at_most_the_best_tenth_of_the_pairs():
    image = raster(paint(np.zeros((200, 200), int), [ROAD]))
    labels = grid_labels((200, 200), 20, 20)  # 100 squares, 180 adjacent pairs
    once = group_segments(labels, image, max_iterations=1, split_branches=False)
    assert 100 - len(np.unique(once)) == 18
    assert len(np.unique(group_segments(labels, image, split_branches=False))) == 1


def cross(shape=(240, 240), width=32):
    mask = np.zeros(shape, bool)
    centre = shape[0] // 2
    mask[centre - width // 2:centre + width // 2] = True
    mask[:, centre - width // 2:centre + width // 2] = True
    return mask


def test_a_cross_shaped_segment_is_split_into_its_arms():
    mask = cross()
    labels = np.where(mask, 0, 1)
    labels[:5] = -1
    split = split_branching_segments(labels, pixel_m=PX)
    assert (split[:5] == -1).all()
    arms = segments_in(split, mask & (split >= 0))
    assert len(arms) == 4
    ends = [split[60, 120], split[235, 120], split[120, 2], split[120, 237]]
    assert sorted(ends) == sorted(arms)
    assert len(segments_in(split, ~mask & (split >= 0))) == 4  # the corners, as before


@pytest.mark.parametrize("shape", ["bar", "ell", "square"])
def test_segments_without_a_junction_are_not_split(shape):
    mask = np.zeros((240, 240), bool)
    if shape == "bar":
        mask[100:132, 10:230] = True
    elif shape == "ell":
        mask[100:132, 10:132] = True
        mask[10:132, 100:132] = True
    else:
        mask[20:220, 20:220] = True
    split = split_branching_segments(np.where(mask, 0, -1), pixel_m=PX)
    assert len(segments_in(split, mask)) == 1


def test_grouping_keeps_crossing_roads_apart_and_splits_a_crossroads_segment():
    mask = cross()
    image = raster(paint(mask.astype(int), [GRASS, ROAD]))
    # road pieces: convexity keeps the arms of the cross from joining the straight road
    pieces = np.where(mask, grid_labels(mask.shape, 30, 30), -1)
    grouped = group_segments(pieces, image)
    assert len(segments_in(grouped, mask)) == 3
    assert (grouped[:, 112:128] == grouped[0, 120]).all()  # the straight road, whole
    # a crossroads that is one segment (merged by hand, say) is cut into its four arms
    grouped = group_segments(np.where(mask, 0, -1), image)
    assert len(segments_in(grouped, mask)) == 4 and (grouped[~mask] == -1).all()


def test_bad_input_is_refused():
    image = raster(paint(np.zeros((50, 50), int), [ROAD]))
    labels = grid_labels((50, 50), 10, 10)
    with pytest.raises(ValueError, match="differ in shape"):
        group_segments(labels[:40], image)
    with pytest.raises(ValueError, match="merge_fraction"):
        group_segments(labels, image, merge_fraction=0)
    with pytest.raises(ValueError, match="unknown criterion"):
        group_segments(labels, image, criteria={"shape": (0, 1)})
    with pytest.raises(ValueError, match="edge_magnitude"):
        group_segments(labels, image, edge_magnitude=np.zeros((5, 5)))
    with pytest.raises(ValueError, match="integer"):
        group_segments(labels.astype(float), image)

    def cancel(fraction, message):
        if "iteration" in message:
            raise Cancelled
    with pytest.raises(Cancelled):
        group_segments(labels, image, progress=cancel)
    assert set(CRITERIA) == {"colour", "edge", "convexity", "border_m", "border_rel",
                             "height_m", "ndvi", "probability"}


def mixed_share(labels, region):
    ids = labels[labels >= 0]
    total, inside = np.bincount(ids), np.bincount(ids, region[labels >= 0])
    return float(np.minimum(inside, total - inside).sum() / ids.size)


def test_synthetic_scene_grouping_in_time():
    scene = make_scene(seed=1, size_m=(300, 300))
    image, dsm = render_image(scene, pixel_m=0.3)  # 1000 x 1000
    road = rasterize([(g, 1) for g in scene.truth.polygons.geometry], out_shape=image.shape,
                     transform=image.transform).astype(bool)
    labels = segment_image(image, nir_band=4)
    start = time.process_time()
    grouped = group_segments(labels, image, dsm=dsm, nir_band=4)
    seconds = time.process_time() - start
    before, after = labels.max() + 1, grouped.max() + 1
    road_before = len(segments_in(labels, road))
    road_after = len(segments_in(grouped, road))
    print(f"1000 x 1000: {before} -> {after} segments, {road_before} -> {road_after} on "
          f"roads, mixed {mixed_share(labels, road):.3f} -> {mixed_share(grouped, road):.3f}, "
          f"{seconds:.2f} s CPU")
    assert after < before / 2.5 and road_after < road_before / 2
    assert mixed_share(grouped, road) < mixed_share(labels, road) + 0.01
    assert seconds < 6


def test_real_eth_image_grouping():
    path = sorted((DATA / "eth" / "images").glob("*.png"))[0]
    image = read_raster(path, pixel_size=ETH_PIXEL_M, crs=LOCAL_CRS)
    labels = segment_image(image)
    start = time.process_time()
    grouped = group_segments(labels, image)
    seconds = time.process_time() - start
    print(f"{path.name}: {labels.max() + 1} -> {grouped.max() + 1} segments, "
          f"{seconds:.2f} s CPU")
    assert (grouped >= 0).all() and grouped.max() + 1 < (labels.max() + 1) / 2
    bands = image.data.astype(float)
    spread = np.mean([ndimage.standard_deviation(b, grouped, np.arange(grouped.max() + 1))
                      .mean() for b in bands])
    assert spread < 0.8 * bands.std(axis=(1, 2)).mean()
