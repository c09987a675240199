"""The convolutional road network through the gisroads command: `image --model` names the
model it used and writes its probability on the image grid; `train -o model.onnx`
fine-tunes the network (PyTorch) into a file `image --model` takes; without PyTorch it is
a one-line error that says what to install."""
import json
import subprocess
import sys

import numpy as np
import pytest
import rasterio

from gisroads.cli import main
from gisroads.imagery.pipeline import PROBABILITY_THRESHOLD
from gisroads.io.raster import read_raster
from gisroads.learn.convnet import DEFAULT_CONVNET_PATH, load_convnet


def gisroads(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "gisroads.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=900)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A 300 x 300 m synthetic scene at 1 m: image.tif and truth.gpkg."""
    folder = tmp_path_factory.mktemp("scene")
    made = gisroads("synth", "-o", folder, "--no-cloud", "--size", 300, "--pixel", 1.0)
    assert made.returncode == 0, made.stderr
    return folder


@pytest.fixture(scope="module")
def bundled():
    if not DEFAULT_CONVNET_PATH.is_file():
        pytest.skip(f"the bundled road network {DEFAULT_CONVNET_PATH} is missing")
    return load_convnet()


def _image(folder, out, *args):
    result = gisroads("image", folder / "image.tif", "-o", out, *args, "--json")
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


@pytest.mark.parametrize("model", ["default", "boosted"])
def test_image_reports_the_model_and_threshold_it_used(scene, bundled, tmp_path, model):
    if model == "boosted":
        pytest.importorskip("sklearn")
    summary = _image(scene, tmp_path / "roads.gpkg", "--model", model,
                     "--probability", tmp_path / "p.tif")
    if model == "boosted":
        assert summary["model"] == "boosted"
        assert summary["threshold"] == pytest.approx(PROBABILITY_THRESHOLD)
    else:
        assert summary["model"] == "road_convnet.onnx"
        assert summary["threshold"] == pytest.approx(bundled.threshold)
        assert summary["context_model"] is False  # the context model is for boosted trees
    assert summary["cues"] == "model" and summary["method"] == "learned-probability"
    assert summary["probability"] == str(tmp_path / "p.tif")
    with rasterio.open(scene / "image.tif") as image, rasterio.open(tmp_path / "p.tif") as p:
        assert p.count == 1 and p.dtypes == ("float32",)
        assert (p.width, p.height) == (image.width, image.height)
        assert p.transform == image.transform and p.crs == image.crs
        assert np.isnan(p.nodata) and p.descriptions == ("road_probability",)
        values = p.read(1)
    assert np.isfinite(values).all() and values.min() >= 0 and values.max() <= 1


def test_the_two_models_give_different_probabilities(scene, bundled, tmp_path):
    pytest.importorskip("sklearn")
    for model in ("default", "boosted"):
        _image(scene, tmp_path / f"{model}.gpkg", "--model", model,
               "--probability", tmp_path / f"{model}.tif")
    default = read_raster(tmp_path / "default.tif").data[0]
    boosted = read_raster(tmp_path / "boosted.tif").data[0]
    assert np.abs(default - boosted).max() > 0.05


def test_train_onnx_writes_a_network_image_takes(scene, bundled, tmp_path):
    pytest.importorskip("torch")
    pytest.importorskip("onnx")
    out = tmp_path / "m.onnx"
    trained = gisroads("train", scene / "image.tif", scene / "truth.gpkg", "-o", out,
                       "--width-field", "width_m", "--steps", 2, "--check", 0, "--json")
    assert trained.returncode == 0, trained.stderr
    summary = json.loads(trained.stdout)
    assert summary["model"] == str(out) and summary["steps"] == 2
    assert 0 < summary["road_share"] < 0.5 and summary["roads"] > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.onnx"]
    net = load_convnet(out)
    assert net.metadata["trained_on"] == "road layer"
    assert net.metadata["fine_tune_steps"] == 2 and net.metadata["image"] == "image.tif"
    assert net.metadata["width_field"] == "width_m"
    assert net.pixel_m == bundled.pixel_m
    result = _image(scene, tmp_path / "roads.gpkg", "--model", out,
                    "--probability", tmp_path / "p.tif")
    assert result["model"] == "m.onnx"
    assert result["threshold"] == pytest.approx(net.threshold)
    assert read_raster(tmp_path / "p.tif").shape == read_raster(scene / "image.tif").shape


def test_train_onnx_starts_from_the_base_network(scene, tmp_path):
    torch = pytest.importorskip("torch")
    pytest.importorskip("onnx")
    from gisroads.learn.convnet_training import RoadUNet, export_onnx

    torch.manual_seed(0)
    base = export_onnx(RoadUNet().eval(), tmp_path / "base.onnx",
                       {"pixel_m": 2.0, "threshold": 0.3, "note": "the base"})
    out = tmp_path / "tuned.onnx"
    assert main(["train", str(scene / "image.tif"), str(scene / "truth.gpkg"), "-o", str(out),
                 "--base", str(base), "--steps", "1", "--check", "0", "--json"]) == 0
    net = load_convnet(out)
    assert net.metadata["note"] == "the base" and net.pixel_m == 2.0
    assert net.threshold == 0.3 and net.metadata["fine_tune_steps"] == 1


@pytest.mark.parametrize("option, value, message", [
    ("--steps", "0", "at least 1"),
    ("--check", "1.5", "check the fine-tuning"),
])
def test_train_onnx_refuses_a_bad_option_in_one_line(scene, tmp_path, capsys, option, value,
                                                      message):
    pytest.importorskip("torch")
    status = main(["train", str(scene / "image.tif"), str(scene / "truth.gpkg"), "-o",
                   str(tmp_path / "m.onnx"), option, value])
    assert status == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_train_onnx_without_torch_says_what_to_install(scene, tmp_path, capsys,
                                                       monkeypatch):
    monkeypatch.setitem(sys.modules, "torch", None)  # import torch raises ImportError
    monkeypatch.delitem(sys.modules, "gisroads.learn.convnet_training", raising=False)
    status = main(["train", str(scene / "image.tif"), str(scene / "truth.gpkg"), "-o",
                   str(tmp_path / "m.onnx")])
    captured = capsys.readouterr()
    assert status != 0
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("gisroads: error: ") and "gisroads[train]" in lines[0]
    assert captured.out == ""
    assert list(tmp_path.iterdir()) == []


def test_train_output_must_be_onnx_or_npz(scene, tmp_path, capsys):
    status = main(["train", str(scene / "image.tif"), str(scene / "truth.gpkg"), "-o",
                   str(tmp_path / "m.pt")])
    assert status == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and ".onnx or .npz" in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_a_missing_onnx_model_is_a_one_line_error(scene, tmp_path):
    result = gisroads("image", scene / "image.tif", "-o", tmp_path / "r.gpkg", "--model",
                      tmp_path / "missing.onnx")
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "missing.onnx" in lines[0]
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"\x00not an onnx graph" * 50)
    result = gisroads("image", scene / "image.tif", "-o", tmp_path / "r.gpkg", "--model",
                      junk)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "not a readable ONNX model" in lines[0], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["junk.onnx"]
