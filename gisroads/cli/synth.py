"""``gisroads synth``: a synthetic scene with exact ground truth."""
import argparse
from pathlib import Path

from .options import _positive, add_command, job_default
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    from ..jobs import synth_job
    p = add_command(
        subparsers, "synth", run, "write a synthetic scene with exact ground truth",
        "Write a synthetic suburban scene: truth.gpkg (road centre lines with widths, "
        "road polygons, junctions, scene objects), cloud.laz (airborne point cloud) and "
        "image.tif + dsm.tif (R,G,B,NIR orthoimage and surface model).")
    p.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    size = job_default(synth_job, "size_m")
    p.add_argument("--size", type=_size, default=size, metavar="WxH",
                   help=f"scene size in metres, e.g. 400x300 (default {size[0]:g}x{size[1]:g})")
    p.add_argument("--seed", type=int, default=job_default(synth_job, "seed"),
                   help="random seed (default %(default)s)")
    p.add_argument("--density", type=_positive,
                   default=job_default(synth_job, "density_per_m2"),
                   help="point density in points per m² (default %(default)g)")
    p.add_argument("--pixel", type=_positive, default=job_default(synth_job, "pixel_m"),
                   help="image pixel size in metres (default %(default)g)")
    p.add_argument("--no-cloud", action="store_true", help="skip the point cloud")
    p.add_argument("--no-image", action="store_true", help="skip the image and DSM")


def run(args) -> int:
    from ..jobs import synth_job
    paths = synth_job(args.out, size_m=args.size, seed=args.seed,
                      density_per_m2=args.density, pixel_m=args.pixel,
                      cloud=not args.no_cloud, image=not args.no_image,
                      progress=ProgressBar(not args.json))
    print_result(paths, args.json)
    return 0


def _size(text: str) -> tuple[float, float]:
    try:
        parts = [float(v) for v in text.lower().split("x")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT in metres") from None
    if len(parts) == 1:
        parts *= 2
    if len(parts) != 2 or min(parts) < 100:
        raise argparse.ArgumentTypeError("size is WIDTHxHEIGHT in metres, each at least 100")
    return parts[0], parts[1]
