"""The learned road cue in QGIS through qgis_process: Train road model on the scene's image
from its road layer, then Imagery road network with that model and its probability raster."""
import numpy as np
import pytest
import rasterio.features

from gisroads.io.raster import read_raster
from gisroads.io.vector import read_layer
from gisroads.learn import load_model
from gisroads.learn.scores import pixel_auc

pytest.importorskip("sklearn")


def test_train_then_extract_with_the_model_and_its_probability(qgis_process, scene_dir,
                                                                tmp_path):
    trained = qgis_process.run(
        "trainroadmodel", IMAGE=scene_dir / "image.tif",
        ROADS=f"{scene_dir / 'truth.gpkg'}|layername=road_centrelines",
        WIDTH_FIELD="width_m", GUARD=3.0, SAMPLES=20000, OUTPUT=tmp_path / "model.npz")
    model = load_model(tmp_path / "model.npz")
    # half of them road: at 1 m pixels the roads' core holds fewer than 10000 pixels
    assert trained["SAMPLES_USED"] == model.metadata["samples"]
    assert 15000 < trained["SAMPLES_USED"] <= 20000
    assert model.metadata["guard_m"] == 3.0 and model.metadata["width_field"] == "width_m"
    assert 0.05 < trained["ROAD_SHARE"] < 0.5
    result = qgis_process.run("imageryroadnetwork", INPUT=scene_dir / "image.tif",
                              USE_MODEL="true", MODEL=tmp_path / "model.npz",
                              PROBABILITY=tmp_path / "p.tif", OUTPUT=tmp_path / "roads.gpkg")
    assert "model" in result["CUES"] and result["ROADS"] > 0
    probability = read_raster(tmp_path / "p.tif")
    polygons = read_layer(scene_dir / "truth.gpkg", "road_polygons")
    road = rasterio.features.rasterize(((g, 1) for g in polygons.geometry),
                                       out_shape=probability.shape,
                                       transform=probability.transform).astype(bool)
    assert pixel_auc(probability.data[0], road) > 0.9
    assert np.nanmax(probability.data) <= 1.0
    lines = read_layer(tmp_path / "roads.gpkg", "road_centrelines")
    assert lines.cues.str.contains("model").all()


def test_train_errors_are_processing_errors(qgis_process, scene_dir, tmp_path):
    result = qgis_process("run", "gisroads:trainroadmodel", "--",
                          f"IMAGE={scene_dir / 'image.tif'}",
                          f"ROADS={scene_dir / 'truth.gpkg'}|layername=junctions",
                          f"OUTPUT={tmp_path / 'm.npz'}", check=False)
    assert result.returncode == 1
    assert not (tmp_path / "m.npz").exists()


def test_context_model_can_be_switched_off(qgis_process, scene_dir, tmp_path):
    """The bundled boosted trees' probability is re-scored by the context model unless
    USE_CONTEXT is off: the two probability rasters differ."""
    rasters = {}
    for use in ("true", "false"):
        result = qgis_process.run("imageryroadnetwork", INPUT=scene_dir / "image.tif",
                                  BUNDLED_MODEL=1, USE_CONTEXT=use,
                                  PROBABILITY=tmp_path / f"p_{use}.tif",
                                  OUTPUT=tmp_path / f"roads_{use}.gpkg")
        assert "model" in result["CUES"]
        rasters[use] = read_raster(tmp_path / f"p_{use}.tif").data[0]
    assert np.nanmax(np.abs(rasters["true"] - rasters["false"])) > 0.1


def test_papers_pipeline_alone_writes_no_probability(qgis_process, scene_dir, tmp_path):
    result = qgis_process.run("imageryroadnetwork", INPUT=scene_dir / "image.tif",
                              USE_MODEL="false", OUTPUT=tmp_path / "roads.gpkg")
    assert "model" not in result["CUES"] and "PROBABILITY" not in result


def test_cancel_while_training_writes_no_model(run_algorithm, tmp_path):
    from qgis.core import QgsProcessingException, QgsProcessingFeedback

    from gisroads.jobs import synth_job

    paths = synth_job(tmp_path / "scene", size_m=(300.0, 300.0), cloud=False, pixel_m=0.6)
    feedback = QgsProcessingFeedback()
    percents = []
    feedback.progressChanged.connect(
        lambda percent: (percents.append(percent), percent > 20 and feedback.cancel()))
    with pytest.raises(QgsProcessingException, match="cancelled"):
        run_algorithm("trainroadmodel", {
            "IMAGE": str(paths["image"]),
            "ROADS": f"{paths['truth']}|layername=road_centrelines",
            "OUTPUT": str(tmp_path / "model.npz")}, feedback)
    assert 20 < max(percents) < 80
    assert not (tmp_path / "model.npz").exists()


def test_the_default_model_is_the_network(qgis_process, scene_dir, tmp_path):
    """With no model file the bundled convolutional network gives the probability: it
    finds the scene's roads, and its probability differs from the boosted trees'."""
    rasters = {}
    for choice in (0, 1):
        result = qgis_process.run("imageryroadnetwork", INPUT=scene_dir / "image.tif",
                                  BUNDLED_MODEL=choice, PROBABILITY=tmp_path / f"p{choice}.tif",
                                  OUTPUT=tmp_path / f"roads{choice}.gpkg")
        assert "model" in result["CUES"] and result["ROADS"] > 0
        rasters[choice] = read_raster(tmp_path / f"p{choice}.tif").data[0]
    polygons = read_layer(scene_dir / "truth.gpkg", "road_polygons")
    road = rasterio.features.rasterize(((g, 1) for g in polygons.geometry),
                                       out_shape=rasters[0].shape,
                                       transform=read_raster(tmp_path / "p0.tif").transform
                                       ).astype(bool)
    # a rendered scene is none of the training sources: measured 0.878
    assert pixel_auc(rasters[0], road) > 0.85
    assert np.nanmax(np.abs(rasters[0] - rasters[1])) > 0.1


def test_fine_tuning_without_torch_is_one_clear_error(qgis_process, scene_dir, tmp_path):
    """QGIS's Python has no PyTorch: an .onnx output says how to get it, writes nothing."""
    try:
        import torch  # noqa: F401
        pytest.skip("PyTorch is installed here")
    except ImportError:
        pass
    result = qgis_process("run", "gisroads:trainroadmodel", "--",
                          f"IMAGE={scene_dir / 'image.tif'}",
                          f"ROADS={scene_dir / 'truth.gpkg'}|layername=road_centrelines",
                          f"OUTPUT={tmp_path / 'm.onnx'}", check=False)
    assert result.returncode == 1
    assert "gisroads[train]" in result.stdout + result.stderr
    assert not (tmp_path / "m.onnx").exists()
