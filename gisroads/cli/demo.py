"""``gisroads demo``: both road pipelines on the bundled real data."""
from pathlib import Path

from .options import add_command
from .report import ProgressBar, print_result


def add_parser(subparsers) -> None:
    p = add_command(
        subparsers, "demo", run, "run both road pipelines on the bundled real data",
        "Run the imagery pipeline on a bundled SpaceNet Paris tile (scored against its "
        "OpenStreetMap centre lines) and the LiDAR pipeline on a bundled IGN LiDAR HD "
        "tile; write their GeoPackages and PNG quick-looks. Sources and licences: "
        "the README.md beside the data (data/demo/ in the repository, gisroads/_demo/ "
        "in an installed gisroads).")
    p.add_argument("-o", "--out", type=Path, default=Path("out/demo"), help="output folder")


def run(args) -> int:
    from ..jobs import demo_job
    result = demo_job(args.out, progress=ProgressBar(not args.json))
    image, lidar, intensity = result["image"], result["lidar"], result["lidar_intensity"]
    print_result(result, args.json, "\n".join([
        f"imagery (SpaceNet Paris tile): {image['roads']} roads, {image['length_m']:.0f} m, "
        f"{image['junctions']} junctions, cues {image['cues']}",
        "scored against OpenStreetMap's centre lines (2-5 m off the road centres):",
        result["image_report"], "",
        f"LiDAR (IGN LiDAR HD tile), every cue it carries ({lidar['cues']}): "
        f"{lidar['roads']} roads, {lidar['length_m']:.0f} m, {lidar['junctions']} junctions",
        f"LiDAR, the paper's intensity cue alone: {intensity['roads']} roads, "
        f"{intensity['length_m']:.0f} m, {intensity['junctions']} junctions",
        f"outputs in {args.out}/: image_roads.gpkg/.png, lidar_roads.gpkg/.png, "
        "lidar_intensity_roads.gpkg/.png"]))
    return 0
