"""Conflation of extracted centre lines with a road database (gisroads.update.conflate)."""
import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import shapely
from affine import Affine

from gisroads.geo import GeoRaster
from gisroads.io.vector import write_geopackage
from gisroads.synthetic import make_scene
from gisroads.update import (FUSA_UNLABELLED_PAVEMENT, LAYERS, conflate, edit_database,
                             read_database, score_changes, truth_pavement)

DATABASE_CRS = "EPSG:4326"  # degrees: the matching must reproject to the extraction's metres


def truth_edges(scene):
    """The scene's junction-to-junction truth lines with their road's width: the database
    granularity of a street layer (roads split at every junction)."""
    widths = scene.truth.centrelines[["road_id", "width_m"]]
    return scene.truth_edges.merge(widths, on="road_id")


@pytest.fixture(scope="module", params=[0, 2])
def benchmark(request):
    scene = make_scene(seed=request.param, size_m=(1000.0, 700.0))
    edited = edit_database(truth_edges(scene), seed=request.param)
    database = edited.database.to_crs(DATABASE_CRS)
    changes = conflate(scene.truth.centrelines, database, id_field="db_id",
                       width_field="width_m")
    return scene, edited, database, changes


def test_every_change_class_found_when_the_extraction_is_the_truth(benchmark):
    _, edited, _, changes = benchmark
    scores = score_changes(changes, edited)
    for name in ("missing", "moved", "width", "new"):
        assert scores[name]["actual"] >= 8, name
        assert scores[name]["precision"] >= 0.9, (name, scores[name])
        assert scores[name]["recall"] >= 0.9, (name, scores[name])


def test_layers_are_in_the_database_crs(benchmark):
    _, _, database, changes = benchmark
    assert list(changes) == list(LAYERS)
    for name, layer in changes.items():
        assert layer.crs == database.crs, name
    lon, lat = changes["new"].total_bounds[:2]
    assert -180 <= lon <= 180 and -90 <= lat <= 90


def test_ids_and_attributes_come_through_unchanged(benchmark):
    _, _, database, changes = benchmark
    columns = [c for c in database.columns if c != "geometry"]
    by_id = database.set_index("db_id", drop=False)
    for name in ("confirmed", "moved"):
        layer = changes[name]
        pd.testing.assert_frame_equal(
            layer[columns].reset_index(drop=True),
            by_id.loc[layer["db_id"], columns].reset_index(drop=True),
            check_dtype=False, check_exact=True, obj=name)
        assert (layer["db_id"] == layer["db_id"].astype(np.int64)).all()
    update = changes["proposed_update"]
    kept = update[update["change"] != "new"]
    assert kept["db_id"].tolist() == database["db_id"].tolist()
    unchanged = (kept["change"] == "unchanged").to_numpy()
    assert unchanged.sum() > len(kept) / 2
    assert shapely.equals_exact(kept.geometry.values[unchanged],
                                database.geometry.values[unchanged], 0.0).all()
    widths = ~kept["change"].isin(["width", "moved"]).to_numpy()
    assert np.array_equal(kept["width_m"].to_numpy(float)[widths],
                          database["width_m"].to_numpy(float)[widths])
    assert update.loc[update["change"] == "new", "db_id"].isna().all()


def test_moved_roads_are_proposed_on_the_extracted_line(benchmark):
    scene, edited, _, changes = benchmark
    moved = changes["moved"].to_crs(scene.crs)
    assert len(moved) > 0
    truth = shapely.force_2d(shapely.union_all(scene.truth.centrelines.geometry.values))
    along = shapely.points(shapely.get_coordinates(shapely.segmentize(moved.geometry.values,
                                                                      1.0)))
    assert shapely.distance(along, truth).max() < 0.5
    shifted = edited.database.set_index("db_id").loc[moved["db_id"]]
    offsets = changes["moved"]["mean_offset_m"].to_numpy()
    assert ((offsets > 4.5) & (offsets < 10.5)).all()
    assert shapely.length(moved.geometry.values) == pytest.approx(
        shapely.length(shifted.geometry.values), rel=0.25)


def test_width_changes_report_both_widths(benchmark):
    _, edited, _, changes = benchmark
    confirmed = changes["confirmed"].set_index("db_id")
    rewidened = confirmed.loc[confirmed.index.isin(edited.edit.index[edited.edit == "width"])]
    assert (rewidened["width_diff_m"].abs() >= 3.0 - 1e-9).all()
    assert np.allclose(rewidened["db_width_m"], rewidened["width_m"])
    update = changes["proposed_update"].set_index("db_id")
    measured = rewidened.loc[rewidened["width_changed"], "measured_width_m"]
    assert np.allclose(update.loc[measured.index, "width_m"], measured)


def test_new_roads_connect_to_database_roads(benchmark):
    _, _, database, changes = benchmark
    new = changes["new"]
    assert (new["length_m"] >= 15.0).all()
    ends = pd.concat([new["start_db_id"], new["end_db_id"]]).dropna()
    assert len(ends) >= len(new)  # most new roads meet the network at both ends
    assert set(ends) <= set(database["db_id"])


@pytest.fixture(scope="module")
def street():
    """One straight 300 m street, in metres, and the same as a database row."""
    crs = "EPSG:32633"
    line = shapely.LineString([(500000, 4500000), (500300, 4500000)])
    extracted = gpd.GeoDataFrame({"road_id": [7], "width_m": [8.0], "score": [0.9]},
                                 geometry=[line], crs=crs)
    database = gpd.GeoDataFrame({"road_id": ["A7"], "lanes": [2]}, geometry=[line],
                                crs=crs, index=[41])
    return extracted, database


def test_partly_seen_road_gives_missing_stretches_with_evidence(street):
    extracted, database = street
    half = extracted.copy()
    half.geometry = [shapely.LineString([(500000, 4500000), (500200, 4500000)])]
    # the data could show the road over x < 500270 only (e.g. trees hide the rest)
    coverage = gpd.GeoDataFrame(geometry=[shapely.box(499900, 4499900, 500270, 4500100)],
                                crs=database.crs)
    changes = conflate(half, database, coverage=coverage)
    assert changes["confirmed"]["db_id"].tolist() == [41]
    assert changes["confirmed"]["matched_share"].iloc[0] == pytest.approx(2 / 3, abs=0.06)
    missing = changes["missing"]
    assert missing["db_id"].tolist() == [41] and missing["road_id"].tolist() == ["A7"]
    assert missing["length_m"].iloc[0] == pytest.approx(100, abs=16)
    assert missing["observable_share"].iloc[0] == pytest.approx(0.7, abs=0.1)
    assert missing["evidence"].iloc[0] == "not_seen"

    raster = GeoRaster(np.zeros((10, 10), np.uint8), Affine(100, 0, 499800, 0, -100, 4500500),
                       database.crs)
    hidden = conflate(half, database, coverage=raster)["missing"]
    assert hidden["observable_share"].iloc[0] == 0.0
    assert hidden["evidence"].iloc[0] == "not_observable"
    assert conflate(half, database)["missing"]["evidence"].iloc[0] == "unknown"


def test_unseen_road_is_missing_and_index_gives_the_ids(street):
    extracted, database = street
    elsewhere = extracted.copy()
    elsewhere.geometry = [shapely.LineString([(500000, 4500200), (500300, 4500200)])]
    changes = conflate(elsewhere, database)
    assert changes["confirmed"].empty and changes["moved"].empty
    update = changes["proposed_update"]
    assert update["change"].tolist() == ["missing", "new"]
    assert update["db_id"].iloc[0] == 41 and pd.isna(update["db_id"].iloc[1])
    assert update["lanes"].iloc[0] == 2
    assert changes["new"]["road_id"].tolist() == [7]
    assert changes["new"][["start_db_id", "end_db_id"]].isna().all().all()


def test_an_extraction_without_roads_leaves_every_road_missing(street):
    extracted, database = street
    for crs in (extracted.crs, "EPSG:4326"):  # metres, or degrees: matched in UTM
        changes = conflate(extracted.iloc[:0].to_crs(crs), database)
        assert changes["proposed_update"]["change"].tolist() == ["missing"]
        assert changes["missing"]["length_m"].tolist() == pytest.approx([300.0], abs=0.5)
        assert changes["new"].empty and changes["confirmed"].empty


def test_an_extraction_in_degrees_is_matched_in_metres(street):
    extracted, database = street
    changes = conflate(extracted.to_crs("EPSG:4326"), database, width_field="lanes")
    confirmed = changes["confirmed"]
    assert confirmed["db_id"].tolist() == [41] and confirmed.crs == database.crs
    assert confirmed["max_offset_m"].iloc[0] < 0.05
    assert confirmed["width_diff_m"].iloc[0] == pytest.approx(6.0)  # 8 m measured, "2"


def test_a_crossing_road_is_no_match(street):
    extracted, database = street
    crossing = extracted.copy()
    crossing.geometry = [shapely.LineString([(500150, 4499850), (500150, 4500150)])]
    changes = conflate(crossing, database)
    assert changes["proposed_update"]["change"].tolist() == ["missing", "new"]


def _divided_road(*ys):
    crs = "EPSG:32633"
    return gpd.GeoDataFrame({"db_id": np.arange(1, len(ys) + 1)},
                            geometry=[shapely.LineString([(500000, 4500000 + y),
                                                          (500200, 4500000 + y)]) for y in ys],
                            crs=crs)


def test_a_carriageway_moved_onto_its_twin_is_moved_and_one_line_serves_both():
    """A divided road, carriageways 7 m apart, both extracted. One carriageway digitised
    8 m off, across its twin: it is moved (its own line 8 m away), not the twin's road;
    the twin stays unchanged. A single line down the middle of carriageways 5 m apart still
    serves both."""
    extracted = _divided_road(0.0, 7.0)
    database = _divided_road(8.0, 7.0)
    changes = conflate(extracted, database, id_field="db_id")
    change = changes["proposed_update"].set_index("db_id")["change"]
    assert change[1] == "moved" and change[2] == "unchanged"
    middle = _divided_road(2.5)
    change = conflate(middle, _divided_road(0.0, 5.0), id_field="db_id")[
        "proposed_update"].set_index("db_id")["change"]
    assert change.tolist() == ["unchanged", "unchanged"]


def test_bad_input_is_refused(street):
    extracted, database = street
    points = gpd.GeoDataFrame({"id": [1]}, geometry=[shapely.Point(500000, 4500000)],
                              crs=database.crs)
    with pytest.raises(ValueError, match="no line geometry"):
        conflate(extracted, points)
    with pytest.raises(ValueError, match="no field 'osm_id'"):
        conflate(extracted, database, id_field="osm_id")
    with pytest.raises(ValueError, match="width field"):
        conflate(extracted, database, width_field="breite")
    with pytest.raises(ValueError, match="CRS"):
        conflate(extracted, gpd.GeoDataFrame(geometry=list(database.geometry)))
    with pytest.raises(ValueError, match="tolerance"):
        conflate(extracted, database, tolerance_m=20.0, search_m=15.0)


def test_read_database_keeps_feature_ids(tmp_path, street):
    _, database = street
    path = tmp_path / "db.gpkg"
    two = pd.concat([database, database.set_index(pd.Index([77]))])
    write_geopackage(path, {"roads": two.reset_index(names="fid")})
    read = read_database(path)
    assert read.index.tolist() == [41, 77]
    assert read["road_id"].tolist() == ["A7", "A7"]
    with pytest.raises(ValueError, match="cannot be read"):
        read_database(tmp_path / "nothing.gpkg")


def test_edit_database_is_seeded_and_disjoint():
    scene = make_scene(seed=1, size_m=(1000.0, 700.0))
    truth = truth_edges(scene)
    edited = edit_database(truth, seed=5)
    again = edit_database(truth, seed=5)
    assert edited.edit.equals(again.edit)
    counts = edited.edit.value_counts()
    n = len(truth)
    assert len(edited.deleted) == round(0.2 * n)
    for kind in ("shifted", "width", "fake"):
        assert counts[kind] == round(0.1 * n), kind
    database = edited.database.set_index("db_id")
    original = truth.set_index("edge_id")
    shifted = database.loc[edited.edit.index[edited.edit == "shifted"]]
    distance = shapely.hausdorff_distance(
        shifted.geometry.values,
        shapely.force_2d(original.loc[shifted["edge_id"]].geometry.values))
    assert ((distance >= 5.0 - 1e-6) & (distance <= 10.0 + 1e-6)).all()
    fakes = database.loc[edited.edit.index[edited.edit == "fake"]]
    assert (shapely.distance(fakes.geometry.values,
                             shapely.union_all(truth.geometry.values)) >= 25.0).all()
    rewidened = database.loc[edited.edit.index[edited.edit == "width"]]
    change = rewidened["width_m"] - original.loc[rewidened["edge_id"], "width_m"].to_numpy()
    assert change.abs().between(3.0, 6.0).all()


def test_fakes_keep_clear_of_pavement_the_truth_lines_leave_out():
    """A fake over a car park or service way the truth's lines leave out is a road in the
    data, confirmed by a good extraction: fakes keep their clearance from such pavement."""
    scene = make_scene(seed=1, size_m=(1000.0, 700.0))
    truth = truth_edges(scene)
    # where the seed-5 fakes fall without it: pavement in the truth's tables only
    fakes = edit_database(truth, seed=5).database.iloc[-round(0.1 * len(truth)):]
    pavement = gpd.GeoSeries(fakes.geometry.values, crs=truth.crs).buffer(4.0)
    for seed in (5, 0, 1):
        edited = edit_database(truth, seed=seed, pavement=pavement)
        placed = edited.database[edited.edit.to_numpy() == "fake"]
        assert len(placed) == round(0.1 * len(truth))
        assert (shapely.distance(placed.geometry.values,
                                 shapely.union_all(pavement.values)) >= 25.0).all()


def test_truth_pavement_holds_service_ways_road_area_and_described_areas(lidar_dir):
    folder = lidar_dir / "ground_truth" / "fusa"
    pavement = truth_pavement(folder, FUSA_UNLABELLED_PAVEMENT)
    assert pavement.crs.to_epsg() == 32754
    service = gpd.read_file(folder / "service.geojson")
    area = shapely.union_all(pavement.values)
    assert shapely.covers(area, shapely.union_all(service.geometry.values))
    for box in FUSA_UNLABELLED_PAVEMENT:
        assert shapely.covers(area, shapely.box(*box))
    truth = gpd.read_file(folder / "centrelines.geojson")
    for seed in range(10):
        edited = edit_database(truth, seed=seed, fake_length_m=(20.0, 40.0),
                               fake_clearance_m=15.0, pavement=pavement)
        fake = edited.database[edited.edit.to_numpy() == "fake"].geometry.values
        assert (shapely.distance(fake, area) >= 15.0).all()
