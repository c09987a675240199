import geopandas as gpd
import numpy as np
import pytest
import shapely

from gisroads.tiling.tiles import Tile, clip_to_core, merge_pieces, stitch_tiles, tile_grid


def test_grid_follows_the_paper_and_cores_partition_the_extent():
    tiles = tile_grid((0, 0, 700, 500), tile_m=300, overlap_m=100)
    assert {t.bounds[2] - t.bounds[0] for t in tiles} == {300}
    xs = sorted({t.bounds[0] for t in tiles})
    assert xs == [0, 200, 400]  # stride = 300 - 100
    cores = shapely.union_all([shapely.box(*t.core) for t in tiles])
    assert cores.equals(shapely.box(0, 0, 700, 500))
    assert sum(shapely.box(*t.core).area for t in tiles) == pytest.approx(700 * 500)
    for t in tiles:
        assert shapely.box(*t.bounds).contains(shapely.box(*t.core)) or t.core[2] == 700 \
            or t.core[3] == 500
    inner = [t for t in tiles if t.col == 1][0]
    assert inner.core[0] == 250 and inner.core[2] == 450  # half the overlap in from each side


def test_small_extent_is_one_tile():
    (tile,) = tile_grid((10, 20, 110, 120))
    assert tile.core == (10, 20, 110, 120)


def lines(*coords, width=8.0):
    return gpd.GeoDataFrame({"width_m": np.full(len(coords), width),
                             "score": np.ones(len(coords)), "road_id": np.arange(len(coords))},
                            geometry=[shapely.LineString(c) for c in coords], crs="EPSG:32633")


def test_road_across_a_seam_is_one_line_without_duplicates():
    tiles = tile_grid((0, 0, 500, 300), tile_m=300, overlap_m=100)
    assert len(tiles) == 2
    left, right = tiles
    # each tile found the same E-W road over its whole extent, 0.8 m apart in y
    a = lines([(0, 100.0), (300, 100.0)], width=8.0)
    b = lines([(200, 100.8), (500, 100.8)], width=10.0)
    stitched = stitch_tiles([(left, a), (right, b)], snap_m=3.0)
    assert len(stitched) == 1
    line = stitched.geometry.iloc[0]
    assert line.length == pytest.approx(500, abs=1.0)
    assert stitched.width_m.iloc[0] == pytest.approx(9.0, abs=0.1)  # 250 m of each
    # no gap at the seam x = 250
    assert line.distance(shapely.Point(250, 100.4)) < 1e-6


def test_far_apart_pieces_are_not_joined():
    left, right = tile_grid((0, 0, 500, 300), tile_m=300, overlap_m=100)
    a = lines([(0, 100.0), (300, 100.0)])
    b = lines([(200, 120.0), (500, 120.0)])
    assert len(stitch_tiles([(left, a), (right, b)], snap_m=3.0)) == 2


def test_clip_to_core_drops_the_margin():
    tile = Tile(0, 1, (200, 0, 500, 300), (250, 0, 500, 300))
    clipped = clip_to_core(lines([(0, 50), (500, 50)], [(0, 10), (100, 10)]), tile)
    assert len(clipped) == 1 and clipped.geometry.iloc[0].length == pytest.approx(250)


def test_merge_pieces_weights_widths_and_keeps_ids():
    merged = merge_pieces(gpd.GeoDataFrame(
        {"width_m": [6.0, 12.0], "road_id": [3, 4]},
        geometry=[shapely.LineString([(0, 0), (30, 0)]), shapely.LineString([(30, 0), (40, 0)])],
        crs="EPSG:32633"))
    assert len(merged) == 1
    assert merged.width_m.iloc[0] == pytest.approx((6 * 30 + 12 * 10) / 40)
    assert merged.road_id.iloc[0] == 3


def test_merge_pieces_gives_every_piece_of_a_crossing_its_attributes():
    # the union splits both lines at the crossing: four lines, only two hold a midpoint
    merged = merge_pieces(gpd.GeoDataFrame(
        {"width_m": [6.0, 9.0], "level": np.array([1, 2], np.int64)},
        geometry=[shapely.LineString([(-50, 0), (50, 0)]),
                  shapely.LineString([(0, -50), (0, 50)])], crs="EPSG:32633"))
    assert len(merged) == 4
    bounds = shapely.bounds(merged.geometry.values)
    horizontal = bounds[:, 3] - bounds[:, 1] < 1e-9
    assert merged.level.dtype == np.int64
    assert merged.level.tolist() == np.where(horizontal, 1, 2).tolist()
    assert merged.width_m.tolist() == np.where(horizontal, 6.0, 9.0).tolist()
