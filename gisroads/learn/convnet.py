"""The convolutional road model at run time: an ONNX network applied with onnxruntime.

Beyond the papers: a small U-Net (:mod:`gisroads.learn.convnet_training` defines and trains
it with PyTorch, which is never imported here) maps an image, resampled to the model's
working pixel size and normalised by the image's own percentiles, to a road probability.
The image is read in overlapping tiles of the working grid whose predictions are blended
with a weight that falls towards a tile's border, so the network's memory follows the tile
(the image adds two float32 arrays of the working grid, the blend's sums, besides the
output) and seams do not show.

The model file is an ONNX graph with one input ``image`` ``(n, 3, rows, cols)`` and one
output ``logit`` of the same size; its metadata entry ``gisroads`` (JSON) holds at least
``pixel_m`` (the working pixel size, metres) and ``threshold`` (the road threshold chosen
on held-out tiles).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..progress import Progress, report
from .features import metric_pixel_size, rgb_bands, valid_pixels

DEFAULT_CONVNET_PATH = Path(__file__).resolve().parent / "models" / "road_convnet.onnx"
NORMALISE_PERCENTILES = (1.0, 99.0)
"""Percentiles of the image's valid values (all bands together) mapped to -0.5 and 0.5:
the network sees contrast, not a sensor's range (8-bit, 11-bit, reflectance)."""
TILE_PX = 1024
"""Side of the tiles the network sees, working pixels."""
OVERLAP_PX = 64
"""Overlap of neighbouring tiles, working pixels: their predictions are blended across it."""
TAIL_CONTEXT_PX = 96
"""Context, working pixels, that the narrow window over the end of a short axis sees
before the part the first window leaves out (:func:`_windows`)."""
VIEWS = 2
"""Views of each tile averaged by default (:func:`convnet_probability`): the tile and its
half-turn, chosen on the held-out training tiles (figures in docs/imagery.md)."""
FINE_TUNE_STEPS = 150
"""Optimiser steps of :func:`gisroads.learn.convnet_training.fine_tune_on_layer` (8 crops of
224 working pixels each): about 25 passes over a 1500 x 1500 tile at 1 m, about a minute on
two CPU cores (figures in docs/imagery.md)."""
CHECK_SHARE = 0.2
"""Share of a road layer's length (whole roads, seeded) that
:func:`gisroads.learn.convnet_training.fine_tune_on_layer` leaves out of the training, to
check the fine-tuned model against the base model on them."""
FINE_TUNE_CORE_FRACTION = 1.0
"""``core_fraction`` of the labels :func:`gisroads.learn.convnet_training.fine_tune_on_layer`
teaches (:class:`gisroads.learn.training.LayerLabels`): the whole width of a road is road,
since the network draws road surfaces (taught the core half, it learns to miss roads)."""


@dataclass(frozen=True)
class ConvNet:
    """A loaded convolutional road model.

    Attributes
    ----------
    path : Path
        The ONNX file.
    metadata : dict
        Its ``gisroads`` metadata: ``pixel_m``, ``threshold`` and the model card's facts.
    session : onnxruntime.InferenceSession
    """

    path: Path
    metadata: dict
    session: object = field(repr=False, compare=False)

    @property
    def pixel_m(self) -> float:
        """Working pixel size, metres."""
        return float(self.metadata["pixel_m"])

    @property
    def threshold(self) -> float:
        """Road threshold of the probability, chosen on held-out tiles."""
        return float(self.metadata.get("threshold", 0.5))


def _session(path: Path, threads: int):
    try:
        import onnxruntime as ort
    except ImportError as error:  # pragma: no cover - a dependency
        raise ImportError("the convolutional road model needs onnxruntime "
                          "(pip install onnxruntime)") from error
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.log_severity_level = 3
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def is_convnet_file(path) -> bool:
    """Whether ``path`` names an ONNX model file (by its suffix)."""
    return Path(path).suffix.lower() == ".onnx"


def load_convnet(path=None, *, threads: int = 1) -> ConvNet:
    """The convolutional road model of an ONNX file (the bundled one by default).

    Parameters
    ----------
    path : str or Path, optional
        An ``.onnx`` file written by ``gisroads train`` or ``scripts/train_road_cnn.py``.
    threads : int
        onnxruntime's threads for one tile (the library pins every pool to one by default).

    Raises
    ------
    ValueError
        A file that is not a gisroads road network (no ``gisroads`` metadata).
    """
    path = Path(path) if path is not None else DEFAULT_CONVNET_PATH
    if not path.is_file():
        raise GisroadsError(f"{path}: no such road model file")
    try:
        session = _session(path, threads)
    except Exception as error:  # onnxruntime raises its own exception types
        raise GisroadsError(f"{path}: not a readable ONNX model ({error})") from error
    entries = session.get_modelmeta().custom_metadata_map
    if "gisroads" not in entries:
        raise GisroadsError(f"{path}: an ONNX model without gisroads metadata (train it with "
                            "'gisroads train' or scripts/train_road_cnn.py)")
    metadata = json.loads(entries["gisroads"])
    if "pixel_m" not in metadata:
        raise GisroadsError(f"{path}: its gisroads metadata has no pixel_m")
    return ConvNet(path, metadata, session)


def normalisation(bands: np.ndarray, valid: np.ndarray, *,
                  percentiles=NORMALISE_PERCENTILES, max_samples: int = 200_000
                  ) -> tuple[float, float]:
    """The image values mapped to -0.5 and 0.5: percentiles of the valid values of all
    bands together (from at most ``max_samples`` evenly spaced valid pixels).

    Parameters
    ----------
    bands : ndarray, shape (bands, rows, cols)
    valid : ndarray of bool, shape (rows, cols)
    """
    values = bands[:, valid]
    step = max(1, values.shape[1] // max_samples)
    values = values[:, ::step].ravel()
    if values.size == 0:
        raise GisroadsError("the image has no valid pixel")
    low, high = np.percentile(values, percentiles)
    return float(low), float(max(high, low + 1e-6))


def network_input(bands: np.ndarray, valid: np.ndarray, low: float, high: float
                  ) -> np.ndarray:
    """Bands as the network takes them: three channels (a single band repeated), scaled so
    that ``low`` and ``high`` are -0.5 and 0.5, clipped to [-1.5, 1.5], zero where not
    ``valid``; float32 ``(3, rows, cols)``."""
    bands = np.asarray(bands, np.float32)
    if bands.shape[0] == 1:
        bands = np.repeat(bands, 3, axis=0)
    scaled = (bands[:3] - np.float32(low)) / np.float32(high - low) - np.float32(0.5)
    scaled = np.clip(np.nan_to_num(scaled), -1.5, 1.5)
    return np.where(valid, scaled, np.float32(0.0)).astype(np.float32)


def _blend_weight(rows: int, cols: int, overlap: int) -> np.ndarray:
    """A tile's blending weight: 1 in its middle, falling linearly over ``overlap`` pixels
    towards each border (never quite to zero, so an image's own border keeps a weight)."""
    def ramp(n):
        r = np.ones(n, np.float32)
        if overlap > 0:
            edge = (np.arange(min(overlap, n), dtype=np.float32) + 0.5) / overlap
            r[:edge.size] = np.minimum(r[:edge.size], edge)
            r[n - edge.size:] = np.minimum(r[n - edge.size:], edge[::-1])
        return r
    return np.outer(ramp(rows), ramp(cols))


def _windows(n: int, tile: int, overlap: int) -> list[tuple[int, int]]:
    """``(start, size)`` of the network's windows along an axis of ``n`` working pixels.

    Sizes are multiples of 32 (the network halves its grid five times) and the windows lie
    inside the image: padding would show the network a no-data border along the image's
    edge, where it learnt that roads may run. An axis shorter than ``tile`` that is no
    multiple of 32 gets a second, narrow window over its end with
    :data:`TAIL_CONTEXT_PX` of context; one shorter than 32 is padded.
    """
    if n < 32:
        return [(0, 32)]
    if n >= tile:
        starts = list(range(0, n - tile, tile - overlap)) + [n - tile]
        return [(start, tile) for start in starts]
    size = n // 32 * 32
    if size == n:
        return [(0, n)]
    tail = min(size, -(-(n - size + TAIL_CONTEXT_PX) // 32) * 32)
    return [(0, size), (n - tail, tail)]


class _Resampler:
    """Reads an image window on the working grid: each working pixel the bilinear value
    of the image after a Gaussian anti-aliasing blur of the zoom (downsampling), or the
    plain bilinear value (upsampling)."""

    def __init__(self, image: GeoRaster, pixel_m: float):
        self.image = image
        self.data = np.asarray(image.data)
        self.image_pixel_m = metric_pixel_size(image)
        self.zoom = self.image_pixel_m / pixel_m  # working pixels per image pixel
        rows, cols = image.shape
        self.shape = (max(1, int(round(rows * self.zoom))), max(1, int(round(cols * self.zoom))))
        self.sigma = 0.0 if self.zoom >= 1 else 0.45 / self.zoom

    def window(self, r0: int, r1: int, c0: int, c1: int) -> tuple[np.ndarray, np.ndarray]:
        """Bands ``(b, r1-r0, c1-c0)`` and valid mask of a working-grid window."""
        if self.zoom == 1.0:  # the image is on the working grid already
            crop = GeoRaster(self.data[..., r0:r1, c0:c1], self.image.transform,
                             self.image.crs, self.image.nodata)
            valid = valid_pixels(crop)
            return np.where(valid, rgb_bands(crop.data), np.float32(0.0)), valid
        halo = int(np.ceil(3 * self.sigma)) + 2
        rows, cols = self.image.shape
        # image pixel centres of the working pixels
        y = (np.arange(r0, r1) + 0.5) / self.zoom - 0.5
        x = (np.arange(c0, c1) + 0.5) / self.zoom - 0.5
        i0 = max(0, int(np.floor(y[0])) - halo)
        i1 = min(rows, int(np.ceil(y[-1])) + halo + 1)
        j0 = max(0, int(np.floor(x[0])) - halo)
        j1 = min(cols, int(np.ceil(x[-1])) + halo + 1)
        crop = GeoRaster(self.data[..., i0:i1, j0:j1], self.image.transform, self.image.crs,
                         self.image.nodata)
        bands = rgb_bands(crop.data)
        valid = valid_pixels(crop)
        bands = np.where(valid, bands, 0.0).astype(np.float32)
        if self.sigma > 0:
            weight = ndimage.gaussian_filter(valid.astype(np.float32), self.sigma)
            bands = np.stack([ndimage.gaussian_filter(b, self.sigma) for b in bands])
            bands = bands / np.maximum(weight, 1e-6)
        yy, xx = np.meshgrid(np.clip(y - i0, 0, i1 - i0 - 1), np.clip(x - j0, 0, j1 - j0 - 1),
                             indexing="ij")
        out = np.stack([ndimage.map_coordinates(b, (yy, xx), order=1, mode="nearest")
                        for b in bands])
        out_valid = ndimage.map_coordinates(valid.astype(np.float32), (yy, xx), order=1,
                                            mode="nearest") > 0.5
        return out, out_valid

    def sample(self, max_samples: int = 200_000) -> tuple[np.ndarray, np.ndarray]:
        """Evenly spaced image pixels (bands, valid) for the normalisation."""
        rows, cols = self.image.shape
        step = max(1, int(np.sqrt(rows * cols / max_samples)))
        crop = GeoRaster(self.data[..., ::step, ::step], self.image.transform,
                         self.image.crs, self.image.nodata)
        return rgb_bands(crop.data), valid_pixels(crop)


#: The views of a tile that the network sees, as (rows reversed, columns reversed): the tile,
#: then its half-turn, then its two mirror images.
_VIEWS = ((False, False), (True, True), (True, False), (False, True))


def _view(array: np.ndarray, flip_rows: bool, flip_cols: bool) -> np.ndarray:
    """``array`` with its last two axes reversed as asked (its own inverse)."""
    return array[..., ::-1 if flip_rows else 1, ::-1 if flip_cols else 1]


def _predict(model: ConvNet, x: np.ndarray, views: int) -> np.ndarray:
    """Road probability of one network input ``(1, 3, rows, cols)``: the mean over the
    first ``views`` of :data:`_VIEWS`, run as one batch."""
    chosen = _VIEWS[:views]
    batch = np.concatenate([_view(x, *view) for view in chosen])
    p = 1.0 / (1.0 + np.exp(-model.session.run(None, {"image": batch})[0][:, 0]))
    return sum(_view(p[k], *view) for k, view in enumerate(chosen)) / len(chosen)


def convnet_probability(image: GeoRaster, model: ConvNet | None = None, *,
                        tile_px: int = TILE_PX, overlap_px: int = OVERLAP_PX,
                        views: int = VIEWS, progress: Progress = None) -> GeoRaster:
    """Road probability of every pixel of an image from the convolutional road model.

    Parameters
    ----------
    image : GeoRaster
        1-band (panchromatic) or 3+-band image (the first three taken as R, G, B), any
        numeric dtype, NaN or ``nodata`` where it has no data, in a projected metre CRS
        with square north-up pixels.
    model : ConvNet, optional
        The bundled model (:func:`load_convnet`) when None.
    tile_px, overlap_px : int
        Tile side and overlap on the model's working grid, pixels.
    views : {1, 2, 4}
        Views of each tile averaged (test-time augmentation): the tile alone; with its
        half-turn; with its two mirror images too. Each costs one run of the network.
    progress : callable, optional
        ``progress(fraction, message)`` after each tile; may raise
        :class:`gisroads.progress.Cancelled`.

    Returns
    -------
    GeoRaster
        float32 probabilities in [0, 1] on the image's grid, NaN where it has no data.

    Raises
    ------
    ValueError
        Geographic or unit-less CRS, rotated pixels, 2-band image, no valid pixel.
    """
    model = load_convnet() if model is None else model
    if views not in (1, 2, 4):
        raise GisroadsError(f"views must be 1, 2 or 4, not {views!r}")
    if overlap_px >= tile_px // 2:
        raise GisroadsError("overlap_px must be less than half of tile_px")
    grid = _Resampler(image, model.pixel_m)
    low, high = normalisation(*grid.sample())
    rows, cols = grid.shape
    total = np.zeros(grid.shape, np.float32)
    weights = np.zeros(grid.shape, np.float32)
    windows = [(r0, tile_r, c0, tile_c) for r0, tile_r in _windows(rows, tile_px, overlap_px)
               for c0, tile_c in _windows(cols, tile_px, overlap_px)]
    for k, (r0, tile_r, c0, tile_c) in enumerate(windows):
        r1, c1 = min(rows, r0 + tile_r), min(cols, c0 + tile_c)
        bands, valid = grid.window(r0, r1, c0, c1)
        if valid.any():
            x = np.zeros((1, 3, tile_r, tile_c), np.float32)
            x[0, :, :r1 - r0, :c1 - c0] = network_input(bands, valid, low, high)
            p = _predict(model, x, views)[:r1 - r0, :c1 - c0].astype(np.float32)
            weight = _blend_weight(r1 - r0, c1 - c0, overlap_px)
            total[r0:r1, c0:c1] += weight * p
            weights[r0:r1, c0:c1] += weight
        report(progress, (k + 1) / len(windows), f"road model: tile {k + 1} of {len(windows)}")
    work = total / np.maximum(weights, 1e-12)
    return _to_image(image, work, grid.zoom)


def _to_image(image: GeoRaster, work: np.ndarray, zoom: float, chunk_rows: int = 1024
              ) -> GeoRaster:
    """A working-grid probability read back onto the image grid (bilinear), NaN where the
    image has no data; row by row in chunks, so no second full-size index array is made."""
    rows, cols = image.shape
    if zoom == 1.0:
        out = work
    else:
        out = _bilinear(work, zoom, rows, cols, chunk_rows)
    out = np.where(valid_pixels(image), np.clip(out, 0.0, 1.0), np.float32(np.nan))
    return GeoRaster(out.astype(np.float32, copy=False), image.transform, image.crs,
                     float("nan"))


def _bilinear(work: np.ndarray, zoom: float, rows: int, cols: int, chunk_rows: int
              ) -> np.ndarray:
    out = np.empty((rows, cols), np.float32)
    x = np.clip((np.arange(cols) + 0.5) * zoom - 0.5, 0, work.shape[1] - 1)
    for r0 in range(0, rows, chunk_rows):
        y = np.clip((np.arange(r0, min(rows, r0 + chunk_rows)) + 0.5) * zoom - 0.5, 0,
                    work.shape[0] - 1)
        yy, xx = np.meshgrid(y, x, indexing="ij")
        out[r0:r0 + len(y)] = ndimage.map_coordinates(work, (yy, xx), order=1,
                                                       mode="nearest")
    return out
