"""Read once (issue 12, item 1): one streaming pass buckets the points into the tile grid on
disk; tiles read their points from there; several files, a folder or a glob are one cloud."""
import laspy
import numpy as np
import pytest
import shapely
from pyproj import CRS

import gisroads.tiling.tilestore as tilestore
from gisroads.io.las import LasError, LasPointWriter, read_las
from gisroads.lidar.pipeline import extract_roads
from gisroads.tiling.tilestore import las_inputs, open_store
from gisroads.synthetic import make_scene, write_cloud


@pytest.fixture(scope="module")
def cloud(tiled_cloud):
    return tiled_cloud


@pytest.fixture(scope="module")
def split(cloud, tmp_path_factory):
    """The cloud cut into three files at x = 250 m and 480 m from its west edge."""
    folder = tmp_path_factory.mktemp("split")
    las = laspy.read(cloud)
    x = np.asarray(las.x)
    cuts = [-np.inf, x.min() + 250, x.min() + 480, np.inf]
    for i in range(3):
        part = laspy.LasData(las.header)
        part.points = las.points[(x >= cuts[i]) & (x < cuts[i + 1])]
        part.write(folder / f"part_{i}.laz")
    return folder


def _sorted_rows(cloud):
    rows = np.column_stack([cloud.xyz, cloud.intensity, cloud.classification,
                            cloud.return_number, cloud.number_of_returns])
    return rows[np.lexsort(rows.T[::-1])]


def test_each_tile_reads_exactly_the_points_inside_its_bounds(cloud, tmp_path):
    store = open_store(cloud, tmp_path, tile_m=300.0, overlap_m=100.0, chunk_size=50_000)
    whole = read_las(cloud)
    assert store.point_count == len(whole)
    assert len(store.tiles) == 6  # 700 x 500 m: 3 x 2 tiles of 300 m every 200 m
    for tile in store.tiles:
        from_store = store.read(tile)
        direct = read_las(cloud, bbox=tile.bounds)
        assert len(from_store) == len(direct) > 0
        np.testing.assert_array_equal(_sorted_rows(from_store), _sorted_rows(direct))
    # points on the tiles' edges belong to both tiles: a tile spans 2 cells of 200 m
    assert store.reach == 2
    # a second opening reuses the finished store
    again = open_store(cloud, tmp_path, tile_m=300.0, overlap_m=100.0)
    assert again.folder == store.folder and again.cells == store.cells


def test_a_pass_that_fails_midway_leaves_no_store(cloud, tmp_path, monkeypatch):
    real = tilestore.iter_las_chunks

    def failing(path, **kw):
        for i, chunk in enumerate(real(path, **kw)):
            if i == 2:
                raise KeyboardInterrupt
            yield chunk

    monkeypatch.setattr(tilestore, "iter_las_chunks", failing)
    with pytest.raises(KeyboardInterrupt):
        open_store(cloud, tmp_path, chunk_size=50_000)
    assert list(tmp_path.iterdir()) == []


def test_the_input_is_decoded_once_whatever_the_tile_count(cloud, monkeypatch):
    decoded = []
    real = tilestore.iter_las_chunks

    def counting(path, **kw):
        for chunk in real(path, **kw):
            decoded.append(len(chunk))
            yield chunk

    monkeypatch.setattr(tilestore, "iter_las_chunks", counting)
    monkeypatch.setattr(tilestore, "PART_POINTS", 70_000)  # the pass in several parts
    roads = extract_roads(cloud, cue="evidence", tile_m=200.0, overlap_m=50.0)
    assert roads.run["tiles"] == 15  # 5 x 3 tiles of 200 m every 150 m
    assert sum(decoded) == len(read_las(cloud))
    assert roads.network.centrelines.length.sum() > 2000


def test_parts_read_on_workers_give_the_store_of_one_pass(cloud, tmp_path, monkeypatch):
    # parts of 70 000 points: a LAZ file decoded from inside its compressed chunks
    monkeypatch.setattr(tilestore, "PART_POINTS", 70_000)
    whole = read_las(cloud)
    assert len(whole) > 3 * 70_000
    here = open_store(cloud, tmp_path / "here", chunk_size=30_000)
    on_workers = open_store(cloud, tmp_path / "workers", chunk_size=30_000, workers=2)
    assert here.cells == on_workers.cells and here.parts == on_workers.parts
    assert max(len(parts) for parts in here.parts.values()) > 1
    every = np.concatenate([index for index, _ in here.iter_cells()])
    np.testing.assert_array_equal(np.sort(every), np.arange(len(whole)))
    for tile in here.tiles:
        a, b = here.read(tile), on_workers.read(tile)
        np.testing.assert_array_equal(a.xyz, b.xyz)
        np.testing.assert_array_equal(a.intensity, b.intensity)
        direct = read_las(cloud, bbox=tile.bounds)
        # the points of a cell keep the file's order
        np.testing.assert_array_equal(_sorted_rows(a), _sorted_rows(direct))
    for index, points in here.iter_cells():  # in the file's order, the file's points
        assert np.all(np.diff(index) > 0)
        np.testing.assert_array_equal(points.xyz, whole.xyz[index])


def test_a_folder_a_glob_and_a_list_of_tiles_give_the_network_of_the_merged_file(
        cloud, split):
    merged = extract_roads(cloud, cue="evidence").network
    files = sorted(split.glob("*.laz"))
    assert las_inputs(split) == files == las_inputs(str(split / "part_*.laz"))
    assert las_inputs([files[2], files[0], files[1], files[0]]) == files
    for source in (split, str(split / "*.laz"), files):
        network = extract_roads(source, cue="evidence").network
        assert len(network.centrelines) == len(merged.centrelines) > 10
        assert shapely.equals_exact(
            shapely.normalize(shapely.union_all(network.centrelines.geometry.values)),
            shapely.normalize(shapely.union_all(merged.centrelines.geometry.values)), 1e-6)


def test_overlapping_files_each_give_their_points_to_every_tile_holding_them(cloud, split,
                                                                            tmp_path):
    # a fourth file repeating the strip 240-260 m: the tiles over it hold both copies
    las = laspy.read(cloud)
    x = np.asarray(las.x)
    strip = (x >= x.min() + 240) & (x < x.min() + 260)
    extra = laspy.LasData(las.header)
    extra.points = las.points[strip]
    extra.write(tmp_path / "strip.laz")
    store = open_store([split, tmp_path / "strip.laz"], tmp_path / "work")
    assert store.point_count == len(x) + strip.sum()
    for tile in store.tiles:
        inside = ((x >= tile.bounds[0]) & (x <= tile.bounds[2])
                  & (np.asarray(las.y) >= tile.bounds[1]) & (np.asarray(las.y) <= tile.bounds[3]))
        assert len(store.read(tile)) == inside.sum() + (inside & strip).sum()


def test_inputs_in_different_crs_or_missing_are_refused(cloud, tmp_path):
    assert read_las(cloud).crs != CRS("EPSG:2154")
    with LasPointWriter(tmp_path / "other.laz", crs=CRS("EPSG:2154")) as writer:
        writer.write(np.random.default_rng(0).uniform([0, 0, 0], [10, 10, 1], (100, 3)))
    with pytest.raises(LasError, match="CRS"):
        open_store([cloud, tmp_path / "other.laz"], tmp_path / "work")
    with pytest.raises(LasError, match="no such file"):
        las_inputs(tmp_path / "missing.laz")
    with pytest.raises(LasError, match="no LAS/LAZ"):
        las_inputs(str(tmp_path / "nothing_*.laz"))


def test_snakes_read_the_map_corridor_from_the_store_as_from_the_file(tmp_path):
    from gisroads.snakes.registration import register_map
    from gisroads.snakes.subclouds import read_corridor, road_patches
    from gisroads.synthetic.perturb import perturb_lines

    scene = make_scene(seed=0, size_m=(500.0, 300.0), features=("bridge", "trees"))
    path = tmp_path / "cloud.laz"
    write_cloud(scene, path, density_per_m2=3.0, seed=0)
    store = open_store(path, tmp_path / "work", tile_m=100.0, overlap_m=50.0)
    # a map of the roads in the western 150 m only: the store reads the cells along it
    edges = scene.truth_edges
    west = edges[edges.geometry.bounds["maxx"] < scene.extent[0] + 150]
    assert 0 < len(west) < len(edges)
    shifted = perturb_lines(west, shift_m=3.0, jitter_m=0.3, seed=1)
    along = shapely.get_coordinates(shapely.segmentize(shifted.geometry.values, 0.5))
    near = store.cells_near(along, 5.0)
    assert 0 < len(near) < 0.6 * len(store.cells)
    from_file, file_index = read_corridor(path, along, 5.0)
    from_store, store_index = read_corridor(store, along, 5.0)
    assert len(file_index) > 1000
    np.testing.assert_array_equal(store_index, file_index)
    np.testing.assert_array_equal(from_store.xyz, from_file.xyz)
    registered = register_map(shifted, from_file, snap_m=8.0)
    patches_file = road_patches(registered, path, chunk_size=100_000)
    patches_store = road_patches(registered, store)
    assert sum(len(p.points) for p in patches_file) > 10_000
    for a, b in zip(patches_file, patches_store, strict=True):
        assert a.road_id == b.road_id
        np.testing.assert_array_equal(a.point_index, b.point_index)
        np.testing.assert_array_equal(a.sample_index, b.sample_index)
        np.testing.assert_array_equal(a.points, b.points)
