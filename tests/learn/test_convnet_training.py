"""Training the convolutional road model (torch): the ONNX export computes what torch
computes and carries the weights to fine-tune again; the loss ignores no-data pixels; the
augmented batches are seeded; fine-tuning on a road layer trains the network and keeps
the base model's batch-norm statistics. Small models, images and step counts: each test
takes seconds on one core."""
import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from gisroads.geo import GeoRaster  # noqa: E402
from gisroads.learn import convnet_training as ct  # noqa: E402
from gisroads.learn.convnet import (DEFAULT_CONVNET_PATH, convnet_probability,  # noqa: E402
                                    load_convnet)
from gisroads.synthetic import make_scene, render_image  # noqa: E402

METADATA = {"pixel_m": 1.0, "threshold": 0.5, "note": "test"}


def _random_unet(seed: int = 0) -> "ct.RoadUNet":
    """A seeded RoadUNet with batch-norm statistics and affine parameters away from their
    initial 0 / 1 (so an export that dropped them would show)."""
    torch.manual_seed(seed)
    model = ct.RoadUNet()
    with torch.no_grad():
        for module in model.modules():
            if isinstance(module, torch.nn.BatchNorm2d):
                module.weight.uniform_(0.5, 1.5)
                module.bias.uniform_(-0.2, 0.2)
                module.running_mean.uniform_(-0.1, 0.1)
                module.running_var.uniform_(0.5, 2.0)
    return model.eval()


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    model = _random_unet()
    path = ct.export_onnx(model, tmp_path_factory.mktemp("onnx") / "road.onnx", METADATA)
    return model, path


@pytest.fixture(scope="module")
def scene():
    """A 300 x 300 m synthetic scene at 1 m (300 x 300 px, R, G, B, NIR) and its roads."""
    scene = make_scene(seed=0, size_m=(300.0, 300.0))
    image, _ = render_image(scene, pixel_m=1.0)
    return scene, image


def test_onnx_export_computes_the_torch_logits(exported):
    model, path = exported
    net = load_convnet(path)
    assert net.metadata == METADATA and net.pixel_m == 1.0 and net.threshold == 0.5
    x = np.random.default_rng(1).standard_normal((1, 3, 64, 64)).astype(np.float32)
    onnx_logit = net.session.run(None, {"image": x})[0]
    with torch.no_grad():
        torch_logit = model(torch.from_numpy(x)).numpy()
    assert onnx_logit.shape == torch_logit.shape == (1, 1, 64, 64)
    assert torch_logit.std() > 1e-3  # not a constant output
    np.testing.assert_allclose(onnx_logit, torch_logit, rtol=0, atol=1e-4)
    # any batch and any size that is a multiple of 32 (dynamic axes)
    y = np.random.default_rng(2).standard_normal((2, 3, 96, 160)).astype(np.float32)
    with torch.no_grad():
        np.testing.assert_allclose(net.session.run(None, {"image": y})[0],
                                   model(torch.from_numpy(y)).numpy(), rtol=0, atol=1e-4)


def test_model_from_onnx_gives_back_the_weights(exported):
    model, path = exported
    loaded, metadata = ct.model_from_onnx(path)
    assert metadata == METADATA
    assert isinstance(loaded, ct.RoadUNet) and not loaded.training
    original, restored = model.state_dict(), loaded.state_dict()
    assert original.keys() == restored.keys()
    for name, value in original.items():
        assert restored[name].dtype == value.dtype, name
        np.testing.assert_allclose(restored[name].numpy(), value.numpy(), rtol=1e-3,
                                   atol=1e-3, err_msg=name)
    x = torch.from_numpy(np.random.default_rng(3).standard_normal((1, 3, 64, 64))
                         .astype(np.float32))
    with torch.no_grad():
        np.testing.assert_allclose(loaded(x).numpy(), model(x).numpy(), rtol=0, atol=0.05)


def test_export_is_atomic_and_replaces_an_older_file(tmp_path):
    path = tmp_path / "m.onnx"
    path.write_bytes(b"an older file")
    written = ct.export_onnx(_random_unet(seed=1), path, METADATA)
    assert written == path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.onnx"]
    assert load_convnet(path).metadata == METADATA


def test_model_from_onnx_refuses_a_file_without_weights(tmp_path):
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Identity", ["image"], ["logit"])], "identity",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 32, 32])],
        [helper.make_tensor_value_info("logit", TensorProto.FLOAT, [1, 3, 32, 32])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    entry = model.metadata_props.add()
    entry.key, entry.value = "gisroads", '{"pixel_m": 1.0}'
    onnx.save(model, str(tmp_path / "identity.onnx"))
    with pytest.raises(ValueError, match="no gisroads weights"):
        ct.model_from_onnx(tmp_path / "identity.onnx")


def test_road_loss_ignores_invalid_pixels():
    generator = torch.Generator().manual_seed(0)
    logit = torch.randn(2, 1, 32, 32, generator=generator)
    valid = (torch.rand(2, 1, 32, 32, generator=generator) > 0.3).float()
    # road only where valid, as training_batch and fine_tune_on_layer give it
    road = (torch.rand(2, 1, 32, 32, generator=generator) > 0.8).float() * valid
    loss = ct.road_loss(logit, road, valid)
    assert torch.isfinite(loss) and loss > 0
    changed = torch.where(valid == 0, logit + 50 * torch.randn(logit.shape, generator=generator),
                          logit)
    assert not torch.equal(changed, logit)
    torch.testing.assert_close(ct.road_loss(changed, road, valid), loss, rtol=1e-6, atol=1e-6)
    # a change where the pixels are valid does change it
    moved = torch.where(valid == 1, logit + 1.0, logit)
    assert abs(float(ct.road_loss(moved, road, valid) - loss)) > 1e-3
    # the right answer scores lower than the wrong one
    right = torch.where(road == 1, torch.tensor(8.0), torch.tensor(-8.0))
    assert ct.road_loss(right, road, valid) < 0.05 < ct.road_loss(-right, road, valid)
    # no valid pixel: finite (no division by zero)
    assert torch.isfinite(ct.road_loss(logit, road, torch.zeros_like(valid)))


def test_road_loss_ignores_road_labels_on_invalid_pixels():
    generator = torch.Generator().manual_seed(0)
    logit = torch.randn(1, 1, 32, 32, generator=generator)
    valid = torch.zeros(1, 1, 32, 32)
    valid[..., :16] = 1
    road = torch.zeros(1, 1, 32, 32)
    road[..., 4, :] = 1  # a road across the valid and the invalid half
    torch.testing.assert_close(ct.road_loss(logit, road, valid),
                               ct.road_loss(logit, road * valid, valid))


@pytest.fixture(scope="module")
def tiles(scene):
    """Two labelled tiles of the scene (road polygons rasterised) on a 2 m working grid."""
    import rasterio.features

    scene, image = scene
    road = rasterio.features.rasterize(
        ((g.buffer(w / 2), 1) for g, w in zip(scene.roads.geometry, scene.roads.width_m)),
        out_shape=image.shape, transform=image.transform).astype(bool)
    valid = np.ones(image.shape, bool)
    valid[:, :40] = False
    rgb = image.data[:3]
    made = [ct.working_tile(rgb, road, valid, source="a", source_pixel_m=1.0, pixel_m=2.0),
            ct.working_tile(rgb[:, :200, :200], road[:200, :200], valid[:200, :200],
                            source="b", source_pixel_m=1.0, pixel_m=2.0)]
    assert made[0].bands.shape == (3, 150, 150) and made[0].road.shape == (150, 150)
    assert made[0].bands.dtype == np.float32 and 0 <= made[0].bands.min()
    assert made[0].bands.max() <= 1.0
    assert 0.02 < made[0].road.mean() < 0.5 and not made[0].valid[:, :15].any()
    return made


def test_training_batches_are_seeded_and_label_only_valid_pixels(tiles):
    first = ct.training_batch(tiles, np.random.default_rng(5), batch=4, crop_px=64)
    again = ct.training_batch(tiles, np.random.default_rng(5), batch=4, crop_px=64)
    other = ct.training_batch(tiles, np.random.default_rng(6), batch=4, crop_px=64)
    x, road, valid = first
    assert x.shape == (4, 3, 64, 64) and road.shape == valid.shape == (4, 1, 64, 64)
    assert x.dtype == road.dtype == valid.dtype == torch.float32
    for a, b in zip(first, again):
        assert torch.equal(a, b)
    assert not torch.equal(x, other[0])
    assert set(torch.unique(road).tolist()) <= {0.0, 1.0}
    assert set(torch.unique(valid).tolist()) <= {0.0, 1.0}
    assert bool((road <= valid).all())  # road only where valid
    assert road.sum() > 0 and valid.sum() > 0
    assert bool((x[valid.expand_as(x) == 0] == 0).all())  # no-data pixels are zero input
    assert float(x.abs().max()) <= 1.5


def test_soft_targets_stay_soft_in_a_batch(tiles):
    """A tile whose road is a probability (fine-tuning's off-layer targets) gives targets in
    [0, 1] that keep their levels, zero where invalid."""
    tile = tiles[0]
    soft = ct.LabelledTile(tile.bands, np.where(tile.road, 1.0, 0.25).astype(np.float32),
                           tile.valid, "soft")
    _, road, valid = ct.training_batch([soft], np.random.default_rng(5), batch=4, crop_px=64,
                                       scale_range=(1.0, 1.0))
    inside = road[valid == 1]
    assert float(inside.min()) >= 0.25 - 1e-6 and float(inside.max()) <= 1.0 + 1e-6
    assert bool(((inside - 0.25).abs() < 1e-6).any()) and bool((inside == 1.0).any())
    assert bool((road[valid == 0] == 0).all())


def test_training_is_seeded(tiles):
    runs = [ct.train_convnet(tiles, steps=2, batch=2, crop_px=64, seed=4) for _ in range(2)]
    for name, value in runs[0].state_dict().items():
        assert torch.equal(value, runs[1].state_dict()[name]), name
    assert not runs[0].training


def test_fine_tune_on_layer_trains_on_the_road_layer(exported, scene):
    base_model, base_path = exported
    scene, image = scene
    calls = []
    tuned, metadata = ct.fine_tune_on_layer(
        GeoRaster(image.data[:3], image.transform, image.crs), scene.roads, model=base_path,
        steps=20, seed=0, check_share=0.0,
        progress=lambda fraction, message: calls.append(fraction))
    assert isinstance(tuned, ct.RoadUNet) and not tuned.training
    assert metadata["trained_on"] == "road layer"
    assert 0 < metadata["road_share"] < 0.5
    assert metadata["fine_tune_steps"] == 20 and metadata["fine_tune_seed"] == 0
    assert metadata["off_layer"] == "base"
    assert metadata["pixel_m"] == METADATA["pixel_m"] and metadata["note"] == "test"
    assert calls[-1] == 1.0
    base, tuned_state = base_model.state_dict(), tuned.state_dict()
    # trained: the convolution weights moved; batch-norm statistics stayed the base's
    assert not torch.allclose(tuned_state["head.weight"], base["head.weight"], atol=1e-3)
    for name in base:
        if name.endswith(("running_mean", "running_var")):
            np.testing.assert_allclose(tuned_state[name].numpy(), base[name].numpy(),
                                       rtol=1e-3, atol=1e-3, err_msg=name)


def test_a_fine_tuned_model_is_a_run_time_model(exported, scene, tmp_path):
    _, base_path = exported
    scene, image = scene
    tuned, metadata = ct.fine_tune_on_layer(image, scene.roads, model=base_path, steps=2,
                                            off_layer="background", check_share=0.0)
    assert metadata["off_layer"] == "background"
    path = ct.export_onnx(tuned, tmp_path / "tuned.onnx", metadata)
    net = load_convnet(path)
    assert net.metadata["trained_on"] == "road layer"
    p = convnet_probability(image, net)
    assert p.data.shape == image.shape and np.isfinite(p.data).all()


def test_held_out_roads_are_whole_roads_to_the_share_and_seeded(scene):
    scene, _ = scene
    roads = scene.roads
    held = ct.held_out_roads(roads, 0.2, seed=3)
    share = roads.length[held].sum() / roads.length.sum()
    assert held.dtype == bool and held.any() and not held.all()
    assert 0.2 <= share < 0.2 + roads.length.max() / roads.length.sum()
    assert (ct.held_out_roads(roads, 0.2, seed=3) == held).all()
    assert not ct.held_out_roads(roads, 0.0, seed=3).any()
    assert not ct.held_out_roads(roads.iloc[:ct.CHECK_MIN_ROADS - 1], 0.2, seed=3).any()


def test_a_fine_tuning_that_finds_fewer_held_out_roads_gives_back_the_base(scene):
    """A learning rate a hundred times too high wrecks the bundled network in a few steps:
    the check on the roads left out sees it and the base model comes back, unchanged."""
    scene, image = scene
    rgb = GeoRaster(image.data[:3], image.transform, image.crs)
    model, metadata = ct.fine_tune_on_layer(rgb, scene.roads, steps=4, learning_rate=0.05,
                                            off_layer="background", seed=0)
    check = metadata["check"]
    assert check["kept"] == "base" and check["held_out_roads"] >= 1
    assert check["fine-tuned"] < check["base"]
    assert "trained_on" not in metadata
    base, _ = ct.model_from_onnx(DEFAULT_CONVNET_PATH)
    for name, value in base.state_dict().items():
        assert torch.equal(value, model.state_dict()[name]), name


def test_fine_tuning_needs_a_road_on_the_image(exported, scene):
    _, base_path = exported
    scene, image = scene
    far = scene.roads.copy()
    far["geometry"] = far.translate(xoff=10_000.0)
    with pytest.raises(ValueError, match="no road of the layer lies on the image"):
        ct.fine_tune_on_layer(image, far, model=base_path, steps=1)
    with pytest.raises(ValueError, match="off_layer must be 'base' or 'background'"):
        ct.fine_tune_on_layer(image, scene.roads, model=base_path, steps=1, off_layer="zero")
