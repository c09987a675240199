"""Train the bundled convolutional road model and write its model card (seeded).

    OMP_NUM_THREADS=2 .venv/bin/python scripts/train_road_cnn.py [--steps 3000]
    # a further cycle from a written model (warm restart, lower peak learning rate):
    .venv/bin/python scripts/train_road_cnn.py --init road_convnet.onnx --seed 1 \
        --learning-rate 1e-3 --output new.onnx

Reads the four labelled sources of ``../shared/data/training`` (never a benchmark image),
holds out the tiles listed in its ``validation.txt``, resamples every tile to the working
pixel size (:data:`PIXEL_M`), trains :class:`gisroads.learn.convnet_training.RoadUNet`
(:func:`~gisroads.learn.convnet_training.train_convnet`, sources drawn equally often),
chooses the road threshold on the held-out tiles (the best mean pixel IoU over the four
sources), and writes ``gisroads/learn/models/road_convnet.onnx`` and its card
``road_convnet.md``. Needs the ``train`` extra (torch, onnx).
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import torch  # noqa: E402

from gisroads.imagery.datasets import massachusetts_valid  # noqa: E402
from gisroads.learn.convnet import DEFAULT_CONVNET_PATH  # noqa: E402
from gisroads.learn.convnet_training import (export_onnx, model_from_onnx,  # noqa: E402
                                             predict_tiles, state_to_arrays, train_convnet,
                                             working_tile)
from gisroads.learn.scores import pixel_auc  # noqa: E402
from gisroads.synthetic.rural import render_rural_tile  # noqa: E402

TRAINING_DIR = ROOT.parent / "shared" / "data" / "training"
PIXEL_M = 1.0
"""Working pixel size, metres: the coarsest source (Massachusetts, 1 m; Dubai about 1-2 m)
is not made finer than it was recorded, roads of 3 m and more stay three pixels wide, and a
1000 x 1000 tile at 1 m costs the network a quarter of the work it would at 0.5 m."""
#: pixel IoU is reported at each of these road thresholds
THRESHOLDS = tuple(np.round(np.arange(0.2, 0.75, 0.05), 2))
SOURCE_PIXEL_M = {"eth_cil": 0.6, "cil2022": 0.6, "massachusetts_crops": 1.0, "dubai": 1.2}
RURAL_SOURCE = "synthetic_rural"
RURAL_PIXEL_M = 0.5
RURAL_VALIDATION_SEEDS = range(100_000, 100_030)
"""Seeds of the held-out synthetic rural tiles (the training tiles take 0, 1, 2, ...)."""
DUBAI_ROAD = np.array([0x6E, 0xC1, 0xE4])
DUBAI_UNLABELLED = np.array([0x9B, 0x9B, 0x9B])


def _rgb(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB")).transpose(2, 0, 1)


def _grey(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("L"))


def _colour(mask: np.ndarray, colour: np.ndarray) -> np.ndarray:
    return (np.abs(mask.astype(int) - colour[:, None, None]) <= 12).all(axis=0)


def read_source(source: str):
    """``(relative image path, rgb, road, valid)`` of every tile of a source."""
    folder = TRAINING_DIR / source
    if source in ("eth_cil", "cil2022"):
        for path in sorted((folder / "images").glob("*.png")):
            rgb = _rgb(path)
            road = _grey(folder / "groundtruth" / path.name) > 127
            yield path.relative_to(TRAINING_DIR), rgb, road, np.ones(road.shape, bool)
    elif source == "massachusetts_crops":
        for path in sorted((folder / "images").glob("*.jpg")):
            rgb = _rgb(path)
            road = _grey(folder / "masks" / (path.stem + ".png")) > 0
            yield path.relative_to(TRAINING_DIR), rgb, road, massachusetts_valid(rgb, 1.0)
    elif source == "dubai":
        for path in sorted(folder.glob("tile_*/images/*.jpg")):
            rgb = _rgb(path)
            mask = _rgb(path.parent.parent / "masks" / (path.stem + ".png"))
            valid = ~_colour(mask, DUBAI_UNLABELLED)
            yield path.relative_to(TRAINING_DIR), rgb, _colour(mask, DUBAI_ROAD), valid
    else:
        raise ValueError(source)


def rural_tiles(seeds) -> list:
    """Synthetic rural tiles (:func:`gisroads.synthetic.rural.render_rural_tile`) on the
    working grid: earth tracks, villages and river beds, which no labelled source shows."""
    tiles = []
    for seed in seeds:
        rgb, road = render_rural_tile(seed, pixel_m=RURAL_PIXEL_M)
        tiles.append(working_tile(rgb, road, np.ones(road.shape, bool), source=RURAL_SOURCE,
                                  source_pixel_m=RURAL_PIXEL_M, pixel_m=PIXEL_M))
    return tiles


def load_tiles():
    held_out = {line.strip() for line in (TRAINING_DIR / "validation.txt").read_text().split("\n")
                if line.strip() and not line.startswith("#")}
    train, validation = [], []
    for source, pixel in SOURCE_PIXEL_M.items():
        for name, rgb, road, valid in read_source(source):
            tile = working_tile(rgb, road, valid, source=source, source_pixel_m=pixel,
                                pixel_m=PIXEL_M)
            (validation if str(name) in held_out else train).append(tile)
    return train, validation


def evaluate(model, tiles, thresholds=THRESHOLDS):
    """Per source: pixel AUC and the pixel IoU at each threshold (valid pixels)."""
    probabilities = predict_tiles(model, tiles)
    rows = {}
    for source in sorted({t.source for t in tiles}):
        picked = [(p, t) for p, t in zip(probabilities, tiles) if t.source == source]
        p = np.concatenate([q[t.valid] for q, t in picked])
        y = np.concatenate([t.road[t.valid] for _, t in picked])
        ious = {float(th): float((((p >= th) & y).sum()) / max(1, ((p >= th) | y).sum()))
                for th in thresholds}
        rows[source] = {"tiles": len(picked), "auc": float(pixel_auc(p, y)), "iou": ious}
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--batch", type=int, default=12)
    parser.add_argument("--crop", type=int, default=224)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--learning-rate", type=float, default=3e-3,
                        help="peak of the one-cycle schedule")
    parser.add_argument("--init", type=Path,
                        help="an .onnx written by this script to train further (its "
                             "training is recorded in the new card)")
    parser.add_argument("--rural-tiles", type=int, default=0,
                        help="synthetic rural tiles to train on as a fifth source")
    parser.add_argument("--rural-weight", type=float, default=0.5,
                        help="how often the rural source is drawn, relative to each "
                             "labelled source")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--work", type=Path, default=ROOT / "out" / "train_road_cnn")
    parser.add_argument("--output", type=Path, default=DEFAULT_CONVNET_PATH)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    args.work.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    train, validation = load_tiles()
    weights = None
    if args.rural_tiles:
        train += rural_tiles(range(args.rural_tiles))
        validation += rural_tiles(RURAL_VALIDATION_SEEDS)
        weights = {RURAL_SOURCE: args.rural_weight}
    print(f"{len(train)} training and {len(validation)} held-out tiles "
          f"({time.perf_counter() - started:.0f} s)", flush=True)

    def checkpoint(step, model):
        np.savez(args.work / "weights.npz", step=step, **state_to_arrays(model))

    def progress(fraction, message):
        step = int(round(fraction * args.steps))
        if step % 50 == 0:
            print(message, flush=True)

    model, earlier = (model_from_onnx(args.init) if args.init else (None, None))
    model = train_convnet(train, steps=args.steps, batch=args.batch, crop_px=args.crop,
                          learning_rate=args.learning_rate, seed=args.seed, model=model,
                          source_weights=weights,
                          progress=progress, checkpoint=checkpoint)
    seconds = time.perf_counter() - started
    scores = evaluate(model, validation)
    thresholds = list(next(iter(scores.values()))["iou"])
    labelled = [s for source, s in scores.items() if source != RURAL_SOURCE]
    mean_iou = {th: float(np.mean([s["iou"][th] for s in labelled])) for th in thresholds}
    threshold = max(mean_iou, key=mean_iou.get)
    metadata = {"pixel_m": PIXEL_M, "threshold": threshold, "architecture": "RoadUNet",
                "parameters": int(sum(v.size for v in state_to_arrays(model).values())),
                "steps": args.steps, "batch": args.batch, "crop_px": args.crop,
                "seed": args.seed, "learning_rate": args.learning_rate,
                "training_seconds": round(seconds),
                "machine": f"{platform.processor() or platform.machine()}, "
                           f"{torch.get_num_threads()} torch threads",
                "torch": torch.__version__, "training_tiles": len(train),
                "rural_tiles": args.rural_tiles, "rural_weight": args.rural_weight,
                "validation": {s: {"tiles": v["tiles"], "auc": round(v["auc"], 3),
                                   "iou": round(v["iou"][threshold], 3)}
                               for s, v in scores.items()}}
    if earlier is not None:
        metadata["continued_from"] = {key: earlier.get(key) for key in (
            "steps", "batch", "crop_px", "seed", "learning_rate", "training_seconds",
            "rural_tiles", "rural_weight", "continued_from")}
    export_onnx(model, args.output, metadata)
    (args.work / "validation.json").write_text(json.dumps(scores, indent=1))
    write_card(args.output.with_suffix(".md"), metadata, scores, mean_iou)
    print(json.dumps(metadata, indent=1))


def write_card(path: Path, metadata: dict, scores: dict, mean_iou: dict) -> None:
    threshold = metadata["threshold"]
    lines = [
        "# Model card: the bundled convolutional road model (`road_convnet.onnx`)", "",
        "Written by `scripts/train_road_cnn.py`; every figure here comes from that run.", "",
        f"- Architecture: `RoadUNet` (gisroads.learn.convnet_training), "
        f"{metadata['parameters']:,} parameters, trained from scratch.",
        f"- Working pixel size: {metadata['pixel_m']} m (images are resampled to it).",
        *_earlier_cycles(metadata.get("continued_from")),
        f"- Training (cycle {len(_earlier_cycles(metadata.get('continued_from'))) + 1}"
        f"{', the last' if 'continued_from' in metadata else ', from scratch'}): "
        f"{metadata['steps']} steps of {metadata['batch']} crops of "
        f"{metadata['crop_px']} px, seed {metadata['seed']}, one-cycle peak learning rate "
        f"{metadata['learning_rate']:g}, "
        f"{metadata['training_seconds'] / 60:.0f} min on {metadata['machine']} "
        f"(torch {metadata['torch']}); {metadata['training_tiles']} tiles: "
        + _sources_line(metadata),
        "- Augmentation: scale 0.6-1.6, rotation, flips, colour, brightness, contrast, gamma, "
        "haze, greyscale, blur, noise, JPEG, straight no-data borders. Loss: BCE + soft "
        "Dice, no-data masked out.",
        f"- Road threshold {threshold}: the best mean pixel IoU of the four labelled sources "
        "on their held-out tiles (`validation.txt`).", "",
        "## Held-out tiles (working grid)", "",
        "| source | tiles | pixel AUC | pixel IoU at the threshold |", "|---|---|---|---|"]
    for source, row in scores.items():
        lines.append(f"| {source} | {row['tiles']} | {row['auc']:.3f} | "
                     f"{row['iou'][threshold]:.3f} |")
    lines += ["", "Mean IoU of the four labelled sources by threshold: " + ", ".join(f"{t}: {v:.3f}"
                                                      for t, v in mean_iou.items()), "",
              "Provenance: the training tiles state no licence except Dubai's (CC0); "
              "see ../shared/data/training/README.md.", ""]
    path.write_text("\n".join(lines))


def _sources_line(metadata: dict) -> str:
    """What the last cycle trained on, for the card."""
    labelled = ("the four labelled sources (ETH CIL, CIL 2022, Massachusetts crops, Dubai; "
                "see ../shared/data/training)")
    rural = metadata.get("rural_tiles")
    if not rural:
        return labelled + ", drawn equally often by source."
    return (f"{labelled} and {rural} synthetic rural tiles at {RURAL_PIXEL_M} m "
            "(`gisroads.synthetic.rural`: earth tracks, villages, river beds), the labelled "
            f"sources drawn equally often, the rural tiles {metadata['rural_weight']:g} times "
            f"as often as one of them; the held-out rural tiles are seeds "
            f"{RURAL_VALIDATION_SEEDS.start}-{RURAL_VALIDATION_SEEDS.stop - 1}, left out of "
            "the threshold's choice.")


def _earlier_cycles(earlier: dict | None) -> list[str]:
    """Card lines for the cycles a model was trained in before its last one, first first."""
    chain = []
    while earlier:
        chain.insert(0, earlier)
        earlier = earlier.get("continued_from")
    return [f"- Cycle {k}{' (from scratch)' if k == 1 else ''}: {cycle['steps']} steps of "
            f"{cycle['batch']} crops of {cycle['crop_px']} px, seed {cycle['seed']}, one-cycle "
            f"peak learning rate {cycle.get('learning_rate') or 3e-3:g}, "
            f"{cycle['training_seconds'] / 60:.0f} min"
            + (f", with {cycle['rural_tiles']} synthetic rural tiles." if cycle.get("rural_tiles")
               else ".")
            for k, cycle in enumerate(chain, start=1)]

if __name__ == "__main__":
    main()
