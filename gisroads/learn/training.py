"""Training pixels for the road model: labelled tiles, the user's road layer, the image itself.

Three sources, each giving balanced, seeded feature samples ``X`` of shape
``(n_features, n)`` with labels ``y`` for :func:`~gisroads.learn.model.fit_model`
(training needs scikit-learn; prediction does not):

- :func:`tile_samples`: labelled tiles (the bundled model's ETH/EPFL tiles), each rescaled to
  several pixel sizes, colour-jittered and partly turned to one grey band, so one model
  serves 0.3-1.2 m RGB and panchromatic images;
- :func:`train_from_layer`: an image with an existing road layer over it (the agency case),
  positives from a core band along the lines, negatives beyond a guard band;
- :func:`adapt_to_image`: an image and a model, the model's most confident pixels as
  labels; a second model fitted to them (:func:`fit_to_image`) is blended with the first
  (self-adaptation to an image's sensor, season and pixel size);
  :func:`adapted_probability` gives the adapted model's probability of the image directly,
  computing the features once.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import geopandas as gpd
import numpy as np
import shapely
from rasterio import features as rio_features
from scipy import ndimage

from ..errors import GisroadsError, MissingFileError
from ..geo import LOCAL_CRS, GeoRaster, local_transform
from ..progress import Progress, report, scaled
from . import features as ft
from ..options import with_changes
from .model import (RoadModel, TreeOptions, WorkGrid, blend_models, fit_model,
                    image_probability, sigmoid, work_decision, work_probability)

TRAINING_PIXEL_M = (0.45, 0.6, 0.8, 1.0, 1.2)
"""Pixel sizes the labelled tiles are rescaled to, metres."""


def _sample(mask: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """Up to ``count`` flat indices of True pixels, without replacement."""
    index = np.flatnonzero(mask)
    if len(index) <= count:
        return index
    return np.sort(rng.choice(index, count, replace=False))


def grid_samples(grid: WorkGrid, positive: np.ndarray, negative: np.ndarray, count: int,
                 rng: np.random.Generator, *, tile_px: int = 512,
                 progress: Progress = None) -> tuple[np.ndarray, np.ndarray]:
    """Balanced feature samples of a work grid: up to ``count / 2`` positive and as many
    negative pixels, drawn at random over the whole grid and computed tile by tile.

    Parameters
    ----------
    grid : WorkGrid
    positive, negative : ndarray of bool, shape ``grid.shape``
        Candidate pixels of each class (invalid pixels are left out).
    count : int
        Samples wanted in all.

    Returns
    -------
    X : ndarray of float32, shape (n_features, n)
    y : ndarray of bool, shape (n,)
    """
    chosen = np.zeros(grid.shape, np.int8)
    half = max(1, count // 2)
    pos = _sample(positive, half, rng)
    neg = _sample(negative & ~positive, len(pos), rng)
    chosen.flat[pos], chosen.flat[neg] = 1, 2
    X, y = [], []
    tiles = list(grid.tiles(tile_px))
    for k, (r0, r1, c0, c1) in enumerate(tiles):
        report(progress, k / len(tiles), f"features of tile {k + 1} of {len(tiles)}")
        here = chosen[r0:r1, c0:c1]
        if not here.any():
            continue
        values, valid = grid.features(r0, r1, c0, c1)
        take = (here > 0) & valid
        X.append(values[:, take])
        y.append(here[take] == 1)
    if not X:
        return np.empty((len(ft.feature_names()), 0), np.float32), np.empty(0, bool)
    return np.concatenate(X, axis=1), np.concatenate(y)


def _rescale(values: np.ndarray, zoom: float, order: int) -> np.ndarray:
    """A 2-D array resampled by ``zoom`` (anti-aliased when shrinking)."""
    values = values.astype(np.float32)
    if zoom < 1 and order > 0:
        values = ndimage.gaussian_filter(values, 0.5 * (1 / zoom - 1) + 1e-3)
    return ndimage.zoom(values, zoom, order=order, mode="nearest", grid_mode=True)


def augment(rgb: np.ndarray, road: np.ndarray, source_pixel_m: float, pixel_m: float,
            rng: np.random.Generator, *, grey: bool) -> tuple[GeoRaster, np.ndarray]:
    """One augmented copy of a labelled RGB tile.

    The tile is resampled from ``source_pixel_m`` to ``pixel_m``, given a random gamma
    (0.75-1.33), per-band gains (+-15 %), an offset and noise, and when ``grey`` is set
    reduced to one band (a random positive mix of R, G, B: panchromatic sensors weigh the
    bands differently).

    Returns
    -------
    image : GeoRaster
        float32, 3 or 1 band(s), in a local metric CRS at ``pixel_m``.
    road : ndarray of bool
        The road mask on the same grid.
    """
    zoom = source_pixel_m / pixel_m
    bands = np.stack([_rescale(b, zoom, 1) for b in np.asarray(rgb, np.float32) / 255.0])
    mask = _rescale(np.asarray(road, np.float32), zoom, 1) > 0.5
    gamma = np.exp(rng.uniform(np.log(0.75), np.log(1.33)))
    gain = rng.uniform(0.85, 1.15, (3, 1, 1))
    bands = np.clip(bands, 0, 1) ** gamma * gain + rng.uniform(-0.05, 0.05)
    bands += rng.normal(0, 0.01, bands.shape)
    if grey:
        bands = np.tensordot(rng.dirichlet((4, 4, 4)), bands, axes=1)[None]
    bands = np.clip(bands, 0.0, 1.5).astype(np.float32)
    return GeoRaster(bands, local_transform(mask.shape, pixel_m), LOCAL_CRS), mask


def read_tiles(folder) -> list[tuple[np.ndarray, np.ndarray]]:
    """The labelled tiles of a folder with ``images/*.png`` and ``groundtruth/*.png`` (the
    ETH/EPFL layout): ``(rgb uint8 (3, rows, cols), road bool)`` pairs, road = value > 128.
    """
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning

    folder = Path(folder)
    paths = sorted((folder / "images").glob("*.png"))
    if not paths:
        raise MissingFileError(f"{folder}: no images/*.png")
    tiles = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        for path in paths:
            with rasterio.open(path) as src:
                rgb = src.read()[:3]
            with rasterio.open(folder / "groundtruth" / path.name) as src:
                road = src.read(1) > 128
            tiles.append((rgb, road))
    return tiles


def tile_samples(tiles, *, source_pixel_m: float = 0.6, pixel_sizes=TRAINING_PIXEL_M,
                 copies: int = 4, grey_share: float = 0.3, samples_per_copy: int = 600,
                 border_px: int = 1, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Balanced feature samples of labelled tiles, each augmented ``copies`` times.

    Parameters
    ----------
    tiles : sequence of (rgb, road)
        From :func:`read_tiles`.
    source_pixel_m : float
        Pixel size of the tiles, metres.
    pixel_sizes : sequence of float
        Each copy is rescaled to one of them at random, metres.
    copies : int
        Augmented copies per tile (see :func:`augment`).
    grey_share : float
        Share of the copies reduced to one band.
    samples_per_copy : int
        Samples per copy, half road.
    border_px : int
        Pixels next to the road border (mislabelled in masks) are not sampled.
    seed : int

    Returns
    -------
    X : ndarray of float32, shape (n_features, n)
    y : ndarray of bool, shape (n,)
    """
    rng = np.random.default_rng(seed)
    X, y = [], []
    for rgb, road in tiles:
        for _ in range(copies):
            pixel_m = float(rng.choice(pixel_sizes))
            image, mask = augment(rgb, road, source_pixel_m, pixel_m, rng,
                                  grey=rng.random() < grey_share)
            grid = WorkGrid(image)
            positive = ndimage.binary_erosion(mask, iterations=border_px)
            negative = ~ndimage.binary_dilation(mask, iterations=border_px)
            xs, ys = grid_samples(grid, positive, negative, samples_per_copy, rng)
            X.append(xs)
            y.append(ys)
    return np.concatenate(X, axis=1), np.concatenate(y)


@dataclass(frozen=True)
class LayerLabels:
    """How a road layer labels the pixels of a grid (:func:`line_labels`): each road's
    width, the guard band beside it and the core taught as road.

    Attributes
    ----------
    width_m : float, optional
        One width for every road, metres; else ``width_field`` or ``default_width_m``.
    width_field : str, optional
        Field holding each road's width in metres (empty or non-positive values take
        ``default_width_m``).
    default_width_m : float
        Width of a road without one, metres.
    guard_m : float
        No negative within ``width / 2 + guard_m`` of a line, metres (the guard absorbs
        misregistered lines and kerbs; OpenStreetMap lines are often 2-5 m off).
    core_fraction : float
        Positives within ``max(core_fraction * width / 2, pixel)`` of a line, in (0, 1].
    """

    width_m: float | None = None
    width_field: str | None = None
    default_width_m: float = 6.0
    guard_m: float = 5.0
    core_fraction: float = 0.5


def _road_widths(roads: gpd.GeoDataFrame, width_m, width_field, default_width_m) -> np.ndarray:
    if width_m is not None:
        return np.full(len(roads), float(width_m))
    if width_field is not None:
        if width_field not in roads.columns:
            raise GisroadsError(f"the road layer has no field {width_field!r}")
        widths = np.asarray(roads[width_field], float)
        return np.where(np.isfinite(widths) & (widths > 0), widths, default_width_m)
    return np.full(len(roads), float(default_width_m))


def layer_labels(grid: WorkGrid, roads: gpd.GeoDataFrame, labels: LayerLabels = LayerLabels(),
                 **changes) -> tuple[np.ndarray, np.ndarray]:
    """Positive and negative pixels of a work grid from road centre lines
    (:func:`line_labels` on the grid)."""
    return line_labels(roads, labels, shape=grid.shape, transform=grid.transform,
                       crs=grid.image.crs, pixel_m=grid.pixel_m, **changes)


def line_labels(roads: gpd.GeoDataFrame, labels: LayerLabels = LayerLabels(), *, shape,
                transform, crs, pixel_m: float, between_negative: bool = False,
                **changes) -> tuple[np.ndarray, np.ndarray]:
    """Positive and negative cells of a raster grid from road centre lines.

    A road of width ``w`` gives positives within ``max(core_fraction * w / 2, pixel_m)`` of
    its line and forbids negatives within ``w / 2 + guard_m`` of it (the guard absorbs
    misregistered lines and kerbs).

    Parameters
    ----------
    roads : GeoDataFrame
        (Multi)LineStrings; reprojected to ``crs`` when both are known.
    shape : (int, int)
        Rows and columns of the grid.
    transform : Affine
        The grid's transform (metres).
    crs : CRS or None
    pixel_m : float
        Cell side, metres.
    labels : LayerLabels
        Widths, guard band and core (:class:`LayerLabels`); ``**changes`` change its
        fields for this call.
    between_negative : bool
        Cells in the guard bands of two or more roads but beyond every road's edge (plus
        half a cell) are negatives too: the median between two carriageways, the verge
        between parallel roads, which the guard bands would otherwise swallow.

    Returns
    -------
    positive, negative : ndarray of bool, shape ``shape``
    """
    labels = replace(labels, **changes)
    guard_m, core_fraction = labels.guard_m, labels.core_fraction
    if guard_m < 0 or not 0 < core_fraction <= 1:
        raise GisroadsError("guard_m must be >= 0 and core_fraction in (0, 1]")
    if roads.crs is not None and crs is not None:
        roads = roads.to_crs(crs)
    lines = shapely.force_2d(np.asarray(roads.geometry.values, dtype=object))
    keep = ~(shapely.is_missing(lines) | shapely.is_empty(lines))
    kinds = set(shapely.get_type_id(lines[keep]).tolist())
    if not kinds <= {1, 5}:
        raise GisroadsError("the road layer must hold (Multi)LineStrings")
    if keep.any() and not np.isfinite(shapely.bounds(lines[keep])).all():
        # (rasterising infinite coordinates crashes GDAL)
        raise GisroadsError("the road layer's coordinates do not fit its CRS (metres "
                            "labelled as degrees?): give the layer its true CRS")
    widths = _road_widths(roads, labels.width_m, labels.width_field,
                          labels.default_width_m)[keep]
    lines = lines[keep]
    if len(lines) == 0:
        raise GisroadsError("the road layer has no line")
    core = shapely.buffer(lines, np.maximum(core_fraction * widths / 2, pixel_m))
    guard = shapely.buffer(lines, widths / 2 + guard_m)

    def burn(shapes, merge_alg=rio_features.MergeAlg.replace):
        return rio_features.rasterize(((g, 1) for g in shapes), out_shape=tuple(shape),
                                      transform=transform, fill=0, dtype=np.uint8,
                                      merge_alg=merge_alg)

    negative = burn(guard) == 0
    if between_negative:
        edge = burn(shapely.buffer(lines, widths / 2 + pixel_m / 2)) > 0
        negative |= (burn(guard, rio_features.MergeAlg.add) >= 2) & ~edge
    return burn(core) > 0, negative


ROAD_LAYER = "road layer"
"""``metadata["trained_on"]`` of a model of :func:`train_from_layer`."""


def trained_on_road_layer(model: RoadModel) -> bool:
    """Whether ``model`` was trained on an image's own road layer (:func:`train_from_layer`)."""
    return model.metadata.get("trained_on") == ROAD_LAYER


def train_from_layer(image: GeoRaster, roads: gpd.GeoDataFrame,
                     labels: LayerLabels = LayerLabels(), trees: TreeOptions = TreeOptions(),
                     *, samples: int = 100_000, base_samples=None, seed: int = 0,
                     tile_px: int = 512, road_share=None,
                     unmapped_probability: float | None = None, progress: Progress = None,
                     **changes) -> RoadModel:
    """Train a road model on an image from a road layer over it.

    Parameters
    ----------
    image : GeoRaster
        1-band or 3+-band image in a projected metre CRS.
    roads : GeoDataFrame
        Road centre lines (reprojected to the image's CRS); they need not be complete:
        missing roads fall among the negatives, a few per cent of them.
    labels : LayerLabels
        Widths, guard band and core of the layer's roads (:class:`LayerLabels`).
    trees : TreeOptions
        The boosted trees (:class:`~gisroads.learn.model.TreeOptions`).
    samples : int
        Samples drawn from the image, half road.
    base_samples : (X, y), optional
        Samples to train on as well (e.g. :func:`tile_samples` of the default model's
        tiles).
    seed : int
    tile_px : int
        Work-grid tile side of the feature computation.
    road_share : "default", "layer", float or None
        Share of road pixels the probabilities are calibrated to (see
        :func:`~gisroads.learn.model.fit_model`): ``"default"``, the bundled model's (its
        training tiles' road share, 0.20), so that the extraction's probability threshold,
        chosen for the bundled model, means the same for this model; ``"layer"``, the
        share of the image within the roads' half width (at least 1 %, at most 50 %); None
        (default) leaves the balanced samples' prior of 0.5. On the four scored
        Massachusetts tiles with 30 % of the roads (whole streets) deleted from the layer,
        one fit (``unmapped_probability=None``), extracted as ``gisroads image --model``
        (adapted, threshold 0.4), completeness of the deleted roads 0.808 with
        ``"default"`` against 0.659 with ``"layer"``
        (correctness on all roads 0.367 / 0.478; mean of two seeds, ``make bench``
        ``imagery_layer_training``, features and bundled model of 4a8d0a1; with those of
        4731bb6, 0.769 with ``"default"``, correctness 0.360; with the adaptation's 30 trees of
        1de21ba, 0.785 and 0.371): the layer's share (1 %
        there, clipped) left roads the layer lacks under the threshold.
    unmapped_probability : float or None
        Roads the layer lacks are no non-road samples: a first model fitted to the layer
        (calibrated like the bundled model) predicts the image, and no non-road sample is
        drawn within 3 m of the road-shaped parts (:func:`elongated`) it finds at this
        probability or more beyond the guard band; then the model is fitted again. None:
        one fit. On the Massachusetts tiles above (``road_share="default"``), extracted
        without adaptation (``adapt=False``) at 0.4: completeness of the deleted roads
        0.697 against 0.605 with one fit, correctness on all roads 0.577 / 0.639, quality
        0.522 / 0.552 (``imagery_layer_training``, 4a8d0a1's features; 4731bb6's: 0.681
        against 0.615, correctness 0.597 / 0.656; single runs move by up to 0.17 when the
        first fit's calibration moves from 0.2012 to 0.20, the mean by 0.02). In scratch
        runs: taking those parts as road samples as well, 0.748 / 0.564 / 0.507; adapted
        (``gisroads image --model``), 0.772 against 0.808, correctness 0.373 / 0.367. So
        it is off by default while ``gisroads image`` adapts every model; and trained on a
        whole layer it takes road-like surfaces the layer leaves out (the command-line
        test's synthetic scene: correctness 0.797, under the 0.8 that test asks for, in
        ``.venv-qgis``). Training takes about 3.5 times as long (7 s against 2 s on a
        1500 x 1500 tile at 1 m).
    progress : callable, optional
        ``progress(fraction, message)``; may raise :class:`gisroads.progress.Cancelled`.
    **changes
        Fields of ``labels`` or ``trees`` to change for this call, e.g.
        ``width_field="width_m"``.

    Raises
    ------
    ValueError
        Non-metric image, a layer without lines, bad widths, or no road pixel in the image.
    """
    labels, trees = with_changes(changes, labels, trees)
    # a second fit samples the tiles again: their features are kept for it
    grid = WorkGrid(image, cache_mb=0.0 if unmapped_probability is None else ADAPT_CACHE_MB)
    positive, negative = layer_labels(grid, roads, labels)
    if not positive.any():
        raise GisroadsError("no road of the layer lies on the image")
    surface, _ = layer_labels(grid, roads, labels, core_fraction=1.0)
    surface_share = float(surface[_on_work_grid(ft.valid_pixels(image), grid)].mean())
    if road_share == "default":
        road_share = _bundled_road_share()
    elif road_share == "layer":
        road_share = float(np.clip(surface_share, 0.01, 0.5))
    elif isinstance(road_share, str):
        raise GisroadsError(f"road_share must be 'default', 'layer', a share or None, not "
                            f"{road_share!r}")
    rng = np.random.default_rng(seed)
    report(progress, 0.0, "sampling road and non-road pixels")
    passes = 1 if unmapped_probability is None else 2
    X, y = grid_samples(grid, positive, negative, samples, rng, tile_px=tile_px,
                        progress=scaled(progress, 0.0, 0.8 / passes))
    unmapped = 0
    if unmapped_probability is not None:
        report(progress, 0.4, "looking for roads the layer lacks")
        first = fit_model(X, y, seed=seed, road_share=_bundled_road_share(), trees=trees)
        found = _unmapped_roads(grid, first, negative, unmapped_probability, tile_px=tile_px)
        unmapped = int(found.sum())
        if unmapped:
            X, y = grid_samples(grid, positive, negative & ~found, samples, rng,
                                tile_px=tile_px, progress=scaled(progress, 0.4, 0.8))
    if base_samples is not None:
        X = np.concatenate([X, np.asarray(base_samples[0], np.float32)], axis=1)
        y = np.concatenate([y, np.asarray(base_samples[1], bool)])
    meta = {"trained_on": ROAD_LAYER, "guard_m": labels.guard_m,
            "core_fraction": labels.core_fraction, "default_width_m": labels.default_width_m,
            "base_samples": base_samples is not None,
            "unmapped_probability": unmapped_probability, "unmapped_px": unmapped,
            "road_surface_share": surface_share}
    report(progress, 0.8, f"fitting the model on {len(y)} samples")
    model = fit_model(X, y, seed=seed, metadata=meta, road_share=road_share,
                      trees=trees)
    report(progress, 1.0, "model trained")
    return model


def _bundled_road_share() -> float:
    """The road share the bundled model is calibrated to."""
    from .model import load_model

    return load_model().metadata["calibrated_road_share"]


def _unmapped_roads(grid: WorkGrid, model: RoadModel, negative: np.ndarray, threshold: float,
                    *, tile_px: int, margin_m: float = 3.0) -> np.ndarray:
    """Work pixels within ``margin_m`` of the road-shaped parts (:func:`elongated`) of the
    ``negative`` pixels where ``model`` gives at least ``threshold``: roads a layer lacks."""
    probability = np.nan_to_num(work_probability(grid, model, tile_px=tile_px))
    found = elongated(negative & (probability >= threshold), grid.pixel_m)
    return ndimage.binary_dilation(found, iterations=max(1, round(margin_m / grid.pixel_m)))


def elongated(mask: np.ndarray, pixel_m: float, *, min_length_m: float = 30.0,
              max_width_m: float = 20.0) -> np.ndarray:
    """The connected parts of a mask shaped like roads: a skeleton of at least
    ``min_length_m`` and a mean width (area over skeleton length) of at most
    ``max_width_m``."""
    from skimage.morphology import skeletonize

    label, count = ndimage.label(mask, structure=np.ones((3, 3)))
    if count == 0:
        return mask
    area = np.bincount(label.ravel(), minlength=count + 1) * pixel_m ** 2
    length = np.bincount(label[skeletonize(mask)], minlength=count + 1) * pixel_m
    keep = (length >= min_length_m) & (area <= max_width_m * np.maximum(length, 1e-9))
    keep[0] = False
    return keep[label]


def _on_work_grid(mask: np.ndarray, grid: WorkGrid) -> np.ndarray:
    """An image-grid mask on a work grid: a work pixel is set when most of the image
    pixels it covers are."""
    f = grid.factor
    if mask.shape != grid.image.shape:
        raise GisroadsError(f"the mask {mask.shape} is not on the image grid "
                            f"{grid.image.shape}")
    if f == 1:
        return mask
    rows, cols = grid.shape
    padded = np.pad(mask.astype(np.float32),
                    ((0, rows * f - mask.shape[0]), (0, cols * f - mask.shape[1])))
    return padded.reshape(rows, f, cols, f).mean(axis=(1, 3)) > 0.5


POSITIVE_SHARE = 0.08
"""Share of an image's valid pixels the adaptation (:func:`fit_to_image`) takes as road
candidates, the most probable first."""
LAYER_POSITIVE_SHARE = (0.04, 0.3)
"""Bounds of :func:`layer_positive_share` (the upper one below the adaptation's non-road
share)."""


def layer_positive_share(model: RoadModel) -> float:
    """The adaptation's road share for a model trained on the image's road layer: the share
    of the image the layer's roads cover (``road_surface_share``), within
    :data:`LAYER_POSITIVE_SHARE`.

    The adaptation takes the most probable pixels as road. Where roads cover more of the
    image than :data:`POSITIVE_SHARE`, as in a city, that share holds only the most
    confident roads and the image's own model learns a narrower road than the layer's;
    where they cover less, it holds driveways, roofs and yards as well. Measured with
    ``make bench`` ``imagery_layer_training``: on the Massachusetts tiles (layers covering
    1-3 % of the tile, eight deletions each) completeness of the deleted roads 0.785 against
    0.780 with 0.08, correctness on all roads 0.380 against 0.352 (with the layer's share
    down to 0.01: 0.777, 0.427, but one tile at 0.696); SpaceNet Paris trained on all its
    OpenStreetMap lines (16 % of the image): completeness 0.491 against 0.367, correctness
    0.816 against 0.943 (shares of 0.10-0.20 give 0.40-0.71 there: one image, noisy).
    """
    share = model.metadata.get("road_surface_share")
    if share is None:  # trained before the share was recorded
        return POSITIVE_SHARE
    return float(np.clip(share, *LAYER_POSITIVE_SHARE))


def fit_to_image(grid: WorkGrid, probability: np.ndarray, model: RoadModel, *,
                 positive_share: float | None = None, negative_share: float = 0.5,
                 road_shaped: bool = True, road_like: np.ndarray | None = None,
                 samples: int = 40_000, seed: int = 0, tile_px: int = 512,
                 max_iter: int = 30, **fit_params) -> RoadModel | None:
    """An image's own model, fitted to the most confident pixels of ``model``.

    The ``positive_share`` of the image's valid pixels with the highest probability
    become road samples, the ``negative_share`` with the lowest non-road samples (shares,
    not probabilities, so that the choice does not depend on the model's calibration); with
    ``road_shaped``, only the road samples in connected parts shaped like roads
    (:func:`elongated`: on the 13 benchmark images this raised the mean held-out pixel AUC
    of the adapted default model from 0.742 to 0.751, 11 images up), and with
    ``road_like``, only those that an independent cue also takes for road surface.

    Parameters
    ----------
    grid : WorkGrid
        Of the image (give it a ``cache_mb`` to compute the sampled tiles' features only
        once: they were computed for ``probability``).
    probability : ndarray of float32, shape ``grid.shape``
        ``model``'s probability on the grid (:func:`~gisroads.learn.model.work_probability`),
        NaN where no data.
    model : RoadModel
        The model the new one is calibrated like (its ``calibrated_road_share``).
    positive_share, negative_share : float
        Shares of the image's valid pixels taken as road and non-road candidates;
        ``positive_share`` by default :data:`POSITIVE_SHARE`, or
        :func:`layer_positive_share` for a model trained on the image's road layer.
    road_shaped : bool
        Road samples only in road-shaped connected parts.
    road_like : ndarray of bool, shape ``grid.image.shape``, optional
        Pixels whose surface looks like road to a cue that does not share the model's
        errors (:func:`gisroads.imagery.baseline.road_colour_mask`: grey, neither shadow
        nor white). The model's confident errors under domain shift (forest gaps and
        shadows at 1 m, field margins) are not grey, so the adapted model does not learn
        them back: on the 13 benchmark images, mean held-out pixel AUC 0.799 against
        0.751 and mean quality through the network stage 0.270 against 0.185 (with
        ``positive_share`` 0.08 and a blend weight of 0.75; 0.04 and 0.5 gave 0.253). An
        image where fewer than 50 road samples pass it (no grey surface: a lawn, a field)
        keeps the model as it is: adapting to the model's own confident pixels there
        taught it noise, and a uniform lawn got roads.
    samples : int
        Samples drawn, half road.
    max_iter : int
        Trees of the image's own model: 30 found as much as 60 in half the time (figures in
        the CHANGELOG's history).
    seed, tile_px, **fit_params
        Of the sampling and :func:`~gisroads.learn.model.fit_model`.

    Returns
    -------
    RoadModel or None
        None when the image has too few confident pixels (road samples after the filters,
        or non-road samples).
    """
    if positive_share is None:
        positive_share = (layer_positive_share(model) if trained_on_road_layer(model)
                          else POSITIVE_SHARE)
    valid = np.isfinite(probability)
    if valid.sum() < 100:
        return None
    high, low = np.quantile(probability[valid], [1 - positive_share, negative_share])
    positive = valid & (probability >= high)
    if road_like is not None:
        positive &= _on_work_grid(np.asarray(road_like, bool), grid)
    if road_shaped:
        positive = elongated(positive, grid.pixel_m)
    negative = valid & (probability <= low)
    if positive.sum() < 50 or negative.sum() < 50:
        return None
    rng = np.random.default_rng(seed)
    X, y = grid_samples(grid, positive, negative, samples, rng, tile_px=tile_px)
    # calibrated like the model it is blended with
    return fit_model(X, y, seed=seed, max_iter=max_iter,
                     road_share=model.metadata.get("calibrated_road_share"),
                     metadata={"trained_on": "own confident pixels",
                               "road_like": road_like is not None,
                               "positive_share": positive_share}, **fit_params)


ADAPT_CACHE_MB = 256.0
"""Feature cache of the adaptation, megabytes (:class:`~gisroads.learn.model.WorkGrid`
``cache_mb``): with 49 float32 features, a work grid of up to 1.37 million pixels (a 1000 x
1000 image at 1 m, 2000 x 2000 at 0.3 m, read at 0.6 m) has its features computed once,
not once for the model's probability, once for the samples and once for the adapted
probability; on a larger image the tiles past the budget are computed again, so memory
stays bounded."""


def adapt_to_image(image: GeoRaster, model: RoadModel, *, weight: float = 0.75,
                   tile_px: int = 512, **options) -> RoadModel:
    """A model adapted to one image from the model's most confident pixels: the image's
    own model (:func:`fit_to_image`) blended with ``model``.

    Parameters
    ----------
    image : GeoRaster
    model : RoadModel
    weight : float
        Log-odds weight of the image's own model in the blend.
    tile_px : int
        Work-grid tile side of the feature computation.
    **options
        Keyword arguments of :func:`fit_to_image` (``road_like``, ``samples``, ...).

    Returns
    -------
    RoadModel
        The blend; ``model`` itself when the image has too few confident pixels.
    """
    grid = WorkGrid(image, cache_mb=ADAPT_CACHE_MB)
    own = fit_to_image(grid, work_probability(grid, model, tile_px=tile_px), model,
                       tile_px=tile_px, **options)
    return model if own is None else blend_models(model, own, weight)


ADAPT_WEIGHT = 1.0
"""Log-odds weight of the image's own model in the default path's probability
(:func:`adapted_probability`): 1, the image's own model alone, the bundled model only
choosing its samples. On the 13 benchmark images through the default path at 0.4 (issue
15, the 49-feature model of 4731bb6, 30-tree own model): mean quality 0.297 against 0.298
with a blend weight of 0.75 (0.295 with weight 1 and the samples chosen at every pixel),
mean held-out pixel AUC 0.815 against 0.810; per dataset Vegas 0.101 / 0.091, Paris
0.230 / 0.259, Massachusetts 0.302 / 0.298, DeepGlobe 0.030 / 0.037, ETH 0.453 / 0.451,
within what single images move between runs. The bundled model's trees then run on a
quarter of the pixels (:data:`SELECTION_STRIDE`): the 1000 x 1000 Massachusetts tile at 1 m
in 1.8-1.9 s against 2.7-3.2 s in the same process. A model trained on the image's own
road layer (:func:`train_from_layer`) has no domain to leave behind and keeps its share
(:data:`LAYER_MODEL_WEIGHT`)."""
LAYER_MODEL_WEIGHT = 0.75
"""Log-odds weight of the image's own model when the model given was trained on the
image's road layer: its extraction keeps 0.25 of that model's log-odds. With the own model
alone, the CLI test's synthetic scene, trained on its whole layer, loses correctness (0.76
against 0.80 or more), and so does SpaceNet Paris trained on its OpenStreetMap lines
(completeness 0.285 against 0.377, bench ``imagery_layer_training``)."""
SELECTION_STRIDE = 2
"""With :data:`ADAPT_WEIGHT` 1, the bundled model predicts every second pixel of the work
grid's rows and columns to choose the adaptation's samples (a road of 3 m and more at the
0.6-1 m work grid spans several such pixels)."""


def adapted_probability(image: GeoRaster, model: RoadModel, *, weight: float | None = None,
                        selection_stride: int = SELECTION_STRIDE, tile_px: int = 512,
                        progress: Progress = None, **options) -> GeoRaster:
    """The road probability of the model adapted to the image, the default path's
    (:func:`gisroads.imagery.pipeline.road_probability`).

    The features are computed once (:data:`ADAPT_CACHE_MB`). ``model``'s log-odds choose
    the samples of the image's own model (:func:`fit_to_image`), and the result is the
    log-odds blend ``(1 - weight) * model + weight * own``. With ``weight`` < 1 it equals
    ``predict_probability(image, adapt_to_image(image, model, weight=weight, ...))`` (the
    log-odds differ only in the order of their sums), ``model``'s trees evaluated once;
    with ``weight`` 1 the own model alone, and ``model``'s trees only on every
    ``selection_stride``-th pixel (:func:`~gisroads.learn.model.work_decision`). An image
    the own model cannot be fitted to (too few confident road-coloured pixels) gets
    ``model``'s probability.

    Parameters
    ----------
    image : GeoRaster
    model : RoadModel
    weight : float, optional
        Log-odds weight of the image's own model, in [0, 1]. Default: :data:`ADAPT_WEIGHT`,
        or :data:`LAYER_MODEL_WEIGHT` for a model trained on a road layer.
    selection_stride : int
        With ``weight`` 1, pixels between those ``model`` predicts to choose the samples.
    tile_px, **options
        As :func:`adapt_to_image`.
    progress : callable, optional
        ``progress(fraction, message)``; may raise :class:`gisroads.progress.Cancelled`.

    Returns
    -------
    GeoRaster
        As :func:`~gisroads.learn.model.predict_probability`.
    """
    if weight is None:
        weight = (LAYER_MODEL_WEIGHT if trained_on_road_layer(model)
                  else ADAPT_WEIGHT)
    if not 0 <= weight <= 1:
        raise GisroadsError(f"weight must be in [0, 1], not {weight}")
    grid = WorkGrid(image, cache_mb=ADAPT_CACHE_MB)
    stride = selection_stride if weight == 1 else 1
    report(progress, 0.0, "road probability of the model")
    log_odds = work_decision(grid, model, tile_px=tile_px, stride=stride)
    report(progress, 0.4, "fitting the model to the image")
    own = fit_to_image(grid, sigmoid(log_odds).astype(np.float32), model, tile_px=tile_px,
                       **options)
    if own is None:
        if stride > 1:
            log_odds = work_decision(grid, model, tile_px=tile_px)
    else:
        report(progress, 0.6, "road probability of the adapted model")
        own_log_odds = work_decision(grid, own, tile_px=tile_px)
        log_odds = (own_log_odds if weight == 1 else
                    (1 - weight) * log_odds + weight * own_log_odds)
    report(progress, 1.0, "road probability")
    return image_probability(grid, sigmoid(log_odds).astype(np.float32))
