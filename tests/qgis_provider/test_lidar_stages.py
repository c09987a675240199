"""The LiDAR method stage by stage through qgis_process: each stage algorithm takes the
previous one's output and gives exactly what the same stage gives from Python."""
import numpy as np
import pytest

from gisroads.io.las import read_las
from gisroads.io.raster import read_raster
from gisroads.io.vector import list_layers, read_layer
from gisroads.jobs import ground_intensity_job, lidar_segmentation_job
from tests.road_layers import assert_empty_road_layers


@pytest.fixture(scope="module")
def stages(qgis_process, scene_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("lidar_stages")
    results = {"ground": qgis_process.run("lidargroundintensity",
                                          INPUT=scene_dir / "cloud.laz",
                                          OUTPUT=out / "intensity.tif",
                                          HEIGHTS=out / "heights.tif")}
    results["segments"] = qgis_process.run("lidarsegmentation", INPUT=out / "intensity.tif",
                                           OUTPUT=out / "segments.tif", EDGES=out / "edges.tif")
    results["likelihood"] = qgis_process.run(
        "lidarlikelihood", INPUT=out / "intensity.tif", SEGMENTS=out / "segments.tif",
        LENGTHS="40,80,150", OUTPUT=out / "likelihood.tif", HYPOTHESES=out / "hyps.gpkg")
    results["cover"] = qgis_process.run(
        "lidarmincover", INPUT=f"{out / 'hyps.gpkg'}|layername=hypotheses",
        LIKELIHOOD=out / "likelihood.tif", OUTPUT=out / "rectangles.gpkg")
    results["network"] = qgis_process.run(
        "rectanglestonetwork", INPUT=f"{out / 'rectangles.gpkg'}|layername=rectangles",
        OUTPUT=out / "roads.gpkg")
    return out, results


def test_stages_match_the_python_stages(stages, scene_dir, tmp_path):
    out, results = stages
    python = ground_intensity_job(scene_dir / "cloud.laz", tmp_path / "intensity.tif")
    assert results["ground"]["LEVELS"] == python["levels"] >= 1
    assert results["ground"]["CELL_M"] == python["cell_m"]
    np.testing.assert_array_equal(read_raster(out / "intensity.tif").data,
                                  read_raster(tmp_path / "intensity.tif").data)
    lidar_segmentation_job(tmp_path / "intensity.tif", tmp_path / "segments.tif")
    ours = read_raster(out / "segments.tif").data[0]
    theirs = read_raster(tmp_path / "segments.tif").data[0]
    # the same NCut; eigenvectors may differ in the last bits with the BLAS threads of
    # each process, so compare partitions: each segment lies mostly in one Python segment
    valid = ours >= 0
    assert np.array_equal(valid, theirs >= 0)
    pairs = np.unique(np.stack([ours[valid], theirs[valid]]), axis=1, return_counts=True)
    best = np.zeros(ours.max() + 1)
    np.maximum.at(best, pairs[0][0], pairs[1])
    assert best.sum() / valid.sum() > 0.85
    # 150 cuts; a cut that is not connected counts once per connected piece
    assert 150 <= results["segments"]["N_SEGMENTS"] <= 300


def test_cover_and_network_from_the_stage_layers(stages):
    out, results = stages
    hypotheses = read_layer(out / "hyps.gpkg", "hypotheses")
    rectangles = read_layer(out / "rectangles.gpkg", "rectangles")
    assert len(hypotheses) == results["likelihood"]["N_HYPOTHESES"] > len(rectangles) > 0
    assert set(rectangles.hyp_id) <= set(hypotheses.hyp_id)
    assert results["cover"]["COVER_COST"] > 0
    assert list_layers(out / "roads.gpkg")[:3] == ["road_centrelines", "road_polygons",
                                                   "junctions"]
    assert results["network"]["ROADS"] > 0 and results["network"]["LENGTH_M"] > 200


def test_a_stage_refuses_a_level_the_image_lacks(qgis_process, stages, tmp_path):
    out, _ = stages
    result = qgis_process("run", "gisroads:lidarsegmentation", "--",
                          f"INPUT={out / 'intensity.tif'}", "LEVEL=9",
                          f"OUTPUT={tmp_path / 's.tif'}", check=False)
    assert result.returncode == 1 and "no level 9" in result.stdout + result.stderr
    assert not (tmp_path / "s.tif").exists()


def test_every_stage_of_a_forest_plot_succeeds_with_empty_layers(qgis_process, lidar_dir,
                                                                 tmp_path):
    forest = lidar_dir / "Megaplot.laz"
    qgis_process.run("lidargroundintensity", INPUT=forest, OUTPUT=tmp_path / "intensity.tif",
                     HEIGHTS=tmp_path / "heights.tif")
    qgis_process.run("lidarsegmentation", INPUT=tmp_path / "intensity.tif",
                     OUTPUT=tmp_path / "segments.tif")
    likelihood = qgis_process.run(
        "lidarlikelihood", INPUT=tmp_path / "intensity.tif", SEGMENTS=tmp_path / "segments.tif",
        OUTPUT=tmp_path / "likelihood.tif", HYPOTHESES=tmp_path / "hyps.gpkg")
    # the empty hypotheses layer is a polygon layer QGIS takes as the next stage's input
    cover = qgis_process.run(
        "lidarmincover", INPUT=f"{tmp_path / 'hyps.gpkg'}|layername=hypotheses",
        LIKELIHOOD=tmp_path / "likelihood.tif", OUTPUT=tmp_path / "rectangles.gpkg")
    args = ["run", "gisroads:rectanglestonetwork", "--",
            f"INPUT={tmp_path / 'rectangles.gpkg'}|layername=rectangles",
            f"OUTPUT={tmp_path / 'roads.gpkg'}"]
    network = qgis_process(*args)
    tagged = qgis_process.run("tagroadpoints", INPUT=forest, POLYGONS=tmp_path / "roads.gpkg",
                              OUTPUT=tmp_path / "tagged.laz")
    assert likelihood["N_HYPOTHESES"] == cover["N_RECTANGLES"] == tagged["TAGGED"] == 0
    assert "no road found in" in network.stdout + network.stderr
    assert "ROADS:\t0" in network.stdout
    assert_empty_road_layers(tmp_path / "roads.gpkg")
    assert read_las(tmp_path / "tagged.laz").classification.tolist() == \
        read_las(forest).classification.tolist()
