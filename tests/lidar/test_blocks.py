"""City blocks (Zhu & Mordohai, section 5): hand-made rasters with exact answers, a grid of
blocks with and without a missed road segment, a synthetic scene, the CLI."""
import json
import sqlite3
import subprocess
import sys

import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS
from rasterio import features
from scipy import ndimage

from gisroads.lidar.blocks import (block_affinity, block_nodes, city_blocks,
                             max_likelihood_between, road_likelihood, thin_points)
from gisroads.geo import GeoRaster
from gisroads.io.las import LasPointWriter
from gisroads.io.raster import write_geotiff
from gisroads.io.vector import list_layers, read_layer
from gisroads.progress import Cancelled
from gisroads.synthetic import make_scene

UTM = CRS.from_epsg(32633)
BLOCK_M, ROAD_M, L_MAX = 100.0, 15.0, 25.0
PERIOD = BLOCK_M + ROAD_M
SIZE_M = 3 * BLOCK_M + 4 * ROAD_M  # a 3 x 3 grid of blocks with roads all round
ORIGIN = (500000.0, 4500000.0)


def grid_likelihood(*, missing=False, pixel_m=1.0, seed=0) -> GeoRaster:
    """3 x 3 blocks of 100 m separated by 15 m roads at L_max, noise 0-2 elsewhere;
    ``missing`` removes the road segment between the two western blocks of the top row."""
    cells = int(round(SIZE_M / pixel_m))
    rng = np.random.default_rng(seed)
    values = rng.uniform(0.0, 2.0, (cells, cells))
    centre = (np.arange(cells) + 0.5) * pixel_m
    road = centre % PERIOD < ROAD_M
    values[road, :] = L_MAX
    values[:, road] = L_MAX
    if missing:
        rows = (centre >= ROAD_M) & (centre < PERIOD)
        cols = (centre >= PERIOD) & (centre < PERIOD + ROAD_M)
        values[np.ix_(rows, cols)] = rng.uniform(0.0, 2.0, (rows.sum(), cols.sum()))
    return GeoRaster(values, Affine(pixel_m, 0, ORIGIN[0], 0, -pixel_m, ORIGIN[1] + SIZE_M),
                     UTM)


def true_blocks() -> dict[tuple[int, int], shapely.Polygon]:
    """(row from the north, column from the west) -> the block's square."""
    squares = {}
    for row in range(3):
        for col in range(3):
            x0 = ORIGIN[0] + ROAD_M + col * PERIOD
            y1 = ORIGIN[1] + SIZE_M - ROAD_M - row * PERIOD
            squares[row, col] = shapely.box(x0, y1 - BLOCK_M, x0 + BLOCK_M, y1)
    return squares


def block_at(blocks, point: shapely.Point) -> int:
    hits = blocks[blocks.contains(point)]
    assert len(hits) == 1, f"{len(hits)} blocks at {point}"
    return int(hits.block_id.iloc[0])


def best_iou(blocks, square) -> float:
    inter = shapely.area(shapely.intersection(blocks.geometry.values, square))
    union = shapely.area(shapely.union(blocks.geometry.values, square))
    return float((inter / union).max())


# --- stages on hand-made rasters ----------------------------------------------------------

def tiny_raster(values, pixel_m=1.0, crs=UTM) -> GeoRaster:
    values = np.asarray(values, float)
    return GeoRaster(values, Affine(pixel_m, 0, 0.0, 0, -pixel_m, values.shape[-2] * pixel_m),
                     crs)


def test_max_likelihood_between_finds_the_line_a_segment_crosses():
    values = np.zeros((10, 10))
    values[:, 5] = 7.0  # a one-cell line at x in [5, 6]
    values[2, 2] = 3.0
    raster = tiny_raster(values)
    start = np.array([[1.5, 7.5], [1.5, 7.5], [0.5, 9.5], [6.5, 0.5], [2.5, 7.5]])
    end = np.array([[8.5, 7.5], [4.5, 7.5], [9.5, 0.5], [9.5, 9.5], [2.5, 7.5]])
    # across the line; short of it (over the 3); diagonal across it; beside it; one point
    assert max_likelihood_between(raster, start, end).tolist() == [7.0, 3.0, 7.0, 0.0, 3.0]


def test_max_likelihood_between_samples_every_cell_of_long_segments():
    values = np.zeros((3, 400))
    values[:, 217] = 1.0
    raster = tiny_raster(values, pixel_m=0.5)
    found = max_likelihood_between(raster, [[0.1, 0.75], [0.1, 0.75]],
                                   [[199.9, 0.75], [108.0, 0.75]])
    assert found.tolist() == [1.0, 0.0]


def test_road_likelihood_merges_width_bands_and_scales_probabilities():
    bands = np.zeros((3, 4, 4))
    bands[0, 0, 0], bands[2, 0, 0], bands[1, 3, 3] = 4.0, 9.0, 40.0
    merged = road_likelihood(tiny_raster(bands))
    assert merged.data[0, 0] == 9.0 and merged.data[3, 3] == L_MAX  # capped at L_max
    probability = road_likelihood(tiny_raster(np.full((4, 4), 0.5)))
    assert np.allclose(probability.data, 0.5 * L_MAX)
    as_is = road_likelihood(tiny_raster(np.full((4, 4), 0.5)), probability=False)
    assert np.allclose(as_is.data, 0.5)


@pytest.mark.parametrize("raster, message", [
    (tiny_raster(np.full((5, 5), np.nan)), "no valid cell"),
    (tiny_raster(np.zeros((5, 5)), crs=None), "no CRS"),
    (tiny_raster(np.zeros((5, 5)), crs=CRS.from_epsg(4326)), "geographic"),
    (tiny_raster(-np.ones((5, 5))), "not negative"),
])
def test_bad_rasters_are_refused_with_a_clear_error(raster, message):
    with pytest.raises(ValueError, match=message):
        city_blocks(raster)


def test_nodes_stay_off_the_roads_and_thin_points_keeps_the_most_central():
    raster = road_likelihood(grid_likelihood())
    nodes = block_nodes(raster, road_threshold=0.5 * L_MAX)
    assert len(nodes) == 9 * 100  # a 10 m lattice, 10 x 10 in each block, none on a road
    row, col = raster.xy_to_rowcol(nodes[:, 0], nodes[:, 1])
    assert (raster.data[row, col] < 2.0).all()
    kept = thin_points([[1.0, 1.0], [4.9, 5.2], [9.0, 9.0], [12.0, 3.0], [np.nan, 1.0]], 10.0)
    assert sorted(map(tuple, kept)) == [(4.9, 5.2), (12.0, 3.0)]


def test_affinity_is_eq_9_within_the_edge_length():
    raster = road_likelihood(grid_likelihood(seed=1))
    nodes = np.array([[ORIGIN[0] + 30, ORIGIN[1] + 300], [ORIGIN[0] + 80, ORIGIN[1] + 300],
                      [ORIGIN[0] + 150, ORIGIN[1] + 300], [ORIGIN[0] + 30, ORIGIN[1] + 100]])
    weights = block_affinity(raster, nodes, max_edge_m=80.0).toarray()
    assert weights[0, 1] == weights[1, 0] > np.exp(-2.0)  # same block: noise only
    assert weights[1, 2] == pytest.approx(np.exp(-L_MAX))  # across a road
    assert weights[0, 2] == weights[0, 3] == 0.0  # 120 m and 200 m apart: no edge


# --- the grid of blocks -------------------------------------------------------------------

def test_grid_gives_the_nine_true_blocks():
    blocks = city_blocks(grid_likelihood())
    assert len(blocks) == 9
    for square in true_blocks().values():
        assert best_iou(blocks, square) >= 0.8
    assert blocks.crs == UTM
    assert blocks.area_m2.to_numpy() == pytest.approx(np.full(9, 1e4), rel=0.05)
    assert blocks.perimeter_m.to_numpy() == pytest.approx(np.full(9, 400.0), rel=0.05)
    assert blocks.block_id.tolist() == list(range(9))


@pytest.mark.parametrize("n_blocks", [None, 9])
def test_missed_road_segment_still_separates_its_two_blocks(n_blocks):
    likelihood = grid_likelihood(missing=True)
    band = road_likelihood(likelihood)
    # the thresholded likelihood alone joins the two blocks: 8 regions, not 9
    assert ndimage.label(band.data < 0.5 * L_MAX)[1] == 8
    blocks = city_blocks(likelihood, n_blocks=n_blocks)
    assert len(blocks) == 9
    squares = true_blocks()
    for square in squares.values():
        assert best_iou(blocks, square) >= 0.8
    west, east = squares[0, 0].centroid, squares[0, 1].centroid
    assert block_at(blocks, west) != block_at(blocks, east)
    # the cut runs through the gap: each of the two blocks keeps about half of it
    gap = shapely.box(ORIGIN[0] + PERIOD, ORIGIN[1] + SIZE_M - PERIOD,
                      ORIGIN[0] + PERIOD + ROAD_M, ORIGIN[1] + SIZE_M - ROAD_M)
    shares = shapely.area(shapely.intersection(blocks.geometry.values, gap))
    assert shares.sum() == pytest.approx(gap.area, rel=0.01)
    assert sorted(shares)[-2] > 0.2 * gap.area


def test_blocks_cut_off_by_roads_are_never_merged_to_meet_n_blocks():
    blocks = city_blocks(grid_likelihood(), n_blocks=1)
    assert len(blocks) == blocks.segment.nunique() == 9
    # more blocks than the grid has: the extra cuts go where the eigenvalues are largest,
    # first the missed road segment
    blocks = city_blocks(grid_likelihood(missing=True), n_blocks=8)
    assert len(blocks) == 8
    blocks = city_blocks(grid_likelihood(missing=True), n_blocks=10)
    assert len(blocks) == 10
    squares = true_blocks()
    assert block_at(blocks, squares[0, 0].centroid) != block_at(blocks, squares[0, 1].centroid)


def test_ground_points_as_nodes_give_the_same_blocks():
    rng = np.random.default_rng(4)
    points = rng.uniform(0, SIZE_M, (20000, 2)) + ORIGIN
    blocks = city_blocks(grid_likelihood(missing=True), points_xy=points)
    assert len(blocks) == 9
    for square in true_blocks().values():
        assert best_iou(blocks, square) >= 0.8
    # blocks cover only where there are points: none in an empty half
    half = points[points[:, 0] < ORIGIN[0] + SIZE_M / 2]
    covered = city_blocks(grid_likelihood(), points_xy=half)
    assert covered.total_bounds[2] < ORIGIN[0] + SIZE_M / 2 + 25.0


def test_probability_raster_and_cancel():
    likelihood = grid_likelihood(missing=True)
    probability = GeoRaster(likelihood.data / L_MAX, likelihood.transform, likelihood.crs)
    assert probability.data.max() == 1.0  # roads certain, noise up to 0.08
    blocks = city_blocks(probability)
    assert len(blocks) == 9
    squares = true_blocks()
    assert block_at(blocks, squares[0, 0].centroid) != block_at(blocks, squares[0, 1].centroid)

    def cancel(fraction, message=""):
        if fraction > 0.3:
            raise Cancelled()
    with pytest.raises(Cancelled):
        city_blocks(grid_likelihood(), progress=cancel)


# --- a synthetic scene ------------------------------------------------------------------

def test_synthetic_scene_blocks_do_not_cross_the_truth_roads():
    scene = make_scene(seed=1, size_m=(400.0, 400.0))
    roads = scene.truth.polygons
    x0, y0, x1, y1 = scene.extent
    transform = Affine(1.0, 0, x0, 0, -1.0, y1)
    shape = (int(y1 - y0), int(x1 - x0))
    road_mask = features.rasterize(((g, 1) for g in roads.geometry.values), out_shape=shape,
                                   transform=transform).astype(float)
    noise = np.random.default_rng(0).normal(0.0, 0.08, shape)
    probability = np.clip(ndimage.gaussian_filter(road_mask, 1.5) + noise, 0.0, 1.0)
    blocks = city_blocks(GeoRaster(probability, transform, scene.crs))
    assert len(blocks) >= 12
    coverage = shapely.union_all(blocks.geometry.values)
    off_road = shapely.difference(shapely.box(*scene.extent), shapely.union_all(roads.geometry))
    assert coverage.area > 0.8 * off_road.area
    # no block reaches into a road beyond the blur of its edge
    road_cores = shapely.union_all(shapely.buffer(roads.geometry.values, -1.5))
    assert shapely.intersection(coverage, road_cores).area < 10.0
    lines = scene.truth.centrelines.geometry.values
    inside = shapely.length(shapely.intersection(lines, coverage)).sum()
    assert inside < 0.01 * shapely.length(lines).sum()


# --- the command line -------------------------------------------------------------------

def gisroads(*args):
    return subprocess.run([sys.executable, "-m", "gisroads.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def test_cli_writes_styled_blocks_and_reads_ground_points(tmp_path):
    tif = write_geotiff(tmp_path / "likelihood.tif", grid_likelihood(missing=True))
    cloud = tmp_path / "ground.laz"
    rng = np.random.default_rng(2)
    xyz = np.column_stack([rng.uniform(0, SIZE_M, (30000, 2)) + ORIGIN, np.full(30000, 10.0)])
    classes = np.where(rng.uniform(size=30000) < 0.5, 2, 5).astype(np.uint8)
    with LasPointWriter(cloud, crs=UTM, offset=(ORIGIN[0], ORIGIN[1], 0.0)) as writer:
        writer.write(xyz, classification=classes)
    out = tmp_path / "blocks.gpkg"
    result = gisroads("blocks", tif, "-o", out, "--points", cloud, "--json",
                      "--quicklook", tmp_path / "blocks.png")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["blocks"] == 9
    assert list_layers(out) == ["city_blocks"]
    blocks = read_layer(out, "city_blocks")
    assert len(blocks) == 9 and blocks.crs == UTM
    assert {"block_id", "area_m2", "perimeter_m"} <= set(blocks.columns)
    squares = true_blocks()
    assert block_at(blocks, squares[0, 0].centroid) != block_at(blocks, squares[0, 1].centroid)
    with sqlite3.connect(out) as con:
        assert con.execute("SELECT count(*) FROM layer_styles WHERE f_table_name = "
                           "'city_blocks'").fetchone()[0] == 1
    assert (tmp_path / "blocks.png").stat().st_size > 10000


def test_cli_refuses_a_nan_raster_in_one_line(tmp_path):
    tif = tmp_path / "nan.tif"
    write_geotiff(tif, tiny_raster(np.full((20, 20), np.nan)))
    result = gisroads("blocks", tif, "-o", tmp_path / "out.gpkg")
    assert result.returncode == 2
    assert result.stderr.startswith("gisroads: error: ")
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out.gpkg").exists()
