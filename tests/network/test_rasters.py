"""Any road raster to a network: hand-drawn masks with exact answers, then a real mask."""
from dataclasses import replace

import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS

from gisroads.evaluate.buffer import buffer_metrics
from gisroads.evaluate.topology import line_graph, topology_metrics
from gisroads.geo import GeoRaster
from gisroads.network.rasters import (RASTER_NETWORK, PartOptions, raster_to_network,
                                      road_probability, skeleton_parts, with_missing_roads)

UTM = CRS.from_epsg(32633)
PIXEL_M = 0.5


def _raster(mask, nodata=None, pixel_m=PIXEL_M, crs=UTM):
    return GeoRaster(np.asarray(mask), Affine(pixel_m, 0, 1000.0, 0, -pixel_m, 2000.0), crs,
                     nodata)


def _xy(raster, row, col):
    t = raster.transform
    return t.c + col * t.a, t.f + row * t.e


def _crossing(size=400, width_px=16):
    """A T: a horizontal road across the whole raster, a vertical one from it to the
    bottom; both ``width_px`` wide."""
    mask = np.zeros((size, size), np.uint8)
    half = width_px // 2
    mask[size // 2 - half:size // 2 + half, :] = 1
    mask[size // 2:, size // 2 - half:size // 2 + half] = 1
    return mask


def _spurs(network, spur_m):
    graph = line_graph(network.centrelines.geometry.values)
    degree = graph.degree[graph.edges]
    dangling = (degree.min(axis=1) == 1) & (degree.max(axis=1) >= 3)
    return int((dangling & (graph.lengths < spur_m)).sum())


def test_t_junction_is_one_node_at_the_crossing_with_widths_and_no_spurs():
    mask = _crossing()
    # bumps on the border (a kerb, a driveway) grow skeleton twigs
    mask[180:184, 40:44] = 1
    mask[216:220, 300:305] = 1
    raster = _raster(mask)
    network = raster_to_network(raster)
    assert len(network.junctions) == 1
    assert network.junctions.degree.iloc[0] == 3
    x, y = _xy(raster, 200, 200)
    assert network.junctions.geometry.iloc[0].distance(shapely.Point(x, y)) < 2.0
    # split at the junction, sharing its vertex
    assert len(network.centrelines) == 3
    assert _spurs(network, 5.0) == 0
    np.testing.assert_allclose(network.centrelines.width_m, 8.0, atol=1.0)
    truth = [shapely.LineString([_xy(raster, 200, 0), _xy(raster, 200, 400)]),
             shapely.LineString([_xy(raster, 200, 200), _xy(raster, 400, 200)])]
    metrics = buffer_metrics(network.centrelines, truth, buffer_m=2.0)
    assert metrics.completeness > 0.95 and metrics.correctness > 0.95


def test_the_roads_another_network_has_are_added_and_joined_at_their_junction():
    raster = _raster(_crossing())
    whole = raster_to_network(raster)
    mask = _crossing()
    mask[208:, :] = 0  # the T's stem gone: one straight road
    lacking = raster_to_network(_raster(mask))
    assert len(lacking.centrelines) == 1 and len(lacking.junctions) == 0
    merged = with_missing_roads(lacking, whole.centrelines, raster)
    # the stem joins the road at one T, the road split there
    assert len(merged.junctions) == 1 and merged.junctions.degree.iloc[0] == 3
    assert len(merged.centrelines) == 3
    x, y = _xy(raster, 200, 200)
    assert merged.junctions.geometry.iloc[0].distance(shapely.Point(x, y)) < 2.0
    scores = buffer_metrics(merged.centrelines, whole.centrelines, buffer_m=1.0)
    assert scores.completeness > 0.97 and scores.correctness > 0.97
    # lines along the network's own roads add nothing: the same object back
    assert with_missing_roads(whole, whole.centrelines, raster) is whole
    assert with_missing_roads(lacking, whole.centrelines.iloc[:0], raster) is lacking


def test_a_cut_road_is_bridged_and_parallel_roads_are_not_joined():
    mask = np.zeros((300, 600), np.uint8)
    mask[60:76, :] = 1                  # a road cut by a tree shadow 8 m long
    mask[60:76, 280:296] = 0
    mask[220:236, :250] = 1             # another road, parallel, 80 m away, ends mid-raster
    raster = _raster(mask)
    # the gap edges' bridge: the raster repair of straight cuts (tested below) off
    network = raster_to_network(raster, part_options=PartOptions(max_cut_m=0))
    gaps = network.qa["gap_edges"]
    assert gaps.selected.sum() == 1
    bridged = gaps[gaps.selected].geometry.iloc[0]
    y_cut = _xy(raster, 68, 0)[1]
    assert abs(bridged.centroid.y - y_cut) < 1.0
    lengths = sorted(network.centrelines.length_m)
    assert lengths[-1] > 0.95 * 300          # one road across the cut
    assert len(network.junctions) == 0       # nothing links the two roads
    assert network.centrelines.distance(
        shapely.Point(_xy(raster, 150, 300))).min() > 30


def test_a_false_blob_is_not_joined_across_a_block():
    mask = np.zeros((300, 400), np.uint8)
    mask[60:76, :] = 1                         # a road, 8 m wide
    rows, cols = np.mgrid[:300, :400]
    # a false blob 40 m long and 8 m wide pointing at the road, 30 m off it
    mask[(((rows - 176) / 40.0) ** 2 + ((cols - 200) / 8.0) ** 2) <= 1] = 1
    raster = _raster(mask)
    network = raster_to_network(raster)
    assert len(network.junctions) == 0
    assert network.centrelines.distance(shapely.Point(_xy(raster, 110, 200))).min() > 5
    joined = raster_to_network(raster, network_options=replace(RASTER_NETWORK,
                                                               max_unsupported_m=np.inf))
    assert len(joined.junctions) == 1          # what the unsupported length prevents


def test_probability_scales_and_no_data():
    mask = _crossing()
    as_255 = road_probability(_raster(mask * 255))
    assert np.nanmax(as_255.data) == 1.0
    probability = mask.astype(np.float32) * 0.9
    probability[:, :100] = -9999
    raster = _raster(probability, nodata=-9999)
    assert np.isnan(road_probability(raster).data[:, :100]).all()
    network = raster_to_network(raster)
    xmin = network.centrelines.total_bounds[0]
    assert xmin >= _xy(raster, 0, 100)[0] - 1.0
    np.testing.assert_allclose(network.centrelines.score, 0.9, atol=0.05)


def test_no_line_is_drawn_into_a_no_data_hole():
    """A road running into a strip without data ends at its border: neither an end's
    extension nor a gap edge across the strip draws a line where the image has nothing."""
    probability = _crossing().astype(np.float32) * 0.9
    probability[:, 250:300] = np.nan
    raster = _raster(probability)
    network = raster_to_network(raster)
    (x0, _), (x1, _) = _xy(raster, 0, 250), _xy(raster, 0, 300)
    hole = shapely.box(x0 + 2 * PIXEL_M, 0, x1 - 2 * PIXEL_M, 3000)
    lines = network.centrelines.geometry.values
    assert len(lines) and not shapely.intersects(lines, hole).any()
    # the road on both sides of the strip is still drawn up to it
    assert network.centrelines.total_bounds[2] >= _xy(raster, 0, 399)[0] - 5.0
    assert shapely.length(shapely.intersection(lines, shapely.box(x1, 0, 3000, 3000))).sum() > 40


def test_tiles_are_stitched_into_the_same_network():
    mask = _crossing(size=600)
    mask[100:400, 450:466] = 1          # a road crossing tile seams
    raster = _raster(mask)
    whole = raster_to_network(raster)
    tiled = raster_to_network(raster, part_options=PartOptions(tile_px=128, overlap_px=64))
    assert len(tiled.junctions) == len(whole.junctions)
    assert len(tiled.centrelines) == len(whole.centrelines)
    np.testing.assert_allclose(tiled.centrelines.length_m.sum(),
                               whole.centrelines.length_m.sum(), rtol=0.01)


def test_a_raster_without_roads_gives_empty_typed_layers():
    network = raster_to_network(_raster(np.zeros((100, 100), np.uint8)))
    network.validate()
    assert len(network.centrelines) == len(network.junctions) == 0


@pytest.mark.parametrize("raster, message", [
    (_raster(np.zeros((50, 50)), crs=CRS.from_epsg(4326)), "projected CRS"),
    (_raster(np.full((50, 50), np.nan)), "no valid pixel"),
    (_raster(np.full((50, 50), 300.0)), "0-1 or 0-255"),
])
def test_bad_rasters_are_refused(raster, message):
    with pytest.raises(ValueError, match=message):
        raster_to_network(raster)


def test_missing_band_is_refused():
    with pytest.raises(ValueError, match="band 3 does not exist"):
        skeleton_parts(road_probability(_raster(np.zeros((2, 50, 50))), band=3))


def test_real_massachusetts_mask_to_its_centre_lines():
    from gisroads.imagery.datasets import DATA_DIR, load_massachusetts
    if not DATA_DIR.is_dir():
        pytest.skip("../shared/data/imagery is not beside the repository")
    record = load_massachusetts(stems=["10378795_15"])[0]
    network = raster_to_network(record.truth_mask)
    metrics = buffer_metrics(network.centrelines, record.truth, buffer_m=record.buffer_m,
                             valid_area=record.valid_area)
    assert metrics.quality >= 0.95
    assert topology_metrics(network.centrelines, record.truth)["junction_recall"] >= 0.9
    assert _spurs(network, 5.0) == 0


def test_hysteresis_keeps_a_road_whole_through_a_weak_stretch_and_weak_blobs_out():
    from gisroads.network.rasters import road_mask

    probability = np.zeros((200, 400), np.float32)
    probability[90:106, :] = 0.95        # a road, 8 m wide at 0.5 m pixels
    probability[90:106, 150:250] = 0.65  # 50 m of it on a grey surface
    probability[20:40, 100:160] = 0.65   # a grey blob on its own...
    probability[28:32, 128:132] = 0.95   # ...with 4 m2 of strong pixels: too small to seed
    plain = road_mask(probability, 0.5, threshold=0.8)
    assert not plain[98, 150:250].any() and plain[98, :150].all()
    mask = road_mask(probability, 0.5, threshold=0.8, low_threshold=0.6)
    assert mask[98, :].all()             # the road is whole
    assert not mask[20:40, 100:160].any()  # the blob is not seeded
    # through the network stage: one road across the raster
    network = raster_to_network(_raster(probability), threshold=0.8,
                                part_options=PartOptions(low_threshold=0.6))
    assert len(network.centrelines) == 1
    assert network.centrelines.length_m.iloc[0] > 0.95 * 200


def _cut_road(piece_m=12.0, cut_m=8.0):
    """A road 15 m wide north-south, cut twice across: the piece between the cuts is
    shorter than the road is wide."""
    mask = np.zeros((400, 300), np.uint8)
    mask[:, 120:150] = 1
    cut, piece = int(cut_m / PIXEL_M), int(piece_m / PIXEL_M)
    mask[150:150 + cut, :] = 0
    mask[150 + cut + piece:150 + 2 * cut + piece, :] = 0
    return mask


def test_a_wide_road_cut_twice_is_one_straight_line_along_it():
    raster = _raster(_cut_road())
    network = raster_to_network(raster)
    assert len(network.centrelines) == 1
    line = network.centrelines.geometry.iloc[0]
    x_axis = _xy(raster, 0, 135)[0]
    np.testing.assert_allclose(shapely.get_coordinates(line)[:, 0], x_axis, atol=0.5)
    assert line.length > 200 - 15.5          # the whole road, less half a width at each end
    assert len(network.qa["gap_edges"]) == 0  # closed in the raster, before the skeleton
    # the piece alone gives nothing the gap edges can link: two roads, the cut stays open
    assert len(raster_to_network(raster, part_options=PartOptions(max_cut_m=0)).centrelines) == 2


@pytest.mark.parametrize("smoothed", [False, True])
@pytest.mark.parametrize("angle", range(0, 180, 15))
def test_cuts_are_closed_whatever_the_road_direction(angle, smoothed):
    from gisroads.network.cuts import bridge_cuts
    from gisroads.network.rasters import road_mask

    rows, cols = np.mgrid[:300, :300] - 150.0
    t = np.radians(angle)
    along = rows * np.cos(t) + cols * np.sin(t)
    across = -rows * np.sin(t) + cols * np.cos(t)
    road = np.abs(across) <= 10           # 10 m wide at 0.5 m pixels, stepped borders
    mask = road & ~((np.abs(along) <= 12) | (np.abs(along - 40) <= 8))  # 12 m, 8 m cuts
    if smoothed:                          # corners rounded as the network stage's mask
        mask = road_mask(mask.astype(np.float32), PIXEL_M)
    repaired = bridge_cuts(mask, PIXEL_M)
    # filled across the road but for the pixels of its stepped borders, and not beyond
    assert repaired[(np.abs(across) <= 8) & (np.abs(along) < 120)].all()
    assert not (repaired & (np.abs(across) > 11)).any()


def _not_cuts(which):
    rows, cols = np.mgrid[:400, :400]
    mask = np.zeros((400, 400), bool)
    if which == "block":            # two parallel roads 7 m apart, cross streets 30 m apart
        mask[20:36, 40:130] = mask[50:66, 40:130] = True
        mask[0:100, 40:56] = mask[0:100, 114:130] = True
    elif which == "long block":     # the same, 150 m long
        mask[20:36, 40:360] = mask[50:66, 40:360] = True
        mask[0:100, 40:56] = mask[0:100, 344:360] = True
    elif which == "dead end":       # a road ending 7 m short of another road's side
        mask[50:66, :] = mask[80:400, 120:136] = True
    elif which == "blob ahead":     # a false ellipse 3 m from a road's end, as wide
        mask[(((rows - 200) / 8.0) ** 2 + ((cols - 200) / 10.0) ** 2) <= 1] = True
        mask[192:208, 216:400] = True
    elif which == "round blob ahead":   # a round one, 10 m across
        mask[np.hypot(rows - 200, cols - 200) <= 20] = True
        mask[192:208, 226:400] = True
    elif which == "blob beside":    # an ellipse 2 m off a road's side
        mask[(((rows - 180) / 4.0) ** 2 + ((cols - 200) / 12.0) ** 2) <= 1] = True
        mask[192:208, :] = True
    elif which == "curved median":  # a dual carriageway round a bend, 6 m median
        radius = np.hypot(rows - 400, cols - 200)
        mask = (((radius > 200) & (radius < 216)) | ((radius > 228) & (radius < 244))) & (
            rows < 390)
    return mask


@pytest.mark.parametrize("which", ["block", "long block", "dead end", "blob ahead",
                                   "round blob ahead", "blob beside", "curved median"])
def test_cut_repair_leaves_blocks_dead_ends_blobs_and_medians(which):
    from gisroads.network.cuts import bridge_cuts

    mask = _not_cuts(which)
    assert (bridge_cuts(mask, PIXEL_M) == mask).all()
