"""Grote & Rottensteiner's road extraction from an aerial image, as a composition of stages.

NCut over-segmentation (:mod:`gisroads.imagery.segments`) -> grouping, with the splitting of
branching segments (:mod:`gisroads.imagery.grouping`) -> road-part shape filtering
(:mod:`gisroads.imagery.roadparts`) -> subgraph generation and the integer program over gap
edges (:mod:`gisroads.network.subgraph`) -> road strings to a network with junctions
(:mod:`gisroads.network.junctions`). Each stage is a function of its own; this module only
chains them and times them.

Distances are metres: the stages' defaults are the paper's (its images had 8-10 cm pixels),
expressed in metres, so they hold at the input's pixel size; the segment counts, which the
paper set per image, follow the image's ground area.

Beyond the papers: a learned road probability (by default the bundled convolutional
network, :mod:`gisroads.learn.convnet`; with ``model="boosted"`` the boosted trees of
:mod:`gisroads.learn`, adapted to each image from its own most confident pixels, then
re-scored from its own shape by the context model, :mod:`gisroads.learn.context`). By default
(:data:`DEFAULT_METHOD`) it goes alone through the shared network stage
(:func:`gisroads.network.rasters.raster_to_network`), the better of the measured paths;
with ``method="grote-rottensteiner"`` it runs the papers' stages, where it is an NCut
affinity term (:func:`gisroads.imagery.segments.segment_image`, ``probability``) and a
grouping criterion (:func:`gisroads.imagery.grouping.group_segments`), replaces the colour
tests of the road parts (:func:`gisroads.imagery.roadparts.filter_road_parts`,
``probability_min``) and the radiometric context of the gaps (the mean probability along a
gap, :func:`gisroads.network.subgraph.link_road_parts`). ``model=None`` is the papers'
pipeline alone. BLAS and OpenMP thread pools are pinned (``threads``, default one) for the
whole run, whatever the environment says: oversubscribed pools made the segmentation
collapse on a loaded machine.

An image of more than ``2 * TILE_PX`` pixels a side runs the papers' stages tile by tile
(:func:`image_tiles`: the tiles of :mod:`gisroads.tiling.tiles`, overlapping by
:data:`TILE_OVERLAP_M`), the tiles' road strings stitched at the seams as the LiDAR tiles'
centre lines are, then one network stage (junctions, significance) over the whole image.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely

from ..errors import GisroadsError
from ..geo import GeoRaster, RoadNetwork
from ..tiling.tiles import Tile, clip_to_core, stitch_tiles, tile_grid
from ..progress import Progress, report, scaled
from .cues import context_rasters, image_cues, valid_mask
from .datasets import crop_raster
from .grouping import group_segments
from ..network.junctions import NetworkOptions, strings_to_network
from .roadparts import RoadPartCriteria, extract_road_parts
from .segments import edge_strength, pixel_size_m, segment_image
from ..parallel import pinned_threads
from ..network.subgraph import GapOptions, WeightOptions, link_road_parts

METHOD = "grote-rottensteiner"
PROBABILITY_METHOD = "learned-probability"
"""``method`` of the probability path (the learned cue through the shared network stage)."""
PROBABILITY_THRESHOLD = 0.4
"""Road threshold of the probability path: on the 13 benchmark images (``make bench``,
``imagery_real``) the adapted default model (49 features, seed 0) gives mean quality
0.294 / 0.297 / 0.284 at 0.3 / 0.4 / 0.5, the same features trained with seed 1 0.287 /
0.279 / 0.286: the thresholds are within the training's seed noise (about 0.015) of each
other. At 0.4 and 0.5 Massachusetts is above its naive baseline at both seeds (0.290 and
0.285 at 0.4 against 0.273), at 0.3 not at seed 1 (0.271). Not adapted: 0.189 / 0.193 /
0.168. The 42-feature model before it (24 m lines only): 0.270 / 0.270 / 0.257. With the
image's own model alone, 0.297 / 0.297 / 0.296; re-scored by the context model (the default
since, calibrated for this threshold), 0.352 / 0.353 / 0.336."""
DEFAULT_METHOD = PROBABILITY_METHOD
"""The path :func:`extract_image_roads` takes when given a model and no ``method``: the
probability alone through the network stage (on real images it scores above the papers'
stages fed the same probability; docs/imagery.md gives the figures)."""
LAYER_NETWORK_SHARE = 0.5
"""A model trained on the image's own road layer (:func:`gisroads.learn.training.train_from_layer`)
is not used alone: its probability is averaged with the bundled convolutional network's, this
share the network's, and thresholded at the network's threshold. The trees have learnt this
image's roads, the network what a road looks like anywhere; alone the trees also mark the
lots and roofs of road colour. Chosen on the 25 held-out Massachusetts crops with at least
1.2 km of road (``validation.txt``; 30 % of each crop's roads deleted from the layer, two
seeds; centre lines against the masks' skeletons, 3 m): deleted roads found / correctness /
quality 0.592 / 0.596 / 0.461 with the trees alone (hysteresis to 0.7 of their 0.4), 0.590 /
0.813 / 0.555 with the network alone, 0.641 / 0.796 / 0.627 averaged; averaged with that
hysteresis 0.662 / 0.691 / 0.555, at 0.35 0.673 / 0.693 / 0.565.

The network's own roads are added where the average lacks them
(:func:`gisroads.network.rasters.with_missing_roads`): a layer being updated lacks roads, the
trees learn their absence as non-road and the average loses them, while the network alone
still sees them. On the same crops: 0.672 / 0.772 / 0.624 against 0.641 / 0.796 / 0.627
(the average alone); the same found share as taking the larger of the network's and the
average's probability (0.667 / 0.762 / 0.612), at a higher correctness. Trees trained with
the network's roads kept out of their non-road samples: 0.636 / 0.786 / 0.612."""

IMAGE_THRESHOLD_PERCENTILE = 98.0
IMAGE_THRESHOLD_SHARE = 0.6
IMAGE_THRESHOLD_FLOOR = 0.15
"""The convolutional network's threshold is lowered on an image where it is unsure of
itself: to ``IMAGE_THRESHOLD_SHARE`` of the image's ``IMAGE_THRESHOLD_PERCENTILE`` th
probability percentile when that is below the model's threshold, never below
``IMAGE_THRESHOLD_FLOOR`` (:func:`image_threshold`). Chosen on the 98 held-out training tiles
with roads (``validation.txt``, two views, centre lines scored against the masks' skeletons,
3 m): mean quality 0.450 with the model's 0.45 alone; percentile 97 / 98 / 98.5 / 99 / 99.5 /
99.8 at share 0.6: 0.464 / 0.464 / 0.463 / 0.461 / 0.455 / 0.452; at 98, share 0.5 / 0.6 / 0.7
(percentile 99) 0.461 / 0.461 / 0.458, floor 0.1 / 0.15 / 0.2 (percentile 99.5) alike. Per
source at 98 / 0.6: ETH CIL 0.635 and CIL 2022 0.467 unchanged, Massachusetts 0.423 -> 0.451,
Dubai 0.260 -> 0.251. Hysteresis instead (the mask grown to 0.5 or 0.7 of the threshold):
0.445, 0.450."""


TILE_PX = 1000
"""Tile side of the papers' stages on a large image, pixels: an image with more than
``2 * TILE_PX`` rows or columns runs tile by tile (:func:`image_tiles`), so the stages'
memory (a few float rasters per tile and the segmentation's arrays) stays that of a tile."""
TILE_OVERLAP_M = 100.0
"""Overlap of neighbouring tiles, metres (the LiDAR paper's, :mod:`gisroads.tiling.tiles`):
each core sees 50 m of context on every side, more than the longest gap edge
(:data:`gisroads.network.subgraph.MAX_GAP_M`, 40 m); at most a third of a tile."""


MODEL_NAMES = ("default", "boosted", "none")
"""Names ``model`` takes besides a file: ``"default"`` the bundled convolutional network
(:mod:`gisroads.learn.convnet`), ``"boosted"`` the bundled boosted trees
(:mod:`gisroads.learn.model`), ``"none"`` no learned cue (the papers' stages alone)."""


def resolve_model(model):
    """The learned road cue of ``model``: a :class:`gisroads.learn.convnet.ConvNet` for
    ``"default"`` or an ``.onnx`` file, a :class:`gisroads.learn.RoadModel` for
    ``"boosted"`` or an ``.npz`` file, None for ``None`` or ``"none"``; a model is returned
    as it is."""
    from ..learn.convnet import ConvNet, is_convnet_file, load_convnet
    from ..learn.model import RoadModel, load_model

    if model is None or isinstance(model, (RoadModel, ConvNet)):
        return model
    if isinstance(model, (str, Path)):
        name = str(model).lower()
        if name == "none":
            return None
        if name == "default":
            return load_convnet()
        if name == "boosted":
            return load_model()
        if not Path(model).is_file():
            raise GisroadsError(f"{model}: no such road model file (give an .onnx or .npz "
                                "written by 'gisroads train', or one of "
                                f"{', '.join(MODEL_NAMES)})")
        return load_convnet(model) if is_convnet_file(model) else load_model(model)
    raise TypeError(f"model must be a road model, a path or one of {MODEL_NAMES}, "
                    f"not {model!r}")


def default_threshold(model) -> float:
    """The probability path's road threshold for ``model``: the convolutional network's
    own (chosen on held-out tiles, in its metadata), also for boosted trees trained on a
    road layer (:data:`LAYER_NETWORK_SHARE`), else :data:`PROBABILITY_THRESHOLD`."""
    from ..learn.convnet import ConvNet, load_convnet

    if isinstance(model, ConvNet):
        return model.threshold
    return load_convnet().threshold if _layer_trees(model) else PROBABILITY_THRESHOLD


def _layer_trees(model) -> bool:
    """Whether ``model`` is boosted trees trained on an image's own road layer."""
    from ..learn.model import RoadModel
    from ..learn.training import trained_on_road_layer

    return isinstance(model, RoadModel) and trained_on_road_layer(model)


def image_threshold(probability: GeoRaster, threshold: float) -> float:
    """The road threshold of one image's network probability: ``threshold``, or lower where
    the image's :data:`IMAGE_THRESHOLD_PERCENTILE` th percentile shows the network unsure
    of this image (an unfamiliar sensor or landscape): :data:`IMAGE_THRESHOLD_SHARE` of that
    percentile, at least :data:`IMAGE_THRESHOLD_FLOOR`.

    Parameters
    ----------
    probability : GeoRaster
        Road probability in [0, 1], NaN where the image has no data.
    threshold : float
        The model's threshold.

    Examples
    --------
    >>> import numpy as np
    >>> from affine import Affine
    >>> from gisroads.geo import GeoRaster
    >>> from gisroads.imagery.pipeline import image_threshold
    >>> sure = GeoRaster(np.r_[np.zeros(90), np.ones(10)].reshape(10, 10), Affine.identity(),
    ...                  None)
    >>> image_threshold(sure, 0.45)
    0.45
    >>> unsure = GeoRaster(sure.data * 0.5, sure.transform, None)
    >>> round(image_threshold(unsure, 0.45), 2)
    0.3
    """
    values = np.asarray(probability.data, np.float32)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return float(threshold)
    unsure = IMAGE_THRESHOLD_SHARE * float(np.percentile(values, IMAGE_THRESHOLD_PERCENTILE))
    return float(min(threshold, max(IMAGE_THRESHOLD_FLOOR, unsure)))


def resolve_context(context, model):
    """The context model (:mod:`gisroads.learn.context`) to re-score ``model``'s
    probability with: for ``"default"`` the bundled one, unless ``model`` was trained on a
    road layer (:func:`gisroads.learn.training.train_from_layer`: it has learnt the image's
    own roads, and the context model was trained on the probabilities of models trained on
    labelled tiles); None for ``None`` or ``"none"``; else a path or a model."""
    from ..learn.context import load_context_model
    from ..learn.model import RoadModel

    if context is None or isinstance(context, RoadModel):
        return context
    if str(context).lower() == "none":
        return None
    if str(context).lower() == "default":
        if not isinstance(model, RoadModel) or _layer_trees(model):
            return None
        return load_context_model()
    if not Path(context).is_file():
        raise GisroadsError(f"{context}: no such context model file (give a .npz written by "
                            "scripts/train_context_model.py, 'default' or 'none')")
    return load_context_model(context)


def road_probability(image: GeoRaster, model="default", *, adapt: bool = True,
                     context="default", progress: Progress = None) -> GeoRaster:
    """The learned road probability of an image (float32 in [0, 1], NaN where no data).

    The convolutional network (``"default"``, :func:`gisroads.learn.convnet.convnet_probability`)
    is applied as it is: ``adapt`` and ``context`` are for the boosted trees
    (``"boosted"``). There ``adapt`` adapts the model to the image from its own most confident
    pixels first
    (:func:`gisroads.learn.training.adapted_probability`, needs scikit-learn; without it
    the model is used as it is), taking as road samples only those of road colour
    (:func:`gisroads.imagery.baseline.road_colour_mask`), the naive baseline's cue: the
    model's confident errors on other sensors are not grey. ``context`` then re-scores the
    probability from its own shape (:func:`gisroads.learn.context.context_probability`;
    :func:`resolve_context`: by default the bundled context model, except for a model
    trained on a road layer). Boosted trees trained on a road layer are averaged with the
    bundled network (:data:`LAYER_NETWORK_SHARE`)."""
    from ..learn.convnet import ConvNet, convnet_probability

    model = resolve_model(model)
    if model is None:
        raise GisroadsError("no model")
    if isinstance(model, ConvNet):
        return convnet_probability(image, model, progress=progress)
    if not _layer_trees(model):
        return _trees_probability(image, model, adapt=adapt,
                                  context=resolve_context(context, model), progress=progress)
    return layer_probabilities(image, model, adapt=adapt, progress=progress)[1]


def layer_probabilities(image: GeoRaster, model, *, adapt: bool = True,
                        progress: Progress = None) -> tuple[GeoRaster, GeoRaster]:
    """The bundled network's road probability of an image, and its average with boosted
    trees trained on the image's road layer (``model``; :data:`LAYER_NETWORK_SHARE`)."""
    from ..learn.convnet import convnet_probability

    network = convnet_probability(image, progress=scaled(progress, 0.0, 0.5))
    trees = _trees_probability(image, model, adapt=adapt, context=None,
                               progress=scaled(progress, 0.5, 1.0))
    return network, replace(trees, data=(LAYER_NETWORK_SHARE * network.data + (
        1 - LAYER_NETWORK_SHARE) * trees.data).astype(np.float32))


def _trees_probability(image: GeoRaster, model, *, adapt: bool, context,
                       progress: Progress) -> GeoRaster:
    """The boosted trees' probability of :func:`road_probability`, adapted to the image
    and re-scored by the ``context`` model (a model or None)."""
    from importlib.util import find_spec

    from ..learn.context import context_probability
    from ..learn.model import predict_probability
    from .baseline import road_colour_mask

    first = progress if context is None else scaled(progress, 0.0, 0.85)
    if adapt and find_spec("sklearn") is not None:
        from ..learn.training import adapted_probability
        probability = adapted_probability(image, model, road_like=road_colour_mask(image),
                                          progress=first)
    else:
        report(first, 0.0, "road probability")
        probability = predict_probability(image, model)
        report(first, 1.0, "road probability")
    if context is None:
        return probability
    report(progress, 0.85, "road probability from its context")
    probability = context_probability(probability, context)
    report(progress, 1.0, "road probability")
    return probability


class ImageRoads(NamedTuple):
    """Result of :func:`extract_image_roads`."""

    network: RoadNetwork
    """The contract layers; ``qa`` holds ``segments``, ``road_parts``, ``gap_edges`` and
    ``junction_connections`` (the probability path: ``gap_edges``,
    ``junction_connections`` and ``rejected``)."""
    report: dict
    """``timings_s`` per stage, ``cues`` (:meth:`ImageCues.record`), counts, ``method``
    and ``probability`` (the learned road probability as a :class:`GeoRaster`, or None)."""


@dataclass(frozen=True)
class ImageOptions:
    """The options of :func:`extract_image_roads` beyond its inputs and model: the bands'
    roles, the path and its threshold, the papers' stages (segments, criteria, gaps,
    network, tiles), the boosted trees' adaptation and context model, the threads.

    Attributes
    ----------
    nir_band, red_band : int, optional
        1-based; a NIR band adds the NDVI factor to the segmentation, the NDVI test of the
        road parts and vegetation as gap context.
    method : str, optional
        ``"grote-rottensteiner"`` (the papers' stages, with the probability as road-part
        criterion and gap context when there is one) or ``"learned-probability"`` (the
        probability alone through :func:`gisroads.network.rasters.raster_to_network` at
        ``probability_threshold``; needs a model). Default: :data:`DEFAULT_METHOD` with a
        model, the papers' stages without one.
    probability_threshold : float, optional
        See ``method``; by default the model's own (:func:`default_threshold`), for the
        convolutional network lowered on an image it is unsure of (:func:`image_threshold`;
        not for one fine-tuned on the image's road layer).
    n_segments : int, optional
        NCut over-segmentation size; default
        :func:`gisroads.imagery.segments.default_counts`.
    road_part_criteria : RoadPartCriteria, optional
        The papers' stages: the criteria of
        :func:`gisroads.imagery.roadparts.filter_road_parts`; None: its defaults.
    gap_options : GapOptions, optional
        The papers' stages: the limits of a gap edge
        (:func:`gisroads.network.subgraph.gap_edges`); None: its defaults.
    weight_options : WeightOptions, optional
        The papers' stages: the weights of the gap edges
        (:func:`gisroads.network.subgraph.edge_weights`); None: its defaults.
    network_options : NetworkOptions, optional
        The papers' stages: the network generation
        (:func:`gisroads.network.junctions.strings_to_network`); None: its defaults.
    adapt : bool
        Adapt boosted trees to the image from its own confident pixels first
        (scikit-learn).
    context : "default", "none", str, Path or RoadModel
        The context model that re-scores the probability on the probability path
        (:func:`road_probability`, :func:`resolve_context`); the papers' stages take the
        model's probability as it is (their thresholds were set on it).
    tile_px : int
        The papers' stages run tile by tile on an image with more than ``2 * tile_px`` rows
        or columns (tiles of ``tile_px`` overlapping by :data:`TILE_OVERLAP_M`, road strings
        stitched at the seams, then one network stage over the whole image; QA layers get
        a ``tile`` column; ``n_segments`` then counts per tile). The probability path tiles
        in its own network stage.
    threads : int or None
        BLAS/OpenMP threads during the run (:func:`pinned_threads`).
    """

    nir_band: int | None = None
    red_band: int | None = None
    method: str | None = None
    probability_threshold: float | None = None
    n_segments: int | None = None
    road_part_criteria: RoadPartCriteria | None = None
    gap_options: GapOptions | None = None
    weight_options: WeightOptions | None = None
    network_options: NetworkOptions | None = None
    adapt: bool = True
    context: object = "default"
    tile_px: int = TILE_PX
    threads: int | None = 1


def extract_image_roads(image: GeoRaster, options: ImageOptions = ImageOptions(), *,
                        dsm: GeoRaster | None = None, model="default",
                        probability: GeoRaster | None = None, progress: Progress = None,
                        **changes) -> ImageRoads:
    """The road network of an aerial image (RGB, CIR or panchromatic; NIR and DSM optional).

    Parameters
    ----------
    image : GeoRaster
        ``(bands, rows, cols)`` in a projected CRS in metres; NaN or nodata = no data.
    dsm : GeoRaster, optional
        Surface heights (metres), any grid over the image: adds the height criterion of the
        grouping, the nDSM test of the road parts and buildings as gap context.
    model : ConvNet, RoadModel, str or Path, optional
        The learned road cue (beyond the papers): ``"default"`` (the bundled convolutional
        network), ``"boosted"`` (the bundled boosted trees), a model file written by
        ``gisroads train`` (``.onnx`` or ``.npz``), a model, or ``None`` / ``"none"`` for
        the papers' pipeline alone (:func:`resolve_model`).
    probability : GeoRaster, optional
        A road probability already computed on the image's grid (then ``model``,
        ``adapt`` and ``context`` are not used).
    options : ImageOptions
        The bands, the path, the threshold, the papers' stages and the boosted trees
        (:class:`ImageOptions`).
    progress : callable, optional
        ``progress(fraction, message)``; may raise :class:`gisroads.progress.Cancelled`.
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    ImageRoads
        An empty network (valid, with its QA layers) when no road is found.

    Examples
    --------
    A synthetic scene's orthoimage (R, G, B, NIR at 0.5 m) and DSM:

    >>> import numpy as np
    >>> from gisroads.evaluate import buffer_metrics
    >>> from gisroads.imagery import extract_image_roads
    >>> from gisroads.synthetic import make_scene, render_image
    >>> scene = make_scene(seed=0, size_m=(300, 300))
    >>> image, dsm = render_image(scene, pixel_m=0.5)
    >>> result = extract_image_roads(image)   # the bundled network, then the network stage
    >>> result.report["method"]
    'learned-probability'
    >>> probability = result.report["probability"]        # a GeoRaster on the image's grid
    >>> probability.shape == image.shape, bool(np.nanmax(probability.data) <= 1.0)
    (True, True)
    >>> len(result.network.centrelines) > 0
    True
    >>> papers = extract_image_roads(image, model="none", nir_band=4, dsm=dsm)
    >>> papers.report["method"]                  # Grote & Rottensteiner's stages alone
    'grote-rottensteiner'
    >>> sorted(papers.network.qa)
    ['gap_edges', 'junction_connections', 'road_parts', 'segments']
    >>> scores = buffer_metrics(papers.network.centrelines, scene.truth.centrelines)
    >>> scores.completeness > 0.6, scores.correctness > 0.8
    (True, True)
    """
    options = replace(options, **changes)
    with pinned_threads(options.threads):
        return _extract(image, options, dsm=dsm, model=model, probability=probability,
                        progress=progress)


def _convnet_of_tiles(model) -> bool:
    """Whether ``model`` is a convolutional network trained on labelled tiles (not yet
    fine-tuned on an image's own road layer, whose threshold knows that image)."""
    from ..learn.convnet import ConvNet
    from ..learn.training import ROAD_LAYER

    return isinstance(model, ConvNet) and model.metadata.get("trained_on") != ROAD_LAYER


def _model_name(model) -> str | None:
    """How the summary names a model: the convolutional network's file name, or
    ``"boosted"``."""
    from ..learn.convnet import ConvNet

    if model is None:
        return None
    if isinstance(model, ConvNet):
        return model.path.name
    return "boosted, road layer + network" if _layer_trees(model) else "boosted"


class _StageClock:
    """``lap(stage)`` adds the seconds since the last lap (or start) to ``timings[stage]``:
    a stage run in several tiles sums their times."""

    def __init__(self, timings: dict):
        self.timings = timings
        self.restart()

    def restart(self) -> None:
        self.clock = time.perf_counter()

    def __call__(self, stage: str) -> None:
        now = time.perf_counter()
        self.timings[stage] = self.timings.get(stage, 0.0) + now - self.clock
        self.clock = now


def _extract(image, options: ImageOptions, *, dsm, model, probability,
             progress) -> ImageRoads:
    nir_band, red_band = options.nir_band, options.red_band
    method, probability_threshold = options.method, options.probability_threshold
    if image.crs is not None and not image.crs.is_projected:
        raise GisroadsError("the image must be in a projected CRS in metres (reproject it, "
                            "e.g. to its UTM zone)")
    timings = {}
    lap = _StageClock(timings)
    model = resolve_model(model)
    per_image = probability_threshold is None and _convnet_of_tiles(model)
    if probability_threshold is None:
        probability_threshold = default_threshold(model)
    method = method or (DEFAULT_METHOD if probability is not None or model is not None
                        else METHOD)
    if method not in (METHOD, PROBABILITY_METHOD):
        raise GisroadsError(f"method must be {METHOD!r} or {PROBABILITY_METHOD!r}, "
                            f"not {method!r}")
    # the papers' stages take the first-stage probability: their thresholds were set on it
    context = (resolve_context(options.context, model)
               if probability is None and model is not None and method == PROBABILITY_METHOD
               else None)
    network_probability = None
    if probability is None and _layer_trees(model):
        network_probability, probability = layer_probabilities(
            image, model, adapt=options.adapt, progress=scaled(progress, 0.0, 0.15))
        lap("probability")
    elif probability is None and model is not None:
        probability = road_probability(image, model, adapt=options.adapt, context=context,
                                       progress=scaled(progress, 0.0, 0.15))
        lap("probability")
    elif probability is not None and probability.shape != image.shape:
        raise GisroadsError(f"the probability {probability.shape} is not on the image grid "
                            f"{image.shape}")
    if method == PROBABILITY_METHOD:
        if probability is None:
            raise GisroadsError(f"method {PROBABILITY_METHOD!r} needs a model")
        from ..network.rasters import raster_to_network, with_missing_roads
        if per_image:
            probability_threshold = image_threshold(probability, probability_threshold)
        end = 1.0 if network_probability is None else 0.6
        network = raster_to_network(probability, threshold=probability_threshold,
                                    method=PROBABILITY_METHOD, wide_areas=True,
                                    progress=scaled(progress, 0.15, end))
        if network_probability is not None:
            own = raster_to_network(network_probability, threshold=probability_threshold,
                                    method=PROBABILITY_METHOD, wide_areas=True,
                                    progress=scaled(progress, end, 0.9))
            network = with_missing_roads(network, own.centrelines, probability,
                                         method=PROBABILITY_METHOD,
                                         progress=scaled(progress, 0.9, 1.0))
        lap("network")
        network.centrelines["cues"] = "model"
        timings["total"] = sum(timings.values())
        return ImageRoads(network, {
            "timings_s": timings, "method": method, "probability": probability,
            "cues": {"cues": "model", "model": True}, "context_model": context is not None,
            "threshold": probability_threshold,
            "model": _model_name(model),
            "gap_edges": len(network.qa["gap_edges"]),
            "roads": len(network.centrelines)})
    base = 0.15 if "probability" in timings else 0.0
    progress = scaled(progress, base, 1.0)
    stages = dict(nir_band=nir_band, red_band=red_band, dsm=dsm, n_segments=options.n_segments,
                  road_part_criteria=options.road_part_criteria or RoadPartCriteria(),
                  gap_options=options.gap_options or GapOptions(),
                  weight_options=options.weight_options or WeightOptions())
    tile_px = options.tile_px
    if max(image.shape) > 2 * tile_px:
        strings, qa, record, counts = _tiled_road_strings(
            image, probability, tile_px=tile_px, timings=timings,
            progress=scaled(progress, 0.0, 0.85), **stages)
    else:
        strings, qa, record, counts = _road_strings(
            image, probability, timings=timings, progress=scaled(progress, 0.0, 0.85),
            **stages)
    lap.restart()  # the tiled stages kept their own times
    network, connections = strings_to_network(strings,
                                              options.network_options or NetworkOptions(),
                                              extent=image.bounds, crs=image.crs, method=METHOD,
                                              progress=scaled(progress, 0.85, 1.0))
    lap("network")
    network.centrelines["cues"] = record["cues"]
    network.qa = {**qa, "junction_connections": connections}
    timings["total"] = sum(timings.values())
    report(progress, 1.0, f"{len(network.centrelines)} roads")
    gaps = qa["gap_edges"]
    return ImageRoads(network, {
        "timings_s": timings, "method": METHOD, "probability": probability,
        "cues": record, **counts, "gap_edges": len(gaps),
        "selected_gaps": int(gaps["selected"].sum()) if len(gaps) else 0,
        "roads": len(network.centrelines)})


def _road_strings(image: GeoRaster, probability: GeoRaster | None, *, nir_band, red_band,
                  dsm, n_segments, road_part_criteria: RoadPartCriteria,
                  gap_options: GapOptions, weight_options: WeightOptions, timings: dict,
                  progress: Progress):
    """The papers' stages up to the road strings on one image (or tile): ``(strings, qa,
    cues record, counts)``; each stage's seconds are added to ``timings``."""
    lap = _StageClock(timings)
    report(progress, 0.0, "image cues")
    cues = image_cues(image, nir_band=nir_band, red_band=red_band, dsm=dsm)
    if probability is not None:
        cues = replace(cues, probability=np.asarray(probability.data, np.float32))
    # one local-energy pass for the three stages that weigh edges
    edges = edge_strength(image, nir_band=nir_band, bands=cues.bands)
    lap("cues")
    labels = segment_image(image, nir_band=nir_band, red_band=red_band,
                           n_segments=n_segments, edge_magnitude=edges,
                           probability=cues.probability,
                           progress=scaled(progress, 0.02, 0.45))
    lap("segmentation")
    report(progress, 0.45, "grouping segments")
    labels = group_segments(labels, image, dsm=dsm, ndvi=cues.ndvi, nir_band=nir_band,
                            edge_magnitude=edges, probability=cues.probability,
                            progress=scaled(progress, 0.45, 0.65))
    lap("grouping")
    parts = extract_road_parts(labels, image, cues=cues, edge_magnitude=edges,
                               criteria=road_part_criteria,
                               progress=scaled(progress, 0.65, 0.88))
    lap("road_parts")
    context = context_rasters(cues)
    if cues.probability is not None:
        context["probability"] = cues.probability
    gaps, strings = link_road_parts(parts.road_parts, transform=image.transform,
                                    **context, gap_options=gap_options,
                                    weight_options=weight_options,
                                    progress=scaled(progress, 0.88, 1.0))
    lap("subgraphs")
    qa = {"segments": parts.segments, "road_parts": parts.road_parts, "gap_edges": gaps}
    counts = {"segments": int(np.max(labels)) + 1, "road_parts": len(parts.road_parts)}
    return strings, qa, cues.record(), counts


def image_tiles(image: GeoRaster, tile_px: int = TILE_PX) -> list[tuple[Tile, tuple]]:
    """The tiles the papers' stages run in on a large image: the LiDAR tiles
    (:func:`gisroads.tiling.tiles.tile_grid`) of ``tile_px`` pixels overlapping by
    :data:`TILE_OVERLAP_M` (in whole pixels, at most a third of a tile), each with its pixel
    window
    ``(rows, cols)`` (slices, cut to the image); tiles without a valid pixel are left out.

    Parameters
    ----------
    image : GeoRaster
        North-up, in a projected CRS in metres.
    tile_px : int
        Tile side, pixels.
    """
    transform = image.transform
    if transform.b != 0 or transform.d != 0:
        raise GisroadsError("tiling needs a north-up image (no rotation in its transform)")
    # whole pixels, so that tile and core borders fall on pixel borders
    overlap_px = min(round(TILE_OVERLAP_M / pixel_size_m(image)), tile_px // 3)
    tile_m, overlap_m = tile_px * image.pixel_size, overlap_px * image.pixel_size
    valid = valid_mask(image)
    tiles = []
    for tile in tile_grid(image.bounds, tile_m=tile_m, overlap_m=overlap_m):
        xmin, ymin, xmax, ymax = tile.bounds
        rows = np.round((np.array([ymax, ymin]) - transform.f) / transform.e).astype(int)
        cols = np.round((np.array([xmin, xmax]) - transform.c) / transform.a).astype(int)
        window = tuple(slice(max(0, int(ends.min())), min(n, int(ends.max())))
                       for ends, n in ((rows, image.shape[0]), (cols, image.shape[1])))
        if valid[window].any():
            tiles.append((tile, window))
    return tiles


def _cut_to_core(frame: gpd.GeoDataFrame, tile: Tile) -> gpd.GeoDataFrame:
    """A tile's QA layer cut to the tile's core: lines as the stitched strings are
    (:func:`gisroads.tiling.tiles.clip_to_core`), polygons to their polygonal parts inside
    (a segment along the core's border leaves no line or point behind)."""
    if len(frame) == 0 or not frame.geom_type.isin(["Polygon", "MultiPolygon"]).all():
        return clip_to_core(frame, tile)
    clipped = shapely.intersection(frame.geometry.values, shapely.box(*tile.core))
    parts, owner = shapely.get_parts(clipped, return_index=True)
    area = (shapely.get_type_id(parts) == 3) & ~shapely.is_empty(parts)  # Polygon
    kept = np.unique(owner[area])
    polygons = shapely.multipolygons(parts[area], indices=np.searchsorted(kept, owner[area]))
    single = shapely.get_num_geometries(polygons) == 1
    polygons[single] = shapely.get_geometry(polygons[single], 0)
    kept_rows = frame.iloc[kept]
    return kept_rows.set_geometry(gpd.GeoSeries(polygons, index=kept_rows.index,
                                                crs=frame.crs))


def _tiled_road_strings(image: GeoRaster, probability: GeoRaster | None, *, tile_px: int,
                        timings: dict, progress: Progress, **stages):
    """:func:`_road_strings` tile by tile (:func:`image_tiles`), the tiles' road strings
    stitched as the LiDAR tiles' centre lines are (:func:`gisroads.tiling.tiles.stitch_tiles`:
    clipped to the cores, seam ends joined, pieces of one road merged), the QA layers cut
    to the cores with a ``tile`` column (ids are per tile)."""
    tiles = image_tiles(image, tile_px)
    if not tiles:
        raise GisroadsError("the image has no valid pixel")
    pieces, qa, counts, record = [], {}, {"segments": 0, "road_parts": 0}, None
    for k, (tile, (rows, cols)) in enumerate(tiles):
        report(progress, k / len(tiles), f"tile {k + 1} of {len(tiles)}")
        strings, tile_qa, record, tile_counts = _road_strings(
            crop_raster(image, rows, cols),
            None if probability is None else crop_raster(probability, rows, cols),
            timings=timings, progress=scaled(progress, k / len(tiles), (k + 1) / len(tiles)),
            **stages)
        pieces.append((tile, strings))
        for name, frame in tile_qa.items():
            qa.setdefault(name, []).append(_cut_to_core(frame.assign(tile=k), tile))
        counts = {key: counts[key] + tile_counts[key] for key in counts}
    report(progress, 1.0, "stitching tiles")
    qa = {name: gpd.GeoDataFrame(pd.concat(frames, ignore_index=True), crs=image.crs)
          for name, frames in qa.items()}
    return stitch_tiles(pieces), qa, record, {**counts, "tiles": len(tiles)}
