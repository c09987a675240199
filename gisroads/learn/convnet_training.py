"""Training the convolutional road model with PyTorch (the ``train`` extra).

Beyond the papers. :class:`RoadUNet` is a small U-Net (about 1.8 M parameters): a stride-2
stem, four more halvings of the grid with dilated convolutions at the coarsest two (a
receptive field of about 300 working pixels, for the context that tells a road from a
roof), bilinear upsampling with skip connections back to the full working grid. It is
trained from scratch (no pretrained weights can be fetched here) on labelled tiles
resampled to one working pixel size, with augmentation that makes it sensor-independent
(:func:`training_batch`: scale, rotation, flips, colour, brightness, contrast, gamma, haze,
greyscale, blur, noise, JPEG and straight no-data borders), and a loss for thin structures
(:func:`road_loss`: binary cross-entropy plus soft Dice, no-data pixels masked out).

At run time the model is an ONNX file applied by :mod:`gisroads.learn.convnet`
(onnxruntime); this module is imported only to train, fine-tune or export, and is the only
place in the library that imports torch.
"""
from __future__ import annotations

import copy
import inspect
import io
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy import ndimage

try:
    import torch
    from torch import nn
    from torch.nn import functional as F
except ImportError as error:  # pragma: no cover - the message is the point
    raise ImportError("training the road model needs PyTorch: "
                      "pip install 'gisroads[train]'") from error

from ..errors import GisroadsError
from ..progress import Progress, report, scaled
from .convnet import (CHECK_SHARE, FINE_TUNE_CORE_FRACTION, FINE_TUNE_STEPS, network_input,
                      normalisation)
from .training import LayerLabels

WIDTHS = (16, 32, 64, 128, 192)
"""Channels at 1/2, 1/4, 1/8, 1/16 and 1/32 of the working grid."""


def _conv(inputs: int, outputs: int, *, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(inputs, outputs, 3, stride, padding=dilation, dilation=dilation, bias=False),
        nn.BatchNorm2d(outputs), nn.ReLU(inplace=True))


class RoadUNet(nn.Module):
    """A small U-Net: ``(n, 3, rows, cols)`` normalised bands to ``(n, 1, rows, cols)``
    road logits (rows and cols multiples of 32)."""

    def __init__(self, widths=WIDTHS):
        super().__init__()
        w = widths
        self.stem = nn.Sequential(_conv(3, w[0], stride=2), _conv(w[0], w[0]))
        self.down2 = nn.Sequential(_conv(w[0], w[1], stride=2), _conv(w[1], w[1]))
        self.down3 = nn.Sequential(_conv(w[1], w[2], stride=2), _conv(w[2], w[2]))
        self.down4 = nn.Sequential(_conv(w[2], w[3], stride=2), _conv(w[3], w[3]),
                                   _conv(w[3], w[3], dilation=2))
        self.down5 = nn.Sequential(_conv(w[3], w[4], stride=2), _conv(w[4], w[4], dilation=2),
                                   _conv(w[4], w[4], dilation=4))
        self.up4 = _conv(w[4] + w[3], w[3])
        self.up3 = _conv(w[3] + w[2], w[2])
        self.up2 = _conv(w[2] + w[1], w[1])
        self.up1 = _conv(w[1] + w[0], w[0])
        self.full = _conv(w[0] + 3, 16)
        self.head = nn.Conv2d(16, 1, 1)

    @staticmethod
    def _merge(coarse, skip):
        up = F.interpolate(coarse, size=skip.shape[-2:], mode="bilinear", align_corners=False)
        return torch.cat([up, skip], 1)

    def forward(self, x):
        a = self.stem(x)
        b = self.down2(a)
        c = self.down3(b)
        d = self.down4(c)
        e = self.down5(d)
        y = self.up4(self._merge(e, d))
        y = self.up3(self._merge(y, c))
        y = self.up2(self._merge(y, b))
        y = self.up1(self._merge(y, a))
        return self.head(self.full(self._merge(y, x)))


@dataclass
class LabelledTile:
    """A labelled tile on the working grid.

    Attributes
    ----------
    bands : ndarray of float32, shape (3, rows, cols)
        Reflectance-like values in [0, 1] (8-bit values / 255).
    road : ndarray of bool, or of float in [0, 1] (soft targets), shape (rows, cols)
    valid : ndarray of bool, shape (rows, cols)
        Pixels in the loss.
    source : str
        Name of the data source, for per-source sampling and reporting.
    """

    bands: np.ndarray
    road: np.ndarray
    valid: np.ndarray
    source: str


def working_tile(rgb: np.ndarray, road: np.ndarray, valid: np.ndarray, *, source: str,
                 source_pixel_m: float, pixel_m: float) -> LabelledTile:
    """A labelled tile resampled from ``source_pixel_m`` to ``pixel_m`` (Gaussian
    anti-aliasing when it shrinks, bilinear bands, labels by the majority of their area).

    Parameters
    ----------
    rgb : ndarray, shape (3, rows, cols)
        8-bit bands.
    road, valid : ndarray of bool, shape (rows, cols)
    """
    zoom = source_pixel_m / pixel_m
    bands = np.asarray(rgb, np.float32)[:3] / np.float32(255.0)
    layers = [road.astype(np.float32), valid.astype(np.float32)]
    if zoom < 1:
        sigma = 0.45 / zoom
        bands = np.stack([ndimage.gaussian_filter(b, sigma) for b in bands])
        layers = [ndimage.gaussian_filter(layer, sigma) for layer in layers]
    if not np.isclose(zoom, 1.0):
        bands = np.stack([ndimage.zoom(b, zoom, order=1) for b in bands])
        layers = [ndimage.zoom(layer, zoom, order=1) for layer in layers]
    return LabelledTile(bands.astype(np.float32), layers[0] > 0.5, layers[1] > 0.5, source)


def _affine_crop(tile: LabelledTile, rng: np.random.Generator, crop_px: int,
                 scale_range: tuple[float, float]):
    """A crop of a tile, scaled, rotated and flipped at random (one bilinear resampling)."""
    scale = float(np.exp(rng.uniform(*np.log(scale_range))))
    angle = rng.uniform(0, 2 * np.pi)
    flip = -1.0 if rng.random() < 0.5 else 1.0
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    matrix = rotation @ np.diag([1.0, flip]) / scale  # crop pixel -> tile pixel
    rows, cols = tile.road.shape
    reach = np.abs(matrix).sum(axis=1) * crop_px / 2
    centre = np.array([rng.uniform(min(reach[0], rows / 2), max(rows - reach[0], rows / 2)),
                       rng.uniform(min(reach[1], cols / 2), max(cols - reach[1], cols / 2))])
    offset = centre - matrix @ np.full(2, crop_px / 2)
    shape = (crop_px, crop_px)

    def warp(layer, order, cval=0.0):
        return ndimage.affine_transform(layer, matrix, offset, output_shape=shape, order=order,
                                        mode="constant", cval=cval)
    bands = np.stack([warp(b, 1) for b in tile.bands])
    road = warp(tile.road.astype(np.float32), 1)
    road = road > 0.5 if tile.road.dtype == bool else road  # soft targets stay soft
    valid = warp(tile.valid.astype(np.float32), 0) > 0.5
    return bands, road, valid


def _gaussian_blur(bands: np.ndarray, sigma: float) -> np.ndarray:
    return np.stack([ndimage.gaussian_filter(b, sigma) for b in bands])


def _jpeg(bands: np.ndarray, quality: int) -> np.ndarray:
    from PIL import Image

    pixels = np.clip(bands.transpose(1, 2, 0) * 255 + 0.5, 0, 255).astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="JPEG", quality=quality)
    decoded = np.asarray(Image.open(io.BytesIO(buffer.getvalue())).convert("RGB"))
    return decoded.transpose(2, 0, 1).astype(np.float32) / 255.0


def photometric(bands: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Colour, brightness, contrast, gamma, haze, greyscale, blur, noise and JPEG changes
    of a crop's bands (values about [0, 1]), each drawn at random."""
    x = bands * rng.uniform(0.85, 1.15, size=(3, 1, 1)).astype(np.float32)
    mean = x.mean()
    x = (x - mean) * rng.uniform(0.7, 1.3) + mean + rng.uniform(-0.1, 0.1)
    x = np.clip(x, 0.0, 1.0) ** rng.uniform(0.7, 1.4)
    if rng.random() < 0.3:
        haze = rng.uniform(0.05, 0.35)
        x = x * (1 - haze) + haze * rng.uniform(0.7, 1.0)
    if rng.random() < 0.15:
        x = np.repeat((0.299 * x[0] + 0.587 * x[1] + 0.114 * x[2])[None], 3, axis=0)
    if rng.random() < 0.25:
        x = _gaussian_blur(x, rng.uniform(0.3, 1.2))
    if rng.random() < 0.3:
        x = x + rng.normal(0.0, rng.uniform(0.005, 0.03), size=x.shape)
    if rng.random() < 0.2:
        x = _jpeg(x, int(rng.integers(20, 80)))
    return x.astype(np.float32)


def _nodata_border(valid: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``valid`` with a half-plane cut away along a random straight line (an image's
    no-data border, through a road or beside it)."""
    rows, cols = valid.shape
    angle = rng.uniform(0, 2 * np.pi)
    r, c = np.mgrid[0:rows, 0:cols]
    distance = (r - rows / 2) * np.cos(angle) + (c - cols / 2) * np.sin(angle)
    return valid & (distance < rng.uniform(-0.3, 0.4) * min(rows, cols))


def training_batch(tiles: list[LabelledTile], rng: np.random.Generator, *, batch: int,
                   crop_px: int, scale_range=(0.6, 1.6), source_weights: dict | None = None,
                   nodata_share: float = 0.15):
    """A batch of augmented crops: ``(x (n, 3, crop, crop), road (n, 1, ...), valid
    (n, 1, ...))`` tensors. Sources are drawn with ``source_weights`` (equal by default),
    tiles within a source by their area."""
    sources = sorted({t.source for t in tiles})
    weights = np.array([(source_weights or {}).get(s, 1.0) for s in sources], float)
    by_source = {s: [t for t in tiles if t.source == s] for s in sources}
    area = {s: np.array([t.road.size for t in ts], float) for s, ts in by_source.items()}
    xs, roads, valids = [], [], []
    for _ in range(batch):
        source = sources[rng.choice(len(sources), p=weights / weights.sum())]
        members = by_source[source]
        tile = members[rng.choice(len(members), p=area[source] / area[source].sum())]
        bands, road, valid = _affine_crop(tile, rng, crop_px, scale_range)
        if rng.random() < nodata_share:
            valid = _nodata_border(valid, rng)
        bands = photometric(bands, rng)
        if valid.any():
            low, high = normalisation(bands, valid)
        else:
            low, high = 0.0, 1.0
        xs.append(network_input(bands, valid, low, high))
        roads.append(np.where(valid, road, 0))
        valids.append(valid)
    return (torch.from_numpy(np.stack(xs)),
            torch.from_numpy(np.stack(roads)[:, None].astype(np.float32)),
            torch.from_numpy(np.stack(valids)[:, None].astype(np.float32)))


def road_loss(logit, road, valid, *, dice_weight: float = 1.0):
    """Binary cross-entropy over the valid pixels plus ``dice_weight`` times the soft Dice
    loss of the batch (thin roads are a small share of the pixels: Dice weighs them by
    their overlap, not their count)."""
    road = road * valid
    bce = F.binary_cross_entropy_with_logits(logit, road, reduction="none")
    bce = (bce * valid).sum() / valid.sum().clamp(min=1.0)
    p = torch.sigmoid(logit) * valid
    dice = 1 - (2 * (p * road).sum() + 1.0) / (p.sum() + road.sum() + 1.0)
    return bce + dice_weight * dice


@dataclass(frozen=True)
class TrainingOptions:
    """The options of :func:`train_convnet`: the crops, their augmentation and the
    optimiser.

    Attributes
    ----------
    batch, crop_px : int
        Crops per step and crop side (working pixels, a multiple of 32).
    learning_rate : float
        Peak of the one-cycle schedule (AdamW).
    freeze_batchnorm : bool
        Keep the batch-norm statistics of ``model`` (fine-tuning on a few tiles).
    source_weights : dict, optional
        Weight of each source (``LabelledTile.source``) in drawing a crop (equal by
        default); tiles within a source by their area.
    scale_range : (float, float)
        Range of the random rescaling of a crop (augmentation).
    nodata_share : float
        Share of the crops given a no-data border (masked out of the loss).
    """

    batch: int = 8
    crop_px: int = 256
    learning_rate: float = 3e-3
    freeze_batchnorm: bool = False
    source_weights: dict | None = None
    scale_range: tuple = (0.6, 1.6)
    nodata_share: float = 0.15


def train_convnet(tiles: list[LabelledTile], options: TrainingOptions = TrainingOptions(), *,
                  steps: int, seed: int = 0, model: RoadUNet | None = None,
                  progress: Progress = None, checkpoint=None, **changes) -> RoadUNet:
    """Train (or fine-tune) a :class:`RoadUNet` on labelled tiles.

    Parameters
    ----------
    tiles : list of LabelledTile
        On the model's working grid (:func:`working_tile`).
    steps : int
        Optimiser steps.
    seed : int
        Seeds numpy's and torch's generators: the same call gives the same model.
    model : RoadUNet, optional
        A model to fine-tune; a new one when None.
    options : TrainingOptions
        Crops, augmentation and optimiser (:class:`TrainingOptions`).
    checkpoint : callable, optional
        ``checkpoint(step, model)`` every 250 steps and at the end.
    **changes
        Fields of ``options`` to change for this call.
    """
    options = replace(options, **changes)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model = RoadUNet() if model is None else model
    optimiser = torch.optim.AdamW(model.parameters(), lr=options.learning_rate,
                                  weight_decay=1e-4)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, max_lr=options.learning_rate,
                                                   total_steps=steps, pct_start=0.1)
    started = time.perf_counter()
    running = None
    for step in range(1, steps + 1):
        model.train()
        if options.freeze_batchnorm:
            for module in model.modules():
                if isinstance(module, nn.BatchNorm2d):
                    module.eval()
        x, road, valid = training_batch(tiles, rng, batch=options.batch,
                                        crop_px=options.crop_px,
                                        scale_range=options.scale_range,
                                        source_weights=options.source_weights,
                                        nodata_share=options.nodata_share)
        loss = road_loss(model(x), road, valid)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        running = loss.item() if running is None else 0.98 * running + 0.02 * loss.item()
        report(progress, step / steps,
               f"step {step} of {steps}, loss {running:.3f}, "
               f"{time.perf_counter() - started:.0f} s")
        if checkpoint is not None and (step % 250 == 0 or step == steps):
            checkpoint(step, model)
    model.eval()
    return model


def predict_tiles(model: RoadUNet, tiles: list[LabelledTile]) -> list[np.ndarray]:
    """The model's road probability of each tile (working grid), normalised as at run
    time over the tile's valid pixels."""
    model.eval()
    out = []
    with torch.no_grad():
        for tile in tiles:
            rows, cols = tile.road.shape
            low, high = normalisation(tile.bands, tile.valid)
            x = np.zeros((1, 3, -(-rows // 32) * 32, -(-cols // 32) * 32), np.float32)
            x[0, :, :rows, :cols] = network_input(tile.bands, tile.valid, low, high)
            logit = model(torch.from_numpy(x))[0, 0, :rows, :cols].numpy()
            out.append(1.0 / (1.0 + np.exp(-logit)))
    return out


def state_to_arrays(model: RoadUNet) -> dict[str, np.ndarray]:
    """The model's weights and batch-norm statistics as numpy arrays (for ``np.savez``)."""
    return {name: value.detach().cpu().numpy() for name, value in model.state_dict().items()}


def model_from_arrays(arrays) -> RoadUNet:
    """A :class:`RoadUNet` with the weights of :func:`state_to_arrays`."""
    model = RoadUNet()
    model.load_state_dict({name: torch.from_numpy(np.asarray(arrays[name]))
                           for name in model.state_dict()})
    model.eval()
    return model


def export_onnx(model: RoadUNet, path, metadata: dict) -> Path:
    """Write the model as ONNX (input ``image``, output ``logit``, any batch and size that
    is a multiple of 32) with ``metadata`` as its ``gisroads`` entry and the weights
    (:func:`state_to_arrays`) as the ``gisroads_weights`` entry, so that the file alone can
    be fine-tuned again; written to a temporary file, then renamed."""
    import base64

    import onnx

    path = Path(path)
    model.eval()
    buffer = io.BytesIO()
    # the TorchScript exporter: the newer one needs onnxscript; older torch has no choice
    choice = ({"dynamo": False} if "dynamo" in inspect.signature(torch.onnx.export).parameters
              else {})
    torch.onnx.export(model, torch.zeros(1, 3, 256, 256), buffer, input_names=["image"],
                      output_names=["logit"], opset_version=17, **choice,
                      dynamic_axes={"image": {0: "n", 2: "rows", 3: "cols"},
                                    "logit": {0: "n", 2: "rows", 3: "cols"}})
    graph = onnx.load_from_string(buffer.getvalue())
    weights = io.BytesIO()
    np.savez_compressed(weights, **{k: v.astype(np.float16) if v.dtype == np.float32 else v
                                    for k, v in state_to_arrays(model).items()})
    for key, value in (("gisroads", json.dumps(metadata)),
                       ("gisroads_weights", base64.b64encode(weights.getvalue()).decode())):
        entry = graph.metadata_props.add()
        entry.key, entry.value = key, value
    partial = path.with_name(path.name + ".partial")
    onnx.save(graph, str(partial))
    partial.replace(path)
    return path


def model_from_onnx(path) -> tuple[RoadUNet, dict]:
    """The trainable :class:`RoadUNet` and metadata of an ONNX file written by
    :func:`export_onnx`."""
    import base64

    import onnx

    graph = onnx.load(str(path))
    entries = {p.key: p.value for p in graph.metadata_props}
    if "gisroads_weights" not in entries:
        raise GisroadsError(f"{path}: holds no gisroads weights to fine-tune")
    arrays = np.load(io.BytesIO(base64.b64decode(entries["gisroads_weights"])))
    model = model_from_arrays({k: arrays[k].astype(np.float32)
                               if arrays[k].dtype == np.float16 else arrays[k]
                               for k in arrays.files})
    return model, json.loads(entries.get("gisroads", "{}"))


def _working_grid(image, pixel_m: float):
    """The image on a model's working grid: ``(bands scaled to about [0, 1], valid,
    grid)`` where ``grid`` has the ``shape``, ``transform``, ``pixel_m`` and ``image`` that
    :func:`gisroads.learn.training.layer_labels` reads."""
    from types import SimpleNamespace

    from affine import Affine

    from .convnet import _Resampler

    resampler = _Resampler(image, pixel_m)
    rows, cols = resampler.shape
    bands, valid = resampler.window(0, rows, 0, cols)
    low, high = normalisation(bands, valid)
    t = image.transform
    scale = 1.0 / resampler.zoom
    grid = SimpleNamespace(image=image, pixel_m=pixel_m, shape=(rows, cols),
                           transform=Affine(t.a * scale, 0.0, t.c, 0.0, t.e * scale, t.f))
    scaled = np.repeat(bands, 3, axis=0) if bands.shape[0] == 1 else bands[:3]
    return ((scaled - low) / (high - low)).astype(np.float32), valid, grid


#: Fewest roads a layer needs before some are held out for the check.
CHECK_MIN_ROADS = 5
#: A held-out road is found where the check's network runs within this of it, metres.
CHECK_BUFFER_M = 4.0


def held_out_roads(roads, share: float, seed: int) -> np.ndarray:
    """Whole roads of a layer, in a seeded random order, until ``share`` of its length is
    reached (bool per feature; none for ``share`` 0 or fewer than :data:`CHECK_MIN_ROADS`
    roads)."""
    length = np.asarray(roads.geometry.length, float)
    held = np.zeros(len(roads), dtype=bool)
    if share <= 0 or len(roads) < CHECK_MIN_ROADS:
        return held
    order = np.random.default_rng(seed).permutation(len(roads))
    upto = np.searchsorted(np.cumsum(length[order]), share * length.sum()) + 1
    held[order[:upto]] = True
    return held


def _check(probabilities: dict, grid, valid: np.ndarray, roads, threshold: float) -> dict:
    """Per model: the share of ``roads`` (the held-out ones) that the network stage finds on
    its probability at ``threshold`` (completeness at :data:`CHECK_BUFFER_M`)."""
    from ..evaluate import buffer_metrics
    from ..geo import GeoRaster
    from ..network.rasters import raster_to_network

    crs = grid.image.crs
    truth = roads.to_crs(crs) if roads.crs is not None and crs is not None else roads
    found = {}
    for name, p in probabilities.items():
        network = raster_to_network(GeoRaster(np.where(valid, p, np.nan), grid.transform, crs),
                                    threshold=threshold, method="check")
        found[name] = round(buffer_metrics(network.centrelines, truth,
                                           buffer_m=CHECK_BUFFER_M).completeness, 4)
    return found


def fine_tune_on_layer(image, roads,
                       labels: LayerLabels = LayerLabels(core_fraction=FINE_TUNE_CORE_FRACTION),
                       *, model=None, steps: int = FINE_TUNE_STEPS,
                       learning_rate: float = 3e-4, off_layer: str = "base",
                       check_share: float = CHECK_SHARE, seed: int = 0,
                       progress: Progress = None, **changes) -> tuple[RoadUNet, dict]:
    """Fine-tune the convolutional road model on an image with a road layer as labels (the
    road-database update case).

    The layer is rasterised on the model's working grid as for the boosted trees
    (:func:`gisroads.learn.training.layer_labels`): road within ``core_fraction`` of each
    road's half-width of its line (the whole width by default: the network draws road
    surfaces, and taught the core half it learns to miss roads), non-road beyond half the
    width plus ``guard_m`` (lines a few metres off), the band between left out of the
    loss.

    Parameters
    ----------
    image : GeoRaster
        In a projected metre CRS.
    roads : GeoDataFrame
        Road centre lines, any CRS.
    model : str or Path, optional
        An ``.onnx`` file of :func:`export_onnx` to start from; the bundled model when None.
    labels : LayerLabels
        Widths, guard band and core (:class:`gisroads.learn.training.LayerLabels`; here
        the whole width is road by default); ``**changes`` change its fields for this
        call, e.g. ``width_field="width_m"``.
    steps : int
        Optimiser steps (:data:`FINE_TUNE_STEPS`); batch-norm statistics stay the base
        model's.
    learning_rate : float
        Peak of the one-cycle schedule: low, so that the model stays near the base.
    off_layer : {"base", "background"}
        What the pixels off the layer (beyond the guard band) are taught. ``"base"``: the
        base model's own probability there (soft targets): a layer to update lacks roads,
        and a network taught that its missing roads are background learns to miss them;
        taught its own view it keeps them and learns the image's roads from the layer.
        ``"background"``: non-road, for a layer known to be complete.
    check_share : float
        Share of the layer's length (whole roads, :func:`held_out_roads`) left out of the
        training. On them the fine-tuned model is checked against the base model: the
        network stage runs on each one's probability at the model's threshold, and the
        fine-tuned model is kept when it finds at least as much of those roads' length
        (:data:`CHECK_BUFFER_M`); otherwise the base model is returned, since a layer to
        update is the case where the network must find the roads it was not shown. 0: no
        check, every road trains.
    seed : int

    Returns
    -------
    (RoadUNet, dict)
        The fine-tuned model and its metadata (the base model's with ``trained_on``,
        ``road_share``, ``fine_tune_steps`` and, with a check, ``check``: the two models'
        figures and which was ``kept``); or, when the check keeps it, the base model and
        its own metadata with ``road_share`` and ``check``.
    """
    from .convnet import DEFAULT_CONVNET_PATH
    from .training import ROAD_LAYER, layer_labels

    base, metadata = model_from_onnx(model if model is not None else DEFAULT_CONVNET_PATH)
    report(progress, 0.0, "reading the image on the model's grid")
    bands, valid, grid = _working_grid(image, float(metadata["pixel_m"]))
    labels = replace(labels, **changes)
    held = held_out_roads(roads, check_share, seed)
    positive, negative = layer_labels(grid, roads[~held], labels)
    if held.any():
        negative &= layer_labels(grid, roads, labels)[1]
    if not (positive & valid).any():
        raise GisroadsError("no road of the layer lies on the image")
    bands = np.clip(bands, -0.5, 1.5)
    if off_layer not in ("base", "background"):
        raise GisroadsError(f"off_layer must be 'base' or 'background', not {off_layer!r}")
    target = positive & valid
    whole = [LabelledTile(bands, positive, valid, "layer")]
    seen = None
    if off_layer == "base" or held.any():
        report(progress, 0.02, "reading the image with the base model")
        seen = predict_tiles(base, whole)[0]
    if off_layer == "base":
        target = np.where(target, 1.0, seen).astype(np.float32)
    tile = LabelledTile(bands, target, valid & (positive | negative), "layer")
    tuned = train_convnet([tile], steps=steps, batch=8, crop_px=224,
                          learning_rate=learning_rate, seed=seed, model=copy.deepcopy(base),
                          freeze_batchnorm=True, scale_range=(0.8, 1.25), nodata_share=0.0,
                          progress=scaled(progress, 0.0, 0.95 if held.any() else 1.0))
    road_share = float(positive[valid].mean())
    tuned_metadata = {**metadata, "trained_on": ROAD_LAYER, "road_share": round(road_share, 4),
                      "fine_tune_steps": steps, "fine_tune_seed": seed,
                      "off_layer": off_layer}
    if not held.any():
        return tuned, tuned_metadata
    report(progress, 0.95, "checking the fine-tuned model on the roads left out")
    figures = _check({"base": seen, "fine-tuned": predict_tiles(tuned, whole)[0]}, grid,
                     valid, roads[held], float(metadata["threshold"]))
    kept = "fine-tuned" if figures["fine-tuned"] >= figures["base"] else "base"
    report(progress, 1.0, f"kept the {kept} model")
    verdict = {**figures, "held_out_roads": int(held.sum()), "kept": kept}
    return ((tuned, {**tuned_metadata, "check": verdict}) if kept == "fine-tuned"
            else (base, {**metadata, "road_share": tuned_metadata["road_share"],
                         "check": verdict}))
