"""Memory stays flat (issue 12, item 1) in the driver too: ``gisroads lidar`` writes the
tiles' QA layers and rasters one tile at a time from the files the tiles wrote, holding the
centre lines and one tile, and writes what the in-memory API assembles, whatever the
number of workers."""
import weakref

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import shapely

from gisroads.io.raster import read_raster
from gisroads.io.vector import GeoPackageWriter, list_layers, read_layer
from gisroads.jobs.lidar import lidar_job
from gisroads.lidar import pipeline
from gisroads.lidar.pipeline import TiledRoads, TileRoads, extract_roads
from tests.lidar.tile_runs import assert_same_geometries


def _assert_same_layer(written: gpd.GeoDataFrame, frame: gpd.GeoDataFrame):
    """A GeoPackage layer holds ``frame``: its features in order, its fields and values."""
    assert_same_geometries(written, frame)
    assert set(written.columns) == set(frame.columns)
    pd.testing.assert_frame_equal(
        pd.DataFrame(written.drop(columns="geometry")),
        pd.DataFrame(frame[written.columns].drop(columns="geometry").reset_index(drop=True)),
        check_dtype=False)


def test_the_job_writes_tile_by_tile_what_the_api_assembles(tiled_cloud, tiled_network,
                                                            tmp_path, monkeypatch):
    alive, most = set(), [0]

    def counted(path, read=pipeline.kept_result):
        result = read(path)
        if isinstance(result, TileRoads):  # not the tasks' look for a finished tile
            alive.add(id(result))
            weakref.finalize(result, alive.discard, id(result))
            most[0] = max(most[0], len(alive))
        return result
    monkeypatch.setattr(pipeline, "kept_result", counted)
    out, rasters = tmp_path / "roads.gpkg", tmp_path / "rasters"
    result = lidar_job(tiled_cloud, out, cue="intensity", rasters_dir=rasters)
    # the six tiles' results are read back one after another: at most the one being
    # written and the next one alive at a time
    assert result["tiles"] == 6 and 1 <= most[0] <= 2
    layers = tiled_network.network.layers()
    assert list_layers(out) == list(layers)
    assert len(layers["hypotheses"]) > 1000 and len(layers["rectangles"]) > 10
    for name, frame in layers.items():
        _assert_same_layer(read_layer(out, name), frame)
    # the heights mosaic written window by window is the one made in memory, NaN where no
    # tile's core is
    heights = read_raster(rasters / "ground_heights.tif")
    assert heights.transform == tiled_network.heights.transform
    np.testing.assert_array_equal(heights.data, tiled_network.heights.data)
    assert np.isnan(heights.data).any() and np.isfinite(heights.data).any()
    for tile in tiled_network.tiles:  # whole tiles, with their maps, as --rasters asks
        name = f"tile_r{tile.tile.row}_c{tile.tile.col}"
        np.testing.assert_array_equal(read_raster(rasters / f"{name}_intensity.tif").data,
                                      tile.intensity.data)
        assert len(list(rasters.glob(f"{name}_likelihood_level_*.tif"))) == \
            len(tile.likelihood) > 0


def test_two_workers_write_the_layers_of_one(tiled_cloud, tmp_path):
    pytest.importorskip("distributed")
    one, two = tmp_path / "one.gpkg", tmp_path / "two.gpkg"
    lidar_job(tiled_cloud, one, cue="intensity", workers=1, rasters_dir=tmp_path / "r1",
              tile_maps=False)
    lidar_job(tiled_cloud, two, cue="intensity", workers=2, rasters_dir=tmp_path / "r2",
              tile_maps=False)
    assert list_layers(one) == list_layers(two)
    for name in list_layers(one):
        _assert_same_layer(read_layer(two, name), read_layer(one, name))
    written = sorted(p.name for p in (tmp_path / "r1").iterdir())
    assert written == sorted(p.name for p in (tmp_path / "r2").iterdir())
    assert not any("likelihood" in name for name in written)  # tile_maps=False
    for name in written:
        np.testing.assert_array_equal(read_raster(tmp_path / "r1" / name).data,
                                      read_raster(tmp_path / "r2" / name).data)


def test_the_lazy_network_holds_no_tile_and_removes_its_temporary_store(tiled_cloud,
                                                                        tiled_network):
    with extract_roads(tiled_cloud, cue="intensity", lazy=True) as roads:
        assert isinstance(roads, TiledRoads)
        assert roads.network.qa == {} and len(roads.tiles) == len(roads.files) == 6
        assert_same_geometries(roads.network.centrelines, tiled_network.network.centrelines)
        np.testing.assert_array_equal(roads.mosaic("heights").data,
                                      tiled_network.heights.data)
        folder = roads.files[0].parent
        assert folder.exists()
    assert not folder.exists()


def test_a_cloud_without_tiles_writes_empty_qa_layers(tiled_cloud, tmp_path):
    """No tile holds enough points: the QA layers are there, empty, as the API gives."""
    api = extract_roads(tiled_cloud, cue="intensity", min_points=10**9)
    out = tmp_path / "roads.gpkg"
    with pytest.warns(Warning):
        lidar_job(tiled_cloud, out, cue="intensity", min_points=10**9,
                  rasters_dir=tmp_path / "rasters")
    assert list_layers(out) == list(api.network.layers())
    for name in ("rectangles", "hypotheses"):
        assert len(read_layer(out, name)) == 0
    assert not (tmp_path / "rasters" / "ground_heights.tif").exists()


def test_a_geopackage_written_part_by_part(tmp_path):
    def points(n, y):
        return gpd.GeoDataFrame({"level": np.arange(n, dtype=np.int64)},
                                geometry=[shapely.Point(x, y) for x in range(n)],
                                crs="EPSG:2056")
    out = tmp_path / "parts.gpkg"
    with GeoPackageWriter(out) as gpkg:
        gpkg.write("junctions", points(2, 0))
        gpkg.append("rectangles", points(0, 0))  # no feature yet: its schema is kept
        gpkg.append("rectangles", points(2, 1))
        gpkg.append("rectangles", points(3, 2).iloc[1:])
        gpkg.append("hypotheses", points(0, 0))  # never a feature: an empty layer
    assert list_layers(out) == ["junctions", "rectangles", "hypotheses"]
    rectangles = read_layer(out, "rectangles")
    assert rectangles.geometry.y.tolist() == [1, 1, 2, 2]
    assert rectangles.level.tolist() == [0, 1, 1, 2]
    assert len(read_layer(out, "hypotheses")) == 0
    # a failure midway leaves the file it would have replaced, and no temporary file
    with pytest.raises(RuntimeError):
        with GeoPackageWriter(out) as gpkg:
            gpkg.write("junctions", points(5, 0))
            raise RuntimeError("cancelled")
    assert len(read_layer(out, "junctions")) == 2
    assert [p.name for p in tmp_path.iterdir()] == ["parts.gpkg"]
    # appends held and written in batches of at least 3 features, in their order
    with GeoPackageWriter(out, batch_features=3) as gpkg:
        for y in range(6):
            gpkg.append("rectangles", points(2, y))
            gpkg.append("hypotheses", points(1, y))
    assert list_layers(out) == ["rectangles", "hypotheses"]
    rectangles = read_layer(out, "rectangles")
    assert rectangles.geometry.y.tolist() == [y for y in range(6) for _ in range(2)]
    assert rectangles.level.tolist() == [0, 1] * 6
    assert read_layer(out, "hypotheses").geometry.y.tolist() == list(range(6))
