"""Subgraph generation and evaluation: hand-made road parts and rasters with exact answers."""
import geopandas as gpd
import numpy as np
import pytest
import shapely
import shapely.ops
from affine import Affine

from gisroads.network.subgraph import (edge_weights, gap_context, gap_edges, link_road_parts,
                                       linear_weight, road_strings, select_gap_edges)

CRS = "EPSG:32633"
COS20, SIN20 = np.cos(np.radians(20)), np.sin(np.radians(20))


def parts_frame(rows):
    """rows: (part_id, coords, width_m, quality, mean_b1, mean_b2)."""
    return gpd.GeoDataFrame(
        {"part_id": [r[0] for r in rows], "segment_id": [10 + r[0] for r in rows],
         "width_m": [r[2] for r in rows],
         "length_m": [shapely.LineString(r[1]).length for r in rows],
         "quality": [r[3] for r in rows], "mean_b1": [r[4] for r in rows],
         "mean_b2": [r[5] for r in rows], "mean_intensity": [(r[4] + r[5]) / 2 for r in rows]},
        geometry=[shapely.LineString(r[1]) for r in rows], crs=CRS)


def collinear_with_branch():
    """A and B collinear 10 m apart; C branches off 20 degrees from 8 m ahead of A's end."""
    return parts_frame([
        (1, [(0, 0), (50, 0)], 6.0, 0.9, 0.4, 0.4),
        (2, [(60, 0), (110, 0)], 6.0, 0.8, 0.4, 0.4),
        (3, [(58, 3), (58 + 50 * COS20, 3 + 50 * SIN20)], 4.0, 0.7, 0.5, 0.4),
    ])


def gaps_frame(edges):
    """Hand-made gap edges with given weights: (from_part, from_end, to_part, to_end, w)."""
    return gpd.GeoDataFrame(
        {"from_part": [e[0] for e in edges], "from_end": [e[1] for e in edges],
         "to_part": [e[2] for e in edges], "to_end": [e[3] for e in edges],
         "weight": [e[4] for e in edges]},
        geometry=[shapely.LineString([(0, k), (1, k)]) for k in range(len(edges))], crs=CRS)


# --- generation -----------------------------------------------------------------------------

def test_gap_edges_link_the_collinear_part_and_keep_the_branch_with_exact_features():
    gaps = gap_edges(collinear_with_branch())
    assert list(zip(gaps.from_part, gaps.from_end, gaps.to_part, gaps.to_end)) == [
        (1, 1, 2, 0), (1, 1, 3, 0)]          # B-C (backwards, 160 degrees) is no link
    ab, ac = gaps.iloc[0], gaps.iloc[1]
    assert ab.distance_m == pytest.approx(10.0) and ab.smoothness == pytest.approx(0.0)
    assert ab.direction_diff_rad == pytest.approx(0.0, abs=1e-9)
    assert ab.colour_diff == 0.0 and ab.width_diff_m == 0.0 and ab.width_m == 6.0
    assert ac.distance_m == pytest.approx(np.hypot(8, 3))
    # lateral offsets: C's start is 3 m off A's axis; A's end 8 sin20 - 3 cos20 off C's
    assert ac.smoothness == pytest.approx((3 + abs(8 * SIN20 - 3 * COS20)) / 2)
    assert ac.direction_diff_rad == pytest.approx(np.radians(20))
    assert ac.colour_diff == pytest.approx(np.sqrt(0.1 ** 2 / 2))
    assert (ac.quality_from, ac.quality_to, ac.width_diff_m) == (0.9, 0.7, 2.0)
    assert ac.geometry.equals(shapely.LineString([(50, 0), (58, 3)]))
    assert gaps.subgraph_id.tolist() == [0, 0] and gaps.crs == CRS


def test_gap_edges_respect_each_criterion():
    parts = collinear_with_branch()
    assert len(gap_edges(parts, max_direction_diff_rad=np.radians(19))) == 1
    assert len(gap_edges(parts, max_lateral_offset_m=1.0)) == 1    # C's offset is 1.54 m
    assert len(gap_edges(parts, max_gap_m=9.0)) == 1                # C is 8.54 m away
    assert len(gap_edges(parts, max_gap_relative=0.05)) == 0        # 8.5 / 100 > 0.05
    # side by side (a parallel lane) and overlapping are no continuation
    lanes = parts_frame([(1, [(0, 0), (50, 0)], 6, 0.9, 0.4, 0.4),
                         (2, [(40, 3), (90, 3)], 6, 0.9, 0.4, 0.4)])
    assert len(gap_edges(lanes, max_lateral_offset_m=10)) == 0
    # centre lines reaching a metre past each other still link, three metres do not
    overlap = parts_frame([(1, [(0, 0), (50, 0)], 6, 0.9, 0.4, 0.4),
                           (2, [(49, 0.5), (90, 0.5)], 6, 0.9, 0.4, 0.4)])
    linked = gap_edges(overlap)
    assert len(linked) == 1 and linked.distance_m[0] == pytest.approx(np.hypot(1, 0.5))
    assert len(gap_edges(overlap, max_overlap_m=0.5)) == 0
    assert len(gap_edges(parts_frame([(1, [(0, 0), (50, 0)], 6, 0.9, 0.4, 0.4),
                                      (2, [(47, 0.5), (90, 0.5)], 6, 0.9, 0.4, 0.4)]))) == 0


def test_subgraphs_grow_greedily_from_the_best_part():
    parts = parts_frame([
        (5, [(0, 100), (40, 100)], 6, 0.5, 0.4, 0.4),
        (6, [(50, 100), (90, 100)], 6, 0.6, 0.4, 0.4),
        (7, [(0, 0), (40, 0)], 6, 0.95, 0.4, 0.4),
        (8, [(90, 0), (50, 0)], 6, 0.3, 0.4, 0.4),      # drawn backwards
    ])
    gaps = gap_edges(parts)
    # the best part (7) seeds subgraph 0 and is the 'from' side of its link
    assert list(zip(gaps.subgraph_id, gaps.from_part, gaps.from_end, gaps.to_part,
                    gaps.to_end)) == [(0, 7, 1, 8, 1), (1, 6, 0, 5, 1)]


# --- weights --------------------------------------------------------------------------------

def test_linear_weight_maps_ranges_clips_and_ignores_missing():
    assert linear_weight([0, 15, 60, 90, np.nan], 0, 60).tolist() == [1, 0.75, 0, 0, 1]
    assert linear_weight([1.0, 0.25, -1], 1.0, 0.0).tolist() == [1, 0.25, 0]


def test_relation_weight_is_the_product_of_the_six_linear_weights():
    gaps = edge_weights(gap_edges(collinear_with_branch()))
    # A-B: distance 10 of 60 m, mean quality 0.85, everything else perfect
    assert gaps.relation_weight[0] == pytest.approx((1 - 10 / 60) * 0.85)
    lateral = (3 + abs(8 * SIN20 - 3 * COS20)) / 2
    expected = ((1 - lateral / 6) * (1 - np.hypot(8, 3) / 60) * (1 - (np.pi / 9) / (np.pi / 4))
                * 0.8 * (1 - np.sqrt(0.005) / 0.25) * (1 - 2 / 5))
    assert gaps.relation_weight[1] == pytest.approx(expected)
    # no context computed: the weight is the relation weight
    assert gaps.context_weight.isna().all()
    assert gaps.weight.tolist() == gaps.relation_weight.tolist()
    narrow = edge_weights(gap_edges(collinear_with_branch()),
                          weight_ranges={"distance_m": (0.0, 20.0)})
    assert narrow.relation_weight[0] == pytest.approx(0.5 * 0.85)


def test_unknown_weight_names_are_refused():
    with pytest.raises(ValueError, match="unknown"):
        edge_weights(gap_edges(collinear_with_branch()), weight_ranges={"speed": (0, 1)})


# --- the integer program --------------------------------------------------------------------

def test_integer_program_keeps_the_collinear_link_and_rejects_the_branch():
    gaps, strings = link_road_parts(collinear_with_branch())
    assert gaps.selected.tolist() == [True, False]
    assert gaps.attrs["optimal"]
    assert strings.part_ids.tolist() == ["1,2", "3"]
    assert strings.geometry[0].equals(shapely.LineString([(0, 0), (50, 0), (60, 0), (110, 0)]))


def test_integer_program_beats_greedy():
    gaps = gaps_frame([(1, 1, 2, 0, 0.6), (1, 1, 3, 0, 0.5), (4, 1, 2, 0, 0.5)])
    greedy, booked = 0.0, set()
    for row in gaps.sort_values("weight", ascending=False).itertuples():
        ends = {(row.from_part, row.from_end), (row.to_part, row.to_end)}
        if not ends & booked:
            greedy, booked = greedy + row.weight, booked | ends
    assert greedy == pytest.approx(0.6)
    chosen = select_gap_edges(gaps)
    assert chosen.selected.tolist() == [False, True, True]
    assert chosen.attrs["objective"] == pytest.approx(1.0) and chosen.attrs["optimal"]


def test_at_most_one_connection_per_end_and_nonpositive_weights_never_kept():
    # X.0 (part 9) is the best partner of both A.1 (1) and C.1 (3): picking each end's
    # best would book X.0 twice
    gaps = gaps_frame([(1, 1, 9, 0, 0.9), (3, 1, 9, 0, 0.8), (1, 1, 4, 0, 0.5),
                       (3, 1, 5, 0, 0.3), (6, 1, 7, 0, 0.0), (7, 1, 8, 0, -0.2)])
    chosen = select_gap_edges(gaps)
    assert chosen.selected.tolist() == [False, True, True, False, False, False]
    assert chosen.attrs["objective"] == pytest.approx(1.3)
    kept = chosen[chosen.selected]
    ends = list(zip(kept.from_part, kept.from_end)) + list(zip(kept.to_part, kept.to_end))
    assert len(ends) == len(set(ends))


def test_select_needs_weights_and_handles_no_candidates():
    with pytest.raises(ValueError, match="weight"):
        select_gap_edges(gaps_frame([(1, 1, 2, 0, 0.5)]).drop(columns="weight"))
    assert select_gap_edges(gaps_frame([(1, 1, 2, 0, 0.0)])).selected.tolist() == [False]
    assert len(select_gap_edges(gaps_frame([]))) == 0


# --- context --------------------------------------------------------------------------------

GRID = Affine(1.0, 0.0, -10.0, 0.0, -1.0, 20.0)     # 1 m pixels, x -10..110, y -20..20
SHAPE = (40, 120)


def two_parts(gap_end=60.0):
    return parts_frame([(1, [(0, 0), (40, 0)], 6.0, 0.9, 0.4, 0.4),
                        (2, [(gap_end, 0), (gap_end + 40, 0)], 6.0, 0.9, 0.4, 0.4)])


def block(value, x0, x1, y0, y1, background=0.0):
    """A raster on GRID with ``value`` over x0..x1, y0..y1 (metres)."""
    raster = np.full(SHAPE, background)
    raster[20 - y1:20 - y0, x0 + 10:x1 + 10] = value
    return raster


def test_building_in_the_gap_gives_minus_ten_and_blocks_the_only_link():
    parts = two_parts()
    gaps, _ = link_road_parts(parts, transform=GRID, ndsm=block(8.0, 45, 55, -5, 5))
    assert gaps.n_building.tolist() == [1] and gaps.occlusion.tolist() == [0.0]
    assert gaps.context_weight.tolist() == [-10.0]
    assert gaps.weight.tolist() == [0.0] and gaps.selected.tolist() == [False]
    clear, strings = link_road_parts(parts, transform=GRID, ndsm=np.zeros(SHAPE))
    assert clear.context_weight.tolist() == [0.0]
    assert clear.weight[0] == pytest.approx(clear.relation_weight[0] / 2)
    assert clear.selected.tolist() == [True] and strings.part_ids.tolist() == ["1,2"]


def test_a_tree_occluding_the_gap_supports_the_link_a_lawn_blocks_it():
    parts = two_parts()
    crown = block(0.8, 38, 62, -6, 6)               # NDVI high over the whole gap
    gaps, _ = link_road_parts(parts, transform=GRID, ndvi=crown)
    assert gaps.n_tree.tolist() == [1] and gaps.occlusion.tolist() == [1.0]
    assert gaps.context_weight.tolist() == [1.0]
    assert gaps.weight[0] == pytest.approx((gaps.relation_weight[0] + 1.0) / 2)
    assert gaps.selected.tolist() == [True]
    high, _ = link_road_parts(parts, transform=GRID, ndvi=crown, ndsm=block(9.0, 38, 62, -6, 6))
    assert (high.n_tree[0], high.n_building[0], high.occlusion[0]) == (1, 0, 1.0)
    assert high.selected.tolist() == [True]
    lawn, _ = link_road_parts(parts, transform=GRID, ndvi=crown, ndsm=np.zeros(SHAPE))
    assert (lawn.n_vegetated_area[0], lawn.n_tree[0]) == (1, 0)
    assert lawn.context_weight.tolist() == [-0.5] and lawn.selected.tolist() == [False]


def test_small_gaps_ignore_their_context():
    parts = two_parts(gap_end=42.0)                  # 2 m gap with a building in it
    gaps, _ = link_road_parts(parts, transform=GRID, ndsm=block(8.0, 40, 42, -5, 5))
    assert gaps.n_building.tolist() == [1] and gaps.context_weight.tolist() == [-10.0]
    assert gaps.weight.tolist() == gaps.relation_weight.tolist()
    assert gaps.selected.tolist() == [True]


def test_vehicles_shadow_and_asphalt_from_height_and_intensity():
    parts = two_parts()
    intensity = block(0.05, 40, 45, -3, 3, background=0.4)    # a shadow at the gap's start
    ndsm = block(1.5, 50, 54, -1, 1)                          # a car: 8 m2, 1.5 m high
    gaps = gap_context(gap_edges(parts), transform=GRID, ndsm=ndsm, intensity=intensity)
    row = gaps.iloc[0]
    assert (row.n_vehicle, row.n_building, row.n_shadow, row.n_asphalt) == (1, 0, 1, 1)
    assert row.occlusion == pytest.approx((5 * 6 + 4 * 2) / (20 * 6))
    assert row.context_cues == "ndsm,intensity"
    weighted = edge_weights(gaps)
    assert weighted.context_weight[0] == pytest.approx(0.5 + 0.5 + row.occlusion)


def test_repeated_appearances_count_harmonically():
    cars = np.zeros(SHAPE)
    for x in (42, 47, 52, 57):                                 # four separate cars
        cars += block(1.5, x, x + 2, -1, 1)
    gaps = edge_weights(gap_context(gap_edges(two_parts()), transform=GRID, ndsm=cars))
    assert gaps.n_vehicle.tolist() == [4]
    occlusion = 4 * 4 / 120
    assert gaps.context_weight[0] == pytest.approx(0.5 * (1 + 1 / 2 + 1 / 3 + 1 / 4) + occlusion)


def test_colour_vegetation_without_nir_and_gaps_off_the_raster():
    rgb = np.stack([np.full(SHAPE, 0.3), np.full(SHAPE, 0.3), np.full(SHAPE, 0.3)])
    rgb[1] = block(0.6, 38, 62, -6, 6, background=0.3)         # green over the gap
    gaps = gap_context(gap_edges(two_parts()), transform=GRID, rgb=rgb)
    assert gaps.n_tree.tolist() == [1] and gaps.occlusion.tolist() == [1.0]
    far = gap_context(gap_edges(two_parts()), transform=Affine(1.0, 0.0, 490.0, 0.0, -1.0, 20.0),
                      rgb=rgb)
    assert far.occlusion.isna().all()
    assert edge_weights(far).weight.tolist() == edge_weights(far).relation_weight.tolist()


def test_context_input_errors():
    gaps = gap_edges(two_parts())
    with pytest.raises(ValueError, match="at least one raster"):
        gap_context(gaps, transform=GRID)
    with pytest.raises(ValueError, match="one grid"):
        gap_context(gaps, transform=GRID, ndvi=np.zeros(SHAPE), ndsm=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="transform"):
        link_road_parts(two_parts(), ndsm=np.zeros(SHAPE))


# --- road strings ---------------------------------------------------------------------------

def test_road_strings_chain_reversed_parts_in_order():
    parts = parts_frame([
        (3, [(0, 0), (10, 0)], 4.0, 0.5, 0.4, 0.4),
        (7, [(30, 0), (20, 0)], 6.0, 0.7, 0.4, 0.4),       # drawn backwards
        (9, [(40, 0), (60, 0)], 8.0, 0.9, 0.4, 0.4),
        (11, [(0, 50), (10, 50)], 5.0, 0.2, 0.4, 0.4),     # alone
    ])
    gaps = gaps_frame([(3, 1, 7, 1, 0.9), (9, 0, 7, 0, 0.8), (3, 1, 11, 0, 0.1)])
    gaps["selected"] = [True, True, False]
    strings = road_strings(parts, gaps)
    assert strings.part_ids.tolist() == ["3,7,9", "11"]
    assert strings.n_parts.tolist() == [3, 1] and strings.string_id.tolist() == [0, 1]
    assert shapely.get_coordinates(strings.geometry[0]).tolist() == [
        [0, 0], [10, 0], [20, 0], [30, 0], [40, 0], [60, 0]]
    assert strings.width_m[0] == pytest.approx((4 * 10 + 6 * 10 + 8 * 20) / 40)
    assert strings.quality[0] == pytest.approx((0.5 * 10 + 0.7 * 10 + 0.9 * 20) / 40)
    assert strings.length_m.tolist() == [60.0, 10.0]


def test_a_ring_of_links_gives_a_closed_string():
    square = [[(0, 0), (10, 0)], [(20, 0), (20, 10)], [(20, 20), (10, 20)], [(0, 20), (0, 10)]]
    parts = parts_frame([(k, c, 5.0, 0.5, 0.4, 0.4) for k, c in enumerate(square)])
    gaps = gaps_frame([(0, 1, 1, 0, 1), (1, 1, 2, 0, 1), (2, 1, 3, 0, 1), (3, 1, 0, 0, 1)])
    gaps["selected"] = True
    strings = road_strings(parts, gaps)
    assert strings.part_ids.tolist() == ["0,1,2,3"]
    assert strings.geometry[0].is_ring and strings.length_m[0] == pytest.approx(4 * 10 + 4 * 10)


def test_road_strings_refuse_a_double_booked_end():
    parts = collinear_with_branch()
    gaps = gap_edges(parts)
    gaps["selected"] = True            # e.g. edited by hand in QGIS
    with pytest.raises(ValueError, match="part 1 end 1 has more than one"):
        road_strings(parts, gaps)


def test_bad_road_parts_are_refused():
    parts = collinear_with_branch()
    with pytest.raises(ValueError, match="lacks columns"):
        gap_edges(parts.drop(columns="quality"))
    with pytest.raises(ValueError, match="projected CRS"):
        gap_edges(parts.to_crs("EPSG:4326"))
    with pytest.raises(ValueError, match="duplicate part_id"):
        gap_edges(parts.assign(part_id=[1, 1, 2]))
    with pytest.raises(ValueError, match="LineString"):
        gap_edges(parts.set_geometry(parts.buffer(1.0)))
    assert len(gap_edges(parts.iloc[:0])) == 0
    gaps, strings = link_road_parts(parts.iloc[:1], transform=GRID, ndsm=np.zeros(SHAPE))
    assert len(gaps) == 0 and {"occlusion", "weight", "selected"} <= set(gaps.columns)
    assert strings.part_ids.tolist() == ["1"]
    assert len(road_strings(parts.iloc[:0], gap_edges(parts.iloc[:0]).assign(selected=[]))) == 0


# --- a synthetic scene ----------------------------------------------------------------------

BRANCH = -1000     # road_id of the false side branches


@pytest.fixture(scope="module")
def scene_parts():
    """Road parts cut from the ground-level truth roads of a rendered synthetic scene (gaps
    of 4-14 m, some under trees and cars), a false part branching off at 20 degrees in every
    gap, and false pairs in line through every building."""
    from gisroads.imagery.cues import image_cues
    from gisroads.synthetic import make_scene, render_image
    scene = make_scene(seed=3, size_m=(300, 300))
    image, dsm = render_image(scene, pixel_m=0.5)
    rng = np.random.default_rng(0)
    rows = []
    # the bridge road is left out: raised above the ground, its parts would not pass the
    # road-part stage's nDSM test, and its deck reads as a building here
    for road in scene.roads[scene.roads.level == 0].itertuples():
        line = shapely.force_2d(road.geometry)
        start, order = rng.uniform(0, 5), 0
        while start < line.length - 10:
            stop = min(line.length, start + rng.uniform(30, 50))
            rows.append((road.road_id, order, road.width_m * rng.uniform(0.85, 1.1),
                         rng.uniform(0.4, 0.9), shapely.ops.substring(line, start, stop)))
            gap = rng.uniform(4, 14)
            if stop + gap < line.length - 10:     # a false part branching off in the gap
                end, inner = (np.asarray(line.interpolate(stop - d).coords[0]) for d in (0, 1))
                ahead = (end - inner) / np.linalg.norm(end - inner)
                side = np.array([-ahead[1], ahead[0]])
                branch = COS20 * ahead + SIN20 * side
                first = end + 0.8 * gap * ahead + 2.0 * side
                rows.append((BRANCH, order, 6.0, 0.6,
                             shapely.LineString([first, first + 25 * branch])))
            start, order = stop + gap, order + 1
    for building in scene.buildings.itertuples():
        corners = np.asarray(building.geometry.minimum_rotated_rectangle.exterior.coords)
        axis = max(np.diff(corners[:3], axis=0), key=np.linalg.norm)
        half, along = np.linalg.norm(axis) / 2 + 1.0, axis / np.linalg.norm(axis)
        middle = np.asarray(building.geometry.centroid.coords[0])
        for side in (-1, 1):
            rows.append((-1 - building.building_id, int(side > 0), 6.0, 0.6,
                         shapely.LineString([middle + side * half * along,
                                             middle + side * (half + 20) * along])))
    parts = gpd.GeoDataFrame(
        {"part_id": np.arange(len(rows)), "road_id": [r[0] for r in rows],
         "order": [r[1] for r in rows], "width_m": [r[2] for r in rows],
         "quality": [r[3] for r in rows]},
        geometry=[r[4] for r in rows], crs=scene.crs)
    return parts, image, dsm, image_cues


def _score_links(parts, gaps):
    """True links (consecutive parts of a road), false links (between roads, or a road and
    a branch), links through a building (its two parts), and the number of road gaps."""
    road = parts.set_index("part_id")
    a, b = road.road_id.loc[gaps.from_part].values, road.road_id.loc[gaps.to_part].values
    next_part = np.abs(road.order.loc[gaps.from_part].values
                       - road.order.loc[gaps.to_part].values) == 1
    true_link = (a == b) & (a >= 0) & next_part
    false_link = ((a >= 0) & (b >= 0) & ~true_link) | (np.minimum(a, b) == BRANCH) & (
        np.maximum(a, b) >= 0)
    n_true = int((parts[parts.road_id >= 0].groupby("road_id").size() - 1).sum())
    return true_link, false_link, (a == b) & (a < 0) & (a > BRANCH), n_true


def test_synthetic_scene_links_road_gaps_and_rejects_links_through_buildings(scene_parts):
    from gisroads.imagery.cues import context_rasters
    parts, image, dsm, image_cues = scene_parts
    cues = image_cues(image, nir_band=4, dsm=dsm)
    gaps, strings = link_road_parts(parts, transform=image.transform, **context_rasters(cues))
    true_link, false_link, through_building, n_true = _score_links(parts, gaps)
    assert n_true == 31 and true_link.sum() == n_true          # every road gap hypothesised
    assert gaps.selected[true_link].all()                      # ... and kept
    assert false_link.sum() >= 31 and not gaps.selected[false_link].any()  # branches lose
    assert through_building.sum() == 37                        # one per building
    assert (gaps.n_building[through_building] == 1).all()
    assert (gaps.weight[through_building] == 0).all()
    # gaps under trees and their shadows are kept through the occlusion share
    assert (gaps.occlusion[true_link] > 0.5).sum() >= 5
    assert (gaps.n_building[true_link] == 0).all()
    assert len(strings) == len(parts) - gaps.selected.sum()


def test_synthetic_scene_rgb_only_uses_colour_vegetation(scene_parts):
    from gisroads.geo import GeoRaster
    from gisroads.imagery.cues import context_rasters
    parts, image, _, image_cues = scene_parts
    rgb = image_cues(GeoRaster(image.data[:3], image.transform, image.crs))
    gaps, _ = link_road_parts(parts, transform=image.transform, **context_rasters(rgb))
    true_link, false_link, _, n_true = _score_links(parts, gaps)
    assert gaps.context_cues.iloc[0] == "intensity,rgb"
    assert gaps.selected[true_link].sum() == n_true and not gaps.selected[false_link].any()
    assert (gaps.n_tree[true_link] > 0).sum() >= 5


def test_learned_probability_along_the_gap_is_its_context():
    """A road probability (beyond the papers): its mean along the gap is the occlusion share
    and the context weight; the nDSM still adds buildings."""
    parts = two_parts()
    road = block(1.0, 38, 62, -3, 3)                 # the model sees road across the gap
    gaps, strings = link_road_parts(parts, transform=GRID, probability=road)
    assert gaps.occlusion[0] == pytest.approx(1.0) and gaps.context_weight[0] == 1.0
    assert gaps.context_cues[0] == "probability" and gaps.n_tree[0] == 0
    assert gaps.weight[0] == pytest.approx((gaps.relation_weight[0] + 1.0) / 2)
    assert gaps.selected.tolist() == [True] and strings.part_ids.tolist() == ["1,2"]
    half = block(1.0, 38, 50, -3, 3)                 # road on the first half only
    gaps, _ = link_road_parts(parts, transform=GRID, probability=half)
    assert gaps.occlusion[0] == pytest.approx(0.5, abs=0.1)
    nothing, _ = link_road_parts(parts, transform=GRID, probability=np.zeros(SHAPE))
    assert nothing.context_weight[0] == 0.0
    assert nothing.weight[0] == pytest.approx(nothing.relation_weight[0] / 2)
    # a building in the gap still blocks the link, whatever the model says
    blocked, _ = link_road_parts(parts, transform=GRID, probability=road,
                                 ndsm=block(8.0, 45, 55, -5, 5))
    assert blocked.n_building[0] == 1 and blocked.context_cues[0] == "ndsm,probability"
    assert blocked.weight[0] == 0.0 and blocked.selected.tolist() == [False]
    # colour rasters are left out when the probability is given
    crown = block(0.8, 38, 62, -6, 6)
    lawn, _ = link_road_parts(parts, transform=GRID, ndvi=crown, probability=road)
    assert lawn.n_tree[0] == 0 and lawn.selected.tolist() == [True]
