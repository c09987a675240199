"""``gisroads update``: extraction GeoPackage + any OGR database -> styled change layers."""
import json
import sqlite3

import geopandas as gpd
import pytest
import shapely

from gisroads.cli import main
from gisroads.io.vector import list_layers, write_geopackage
from gisroads.synthetic import make_scene
from gisroads.update import LAYERS, edit_database, read_database, score_changes
from tests.postgis_cluster import throwaway_cluster


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A scene's truth as the extraction, and its edited edges as databases in EPSG:3857: a
    Shapefile, and a GeoPackage whose feature ids are three times its ``ref`` field."""
    folder = tmp_path_factory.mktemp("update")
    scene = make_scene(seed=0, size_m=(1000.0, 700.0))
    write_geopackage(folder / "extracted.gpkg", scene.truth.layers())
    edges = scene.truth_edges.merge(scene.truth.centrelines[["road_id", "width_m"]],
                                    on="road_id")
    edited = edit_database(edges, seed=0)
    database = edited.database.to_crs("EPSG:3857")
    database.geometry = shapely.force_2d(database.geometry.values)
    database.to_file(folder / "roads.shp")
    by_fid = database.rename(columns={"db_id": "ref"})
    write_geopackage(folder / "roads.gpkg", {"roads": by_fid.assign(fid=3 * by_fid.ref)})
    return folder, edited


def test_update_writes_styled_change_layers(files, capsys):
    folder, edited = files
    out = folder / "changes.gpkg"
    status = main(["update", str(folder / "extracted.gpkg"), str(folder / "roads.shp"),
                   "-o", str(out), "--id-field", "db_id", "--width-field", "width_m",
                   "--json"])
    assert status == 0
    result = json.loads(capsys.readouterr().out)
    assert list_layers(out) == list(LAYERS)
    with sqlite3.connect(out) as con:
        styled = {r[0] for r in con.execute("SELECT f_table_name FROM layer_styles")}
    assert styled == set(LAYERS)
    changes = {name: gpd.read_file(out, layer=name) for name in LAYERS}
    assert all(layer.crs.to_epsg() == 3857 for layer in changes.values())
    assert result["changes"]["missing"] == (edited.edit == "fake").sum()
    scores = score_changes(changes, edited)
    for name, score in scores.items():
        assert score["precision"] >= 0.9 and score["recall"] >= 0.9, (name, score)


def test_feature_ids_are_the_default_ids(files):
    folder, _ = files
    out = folder / "by_fid.gpkg"
    assert main(["update", str(folder / "extracted.gpkg"), str(folder / "roads.gpkg"),
                 "-o", str(out)]) == 0
    assert read_database(folder / "roads.gpkg").index.tolist()[:2] == [3003, 3006]
    update = gpd.read_file(out, layer="proposed_update")
    kept = update[update["change"] != "new"]
    assert len(kept) > 50
    assert (kept["db_id"] == 3 * kept["ref"]).all()
    moved = gpd.read_file(out, layer="moved")
    assert len(moved) > 0 and (moved["db_id"] == 3 * moved["ref"]).all()


def test_coverage_tells_not_seen_from_not_observable(files, tmp_path):
    folder, edited = files
    database = read_database(folder / "roads.shp")
    fakes = database[database["db_id"].isin(edited.edit.index[edited.edit == "fake"])]
    # the survey covered the first fake road only
    coverage = gpd.GeoDataFrame(geometry=[fakes.geometry.iloc[0].buffer(50.0)],
                                crs=database.crs).to_crs("EPSG:4326")
    coverage.to_file(tmp_path / "coverage.geojson")
    out = tmp_path / "changes.gpkg"
    assert main(["update", str(folder / "extracted.gpkg"), str(folder / "roads.shp"),
                 "--id-field", "db_id", "--coverage", str(tmp_path / "coverage.geojson"),
                 "-o", str(out)]) == 0
    missing = gpd.read_file(out, layer="missing").set_index("db_id")
    evidence = missing.loc[fakes["db_id"], "evidence"]
    assert evidence.iloc[0] == "not_seen"
    assert (evidence.iloc[1:] == "not_observable").all()


def test_postgis_database_by_connection_string(files, tmp_path):
    """A ``PG:`` source: read by Fiona with the system GDAL, or (pyogrio's wheel has no
    PostgreSQL driver) copied by ogr2ogr; the table's key is the feature id either way."""
    folder, _ = files
    out = tmp_path / "changes.gpkg"
    with throwaway_cluster() as cluster:
        cluster.load(folder / "roads.gpkg", "roads", "roads")
        assert main(["update", str(folder / "extracted.gpkg"), cluster.gdal(), "--layer",
                     "roads", "--width-field", "width_m", "-o", str(out)]) == 0
    update = gpd.read_file(out, layer="proposed_update")
    assert update.crs.to_epsg() == 3857
    kept = update[update["change"] != "new"]
    assert len(kept) > 50 and (kept["db_id"] == 3 * kept["ref"]).all()
    assert set(update["change"]) == {"unchanged", "moved", "width", "missing", "new"}


def test_bad_database_is_one_error_line(files, tmp_path, capsys):
    folder, _ = files
    extracted = str(folder / "extracted.gpkg")
    status = main(["update", extracted, str(folder / "roads.shp"), "-o",
                   str(tmp_path / "a.gpkg"), "--id-field", "osm_id"])
    assert status == 2
    assert "no field 'osm_id'" in capsys.readouterr().err
    status = main(["update", extracted, str(folder / "extracted.gpkg"), "--layer", "junctions",
                   "-o", str(tmp_path / "b.gpkg")])
    assert status == 2
    assert "no line geometry" in capsys.readouterr().err
    status = main(["update", extracted, str(tmp_path / "none.shp"), "-o",
                   str(tmp_path / "c.gpkg")])
    assert status == 2
    assert "cannot be read" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.gpkg"))


def test_update_draws_its_changes_and_says_what_it_counts(files, capsys):
    """The quick-look shows the fakes as missing (red) and the deleted roads as new
    (green) over the database; the summary tells layer features from database roads (it
    printed "missing: 3", then "missing 0")."""
    from matplotlib.image import imread

    folder, edited = files
    png = folder / "changes.png"
    status = main(["update", str(folder / "extracted.gpkg"), str(folder / "roads.shp"),
                   "-o", str(folder / "drawn.gpkg"), "--quicklook", str(png)])
    assert status == 0
    text = capsys.readouterr().out
    assert "features per layer: confirmed" in text and "database roads by change:" in text
    assert f"quicklook: {png}" in text
    pixels = imread(png)[..., :3]
    red = (pixels[..., 0] > 0.9) & (pixels[..., 1] < 0.1) & (pixels[..., 2] < 0.1)
    green = (pixels[..., 1] > 0.7) & (pixels[..., 0] < 0.3) & (pixels[..., 2] < 0.3)
    assert red.sum() > 100 and green.sum() > 100
