"""``gisroads blocks``: city blocks on a road-likelihood raster (Zhu & Mordohai, section 5)."""
from pathlib import Path

from .options import _positive, add_command, add_source_and_out, job_default
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    from ..jobs import blocks_job
    p = add_command(
        subparsers, "blocks", run, "segment city blocks on a road-likelihood raster",
        "Segment a city into blocks bounded by roads (Zhu & Mordohai, section 5): "
        "nodes on the non-road places, edges between nodes within 80 m weighted by "
        "exp(-the highest road likelihood on the segment between them), and a "
        "normalized cut, so blocks are separated even where a road segment was "
        "missed. Input: a likelihood GeoTIFF of 'gisroads lidar --rasters' (the "
        "maximum over its width bands) or any road-probability raster in [0, 1]. "
        "Writes the city_blocks layer (block_id, area_m2, perimeter_m).")
    add_source_and_out(p, "likelihood", "road-likelihood or probability GeoTIFF")
    p.add_argument("--points", type=Path,
                   help="LAS/LAZ whose ground points (class 2) are the graph's nodes "
                        "(default: a regular sample of the raster)")
    p.add_argument("--blocks", type=int,
                   help="number of normalized-cut segments (default: the largest eigengap)")
    p.add_argument("--spacing", type=_positive,
                   default=job_default(blocks_job, "sample_spacing_m"),
                   help="node spacing in metres (default %(default)g)")
    p.add_argument("--max-edge", type=_positive, default=job_default(blocks_job, "max_edge_m"),
                   help="longest graph edge in metres (default %(default)g, as in the paper)")
    p.add_argument("--quicklook", type=Path, help="also draw a PNG of the blocks")


def run(args) -> int:
    from ..jobs import blocks_job
    result = blocks_job(args.likelihood, args.out, points_path=args.points,
                        quicklook=args.quicklook, n_blocks=args.blocks,
                        sample_spacing_m=args.spacing, max_edge_m=args.max_edge,
                        progress=ProgressBar(not args.json))
    print_result(result, args.json)
    return 0
