"""The road-probability model: gradient-boosted trees in a documented numpy archive.

A model is trained with scikit-learn's ``HistGradientBoostingClassifier`` (:func:`fit_model`;
training needs scikit-learn) and then exported to plain node arrays that this module
evaluates with numpy alone (:meth:`RoadModel.predict`), so prediction needs no scikit-learn
and gives the same probabilities whatever scikit-learn (or none) is installed.

File format (:func:`save_model`, :func:`load_model`): a ``.npz`` archive read with
``allow_pickle=False``, holding

=================  ===========  ===========================================================
key                dtype        meaning
=================  ===========  ===========================================================
``format``         str          ``"gisroads-road-model"``
``version``        int          :data:`MODEL_VERSION`; any other version is refused
``feature``        int16 (N,)   feature tested at each node (0 at leaves)
``threshold``      float64 (N)  a sample goes right when its feature is ``> threshold``
``left``           int32 (N,)   index of the left child; the right child is ``left + 1``;
                                a leaf points to itself (threshold ``+inf``)
``missing_left``   bool (N,)    NaN goes left (True) or right; True at leaves
``value``          float64 (N)  leaf contribution to the log-odds (0 at inner nodes)
``roots``          int32 (T,)   root node of each tree
``depth``          int          deepest leaf (levels of traversal)
``baseline``       float64      log-odds before the trees
``feature_names``  str (F,)     :func:`~gisroads.learn.features.feature_names`, or
                                :func:`~gisroads.learn.context.context_feature_names`
                                for a context model
``scales_m``       float64      :data:`~gisroads.learn.features.SCALES_M`, then
                                ``COLOUR_SCALES_M``, ``CONTEXT_M``, ``WORK_PIXEL_M``,
                                ``TRUNCATE``: a model is refused when they differ from
                                the library's
``metadata``       str          JSON: training data, parameters, scores
=================  ===========  ===========================================================

The probability of a pixel is ``1 / (1 + exp(-(baseline + sum of its leaf values)))``,
exactly scikit-learn's ``predict_proba[:, 1]`` for the exported classifier.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from affine import Affine

from ..errors import GisroadsError
from ..geo import GeoRaster
from . import features as ft

MODEL_FORMAT = "gisroads-road-model"
MODEL_VERSION = 1
DEFAULT_MODEL_PATH = Path(__file__).resolve().parent / "models" / "default_road_model.npz"
"""The bundled default model (see ``default_road_model.md`` beside it)."""
_CELLS = 1 << 16
"""Tree-node cells (trees x pixels) evaluated at a time (fits a core's cache)."""


def _scales() -> np.ndarray:
    return np.array([*ft.SCALES_M, *ft.COLOUR_SCALES_M, ft.CONTEXT_M, ft.WORK_PIXEL_M,
                     ft.TRUNCATE], np.float64)


@dataclass(frozen=True)
class RoadModel:
    """Boosted trees as node arrays (see the module docstring for each field)."""

    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    missing_left: np.ndarray
    value: np.ndarray
    roots: np.ndarray
    depth: int
    baseline: float
    feature_names: tuple[str, ...]
    metadata: dict = field(default_factory=dict)

    @property
    def n_trees(self) -> int:
        return len(self.roots)

    @property
    def tree_depth(self) -> np.ndarray:
        """Levels from each tree's root to its deepest leaf."""
        return _tree_depths(self.left, self.roots, self.depth)

    def decision(self, X: np.ndarray) -> np.ndarray:
        """Log-odds of road for samples ``X`` of shape ``(n_features, n)``, float64."""
        X = np.asarray(X)
        if X.ndim != 2 or X.shape[0] != len(self.feature_names):
            raise GisroadsError(f"expected features of shape ({len(self.feature_names)}, n), "
                                f"got {X.shape}")
        n = X.shape[1]
        out = np.full(n, self.baseline, np.float64)
        # deepest trees first: at level k only the first active[k] trees still move
        tree_depth = self.tree_depth
        order = np.argsort(-tree_depth, kind="stable")
        roots = self.roots[order].astype(np.int64)
        active = (tree_depth[order][None, :] > np.arange(self.depth)[:, None]).sum(axis=1)
        left = self.left.astype(np.int64)
        # float32 features against float32 thresholds rounded down: x > t exactly when
        # x > t32 for every float32 x, and faster than comparing in float64
        threshold = self.threshold.astype(np.float32)
        threshold = np.where(threshold > self.threshold, np.nextafter(threshold, -np.inf),
                             threshold).astype(np.float32)
        chunk = max(64, _CELLS // max(self.n_trees, 1))
        for start in range(0, n, chunk):
            x = np.ascontiguousarray(X[:, start:start + chunk], dtype=np.float32)
            m = x.shape[1]
            flat = x.ravel()
            offset = np.arange(m, dtype=np.int64)
            feature_at = self.feature.astype(np.int64) * m
            node = np.repeat(roots[:, None], m, axis=1)
            missing = bool(np.isnan(flat).any())
            for k in active:
                moving = node[:k]
                v = flat.take(feature_at.take(moving) + offset)
                right = v > threshold.take(moving)
                if missing:
                    right = np.where(np.isnan(v), ~self.missing_left.take(moving), right)
                node[:k] = left.take(moving) + right
            out[start:start + m] += self.value.take(node).sum(axis=0)
        return out

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Road probability of samples ``X`` of shape ``(n_features, n)``, float64."""
        return sigmoid(self.decision(X))


def sigmoid(log_odds: np.ndarray) -> np.ndarray:
    """Probability of log-odds, ``1 / (1 + exp(-log_odds))`` (NaN stays NaN)."""
    return 1.0 / (1.0 + np.exp(-log_odds))


def from_sklearn(classifier, feature_names, *, metadata=None) -> RoadModel:
    """Export a fitted binary ``HistGradientBoostingClassifier`` to a :class:`RoadModel`.

    Raises
    ------
    ValueError
        Not binary, categorical splits, or feature names of the wrong length.
    """
    if len(classifier.classes_) != 2 or classifier.n_trees_per_iteration_ != 1:
        raise GisroadsError("only binary classifiers can be exported")
    if classifier.n_features_in_ != len(feature_names):
        raise GisroadsError(f"the classifier has {classifier.n_features_in_} features, "
                            f"{len(feature_names)} names given")
    parts = {k: [] for k in ("feature", "threshold", "left", "missing_left", "value")}
    roots, depth, start = [], 0, 0
    for (predictor,) in classifier._predictors:
        nodes = predictor.nodes
        if np.any(nodes["is_categorical"]):
            raise GisroadsError("categorical splits cannot be exported")
        # breadth-first order puts the two children of a node side by side
        order = [0]
        for node in order:
            if not nodes["is_leaf"][node]:
                order += [int(nodes["left"][node]), int(nodes["right"][node])]
        order = np.array(order)
        new = np.empty(len(nodes), np.int64)
        new[order] = np.arange(len(order)) + start
        tree = nodes[order]
        leaf = tree["is_leaf"].astype(bool)
        parts["feature"].append(np.where(leaf, 0, tree["feature_idx"]).astype(np.int16))
        parts["threshold"].append(np.where(leaf, np.inf, tree["num_threshold"]))
        parts["left"].append(np.where(leaf, np.arange(len(order)) + start,
                                      new[tree["left"]]).astype(np.int32))
        parts["missing_left"].append(leaf | tree["missing_go_to_left"].astype(bool))
        parts["value"].append(np.where(leaf, tree["value"], 0.0))
        roots.append(start)
        depth = max(depth, int(tree["depth"].max()))
        start += len(order)
    arrays = {k: np.concatenate(v) for k, v in parts.items()}
    return _checked(RoadModel(**arrays, roots=np.array(roots, np.int32), depth=depth,
                              baseline=float(np.ravel(classifier._baseline_prediction)[0]),
                              feature_names=tuple(feature_names),
                              metadata=dict(metadata or {})))


def _tree_depths(left: np.ndarray, roots: np.ndarray, levels: int) -> np.ndarray:
    """Depth of each tree (-1 when a tree is not all leaves after ``levels`` levels)."""
    depth = np.zeros(len(roots), np.int64)
    frontier = [np.array([r]) for r in roots]
    for level in range(levels + 1):
        for t, nodes in enumerate(frontier):
            inner = nodes[left[nodes] != nodes]
            if len(inner):
                depth[t] = level + 1
            frontier[t] = np.concatenate([left[inner], left[inner] + 1])
    depth[[len(f) > 0 for f in frontier]] = -1
    return depth


def _checked(model: RoadModel) -> RoadModel:
    n = len(model.feature)
    if not (len(model.threshold) == len(model.left) == len(model.missing_left)
            == len(model.value) == n) or n == 0:
        raise GisroadsError("the model's node arrays differ in length or are empty")
    if model.feature.min() < 0 or model.feature.max() >= len(model.feature_names):
        raise GisroadsError("the model tests features it does not name")
    leaf = model.left == np.arange(n)
    if (model.left.min() < 0 or model.left[~leaf].max(initial=0) + 1 >= n
            or model.roots.min(initial=0) < 0 or model.roots.max(initial=0) >= n):
        raise GisroadsError("the model's node links point outside it")
    if not (0 <= model.depth <= 64) or not np.all(np.isinf(model.threshold[leaf])):
        raise GisroadsError("the model's tree depth or leaves are invalid")
    if (model.tree_depth < 0).any():
        raise GisroadsError("the model's trees are deeper than it states")
    return model


def save_model(model: RoadModel, path) -> Path:
    """Write a model to a ``.npz`` archive (module docstring); returns the path."""
    path = Path(path)
    with open(path, "wb") as stream:
        np.savez_compressed(
            stream, format=np.array(MODEL_FORMAT), version=np.array(MODEL_VERSION),
            feature=model.feature.astype(np.int16), threshold=model.threshold,
            left=model.left.astype(np.int32), missing_left=model.missing_left,
            value=model.value, roots=model.roots.astype(np.int32),
            depth=np.array(model.depth), baseline=np.array(model.baseline),
            feature_names=np.array(model.feature_names), scales_m=_scales(),
            metadata=np.array(json.dumps(model.metadata, sort_keys=True)))
    return path


def load_model(path=None, *, feature_names=None) -> RoadModel:
    """Read a model written by :func:`save_model` (the bundled default when ``path`` is
    None), never unpickling anything.

    ``feature_names`` are those the model must use (default: the image features,
    :func:`~gisroads.learn.features.feature_names`).

    Raises
    ------
    ValueError
        Not a gisroads road model, another format version, features that differ from this
        library's, or inconsistent node arrays.
    """
    path = DEFAULT_MODEL_PATH if path is None else Path(path)
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {key: archive[key] for key in archive.files}
    except (OSError, ValueError) as error:
        if isinstance(error, FileNotFoundError):
            raise
        raise GisroadsError(f"{path}: not a road model archive ({error})") from None
    if "format" not in arrays or str(arrays["format"]) != MODEL_FORMAT:
        raise GisroadsError(f"{path}: not a {MODEL_FORMAT} archive")
    version = int(arrays["version"])
    if version != MODEL_VERSION:
        raise GisroadsError(f"{path}: road model version {version}; this gisroads reads "
                            f"version {MODEL_VERSION} (retrain it)")
    names = tuple(str(n) for n in arrays["feature_names"])
    expected = ft.feature_names() if feature_names is None else tuple(feature_names)
    if names != expected or not np.array_equal(arrays["scales_m"], _scales()):
        raise GisroadsError(f"{path}: the model was trained on other features than this "
                            "gisroads computes (retrain it)")
    return _checked(RoadModel(
        feature=arrays["feature"].astype(np.int16), threshold=arrays["threshold"].astype(float),
        left=arrays["left"].astype(np.int32), missing_left=arrays["missing_left"].astype(bool),
        value=arrays["value"].astype(float), roots=arrays["roots"].astype(np.int32),
        depth=int(arrays["depth"]), baseline=float(arrays["baseline"]), feature_names=names,
        metadata=json.loads(str(arrays["metadata"]))))


@dataclass(frozen=True)
class TreeOptions:
    """The boosted trees of :func:`fit_model`.

    Attributes
    ----------
    max_iter, max_leaf_nodes, max_depth, learning_rate, min_samples_leaf, l2_regularization
        ``HistGradientBoostingClassifier`` parameters (prediction time grows with
        ``max_iter * max_depth``).
    """

    max_iter: int = 80
    max_leaf_nodes: int = 31
    max_depth: int = 6
    learning_rate: float = 0.15
    min_samples_leaf: int = 200
    l2_regularization: float = 1.0


def fit_model(X: np.ndarray, y: np.ndarray, trees: TreeOptions = TreeOptions(), *,
              seed: int = 0, road_share: float | None = None, threads: int = 1,
              metadata=None, feature_names=None, **changes) -> RoadModel:
    """Train boosted trees on feature samples (needs scikit-learn).

    Parameters
    ----------
    X : ndarray, shape (n_features, n)
        Feature samples (:func:`~gisroads.learn.features.compute_features` columns).
    y : ndarray of bool, shape (n,)
        Road (True) or not.
    feature_names : sequence of str, optional
        Names of the rows of ``X``; default :func:`~gisroads.learn.features.feature_names`.
    seed : int
        ``random_state`` of the classifier (early stopping is off, so the fit is
        deterministic for a given scikit-learn).
    trees : TreeOptions
        The trees (:class:`TreeOptions`).
    road_share : float, optional
        Share of road pixels the probabilities are calibrated to: balanced samples
        (half road) give a prior of 0.5, far above a real image's; the log-odds are shifted
        by ``logit(road_share) - logit(share of road samples)``. None: no shift.
    threads : int
        OpenMP threads of the fit (pinned with threadpoolctl).
    metadata : dict, optional
        Stored with the model; the parameters are added.
    **changes
        Fields of ``trees`` to change for this call.
    """
    from sklearn.ensemble import HistGradientBoostingClassifier
    from threadpoolctl import threadpool_limits

    names = ft.feature_names() if feature_names is None else tuple(feature_names)
    X = np.asarray(X, np.float32)
    y = np.asarray(y, bool)
    if X.ndim != 2 or X.shape[0] != len(names) or X.shape[1] != len(y):
        raise GisroadsError(f"expected X of shape ({len(names)}, n) and y of "
                            f"shape (n,), got {X.shape} and {y.shape}")
    if y.all() or not y.any():
        raise GisroadsError("training needs both road and non-road samples")
    params = asdict(replace(trees, **changes))
    classifier = HistGradientBoostingClassifier(**params, early_stopping=False,
                                                random_state=seed)
    with threadpool_limits(limits=threads):
        classifier.fit(X.T, y)
    meta = {**(metadata or {}), "parameters": {**params, "seed": seed},
            "samples": int(len(y)), "sample_road_share": float(y.mean()),
            "calibrated_road_share": road_share}
    model = from_sklearn(classifier, names, metadata=meta)
    if road_share is None:
        return model
    if not 0 < road_share < 1:
        raise GisroadsError(f"road_share must lie in (0, 1), got {road_share}")
    shift = _logit(road_share) - _logit(float(y.mean()))
    return replace(model, baseline=model.baseline + shift)


def _logit(p: float) -> float:
    return float(np.log(p / (1 - p)))


def blend_models(first: RoadModel, second: RoadModel, weight: float) -> RoadModel:
    """One model whose log-odds are ``(1 - weight) * first + weight * second``."""
    if first.feature_names != second.feature_names:
        raise GisroadsError("the models use different features")
    offset = len(first.feature)
    return _checked(RoadModel(
        feature=np.concatenate([first.feature, second.feature]),
        threshold=np.concatenate([first.threshold, second.threshold]),
        left=np.concatenate([first.left, second.left + offset]).astype(np.int32),
        missing_left=np.concatenate([first.missing_left, second.missing_left]),
        value=np.concatenate([(1 - weight) * first.value, weight * second.value]),
        roots=np.concatenate([first.roots, second.roots + offset]).astype(np.int32),
        depth=max(first.depth, second.depth),
        baseline=(1 - weight) * first.baseline + weight * second.baseline,
        feature_names=first.feature_names,
        metadata={"blend": {"weight": weight, "first": first.metadata,
                            "second": second.metadata}}))


class WorkGrid:
    """An image read tile by tile on its working grid (block-averaged towards
    :data:`~gisroads.learn.features.WORK_PIXEL_M`), with per-image statistics.

    Parameters
    ----------
    image : GeoRaster
        1-band or 3+-band image (bands past the third ignored) in a projected metre CRS.
    cache_mb : float
        Keep the features of each window :meth:`features` returns, so that a second
        request of the same window does not compute them again, while the kept features
        take at most this many megabytes (float32, ``n_features x rows x cols`` of the
        grid's cores); 0 keeps none. Windows asked for after the budget is spent are
        computed each time, so memory stays bounded on any image.

    Attributes
    ----------
    factor : int
        Image pixels per work pixel along each axis.
    pixel_m : float
        Work pixel side, metres.
    shape : (rows, cols)
        Of the work grid.
    stats : ImageStatistics
    """

    def __init__(self, image: GeoRaster, *, cache_mb: float = 0.0):
        pixel = ft.metric_pixel_size(image)
        ft.rgb_bands(np.asarray(image.data)[..., :1, :1])  # band count check
        self.image = image
        self.factor = ft.work_factor(pixel)
        self.pixel_m = pixel * self.factor
        rows, cols = image.shape
        self.shape = (-(-rows // self.factor), -(-cols // self.factor))
        self.halo = ft.halo_px(self.pixel_m)
        step = max(1, self.shape[0] // 256)
        sample = [self.bands(r, r + 1, 0, self.shape[1]) for r in range(0, self.shape[0], step)]
        self.stats = ft.image_statistics(np.concatenate([b for b, _ in sample], axis=1),
                                         np.concatenate([v for _, v in sample]))
        self._cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self._cache_left = int(cache_mb * 2 ** 20)

    @property
    def transform(self) -> Affine:
        t = self.image.transform
        return Affine(t.a * self.factor, 0.0, t.c, 0.0, t.e * self.factor, t.f)

    def bands(self, r0: int, r1: int, c0: int, c1: int) -> tuple[np.ndarray, np.ndarray]:
        """Work-grid bands and valid mask of the window ``[r0:r1, c0:c1]``."""
        f = self.factor
        window = GeoRaster(np.asarray(self.image.data)[..., r0 * f:r1 * f, c0 * f:c1 * f],
                           self.image.transform, self.image.crs, self.image.nodata)
        return ft.block_mean(ft.rgb_bands(window.data), ft.valid_pixels(window), f)

    def features(self, r0: int, r1: int, c0: int, c1: int
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Features ``(n_features, rows, cols)`` and valid mask of a work window, computed
        with a halo so that they equal those of the whole image (read-only arrays when
        kept in the cache, see ``cache_mb``)."""
        key = (r0, r1, c0, c1)
        if key in self._cache:
            return self._cache[key]
        rows, cols = self.shape
        h0, h1 = max(0, r0 - self.halo), min(rows, r1 + self.halo)
        k0, k1 = max(0, c0 - self.halo), min(cols, c1 + self.halo)
        bands, valid = self.bands(h0, h1, k0, k1)
        values = ft.compute_features(bands, valid, self.pixel_m, self.stats)
        core = (slice(r0 - h0, r1 - h0), slice(c0 - k0, c1 - k0))
        values, valid = values[(slice(None), *core)], valid[core]
        if values.nbytes <= self._cache_left:
            # a copy of the core, so that the halo's features are freed
            values, valid = np.ascontiguousarray(values), valid.copy()
            values.flags.writeable = valid.flags.writeable = False
            self._cache[key] = values, valid
            self._cache_left -= values.nbytes
        return values, valid

    def tiles(self, tile_px: int):
        """Work windows ``(r0, r1, c0, c1)`` of at most ``tile_px`` square covering the
        grid."""
        if tile_px < 1:
            raise GisroadsError("tile_px must be positive")
        rows, cols = self.shape
        for r0 in range(0, rows, tile_px):
            for c0 in range(0, cols, tile_px):
                yield r0, min(r0 + tile_px, rows), c0, min(c0 + tile_px, cols)

    def to_image(self, work: np.ndarray) -> np.ndarray:
        """A work-grid array spread back onto the image grid (each work pixel to the
        ``factor x factor`` pixels it covers)."""
        f = self.factor
        rows, cols = self.image.shape
        if f == 1:
            return work
        return np.repeat(np.repeat(work, f, axis=0), f, axis=1)[:rows, :cols]


def work_decision(grid: WorkGrid, model: RoadModel, *, tile_px: int = 512,
                  stride: int = 1) -> np.ndarray:
    """Log-odds of road on a :class:`WorkGrid` (:meth:`RoadModel.decision`), float64, NaN
    where no data.

    With ``stride`` > 1 the model predicts every ``stride``-th pixel of each tile's rows
    and columns (``1 / stride ** 2`` of the trees' work) and each value stands for its
    ``stride`` x ``stride`` block (a pixel without data in a block with some keeps NaN)."""
    out = np.full(grid.shape, np.nan, np.float64)
    for r0, r1, c0, c1 in grid.tiles(tile_px):
        values, valid = grid.features(r0, r1, c0, c1)
        if stride > 1:
            sampled = np.full(valid[::stride, ::stride].shape, np.nan)
            picked = valid[::stride, ::stride]
            sampled[picked] = model.decision(values[:, ::stride, ::stride][:, picked])
            blocks = np.repeat(np.repeat(sampled, stride, 0), stride, 1)
            out[r0:r1, c0:c1] = np.where(valid, blocks[:r1 - r0, :c1 - c0], np.nan)
            continue
        # a tile with data everywhere is read as it lies (selecting costs 20 ms a tile)
        X = values.reshape(len(values), -1) if valid.all() else values[:, valid]
        out[r0:r1, c0:c1][valid] = model.decision(X)
    return out


def work_probability(grid: WorkGrid, model: RoadModel, *, tile_px: int = 512) -> np.ndarray:
    """Road probability on a :class:`WorkGrid`, float32, NaN where no data."""
    return sigmoid(work_decision(grid, model, tile_px=tile_px)).astype(np.float32)


def image_probability(grid: WorkGrid, work: np.ndarray) -> GeoRaster:
    """A work-grid probability (:func:`work_probability`) as a float32 raster on the grid's
    image, NaN where the image has no data (see :func:`predict_probability`)."""
    image = grid.image
    probability = np.where(ft.valid_pixels(image), grid.to_image(work), np.float32(np.nan))
    return GeoRaster(probability.astype(np.float32, copy=False), image.transform, image.crs,
                     float("nan"))


def predict_probability(image: GeoRaster, model: RoadModel | None = None, *,
                        tile_px: int = 512) -> GeoRaster:
    """Road probability of every pixel of an image, tile by tile.

    Parameters
    ----------
    image : GeoRaster
        1-band (panchromatic) or 3+-band image (the first three taken as R, G, B), any
        numeric dtype, in a projected metre CRS with square north-up pixels.
    model : RoadModel, optional
        The bundled default (:func:`load_model`) when None.
    tile_px : int
        Tile side on the work grid; tiles overlap by the features' reach, so the result
        does not depend on it, and memory grows with ``tile_px ** 2``, not the image.

    Returns
    -------
    GeoRaster
        float32 probabilities in [0, 1] on the image's grid, NaN where it has no data
        (images finer than 0.45 m are predicted on a grid of about 0.6 m and each value
        spread over the pixels it covers).

    Raises
    ------
    ValueError
        Geographic or unit-less CRS, rotated pixels, 2-band image, no valid pixel.
    """
    model = load_model() if model is None else model
    grid = WorkGrid(image)
    return image_probability(grid, work_probability(grid, model, tile_px=tile_px))


def with_metadata(model: RoadModel, **entries) -> RoadModel:
    """The model with entries added to its metadata."""
    return replace(model, metadata={**model.metadata, **entries})
