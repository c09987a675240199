"""A road likelihood learned from the user's own road layer (beyond the paper).

The evidence rule (:mod:`gisroads.lidar.evidence`) sets its membership ramps by the physics
of the measurements, the same for every cloud. Where a road layer of the area exists (the
road-database update), the layer says what this cloud's roads look like: boosted trees
(:func:`gisroads.learn.model.fit_model`) are fitted on the evidence's measures per cell, with
the layer's centre lines as labels (:func:`gisroads.learn.training.line_labels`: a core
along each line is road, cells beyond its edge and a guard band are not; the guard absorbs
misregistered lines), and their probability replaces the rule's likelihood in the network
stage (:func:`gisroads.lidar.pipeline.extract_roads` with ``model=``). A layer has errors
(roads it lacks, fakes, lines off their road): only cells where the layer and the rule
agree are labelled (:data:`OFF_LAYER_ROAD`, :data:`ON_LAYER_BARE`), so the model learns
what this cloud's roads look like and not the layer's mistakes.

The features of a cell (:data:`EVIDENCE_FEATURES`) are the rule's likelihood and the raw
measures of every cue (NaN where the cloud lacks a cue: the trees send it one way), and
three of them averaged over a neighbourhood (the likelihood and the intensity over 2 m,
the vehicle cells over 4 m), which tell an aisle between parked cars from a street.
Figures: ``docs/lidar.md``.
"""
from __future__ import annotations

from pathlib import Path

import geopandas as gpd
import numpy as np
from scipy import ndimage

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..learn.model import RoadModel, fit_model, load_model, save_model, with_metadata
from ..learn.training import ROAD_LAYER, line_labels
from .evidence import RoadEvidence, vehicle_cells

#: The measures of :func:`gisroads.lidar.evidence.road_evidence` the model reads, in order.
MEASURES = ("height", "density", "pulses", "roughness", "slope", "intensity", "returns",
            "classification", "kerbs")
#: Neighbourhood means (Gaussian sigma, metres) of the likelihood, intensity and vehicles.
CONTEXT_SIGMA_M = {"likelihood": 2.0, "intensity": 2.0, "vehicles": 4.0}
EVIDENCE_FEATURES = ("likelihood", *MEASURES,
                     *(f"{name}_{sigma:g}m" for name, sigma in CONTEXT_SIGMA_M.items()))
"""Feature names of an evidence model, in the order of :func:`evidence_features`."""
#: Labels only where the layer and the rule agree: off the layer, cells the rule calls road
#: (its network threshold) are a road the layer lacks, not a negative; on the layer, cells
#: the rule gives less than this are a fake or misregistered line, not a positive. Chosen
#: on synthetic road-database updates (two scenes, five edits each: deleted, fake, shifted
#: and re-widened roads), against labelling every cell.
OFF_LAYER_ROAD = 0.8
ON_LAYER_BARE = 0.3
#: A learned likelihood goes through the network stage at this threshold (the trees'
#: probability is fitted on balanced samples, so 0.5 is the decision boundary).
MODEL_THRESHOLD = 0.5
MODEL_KIND = "lidar-evidence"
"""``metadata["kind"]`` of an evidence model."""


def _nan_gaussian(values: np.ndarray, sigma_cells: float) -> np.ndarray:
    """Gaussian mean of the finite cells (NaN where none is near)."""
    known = np.isfinite(values)
    total = ndimage.gaussian_filter(np.where(known, values, 0.0), sigma_cells)
    weight = ndimage.gaussian_filter(known.astype(np.float64), sigma_cells)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 1e-3, total / weight, np.nan)


def evidence_features(evidence: RoadEvidence) -> np.ndarray:
    """The features of every cell of a cloud's evidence.

    Parameters
    ----------
    evidence : RoadEvidence
        :func:`gisroads.lidar.evidence.road_evidence` of a cloud or tile.

    Returns
    -------
    ndarray, shape (len(EVIDENCE_FEATURES), rows, cols), float32
        NaN where a cue has no value (outside the data, or a cue the cloud lacks).
    """
    likelihood = np.asarray(evidence.likelihood.data, np.float64)
    shape = likelihood.shape
    missing = np.full(shape, np.nan)
    measures = [np.asarray(evidence.measures[name].data, np.float64)
                if name in evidence.measures else missing for name in MEASURES]
    context = {"likelihood": likelihood,
               "intensity": measures[MEASURES.index("intensity")],
               "vehicles": np.asarray(vehicle_cells(evidence).data, np.float64)}
    smoothed = [_nan_gaussian(context[name], sigma / evidence.cell_m)
                for name, sigma in CONTEXT_SIGMA_M.items()]
    return np.stack([likelihood, *measures, *smoothed]).astype(np.float32)


def learned_likelihood(evidence: RoadEvidence, model: RoadModel) -> GeoRaster:
    """The model's road probability of every cell (NaN outside the data), on the
    evidence's grid; 0 on the medians the kerbs show, as in the rule (a layer's guard bands
    cover a median, so the model never learns it)."""
    features = evidence_features(evidence)
    rows, cols = features.shape[1:]
    probability = model.predict(features.reshape(len(features), -1)).reshape(rows, cols)
    if "kerbs" in evidence.memberships:
        probability[np.asarray(evidence.memberships["kerbs"].data) == 0] = 0.0
    outside = np.isnan(np.asarray(evidence.likelihood.data))
    raster = evidence.likelihood
    return GeoRaster(np.where(outside, np.nan, probability).astype(np.float32),
                     raster.transform, raster.crs, nodata=np.nan)


def _sample(mask: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    index = np.flatnonzero(mask)
    return index if len(index) <= count else rng.choice(index, count, replace=False)


def fit_evidence_model(features: GeoRaster, roads: gpd.GeoDataFrame, *, width_m=None,
                       width_field: str | None = None, default_width_m: float = 6.0,
                       guard_m: float = 3.0, core_fraction: float = 0.5,
                       off_layer_road: float = OFF_LAYER_ROAD,
                       on_layer_bare: float = ON_LAYER_BARE,
                       samples: int = 100_000, seed: int = 0, threads: int = 1) -> RoadModel:
    """Boosted trees that tell road cells from the rest, with a road layer as labels.

    Parameters
    ----------
    features : GeoRaster
        :func:`evidence_features` of the area (bands in :data:`EVIDENCE_FEATURES` order),
        metre CRS.
    roads : GeoDataFrame
        The road layer's centre lines (reprojected to the features' CRS).
    width_m, width_field, default_width_m, guard_m, core_fraction
        Road widths, the guard band (metres) and the share of the half width that is road
        (:func:`gisroads.learn.training.line_labels`).
    off_layer_road, on_layer_bare : float
        Cells off the layer whose rule likelihood is at least ``off_layer_road``, and
        cells on it whose likelihood is below ``on_layer_bare``, are left unlabelled.
    samples : int
        Cells drawn of each class at most.
    seed : int
        Seeds the draw and the trees.
    threads : int
        Threads of the fit.

    Returns
    -------
    RoadModel
        ``metadata``: ``kind`` :data:`MODEL_KIND`, ``trained_on`` "road layer", the
        cells of each class, the threshold.

    Raises
    ------
    GisroadsError
        A layer that misses the area, or an area without non-road cells.
    """
    data = np.asarray(features.data)
    if data.ndim != 3 or len(data) != len(EVIDENCE_FEATURES):
        raise GisroadsError(f"expected {len(EVIDENCE_FEATURES)} feature bands, got "
                            f"shape {data.shape}")
    shape = data.shape[1:]
    positive, negative = line_labels(
        roads, shape=shape, transform=features.transform, crs=features.crs,
        pixel_m=features.pixel_size, width_m=width_m, width_field=width_field,
        default_width_m=default_width_m, guard_m=guard_m, core_fraction=core_fraction,
        between_negative=True)
    inside = np.isfinite(data[0])
    positive &= inside
    # learn where the layer and the cloud agree: a road the layer lacks, a line it holds
    # where the cloud shows none (a fake, a misregistered stretch) stay unlabelled
    rule = data[EVIDENCE_FEATURES.index("likelihood")]
    negative &= inside & (rule < off_layer_road)
    positive &= ~(rule < on_layer_bare)
    if positive.sum() < 50:
        raise GisroadsError("the road layer covers almost none of the cloud (check its CRS "
                            "and extent)")
    if negative.sum() < 50:
        raise GisroadsError("the road layer leaves no non-road cells to learn from")
    rng = np.random.default_rng(seed)
    chosen = np.concatenate([_sample(positive, samples, rng), _sample(negative, samples, rng)])
    X = data.reshape(len(data), -1)[:, chosen]
    y = positive.ravel()[chosen]
    model = fit_model(X, y, seed=seed, threads=threads, feature_names=EVIDENCE_FEATURES,
                      max_iter=60, min_samples_leaf=100,
                      metadata={"kind": MODEL_KIND, "trained_on": ROAD_LAYER,
                                "road_cells": int(positive.sum()),
                                "other_cells": int(negative.sum()),
                                "guard_m": guard_m, "cell_m": features.pixel_size})
    return with_metadata(model, threshold=MODEL_THRESHOLD)


def save_evidence_model(model: RoadModel, path) -> Path:
    """Write an evidence model (``.npz``, :func:`gisroads.learn.model.save_model`)."""
    return save_model(model, path)


def load_evidence_model(path) -> RoadModel:
    """Read a model of :func:`fit_evidence_model`; refuses an image model.

    Raises
    ------
    GisroadsError
        Not a gisroads model, or one trained on other features (an imagery model).
    """
    try:
        model = load_model(path, feature_names=EVIDENCE_FEATURES)
    except GisroadsError as error:
        raise GisroadsError(f"{error}; a LiDAR model comes from `gisroads train CLOUD ROADS`"
                            ) from None
    if model.metadata.get("kind") != MODEL_KIND:
        raise GisroadsError(f"{path}: not a LiDAR evidence model")
    return model
