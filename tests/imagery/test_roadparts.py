import time

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import rasterio.features
import shapely
from affine import Affine
from skimage.measure import label as connected_regions

from gisroads.geo import GeoRaster
from gisroads.imagery.cues import image_cues
from gisroads.imagery.roadparts import (RoadPartCriteria, extract_road_parts, filter_road_parts,
                                        measure_segments, merge_adjacent_parts,
                                        rasterize_segments)
from gisroads.synthetic import make_scene, render_image

PX = 0.25
X0, Y0 = 500000.0, 4500000.0
SHAPE = (600, 600)  # 150 x 150 m
T = Affine(PX, 0, X0, 0, -PX, Y0 + SHAPE[0] * PX)
CRS = "EPSG:32633"
# (R, G, B, NIR) as the synthetic renderer paints them
GRASS = (80, 112, 52, 190)
ASPHALT = (86, 88, 91, 92)
ROOF = (150, 92, 70, 132)
SHADOW = (22, 23, 24, 24)


def _paint(regions, *, bands=4, background=GRASS, seed=0):
    """Labels and a noisy 8-bit image: background segment 0, region i segment i."""
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    x, y = X0 + (cols + 0.5) * PX, T.f - (rows + 0.5) * PX
    labels = np.zeros(SHAPE, np.int32)
    image = np.empty((4, *SHAPE))
    image[:] = np.array(background, float)[:, None, None]
    for i, (polygon, colour) in enumerate(regions, start=1):
        inside = shapely.contains_xy(polygon, x, y)
        labels[inside] = i
        image[:, inside] = np.array(colour, float)[:, None]
    noise = np.random.default_rng(seed).normal(0, 4, image.shape)
    image = np.clip(np.round(image + noise), 0, 255).astype(np.uint8)[:bands]
    return labels, GeoRaster(image, T, CRS)


def _strip(cx, cy, width_m, length_m, angle_deg):
    axis = shapely.LineString([(-length_m / 2, 0), (length_m / 2, 0)])
    axis = shapely.affinity.translate(shapely.affinity.rotate(axis, angle_deg, origin=(0, 0)),
                                      X0 + cx, Y0 + cy)
    return axis, axis.buffer(width_m / 2, cap_style="flat")


def _row(segments, segment_id):
    return segments.set_index("segment_id").loc[segment_id]


def test_elongated_region_passes_with_its_width_length_and_centre_line():
    axis, road = _strip(75, 75, 8.0, 120.0, 30.0)
    labels, image = _paint([(road, ASPHALT)])
    segments = measure_segments(labels, image)
    part = _row(segments, 1)
    assert part.width_m == pytest.approx(8.0, abs=0.5)
    assert part.length_m == pytest.approx(120.0, rel=0.05)
    assert part.convexity > 0.9 and 60 < part.elongation < 90  # 68.3 for the exact shape
    assert part.direction_rad == pytest.approx(np.radians(30), abs=0.01)
    assert part.area_m2 == pytest.approx(960.0, rel=0.01)
    segments, parts = filter_road_parts(segments)
    assert _row(segments, 1).passed and _row(segments, 1).reason == ""
    assert not _row(segments, 0).passed  # the grass around it
    assert list(parts.columns[:5]) == ["part_id", "segment_id", "width_m", "length_m",
                                      "quality"]
    assert {"mean_b1", "mean_b2", "mean_b3", "mean_b4", "mean_intensity"} <= set(parts)
    assert len(parts) == 1 and parts.segment_id.iloc[0] == 1
    line = parts.geometry.iloc[0]
    assert line.geom_type == "LineString"
    assert shapely.hausdorff_distance(line, axis) < 0.6
    assert 0.7 < parts.quality.iloc[0] <= 1.0
    # asphalt is darker and bluer than grass in the band means
    assert parts.mean_intensity.iloc[0] < _row(segments, 0).mean_intensity
    assert parts.mean_b3.iloc[0] > _row(segments, 0).mean_b3


def test_parking_lot_fails_and_names_the_test():
    _, road = _strip(75, 110, 8.0, 120.0, 0.0)
    lot = shapely.box(X0 + 20, Y0 + 10, X0 + 60, Y0 + 60)  # 40 x 50 m
    labels, image = _paint([(road, ASPHALT), (lot, ASPHALT)])
    segments, parts = filter_road_parts(measure_segments(labels, image))
    lot_row = _row(segments, 2)
    assert not lot_row.passed
    assert lot_row.reason == "not elongated"
    assert "too wide" in lot_row.failures  # 40 m against a 16 m maximum
    assert lot_row.width_m == pytest.approx(40.0, abs=1.0)
    assert _row(segments, 1).passed and list(parts.segment_id) == [1]
    # a user loosening the shape tests sees the next reason
    loose, _ = filter_road_parts(segments, elongation_min=10.0, elongation_curved_min=20.0)
    assert _row(loose, 2).reason == "too wide"


def test_roof_strip_fails_on_its_height_or_colour():
    _, strip = _strip(75, 75, 8.0, 100.0, 0.0)
    labels, image = _paint([(strip, ROOF)], background=ASPHALT)
    dsm = np.zeros(SHAPE, np.float32)
    dsm[labels == 1] = 6.0  # a long roof
    with_dsm = extract_road_parts(labels, image, dsm=GeoRaster(dsm, T, CRS))
    assert _row(with_dsm.segments, 1).reason == "too high"
    assert _row(with_dsm.segments, 1).height_m == pytest.approx(6.0, abs=0.01)
    assert len(with_dsm.road_parts) == 0 and with_dsm.cues["cues"] == "rgb+dsm"
    without = extract_road_parts(labels, image)
    assert _row(without.segments, 1).reason == "coloured" and without.cues["cues"] == "rgb"
    assert _row(without.segments, 1).saturation == pytest.approx(0.53, abs=0.03)
    assert np.isnan(_row(without.segments, 1).height_m)
    # a grey roof: only the DSM tells it from a road
    grey = extract_road_parts(labels, image, saturation_max=1.0)
    assert _row(grey.segments, 1).passed


def test_grass_strip_fails_on_ndvi_or_excess_green_and_passes_without_colour():
    _, strip = _strip(75, 75, 8.0, 100.0, 0.0)
    labels, image = _paint([(strip, GRASS)], background=ASPHALT)
    cir = extract_road_parts(labels, image, nir_band=4)      # NDVI 0.41
    assert _row(cir.segments, 1).reason == "vegetation" and cir.cues["cues"] == "rgb+nir"
    assert _row(cir.segments, 1).ndvi == pytest.approx(0.41, abs=0.02)
    rgb = extract_road_parts(labels, GeoRaster(image.data[:3], T, CRS))  # excess green 0.38
    assert _row(rgb.segments, 1).reason == "vegetation"
    assert np.isnan(_row(rgb.segments, 1).ndvi)
    assert _row(rgb.segments, 1).excess_green == pytest.approx(0.38, abs=0.02)
    assert _row(rgb.segments, 0).excess_green == pytest.approx(0.0, abs=0.02)  # asphalt
    # without NIR and colour (or the RGB test loosened) nothing tells grass from asphalt
    grey = np.round(image.data[:3].mean(axis=0)).astype(np.uint8)  # 81 against 88
    grey[:60, :60], grey[-60:, -60:] = 220, 20  # a white roof and a shadow set the stretch
    pan = extract_road_parts(labels, GeoRaster(grey, T, CRS))
    assert _row(pan.segments, 1).passed and pan.cues["cues"] == "pan"
    assert np.isnan(_row(pan.segments, 1).excess_green)
    loose = extract_road_parts(labels, GeoRaster(image.data[:3], T, CRS),
                               excess_green_max=0.5, saturation_max=1.0)
    assert _row(loose.segments, 1).passed


def _half_ring(radius_m, width_m):
    centre = shapely.Point(X0 + 75, Y0 + 20)
    arc = shapely.intersection(centre.buffer(radius_m, quad_segs=64).exterior,
                               shapely.box(X0, Y0 + 20, X0 + 150, Y0 + 150))
    return shapely.line_merge(arc), shapely.line_merge(arc).buffer(width_m / 2,
                                                                  cap_style="flat")


def test_curved_part_passes_thanks_to_relaxed_convexity():
    arc, road = _half_ring(50.0, 8.0)
    labels, image = _paint([(road, ASPHALT)])
    segments, parts = filter_road_parts(measure_segments(labels, image))
    part = _row(segments, 1)
    assert part.convexity < 0.4 and part.elongation > 70
    assert part.passed
    assert part.length_m == pytest.approx(arc.length, rel=0.05)
    assert part.width_m == pytest.approx(8.0, abs=0.5)
    assert shapely.hausdorff_distance(parts.geometry.iloc[0], arc) < 1.0
    strict, _ = filter_road_parts(segments, convexity_curved_min=0.75)
    assert _row(strict, 1).reason == "not convex"


def test_dark_shadow_and_textured_strips_fail():
    _, shadow = _strip(75, 40, 8.0, 100.0, 0.0)
    _, textured = _strip(75, 110, 8.0, 100.0, 0.0)
    labels, image = _paint([(shadow, SHADOW), (textured, ASPHALT)])
    data = image.data.copy()
    checker = ((np.arange(SHAPE[0])[:, None] // 4 + np.arange(SHAPE[1]) // 4) % 2) == 1
    data[:, (labels == 2) & checker] = 230  # asphalt with white blocks all over
    segments, parts = filter_road_parts(measure_segments(labels, GeoRaster(data, T, CRS)))
    assert _row(segments, 1).reason == "too dark"
    assert _row(segments, 2).reason == "textured"
    assert len(parts) == 0


def test_edge_contrast_tells_a_bounded_strip_from_one_cut_out_of_texture():
    """An asphalt strip on grass has its edges on its border; the same strip cut out of a
    striped texture (tree shadows) has as strong edges inside as on its border."""
    _, bounded = _strip(75, 40, 8.0, 100.0, 0.0)
    _, cut_out = _strip(75, 110, 8.0, 100.0, 0.0)
    labels, image = _paint([(bounded, ASPHALT), (cut_out, ASPHALT)])
    data = image.data.copy()
    stripes = (np.arange(SHAPE[1]) // 12 % 2 == 1)[None, :] & (np.arange(SHAPE[0]) < 300)[:, None]
    data[:, stripes] = np.array(SHADOW[:4], np.uint8)[:, None]  # 3 m stripes over the top half
    texture = GeoRaster(data, T, CRS)
    segments = measure_segments(labels, texture)
    contrast = segments.set_index("segment_id")["edge_contrast"]
    assert contrast[1] > 1.5
    assert contrast[2] < 1.1
    checked, parts = filter_road_parts(segments, edge_contrast_min=1.2,
                                       intensity_std_max=1.0, intensity_range=(0.0, 1.0))
    assert _row(checked, 1).passed
    assert _row(checked, 2).reason == "no border edges"
    assert parts.segment_id.tolist() == [1]
    # off by default (it lost as much road as junk on the real images)
    assert filter_road_parts(segments, intensity_std_max=1.0,
                             intensity_range=(0.0, 1.0))[0].passed.sum() == 2


def test_collinear_adjacent_parts_merge_and_a_crossing_part_does_not():
    _, west = _strip(30, 75, 8.0, 40.0, 0.0)      # x 10..50
    _, middle = _strip(70, 75, 8.0, 40.0, 1.0)    # x 50..90, touching west, 1 degree off
    _, east = _strip(110, 75, 8.0, 40.0, 0.0)     # x 90..130, touching middle
    _, north = _strip(70, 111, 8.0, 64.0, 90.0)   # touches the middle from the north
    labels, image = _paint([(west, ASPHALT), (middle, ASPHALT), (east, ASPHALT),
                            (north, ASPHALT)])
    result = extract_road_parts(labels, image)
    merged = _row(result.segments, 1)
    assert merged.merged_from == "1,2,3"          # a chain: merged over two rounds
    assert merged.length_m == pytest.approx(120.0, rel=0.05)
    assert merged.passed and list(result.segments.segment_id) == [0, 1, 4]
    assert sorted(result.road_parts.segment_id) == [1, 4]
    assert (result.labels == 1).sum() == np.isin(labels, [1, 2, 3]).sum()
    assert not np.isin(result.labels, [2, 3]).any()
    assert _row(result.segments, 4).merged_from == ""
    unmerged = extract_road_parts(labels, image, merge=False)
    assert sorted(unmerged.road_parts.segment_id) == [1, 2, 3, 4]


def test_merge_is_refused_when_the_union_fails():
    _, narrow = _strip(40, 75, 5.0, 60.0, 0.0)
    _, wide = _strip(100, 75, 12.0, 60.0, 0.0)   # collinear, touching, of another width
    labels, image = _paint([(narrow, ASPHALT), (wide, ASPHALT)])
    cues = image_cues(image)
    criteria = {"width_constancy_min": 3.0}     # each piece has a constant width
    segments, _ = filter_road_parts(measure_segments(labels, image, cues=cues), **criteria)
    assert segments.passed.tolist() == [False, True, True]
    refused, same = merge_adjacent_parts(segments, labels, image, cues,
                                         criteria=RoadPartCriteria(**criteria))
    assert list(refused.segment_id) == [0, 1, 2]
    np.testing.assert_array_equal(same, labels)
    merged, new_labels = merge_adjacent_parts(segments, labels, image, cues)  # 1.7
    assert list(merged.segment_id) == [0, 1] and merged.merged_from.iloc[1] == "1,2"
    assert set(np.unique(new_labels)) == {0, 1}


def test_bad_input_is_refused_with_a_clear_error():
    labels, image = _paint([])
    with pytest.raises(ValueError, match="differ in shape"):
        measure_segments(labels[:-1], image)
    with pytest.raises(ValueError, match="integer"):
        measure_segments(labels.astype(float), image)
    with pytest.raises(ValueError, match="-1"):
        measure_segments(labels - 5, image)
    geographic = GeoRaster(image.data, Affine(1e-5, 0, 10, 0, -1e-5, 50), "EPSG:4326")
    with pytest.raises(ValueError, match="projected CRS"):
        measure_segments(labels, geographic)
    with pytest.raises(ValueError, match="unknown road-part criteria"):
        extract_road_parts(labels, image, max_width=3)
    with pytest.raises(ValueError, match="min < max"):
        filter_road_parts(measure_segments(labels, image), width_range_m=(16.0, 3.0))


def test_no_data_and_thin_segments():
    labels, image = _paint([])
    labels[:, :300] = -1                 # the west half has no data
    # a 0.5 m wide line (no interior, no centre line) with a sparse id (no lookup table)
    labels[100:102, 300:500] = 2 ** 30
    segments, parts = filter_road_parts(measure_segments(labels, image))
    assert list(segments.segment_id) == [0, 2 ** 30]
    thin = _row(segments, 2 ** 30)
    assert np.isnan(thin.length_m) and np.isnan(thin.width_m) and thin.centreline is None
    assert thin.reason == "too narrow" and not thin.passed
    assert _row(segments, 0).area_m2 == pytest.approx((300 * 600 - 2 * 200) * PX ** 2)
    assert len(parts) == 0


def _perfect_segments(scene, image):
    """The truth road polygons (one per edge between junctions) painted as segments, then
    buildings and parking lots, the rest cut into its connected pieces."""
    edges = scene.truth_edges.merge(scene.roads[["road_id", "width_m"]], on="road_id")
    roads = shapely.buffer(edges.geometry.values, edges.width_m.to_numpy() / 2,
                           cap_style="flat")
    others = list(scene.buildings.geometry) + list(scene.parking_lots.geometry)
    shapes = [(g, i) for i, g in enumerate(list(roads) + others)]
    painted = rasterio.features.rasterize(shapes, out_shape=image.shape,
                                          transform=image.transform, fill=-1, dtype="int32")
    painted[painted < 0] = len(shapes)
    # each connected piece its own segment (painting can cut a road in two)
    labels = connected_regions(painted + 1, connectivity=1) - 1
    is_road = pd.Series(painted.ravel() < len(roads)).groupby(labels.ravel()).mean() > 0.5
    return labels, is_road


def test_perfect_segments_of_a_synthetic_scene():
    scene = make_scene(seed=2, size_m=(300.0, 300.0))
    image, dsm = render_image(scene, pixel_m=0.5)
    labels, is_road = _perfect_segments(scene, image)
    shares = {}
    for name, cues in (("rgb", {}), ("rgb+nir+dsm", {"nir_band": 4, "dsm": dsm})):
        start = time.perf_counter()
        result = extract_road_parts(labels, image, **cues)
        seconds = time.perf_counter() - start
        segments = result.segments[result.segments.area_m2 >= 50.0]
        road = is_road.reindex(segments.segment_id).to_numpy()
        shares[name] = (segments.passed[road].mean(), (~segments.passed[~road]).mean(),
                        seconds)
        print(name, "road parts passing {:.2f}, non-road failing {:.2f}, {:.1f} s".format(
            *shares[name]),
              segments[road].reason.value_counts().to_dict())
        assert result.cues["cues"] == name
    # the truth's roads of 3-16 m pass unless short between junctions, under street-tree
    # crowns (green in the image, high in the DSM) or on the bridge (high in the DSM)
    assert shares["rgb"][0] >= 0.3 and shares["rgb+nir+dsm"][0] >= 0.3
    assert shares["rgb"][1] == 1.0 and shares["rgb+nir+dsm"][1] == 1.0


def test_segment_polygons_back_to_labels():
    _, road = _strip(75, 75, 8.0, 120.0, 30.0)
    labels, image = _paint([(road, ASPHALT)])
    frame = gpd.GeoDataFrame({"segment_id": [5]}, geometry=[road], crs=CRS)
    burnt = rasterize_segments(frame, image)
    np.testing.assert_array_equal(burnt, np.where(labels == 1, 5, -1))
    with pytest.raises(ValueError, match="non-negative integers"):
        rasterize_segments(frame.assign(segment_id=[-2]), image)
    with pytest.raises(ValueError, match="no 'segment_id' field"):
        rasterize_segments(frame.rename(columns={"segment_id": "id"}), image)
    with pytest.raises(ValueError, match="another CRS"):
        rasterize_segments(frame.set_crs("EPSG:32634", allow_override=True), image)


def test_learned_probability_replaces_the_colour_tests():
    """With a model's probability, a red (coloured) strip the model calls road passes, a grey
    strip it calls not road fails on 'low road probability'; without one, the colour tests."""
    import dataclasses

    _, red = _strip(75, 40, 8.0, 100.0, 0.0)
    _, grey = _strip(75, 110, 8.0, 100.0, 0.0)
    labels, image = _paint([(red, ROOF), (grey, ASPHALT)])
    rgb = GeoRaster(image.data[:3], T, CRS)
    cues = image_cues(rgb)
    plain = extract_road_parts(labels, rgb, cues=cues)
    assert _row(plain.segments, 1).reason == "coloured" and _row(plain.segments, 2).passed
    assert np.isnan(_row(plain.segments, 1).road_probability)
    probability = np.where(labels == 1, 0.8, 0.1).astype(np.float32)
    learned = extract_road_parts(labels, rgb,
                                 cues=dataclasses.replace(cues, probability=probability))
    assert _row(learned.segments, 1).passed
    assert _row(learned.segments, 1).road_probability == pytest.approx(0.8)
    assert _row(learned.segments, 2).reason == "low road probability"
    assert list(learned.road_parts.segment_id) == [1]
    assert learned.road_parts.road_probability.iloc[0] == pytest.approx(0.8)
    assert learned.cues["cues"] == "rgb+model"
    # the probability joins the quality measure: the same strip at 0.4 scores lower
    lower = extract_road_parts(labels, rgb, cues=dataclasses.replace(
        cues, probability=np.where(labels == 1, 0.4, 0.1).astype(np.float32)))
    assert lower.road_parts.quality.iloc[0] < learned.road_parts.quality.iloc[0]
    # the threshold is a criterion like the others
    strict = extract_road_parts(labels, rgb, probability_min=0.9,
                                cues=dataclasses.replace(cues, probability=probability))
    assert _row(strict.segments, 1).reason == "low road probability"
