"""The LiDAR evidence cue through qgis_process: the stage algorithm's raster chained into
Road raster to network, and the whole-pipeline algorithm with its default, the evidence cue."""
import geopandas as gpd
import pytest
import rasterio

from gisroads.evaluate import buffer_metrics
from gisroads.io.vector import list_layers
from gisroads.synthetic import make_scene, write_cloud


@pytest.fixture(scope="module")
def scene_cloud(tmp_path_factory):
    scene = make_scene(seed=1, size_m=(300.0, 300.0), features=("buildings", "trees"))
    path = tmp_path_factory.mktemp("evidence") / "cloud.laz"
    write_cloud(scene, path, density_per_m2=4.0, seed=1)
    return scene, path


def test_evidence_stage_chained_into_the_raster_network(qgis_process, scene_cloud, tmp_path):
    scene, cloud = scene_cloud
    raster = tmp_path / "evidence.tif"
    result = qgis_process.run("lidarroadevidence", INPUT=cloud, OUTPUT=raster)
    assert {"intensity", "height", "classification"} <= set(result["CUES"].split(","))
    with rasterio.open(raster) as dataset:
        assert dataset.count == 1 and dataset.res == (0.5, 0.5)
    out = tmp_path / "network.gpkg"
    network = qgis_process.run("roadrastertonetwork", INPUT=raster, THRESHOLD=0.8, OUTPUT=out)
    assert network["JUNCTIONS"] >= 1
    lines = gpd.read_file(out, layer="road_centrelines")
    scores = buffer_metrics(lines, scene.truth.centrelines, buffer_m=3.0)
    assert scores.completeness >= 0.85 and scores.correctness >= 0.85


def test_whole_pipeline_with_the_default_evidence_cue(qgis_process, scene_cloud, tmp_path):
    scene, cloud = scene_cloud
    out = tmp_path / "roads.gpkg"
    result = qgis_process.run("lidarroadnetwork", INPUT=cloud, OUTPUT=out,
                              RASTERS=tmp_path / "rasters")
    assert result["JUNCTIONS"] >= 1
    lines = gpd.read_file(out, layer="road_centrelines")
    assert lines.cues.str.contains("intensity").all()
    assert buffer_metrics(lines, scene.truth.centrelines, buffer_m=3.0).completeness >= 0.85
    assert (tmp_path / "rasters" / "road_evidence.tif").exists()
    assert {"gap_edges", "service_centrelines"} <= set(list_layers(out))
