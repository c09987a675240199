"""Extraction and comparison in one run: ``gisroads lidar ... --database DB``."""
import json
import subprocess
import sys

from gisroads.io.vector import list_layers, read_layer, write_geopackage
from gisroads.synthetic import make_scene, write_cloud
from gisroads.update.benchmark import edit_database, score_changes


def test_lidar_with_a_database_writes_the_change_layers(tmp_path):
    scene = make_scene(seed=1, size_m=(300.0, 300.0), features=("buildings", "trees"))
    cloud = tmp_path / "cloud.laz"
    write_cloud(scene, cloud, density_per_m2=4.0, seed=1)
    truth = scene.truth.centrelines
    edited = edit_database(truth, seed=3, delete_share=0.3, fake_share=0.3)
    write_geopackage(tmp_path / "db.gpkg", {"streets": edited.database})
    out = tmp_path / "roads.gpkg"
    done = subprocess.run([sys.executable, "-m", "gisroads.cli", "lidar", str(cloud), "-o",
                           str(out), "--cue", "evidence", "--database",
                           str(tmp_path / "db.gpkg"), "--id-field", "db_id", "--json"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    changes_path = tmp_path / "roads_changes.gpkg"
    assert result["changes"]["gpkg"] == str(changes_path)
    layers = {name: read_layer(changes_path, name) for name in list_layers(changes_path)}
    assert {"confirmed", "missing", "new", "moved", "proposed_update"} <= set(layers)
    scores = score_changes(layers, edited)
    assert scores["missing"]["recall"] == 1.0       # every fake road flagged missing
    assert scores["new"]["recall"] >= 0.5            # deleted roads found again
    assert read_layer(out, "road_centrelines").crs == truth.crs
