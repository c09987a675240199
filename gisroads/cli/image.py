"""``gisroads image``: roads from an aerial image (learned cue; Grote & Rottensteiner)."""
from pathlib import Path

from .options import (add_command, add_database_options, add_georeferencing_options,
                      add_source_and_out, then_compare)
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    p = add_command(
        subparsers, "image", run, "extract roads from an aerial image (learned cue; "
                                  "Grote & Rottensteiner)",
        "Extract the road network of an aerial image (RGB, CIR or panchromatic GeoTIFF). "
        "By default a learned road probability (the bundled convolutional network; "
        "--model) goes through the network stage of 'gisroads vectorize'. With --model "
        "none, or --method grote-rottensteiner, the papers' pipeline (a NIR band and a "
        "DSM are used when given): normalized-cut over-segmentation, "
        "grouping of segments, road-part shape filtering, linking of road parts with an "
        "integer program over the gaps, junction construction and network significance "
        "checks. Writes road centre lines with widths (and the cues used), road "
        "polygons, junctions and the QA layers segments, road_parts, gap_edges and "
        "junction_connections to a GeoPackage in the image's CRS.")
    add_source_and_out(p, "input", "GeoTIFF (or PNG/JPEG with --pixel and --crs)")
    p.add_argument("--nir-band", type=int, help="1-based band number of the near infrared")
    p.add_argument("--red-band", type=int,
                   help="1-based band number of the red (default: band 1, or 2 in CIR)")
    p.add_argument("--dsm", type=Path, help="digital surface model GeoTIFF (metres)")
    p.add_argument("--segments", type=int,
                   help="NCut segments (default: one per 36 m² of ground, at least 100 "
                        "pixels each: gisroads.imagery.segments.default_counts)")
    add_georeferencing_options(p, "an image")
    p.add_argument("--quicklook", type=Path, help="also draw a PNG of the result")
    _add_model_options(p)
    p.add_argument("--probability", type=Path,
                   help="also write the road probability of the model as a GeoTIFF (.tif)")
    add_database_options(p)


def _add_model_options(p) -> None:
    """The learned road cue: --model, --context and --method."""
    p.add_argument("--model", default="default",
                   help="learned road cue (beyond the papers): 'default' (the bundled "
                        "convolutional network), 'boosted' (the bundled boosted trees, adapted "
                        "to the image and re-scored by the context model), a model file "
                        "written by 'gisroads train' (.onnx or .npz), or 'none' (the papers' "
                        "pipeline alone)")
    p.add_argument("--context", default="default",
                   help="context model that re-scores the boosted trees' probability from "
                        "its own shape before the network stage (beyond the papers): "
                        "'default' (the bundled one; not for the convolutional network or a "
                        "model trained with 'gisroads train'), a "
                        "file written by scripts/train_context_model.py (.npz), or 'none'")
    p.add_argument("--method", choices=("learned-probability", "grote-rottensteiner"),
                   help="with a model: its probability alone through the network stage "
                        "(learned-probability, the default: the better on the benchmark) or "
                        "the papers' stages with the probability as road-part criterion "
                        "and gap context (grote-rottensteiner); without a model always the "
                        "papers' stages")


def run(args) -> int:
    from ..jobs import image_job
    result = image_job(args.input, args.out, nir_band=args.nir_band, red_band=args.red_band,
                       dsm_path=args.dsm, pixel_m=args.pixel, crs=args.crs,
                       quicklook=args.quicklook, model=args.model, context=args.context,
                       probability_path=args.probability, method=args.method,
                       n_segments=args.segments, progress=ProgressBar(not args.json))
    print_result(then_compare(args, result), args.json)
    return 0
