"""``gisroads lidar --cue evidence``: the road-evidence path end to end through the CLI."""
import json
import subprocess
import sys

import rasterio

from gisroads.evaluate import buffer_metrics
from gisroads.io.vector import read_layer
from gisroads.synthetic import make_scene, write_cloud


def test_evidence_cue_writes_network_evidence_raster_and_tagged_cloud(tmp_path):
    scene = make_scene(seed=1, size_m=(300.0, 300.0), features=("buildings", "trees"))
    cloud = tmp_path / "cloud.laz"
    write_cloud(scene, cloud, density_per_m2=4.0, seed=1)
    out = tmp_path / "roads.gpkg"
    done = subprocess.run([sys.executable, "-m", "gisroads.cli", "lidar", str(cloud), "-o",
                           str(out), "--cue", "evidence", "--rasters", str(tmp_path / "r"),
                           "--tagged-las", str(tmp_path / "tagged.laz"), "--json"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["cue"] == "evidence" and "intensity" in result["cues"].split(",")
    assert result["junctions"] >= 1 and result["tagged_points"] > 0
    lines = read_layer(out, "road_centrelines")
    scores = buffer_metrics(lines, scene.truth.centrelines, buffer_m=3.0)
    assert scores.completeness >= 0.85 and scores.correctness >= 0.85
    with rasterio.open(tmp_path / "r" / "road_evidence.tif") as raster:
        likelihood = raster.read(1)
        assert raster.descriptions == ("road_likelihood",)
    assert 0.0 <= float(likelihood[likelihood == likelihood].min()) and \
        float(likelihood[likelihood == likelihood].max()) <= 1.0
