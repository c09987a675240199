"""Compare with road database through the real qgis_process: a PostGIS road table in another
CRS than the extraction as input, PostGIS tables as outputs, read back; the shipped model
chaining the LiDAR road network and the comparison; bad input; cancel."""
import geopandas as gpd
import pandas as pd
import pytest
from qgis.core import QgsProcessingException, QgsProcessingFeedback

from gisroads.io.vector import write_geopackage
from gisroads.synthetic import make_scene
from gisroads.update import CHANGES, LAYERS, edit_database, read_database, score_changes
from tests.postgis_cluster import throwaway_cluster

SINKS = {"CONFIRMED": "confirmed", "MISSING": "missing", "NEW": "new", "MOVED": "moved",
         "PROPOSED_UPDATE": "proposed_update"}
MODEL = "LiDAR road database update"
MODEL_SINKS = {"compare:Confirmed roads": "confirmed",
               "compare:Missing roads and stretches": "missing", "compare:New roads": "new",
               "compare:Moved roads (proposed geometry)": "moved",
               "compare:Proposed database update": "proposed_update"}


def edited_edges(scene, seed):
    """The scene's junction-to-junction truth lines with widths, edited into a database."""
    edges = scene.truth_edges.merge(scene.truth.centrelines[["road_id", "width_m"]],
                                    on="road_id")
    return edit_database(edges, seed=seed)


def gpkg_sinks(folder, names):
    """Sink destinations: one table per output in one GeoPackage."""
    return {param: f"ogr:dbname='{folder / 'changes.gpkg'}' table=\"{table}\" (geom)"
            for param, table in names.items()}


@pytest.fixture(scope="module")
def postgis():
    with throwaway_cluster() as cluster:
        yield cluster


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """A scene's truth (EPSG:32633) as the extraction, and its edges edited into a road
    database in EPSG:3857 whose feature ids are the db_id, also kept as the field ``ref``."""
    folder = tmp_path_factory.mktemp("compare")
    scene = make_scene(seed=0, size_m=(1000.0, 700.0))
    write_geopackage(folder / "extracted.gpkg", scene.truth.layers())
    edited = edited_edges(scene, seed=0)
    database = edited.database.to_crs("EPSG:3857").rename(columns={"db_id": "ref"})
    write_geopackage(folder / "roads.gpkg", {"roads": database.assign(fid=database.ref)})
    return folder, edited


def test_postgis_layer_in_postgis_tables_out(qgis_process, postgis, synthetic):
    folder, edited = synthetic
    postgis.load(folder / "roads.gpkg", "roads", "roads")
    assert postgis.sql("SELECT DISTINCT ST_SRID(geom) FROM roads") == "3857"
    result = qgis_process.run(
        "comparewithroaddatabase",
        EXTRACTED=f"{folder / 'extracted.gpkg'}|layername=road_centrelines",
        DATABASE=postgis.qgis_layer("roads"), WIDTH_FIELD="width_m",
        **{param: postgis.qgis_sink(table) for param, table in SINKS.items()})
    changes = {table: read_database(postgis.gdal(), table) for table in LAYERS}
    for table, frame in changes.items():
        assert frame.crs.to_epsg() == 3857, table
        assert len(frame) == result[f"{table.upper()}_COUNT"], table
    # the feature ids (the table's primary key gid) are the db_id
    source = read_database(postgis.gdal(), "roads")
    for table in ("confirmed", "moved", "proposed_update"):
        frame = changes[table].dropna(subset=["gid"])
        assert len(frame) > 0, table
        assert (frame["db_id"] == frame["gid"]).all() and (frame["gid"] == frame["ref"]).all()
        attributes = frame.set_index(frame["gid"].astype(int))[["ref", "edge_id", "road_id"]]
        pd.testing.assert_frame_equal(attributes, source.loc[attributes.index, attributes.columns],
                                      check_dtype=False, check_names=False, obj=table)
    unchanged = changes["proposed_update"].query("change == 'unchanged'")
    assert (unchanged["width_m"].to_numpy()
            == source.loc[unchanged["gid"].astype(int), "width_m"].to_numpy()).all()
    scores = score_changes(changes, edited)
    for name, score in scores.items():
        assert score["precision"] >= 0.9 and score["recall"] >= 0.9, (name, score)


def test_bad_input_fails_without_output(qgis_process, synthetic, tmp_path):
    folder, _ = synthetic
    extracted = f"{folder / 'extracted.gpkg'}|layername=road_centrelines"
    points = f"{folder / 'extracted.gpkg'}|layername=junctions"
    for database, extra, error in (
            (points, [], "the database holds no line geometry"),
            (f"{folder / 'roads.gpkg'}|layername=roads", ["ID_FIELD=osm_id"],
             "the database has no field 'osm_id'")):
        result = qgis_process("run", "gisroads:comparewithroaddatabase", "--",
                              f"EXTRACTED={extracted}", f"DATABASE={database}", *extra,
                              *[f"{k}={v}" for k, v in gpkg_sinks(tmp_path, SINKS).items()],
                              check=False)
        assert result.returncode == 1, result.stdout
        assert error in result.stdout + result.stderr
        assert not (tmp_path / "changes.gpkg").exists()


def test_cancel_writes_nothing(run_algorithm, synthetic, tmp_path):
    folder, _ = synthetic
    feedback = QgsProcessingFeedback()
    feedback.cancel()
    with pytest.raises(QgsProcessingException, match="cancelled"):
        run_algorithm("comparewithroaddatabase", {
            "EXTRACTED": f"{folder / 'extracted.gpkg'}|layername=road_centrelines",
            "DATABASE": f"{folder / 'roads.gpkg'}|layername=roads",
            **gpkg_sinks(tmp_path, SINKS)}, feedback)
    assert not (tmp_path / "changes.gpkg").exists()


def test_model_chains_lidar_extraction_and_comparison(qgis_process, scene_dir, tmp_path):
    scene = make_scene(seed=3, size_m=(300.0, 300.0))  # the scene of scene_dir
    edited = edited_edges(scene, seed=3)
    write_geopackage(tmp_path / "roads.gpkg", {"roads": edited.database.to_crs("EPSG:4326")})
    qgis_process.run(MODEL, cloud=scene_dir / "cloud.laz",
                     database=f"{tmp_path / 'roads.gpkg'}|layername=roads",
                     id_field="db_id", width_field="width_m",
                     **{"lidar:Road network": tmp_path / "network.gpkg"},
                     **gpkg_sinks(tmp_path, MODEL_SINKS))
    extracted = gpd.read_file(tmp_path / "network.gpkg", layer="road_centrelines")
    assert len(extracted) > 0
    changes = {table: gpd.read_file(tmp_path / "changes.gpkg", layer=table)
               for table in LAYERS}
    update = changes["proposed_update"]
    assert set(update["change"]) <= set(CHANGES)
    assert len(update) == len(edited.database) + len(changes["new"])
    assert sorted(update["db_id"].dropna().astype(int)) == sorted(edited.database["db_id"])
    # fake roads lie 25 m away from every road: no extraction can confirm them
    scores = score_changes(changes, edited)
    assert scores["missing"]["recall"] == 1.0
    assert len(changes["confirmed"]) >= (edited.edit == "unchanged").sum() / 2
