"""``gisroads train``: a road model trained on an image from a road layer."""
from pathlib import Path

from .options import _positive, add_command, add_georeferencing_options, job_default
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    from ..jobs import train_job
    from ..learn.convnet import FINE_TUNE_STEPS
    p = add_command(
        subparsers, "train", run, "train a road model on an image or a point cloud from a "
        "road layer",
        "Train the learned road cue on your own image from an existing road layer over "
        "it (e.g. last year's road database or OpenStreetMap): roads are rasterised at "
        "their width, pixels in the core half of a road are road, pixels beyond "
        "the road plus a guard band are non-road (the guard absorbs lines a few "
        "metres off). An output ending in .onnx fine-tunes the convolutional network "
        "(needs PyTorch: pip install 'gisroads[train]'); an output ending in .npz "
        "trains gradient-boosted trees (scikit-learn) on multiscale features in metres. "
        "Give the output to 'gisroads image --model'. Roads "
        "missing from the layer fall among the non-road pixels, a few per cent of "
        "them, which the models tolerate. Given a LAS/LAZ point cloud, trains boosted "
        "trees on the road evidence's measures per cell (.npz, needs scikit-learn) for "
        "'gisroads lidar --model'.")
    p.add_argument("image", type=Path, help="GeoTIFF (or PNG/JPEG with --pixel and --crs), "
                                            "or a LAS/LAZ point cloud")
    p.add_argument("roads", type=Path, help="road centre lines (GeoPackage, GeoJSON, any OGR "
                                            "line layer, any CRS)")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="output model: .onnx (the network fine-tuned) or .npz (boosted trees)")
    p.add_argument("--base", type=Path,
                   help="with an .onnx output: the network to start from (default: the "
                        "bundled one)")
    p.add_argument("--steps", type=int,
                   help="with an .onnx output: optimiser steps of 8 crops (default "
                        f"{FINE_TUNE_STEPS}: about a minute for a 1500 x 1500 tile on two "
                        "cores)")
    p.add_argument("--check", type=float, default=job_default(train_job, "check_share"),
                   metavar="SHARE",
                   help="with an .onnx output: share of the layer's road length left out of "
                        "the training to check the fine-tuned network against the base one; "
                        "the base one is written when it finds more of those roads (default "
                        "%(default)g; 0: no check)")
    _add_sample_options(p)
    add_georeferencing_options(p, "an image")


def _add_sample_options(p) -> None:
    """What is road and what is not: road widths, the guard band, the samples."""
    from ..jobs import train_job, train_lidar_job
    p.add_argument("--width-field", help="field of the road layer holding each road's width "
                                         "in metres (empty values take --width)")
    p.add_argument("--width", type=_positive, default=job_default(train_job, "default_width_m"),
                   help="road width in metres where no width field or value is given "
                        "(default %(default)g)")
    p.add_argument("--samples", type=int, default=job_default(train_job, "samples"),
                   help="with an .npz output: pixels sampled from the image, half of them "
                        "road (default %(default)s)")
    p.add_argument("--seed", type=int, default=job_default(train_job, "seed"),
                   help="random seed (default %(default)s)")
    p.add_argument("--guard", type=float,
                   help="guard band beyond the road edge, metres, with no non-road sample "
                        f"(default {job_default(train_job, 'guard_m'):g} for an image: "
                        "OpenStreetMap lines are often 2-5 m off; "
                        f"{job_default(train_lidar_job, 'guard_m'):g} for a cloud, whose "
                        "cells are finer)")


def run(args) -> int:
    from ..jobs import train_job, train_lidar_job
    guard = {} if args.guard is None else {"guard_m": args.guard}
    if args.image.suffix.lower() in (".las", ".laz"):
        result = train_lidar_job(args.image, args.roads, args.out,
                                 width_field=args.width_field, width_m=args.width,
                                 seed=args.seed, progress=ProgressBar(not args.json), **guard)
        print_result(result, args.json)
        return 0
    result = train_job(args.image, args.roads, args.out, width_field=args.width_field,
                       default_width_m=args.width, pixel_m=args.pixel, crs=args.crs,
                       samples=args.samples, seed=args.seed, base=args.base,
                       steps=args.steps, check_share=args.check,
                       progress=ProgressBar(not args.json), **guard)
    print_result(result, args.json)
    return 0
