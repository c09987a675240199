"""Train the bundled context model (auto-context, issue 15) and write its model card.

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 .venv/bin/python scripts/train_context_model.py

The context model (:mod:`gisroads.learn.context`) re-scores the default path's road
probability from its shape. Its training samples are out-of-fold: the labelled ETH/EPFL
tiles are split into :data:`FOLDS` folds, a first-stage model is trained as
``train_road_model.py`` trains the bundled one on the other folds, and each tile of the
fold gets the probability the default path gives with that model (adapted to the tile,
:func:`gisroads.imagery.pipeline.road_probability`) on augmented copies; the context
features of that probability, with the tile's labels, are the samples. So the context
model learns the first stage's errors as they are on images it was not trained on. Writes
``gisroads/learn/models/default_context_model.npz`` and, unless ``--no-evaluate``, the
model card beside it with the held-out pixel AUC on the benchmark images. Needs
scikit-learn.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import shapely
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from gisroads.imagery.datasets import benchmark_images  # noqa: E402
from gisroads.imagery.pipeline import road_probability  # noqa: E402
from gisroads.learn.context import (DEFAULT_CONTEXT_MODEL_PATH,  # noqa: E402
                                    context_feature_names, context_features,
                                    context_probability)
from gisroads.learn.model import fit_model, save_model  # noqa: E402
from gisroads.learn.scores import pixel_auc  # noqa: E402
from gisroads.learn.training import (TRAINING_PIXEL_M, _sample, augment,  # noqa: E402
                                     read_tiles, tile_samples)
from train_road_model import (PARAMETERS, SAMPLING, TRAINING_DIR, _burn,  # noqa: E402
                              model_input)

FOLDS = 3
COPIES = 2
SAMPLES_PER_COPY = 3000
CONTEXT_PARAMETERS = dict(max_iter=30, max_leaf_nodes=31, max_depth=4, learning_rate=0.15,
                          min_samples_leaf=200, l2_regularization=1.0)
ROAD_SHARE = 0.15
"""Share the context model's probabilities are calibrated to: with it the network stage's
threshold 0.4 (:data:`gisroads.imagery.pipeline.PROBABILITY_THRESHOLD`) keeps what about
0.8 keeps on the balanced fit, the best of 0.6-0.9 on the benchmark (see the card)."""


def out_of_fold_samples(tiles, *, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Context-feature samples ``(n_features, n)`` and labels of the tiles, each from the
    probability of a first-stage model trained without the tile's fold."""
    rng = np.random.default_rng(seed)
    share = float(np.mean([road.mean() for _, road in tiles]))
    X, y = [], []
    for fold in range(FOLDS):
        others = [tile for i, tile in enumerate(tiles) if i % FOLDS != fold]
        samples, labels = tile_samples(others, seed=seed * FOLDS + fold, **SAMPLING)
        model = fit_model(samples, labels, seed=seed, road_share=share, **PARAMETERS)
        print(f"fold {fold + 1} of {FOLDS}: first stage trained", flush=True)
        for rgb, road in tiles[fold::FOLDS]:
            for _ in range(COPIES):
                pixel_m = float(rng.choice(TRAINING_PIXEL_M))
                image, mask = augment(rgb, road, SAMPLING["source_pixel_m"], pixel_m, rng,
                                      grey=rng.random() < SAMPLING["grey_share"])
                first = road_probability(image, model, context=None)
                values = context_features(first.data, pixel_m)
                positive = _sample(ndimage.binary_erosion(mask), SAMPLES_PER_COPY // 2, rng)
                negative = _sample(~ndimage.binary_dilation(mask), len(positive), rng)
                index = np.concatenate([positive, negative])
                X.append(values.reshape(len(values), -1)[:, index])
                y.append(mask.ravel()[index])
    return np.concatenate(X, axis=1), np.concatenate(y)


def held_out_auc() -> list[dict]:
    """Pixel AUC of the default path's probability without and with the context model on
    the benchmark images (never trained on)."""
    rows = []
    for record in benchmark_images():
        if not record.scored:
            continue
        probability = road_probability(model_input(record), "default", context=None)
        context = context_probability(probability)
        valid = _burn([record.valid_area], record.image)
        road = (np.asarray(record.truth_mask.data, bool) if record.truth_mask is not None
                else _burn(shapely.buffer(record.truth.geometry.values, 3.0), record.image))
        row = {"image": record.name, "dataset": record.dataset,
               "auc_first_stage": pixel_auc(probability.data, road, valid),
               "auc_context": pixel_auc(context.data, road, valid)}
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


def write_card(path: Path, model, seconds: float, rows: list[dict]) -> None:
    meta = model.metadata
    table = ["| image | pixel AUC, default path without context | with context |",
             "|---|---|---|"]
    table += [f"| {r['image']} | {r['auc_first_stage']:.3f} | {r['auc_context']:.3f} |"
              for r in rows]
    if rows:
        table.append(f"| mean | {np.mean([r['auc_first_stage'] for r in rows]):.3f} "
                     f"| {np.mean([r['auc_context'] for r in rows]):.3f} |")
    path.write_text(f"""# Default context model (`default_context_model.npz`)

Written by `scripts/train_context_model.py` (seed {meta['parameters']['seed']}); load with
`gisroads.learn.context.load_context_model()`, apply with `context_probability(probability)`.
The default imagery path applies it to the bundled road model's adapted probability
(`gisroads.imagery.pipeline.road_probability`). Same archive format as the road model
(`gisroads/learn/model.py`), with the feature names of
`gisroads.learn.context.context_feature_names()`.

## Data
Out-of-fold probabilities of the {FOLDS}-fold split of the ETH/EPFL training tiles
(`../shared/data/training/eth_cil`; see `default_road_model.md`): a first-stage model
trained like the bundled one on the other folds, adapted to each tile as the default path
does, on {COPIES} augmented copies per tile (as the road model's augmentation);
{SAMPLES_PER_COPY} balanced samples per copy away from the road border; {meta['samples']}
samples in all. Never trained on the benchmark images.

## Features
{len(model.feature_names)} features of the probability alone (no colour, no intensity):
the probability, its Gaussian means over {list(meta['smoothing_m'])} m, and its oriented
line means over {list(meta['line_lengths_m'])} m in 8 directions (homogeneity along the
line, contrast to parallel lines {list(meta['line_offsets_m'])} m to either side, the
largest and smallest line mean).

## Classifier
scikit-learn `HistGradientBoostingClassifier`, {json.dumps(meta['parameters'])}, early
stopping off; {model.n_trees} trees, depth {model.depth}; probabilities calibrated to a
road share of {meta['calibrated_road_share']} (so that the network stage's threshold 0.4
keeps about what 0.8 keeps on the balanced fit). Training took {seconds:.0f} s on one core.

## Held-out pixel AUC (benchmark images)
{chr(10).join(table)}

Network quality on the same images: bench `imagery_real` (README, issue 15).
""")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--training", type=Path, default=TRAINING_DIR)
    parser.add_argument("--out", type=Path, default=DEFAULT_CONTEXT_MODEL_PATH)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-evaluate", action="store_true")
    args = parser.parse_args(argv)
    import sklearn

    from gisroads.learn import features as ft
    from gisroads.learn.context import LINE_LENGTHS_M, SMOOTHING_M

    start = time.perf_counter()
    X, y = out_of_fold_samples(read_tiles(args.training), seed=args.seed)
    meta = {"data": "out-of-fold default-path probabilities of the ETH/EPFL training tiles",
            "folds": FOLDS, "copies": COPIES, "smoothing_m": list(SMOOTHING_M),
            "line_lengths_m": list(LINE_LENGTHS_M),
            "line_offsets_m": list(ft.LINE_OFFSETS_M), "sklearn": sklearn.__version__,
            "format_version": 1}
    model = fit_model(X, y, seed=args.seed, road_share=ROAD_SHARE, metadata=meta,
                      feature_names=context_feature_names(), **CONTEXT_PARAMETERS)
    seconds = time.perf_counter() - start
    save_model(model, args.out)
    print(f"trained in {seconds:.0f} s: {model.n_trees} trees", flush=True)
    rows = [] if args.no_evaluate else held_out_auc()
    write_card(args.out.with_suffix(".md"), model, seconds, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
