"""The ``gisroads`` command: one subcommand per job, progress on stderr, ``--json`` for scripts.

Errors in the input (unreadable or empty files, missing georeferencing, bad values) print one
line, ``gisroads: error: ...``, and exit with status 2; nothing is written. Any other exception
is a bug and keeps its traceback (see :mod:`gisroads.errors`). Warnings (no road found: the
outputs hold empty layers) print ``gisroads: warning: ...`` after the command's output, which
still exits 0.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from pathlib import Path

from . import __version__
from .errors import INPUT_ERRORS, GisroadsError, reported_warnings
from .progress import Cancelled, to_json

EPILOG = "Distances are in metres. Outputs are written in the input's CRS."


class _ProgressBar:
    """Progress on stderr: a tqdm bar on a terminal; elsewhere (a log file, a pipe, CI),
    where a bar's carriage returns garble the text, one line per 10 %; with
    ``--progress-json`` (even with ``--json``), one JSON object per line for a program
    driving gisroads, ``{"progress": 0.42, "message": "..."}`` at each percent or new
    message (other stderr lines, ``gisroads: ...``, are warnings and errors)."""

    active: list[_ProgressBar] = []
    """Bars on screen, closed before an error or a cancel is printed (:func:`main`)."""
    json_lines = False
    """Set by :func:`main` from ``--progress-json``."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.tty = sys.stderr.isatty()
        self.last = -1
        self.message = None
        self.bar = None

    terminated = False
    """Set by SIGTERM (:func:`_cancel_on_sigterm`): the next report raises
    :class:`~gisroads.progress.Cancelled`, and every later one again."""

    def __call__(self, fraction: float, message: str = "") -> None:
        if _ProgressBar.terminated:
            raise Cancelled()
        percent = max(0, min(100, int(fraction * 100)))
        if self.json_lines:
            if percent != self.last or message != self.message:
                sys.stderr.write(json.dumps({"progress": round(min(max(fraction, 0.0), 1.0),
                                                               4), "message": message}) + "\n")
                sys.stderr.flush()
                self.last, self.message = percent, message
            return
        if not self.enabled:
            return
        if self.tty:
            self._draw(percent, message)
            if fraction >= 1.0:
                self.close()
            return
        if percent // 10 != self.last // 10 or fraction >= 1.0 and self.last < 100:
            sys.stderr.write(f"{percent:3d}% {message}\n")
            sys.stderr.flush()
            self.last = percent

    def _draw(self, percent: int, message: str) -> None:
        if self.bar is None:
            from tqdm import tqdm
            self.bar = tqdm(total=100, file=sys.stderr, dynamic_ncols=True, leave=True,
                            bar_format="{percentage:3.0f}%|{bar}| {elapsed}<{remaining} "
                                       "{desc}")
            _ProgressBar.active.append(self)
        self.bar.set_description_str(message[:40], refresh=False)
        self.bar.update(percent - self.bar.n)  # tqdm takes steps back too

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
            _ProgressBar.active.remove(self)

    @classmethod
    def close_all(cls) -> None:
        for bar in list(cls.active):
            bar.close()


def _text(value, key: str = "") -> str:
    """A result value as a person reads it: floats to 10 significant digits, durations
    (keys ending in ``_s``) in seconds, a dict as ``name value`` pairs, None as ``none``."""
    if isinstance(value, dict):
        return ", ".join(f"{k} {_text(v, key)}" for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_text(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.2f} s" if key.endswith("_s") else f"{value:.10g}"
    return "none" if value is None else str(value)


def _print(result: dict, as_json: bool, text: str | None = None) -> None:
    """``result`` as JSON, else ``text`` (by default a ``key: value`` line per item)."""
    if text is None:
        text = "\n".join(f"{k}: {_text(v, k)}" for k, v in result.items())
    print(to_json(result) if as_json else text)
    sys.stdout.flush()  # a closed pipe raises here, inside main's handler, not at exit


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


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text} must be positive")
    return value


def _format_info(info: dict) -> str:
    if info["kind"] == "vector":
        return "\n".join(
            f"{l['layer']}: {l['features']} features, "
            f"{'/'.join(l['geometry']) or 'no geometry type'}"
            f"{' (declared)' if l['geometry'] and not l['features'] else ''}, "
            f"CRS {l['crs']} (EPSG {l['epsg']}), "
            + (f"extent {_text(l['extent'])}" if l["extent"] else "no extent")
            for l in info["layers"])
    lines = [f"{info['path']} ({info['kind']})"]
    for key, value in info.items():
        if key in {"kind", "path"}:
            continue
        if key == "georeferenced" and not value:
            missing = [what for what, there in (("geotransform", info.get("extent")),
                                                ("CRS", info.get("crs"))) if there is None]
            value = (f"no (no {' and no '.join(missing)}; give the road commands its pixel "
                     "size and CRS with --pixel and --crs)")
        lines.append(f"  {key}: {_text(value)}")
    return "\n".join(lines)


def cmd_info(args) -> int:
    from .jobs import describe_file
    info = describe_file(args.file)
    _print(info, args.json, _format_info(info))
    return 0


def cmd_synth(args) -> int:
    from .jobs import synth_job
    paths = synth_job(args.out, size_m=args.size, seed=args.seed,
                      density_per_m2=args.density, pixel_m=args.pixel,
                      cloud=not args.no_cloud, image=not args.no_image,
                      progress=_ProgressBar(not args.json))
    _print(paths, args.json)
    return 0


def cmd_evaluate(args) -> int:
    from .evaluate import format_report
    from .jobs import evaluate_job
    results = evaluate_job(args.extracted, args.reference, buffer_m=args.buffer,
                           cell_m=args.cell, junction_radius_m=args.junction_radius,
                           extracted_polygons=args.extracted_polygons,
                           reference_polygons=args.reference_polygons,
                           valid_area=args.valid_area, qa_path=args.qa,
                           progress=_ProgressBar(not args.json))
    _print(results, args.json, format_report(results))
    return 0


def _metres(text: str) -> tuple[float, ...]:
    from .jobs import parse_metres
    try:
        return parse_metres(text)
    except GisroadsError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _then_compare(args, result: dict) -> dict:
    """With ``--database``, compare the roads just written with the road database."""
    if args.database is None:
        return result
    from .jobs import update_job
    changes = args.changes or args.out.with_name(f"{args.out.stem}_changes.gpkg")
    result["changes"] = update_job(args.out, args.database, changes,
                                   layer=args.database_layer, id_field=args.id_field,
                                   width_field=args.width_field)
    return result


def cmd_lidar(args) -> int:
    from .jobs import lidar_job
    from .parallel import default_workers
    source = args.input[0] if len(args.input) == 1 else args.input
    result = lidar_job(source, args.out, cue=args.cue, cell_m=args.cell, tile_m=args.tile,
                       overlap_m=args.overlap, widths_m=args.widths, lengths_m=args.lengths,
                       n_segments=args.segments, threshold=args.threshold,
                       workers=args.workers or default_workers(), scheduler=args.scheduler,
                       work_dir=args.work_dir, tagged_las=args.tagged_las,
                       rasters_dir=args.rasters, quicklook=args.quicklook,
                       progress=_ProgressBar(not args.json))
    _print(_then_compare(args, result), args.json)
    return 0


def cmd_blocks(args) -> int:
    from .jobs import blocks_job
    result = blocks_job(args.likelihood, args.out, points_path=args.points,
                        quicklook=args.quicklook, n_blocks=args.blocks,
                        sample_spacing_m=args.spacing, max_edge_m=args.max_edge,
                        progress=_ProgressBar(not args.json))
    _print(result, args.json)
    return 0


def cmd_image(args) -> int:
    from .jobs import image_job
    result = image_job(args.input, args.out, nir_band=args.nir_band, red_band=args.red_band,
                       dsm_path=args.dsm, pixel_m=args.pixel, crs=args.crs,
                       quicklook=args.quicklook, model=args.model, context=args.context,
                       probability_path=args.probability, method=args.method,
                       n_segments=args.segments, progress=_ProgressBar(not args.json))
    _print(_then_compare(args, result), args.json)
    return 0


def cmd_train(args) -> int:
    from .jobs import train_job
    result = train_job(args.image, args.roads, args.out, width_field=args.width_field,
                       width_m=args.width, guard_m=args.guard, pixel_m=args.pixel,
                       crs=args.crs, samples=args.samples, seed=args.seed,
                       base=args.base, steps=args.steps, progress=_ProgressBar(not args.json))
    _print(result, args.json)
    return 0


def cmd_vectorize(args) -> int:
    from .jobs import vectorize_job
    result = vectorize_job(args.input, args.out, band=args.band, threshold=args.threshold,
                           pixel_m=args.pixel, crs=args.crs, quicklook=args.quicklook,
                           progress=_ProgressBar(not args.json))
    _print(result, args.json)
    return 0


def add_parallel_options(p, what: str) -> None:
    """--workers, --scheduler and --work-dir: ``what`` (tiles, road patches) as Dask tasks."""
    p.add_argument("--workers", type=int, metavar="N",
                   help=f"{what} in parallel on a local Dask cluster of N worker processes "
                        "(default or 0: one per core; 1 runs them in this process)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help=f"run the {what} on an existing Dask cluster (e.g. "
                        "tcp://host:8786); its workers must see --work-dir")
    p.add_argument("--work-dir", type=Path, metavar="DIR",
                   help=f"keep the points bucketed by tile and the finished {what} here: a "
                        "stopped run started again resumes where it was (default: a "
                        "temporary folder, removed at the end)")


def cmd_snakes(args) -> int:
    from .jobs import snakes_job
    from .parallel import default_workers
    result = snakes_job(args.input, args.map, args.out, curb_detector=args.curb_detector,
                        tagged_las=args.tagged_las, attractor_tif=args.attractor,
                        workers=args.workers or default_workers(), scheduler=args.scheduler,
                        work_dir=args.work_dir, progress=_ProgressBar(not args.json))
    _print(_then_compare(args, result), args.json)
    return 0


def cmd_demo(args) -> int:
    from .jobs import demo_job
    result = demo_job(args.out, progress=_ProgressBar(not args.json))
    image, lidar, evidence = result["image"], result["lidar"], result["lidar_evidence"]
    _print(result, args.json, "\n".join([
        f"imagery (SpaceNet Paris tile): {image['roads']} roads, {image['length_m']:.0f} m, "
        f"{image['junctions']} junctions, cues {image['cues']}",
        "scored against OpenStreetMap's centre lines (2-5 m off the road centres):",
        result["image_report"], "",
        f"LiDAR (IGN LiDAR HD tile): {lidar['roads']} roads, {lidar['length_m']:.0f} m, "
        f"{lidar['junctions']} junctions",
        f"LiDAR, evidence cue (beyond the paper): {evidence['roads']} roads, "
        f"{evidence['length_m']:.0f} m, {evidence['junctions']} junctions",
        f"outputs in {args.out}/: image_roads.gpkg/.png, lidar_roads.gpkg/.png, "
        "lidar_evidence_roads.gpkg/.png"]))
    return 0


# --- road database update (issue 11) -------------------------------------------------------

def cmd_update(args) -> int:
    from .jobs import update_job
    result = update_job(args.extracted, args.database, args.out, layer=args.layer,
                        id_field=args.id_field, width_field=args.width_field,
                        tolerance_m=args.tolerance, search_m=args.search,
                        coverage=args.coverage, progress=_ProgressBar(not args.json))
    _print(result, args.json)
    return 0


def add_database_options(p) -> None:
    """``--database`` and its options, on the road-extraction subcommands."""
    p.add_argument("--database", help="also compare the roads found with this road database "
                                      "(any OGR source, e.g. roads.gpkg or 'PG:dbname=gis'), "
                                      "as gisroads update does")
    p.add_argument("--changes", type=Path,
                   help="GeoPackage of the change layers (default: OUT_changes.gpkg)")
    p.add_argument("--database-layer", help="the database's layer or table (default: its "
                                            "first)")
    p.add_argument("--id-field", help="the database's feature id field (default: its OGR "
                                      "feature ids)")
    p.add_argument("--width-field", help="the database's road width field, metres")


def add_update_parser(add) -> None:
    """The ``update`` subcommand (``add`` as in :func:`build_parser`)."""
    from .jobs import update_job
    p = add("update", cmd_update, "compare extracted roads with a road database",
            "Match extracted road centre lines to the lines of a road database and write "
            "the changes to a GeoPackage in the database's CRS: confirmed (database roads "
            "seen, with offsets and widths), missing (roads or stretches not seen, and "
            "whether the data could have seen them), new (extracted roads absent from the "
            "database, and the database roads they meet), moved (roads off by more than "
            "the tolerance, with the proposed geometry) and proposed_update (the database "
            "with the updates applied and a change field). The database's ids and "
            "attributes are carried through unchanged.")
    p.add_argument("extracted", type=Path,
                   help="extracted centre lines (GeoPackage: layer road_centrelines)")
    p.add_argument("database", help="road database: any OGR source, e.g. roads.gpkg, "
                                    "roads.shp or 'PG:dbname=gis host=localhost'")
    p.add_argument("-o", "--out", type=Path, required=True, help="output GeoPackage (.gpkg)")
    p.add_argument("--layer", help="the database's layer or table (default: its first)")
    p.add_argument("--id-field", help="the database's feature id field (default: its "
                                      "OGR feature ids)")
    p.add_argument("--width-field", help="the database's road width field, metres "
                                         "(default: widths measured, not compared)")
    p.add_argument("--tolerance", type=_positive, default=_default(update_job, "tolerance_m"),
                   help="offset above which a road has moved, metres (default %(default)g)")
    p.add_argument("--search", type=_positive, default=_default(update_job, "search_m"),
                   help="largest offset still matched as the same road, metres (default "
                        "%(default)g)")
    p.add_argument("--coverage", type=Path,
                   help="where the data could show a road: polygons, or a raster with "
                        "non-zero observable cells (data footprint minus occlusion)")


def _default(job, parameter: str):
    """A job's default for ``parameter``: the one its stage defines (see
    :func:`gisroads.jobs.stage_default`), so argparse, QGIS and the docs show the same."""
    from .jobs import stage_default
    return stage_default(job, parameter)


def _listed(metres) -> str:
    """``6,9,12``: metres as the comma-separated list the options take."""
    return ",".join(f"{m:g}" for m in metres)


def build_parser() -> argparse.ArgumentParser:
    from .jobs import (blocks_job, evaluate_job, lidar_job, snakes_job, synth_job, train_job,
                       vectorize_job)
    from .lidar.pipeline import CUES
    parser = argparse.ArgumentParser(
        prog="gisroads", epilog=EPILOG,
        description="Road networks from airborne LiDAR and aerial imagery, as GIS layers.")
    parser.add_argument("--version", action="version", version=f"gisroads {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def add(name, func, help_text, description):
        p = sub.add_parser(name, help=help_text, description=description, epilog=EPILOG)
        p.add_argument("--json", action="store_true", help="print the result as JSON")
        p.add_argument("--progress-json", action="store_true",
                       help="report progress on stderr as JSON lines, {\"progress\": 0.42, "
                            "\"message\": \"...\"} (for programs running gisroads)")
        p.set_defaults(func=func)
        return p

    def add_source_and_out(p, source, source_help):
        """The positional ``source`` a job reads and the GeoPackage ``-o/--out`` it writes."""
        p.add_argument(source, type=Path, help=source_help)
        p.add_argument("-o", "--out", type=Path, required=True, help="output GeoPackage (.gpkg)")

    p = add("info", cmd_info, "describe a point cloud, raster or vector file",
            "Print what a file holds: for LAS/LAZ its version, point format, point count, "
            "CRS and units (feet are reported and converted), extent; for rasters the size, "
            "bands, CRS and pixel size; for vector files each layer's features and CRS.")
    p.add_argument("file", type=Path, help="LAS/LAZ, GeoTIFF or vector file")

    p = add("synth", cmd_synth, "write a synthetic scene with exact ground truth",
            "Write a synthetic suburban scene: truth.gpkg (road centre lines with widths, "
            "road polygons, junctions, scene objects), cloud.laz (airborne point cloud) and "
            "image.tif + dsm.tif (R,G,B,NIR orthoimage and surface model).")
    p.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    size = _default(synth_job, "size_m")
    p.add_argument("--size", type=_size, default=size, metavar="WxH",
                   help=f"scene size in metres, e.g. 400x300 (default {size[0]:g}x{size[1]:g})")
    p.add_argument("--seed", type=int, default=_default(synth_job, "seed"),
                   help="random seed (default %(default)s)")
    p.add_argument("--density", type=_positive, default=_default(synth_job, "density_per_m2"),
                   help="point density in points per m² (default %(default)g)")
    p.add_argument("--pixel", type=_positive, default=_default(synth_job, "pixel_m"),
                   help="image pixel size in metres (default %(default)g)")
    p.add_argument("--no-cloud", action="store_true", help="skip the point cloud")
    p.add_argument("--no-image", action="store_true", help="skip the image and DSM")

    p = add("evaluate", cmd_evaluate, "score extracted roads against a reference",
            "Compare extracted road centre lines with reference ones: completeness, "
            "correctness, quality and RMS offset within a buffer (Wiedemann et al. 1998), "
            "connected components and junction precision/recall, an APLS path-length score, "
            "and, when road polygons are available on both sides, Boyko & Funkhouser's "
            "area precision/recall/quality with spill size and direction.")
    p.add_argument("extracted", type=Path,
                   help="extracted centre lines (GeoPackage: layer road_centrelines)")
    p.add_argument("reference", type=Path, help="reference centre lines (any line file)")
    p.add_argument("--buffer", type=_positive, default=_default(evaluate_job, "buffer_m"),
                   help="buffer width in metres, about half a carriageway (default "
                        "%(default)g)")
    p.add_argument("--cell", type=_positive, default=_default(evaluate_job, "cell_m"),
                   help="grid cell for the area metrics in metres (default %(default)g)")
    p.add_argument("--junction-radius", type=_positive,
                   default=_default(evaluate_job, "junction_radius_m"),
                   help="distance within which junctions match, metres (default "
                        "%(default)g)")
    p.add_argument("--extracted-polygons", type=Path,
                   help="road area of the extraction (default: its road_polygons layer)")
    p.add_argument("--reference-polygons", type=Path,
                   help="reference road area (default: its road_polygons layer)")
    p.add_argument("--valid-area", type=Path,
                   help="polygon file: score only inside it (e.g. the surveyed area)")
    p.add_argument("--qa", type=Path,
                   help="write matched/missed/false pieces to this GeoPackage")

    p = add("lidar", cmd_lidar, "extract roads from a LAS/LAZ point cloud (Zhu & Mordohai)",
            "Extract the road network of an airborne LiDAR point cloud: ground planes on "
            "several levels, a 0.5 m intensity image per level, edges and a normalized-cut "
            "segmentation, rectangle road hypotheses scored by boundary and interior "
            "filters, per-width likelihood maps and a minimum cover of the hypotheses. "
            "Writes road centre lines with widths, road polygons, junctions and the QA "
            "layers rectangles and hypotheses to a GeoPackage in the cloud's CRS.")
    p.add_argument("input", nargs="+", help="LAS/LAZ point cloud with intensity; or several "
                   "files, a folder of them or a quoted glob ('tiles/*.laz'): tiles of one "
                   "area in one CRS, read as one cloud")
    p.add_argument("-o", "--out", type=Path, required=True, help="output GeoPackage (.gpkg)")
    add_parallel_options(p, "tiles")
    p.add_argument("--cue", choices=CUES, default=_default(lidar_job, "cue"),
                   help="intensity: the paper's rectangles on the ground intensity "
                        "(default); evidence: the road likelihood of every cue the cloud "
                        "carries (intensity, height above the terrain, density, roughness, "
                        "slope, returns, classification) through the network stage")
    p.add_argument("--threshold", type=float, default=_default(lidar_job, "threshold"),
                   help="with --cue evidence: road likelihood at which a cell is road "
                        "(0-1, default %(default)g)")
    p.add_argument("--cell", type=_positive,
                   help="intensity image cell in metres (default: 0.5, or the mean point "
                        "spacing of a sparser cloud)")
    p.add_argument("--widths", type=_metres, default=_default(lidar_job, "widths_m"),
                   help="road widths to try, metres (default "
                        f"{_listed(_default(lidar_job, 'widths_m'))})")
    p.add_argument("--lengths", type=_metres, default=_default(lidar_job, "lengths_m"),
                   help="rectangle lengths to try, metres (default "
                        f"{_listed(_default(lidar_job, 'lengths_m'))})")
    p.add_argument("--tile", type=_positive, default=_default(lidar_job, "tile_m"),
                   help="tile side, metres (%(default)g)")
    p.add_argument("--overlap", type=float, default=_default(lidar_job, "overlap_m"),
                   help="overlap with each neighbouring tile, metres (%(default)g)")
    p.add_argument("--segments", type=int, default=_default(lidar_job, "n_segments"),
                   help="number of NCut segments per tile image (default %(default)s)")
    p.add_argument("--tagged-las", type=Path,
                   help="also write the cloud with road points classified 11")
    p.add_argument("--rasters", type=Path,
                   help="also write intensity, likelihood and ground-height GeoTIFFs here "
                        "(with --cue evidence: road_evidence.tif)")
    p.add_argument("--quicklook", type=Path, help="also draw a PNG of the result")
    add_database_options(p)

    p = add("blocks", cmd_blocks, "segment city blocks on a road-likelihood raster",
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
    p.add_argument("--spacing", type=_positive, default=_default(blocks_job, "sample_spacing_m"),
                   help="node spacing in metres (default %(default)g)")
    p.add_argument("--max-edge", type=_positive, default=_default(blocks_job, "max_edge_m"),
                   help="longest graph edge in metres (default %(default)g, as in the paper)")
    p.add_argument("--quicklook", type=Path, help="also draw a PNG of the blocks")

    p = add("image", cmd_image, "extract roads from an aerial image (learned cue; "
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
    p.add_argument("--pixel", type=_positive,
                   help="pixel size in metres, for an image without georeferencing")
    p.add_argument("--crs", help="projected CRS for an image without georeferencing, "
                                 "e.g. EPSG:32633")
    p.add_argument("--quicklook", type=Path, help="also draw a PNG of the result")
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
    p.add_argument("--probability", type=Path,
                   help="also write the road probability of the model as a GeoTIFF (.tif)")
    add_database_options(p)

    p = add("train", cmd_train, "train a road model on an image from a road layer",
            "Train the learned road cue on your own image from an existing road layer over "
            "it (e.g. last year's road database or OpenStreetMap): roads are rasterised at "
            "their width, pixels in the core half of a road are road, pixels beyond "
            "the road plus a guard band are non-road (the guard absorbs lines a few "
            "metres off). An output ending in .onnx fine-tunes the convolutional network "
            "(needs PyTorch: pip install 'gisroads[train]'); an output ending in .npz "
            "trains gradient-boosted trees (scikit-learn) on multiscale features in metres. "
            "Give the output to 'gisroads image --model'. Roads "
            "missing from the layer fall among the non-road pixels, a few per cent of "
            "them, which the models tolerate.")
    p.add_argument("image", type=Path, help="GeoTIFF (or PNG/JPEG with --pixel and --crs)")
    p.add_argument("roads", type=Path, help="road centre lines (GeoPackage, GeoJSON, any OGR "
                                            "line layer, any CRS)")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="output model: .onnx (the network fine-tuned) or .npz (boosted trees)")
    p.add_argument("--base", type=Path,
                   help="with an .onnx output: the network to start from (default: the "
                        "bundled one)")
    p.add_argument("--steps", type=int,
                   help="with an .onnx output: optimiser steps of 8 crops (default "
                        "150: about two minutes for a 1500 x 1500 tile on two cores)")
    p.add_argument("--width-field", help="field of the road layer holding each road's width "
                                         "in metres (empty values take --width)")
    p.add_argument("--width", type=_positive, default=_default(train_job, "width_m"),
                   help="road width in metres where no width field or value is given "
                        "(default %(default)g)")
    p.add_argument("--samples", type=int, default=_default(train_job, "samples"),
                   help="with an .npz output: pixels sampled from the image, half of them "
                        "road (default %(default)s)")
    p.add_argument("--seed", type=int, default=_default(train_job, "seed"),
                   help="random seed (default %(default)s)")
    p.add_argument("--guard", type=float, default=_default(train_job, "guard_m"),
                   help="guard band beyond the road edge, metres, with no non-road sample "
                        "(default %(default)g: OpenStreetMap lines are often 2-5 m off)")
    p.add_argument("--pixel", type=_positive,
                   help="pixel size in metres, for an image without georeferencing")
    p.add_argument("--crs", help="projected CRS for an image without georeferencing, "
                                 "e.g. EPSG:32633")

    p = add("vectorize", cmd_vectorize, "any road raster (mask or probability) to a network",
            "Turn a road raster (a binary mask, or a road probability 0-1 or 0-255: a "
            "deep-learning segmentation, a classified land-cover map, a thresholded index) "
            "into a clean, connected road network: smoothed, thresholded and cleaned, "
            "skeletonised tile by tile, spurs pruned, junction clusters contracted into single "
            "nodes, gaps across occlusions bridged by an integer program, junctions built, "
            "insignificant pieces dropped. Writes road centre lines with widths (from the "
            "raster), road polygons, junctions and the QA layers gap_edges, "
            "junction_connections and rejected to a GeoPackage in the raster's CRS.")
    add_source_and_out(p, "input", "road raster: GeoTIFF (or PNG with --pixel and --crs)")
    p.add_argument("--threshold", type=float, default=_default(vectorize_job, "threshold"),
                   help="road probability threshold, 0-1 (a 0-255 raster is scaled to 0-1 "
                        "first; default %(default)g)")
    p.add_argument("--band", type=int, default=_default(vectorize_job, "band"),
                   help="1-based band to read (default %(default)s)")
    p.add_argument("--pixel", type=_positive,
                   help="pixel size in metres, for a raster without georeferencing")
    p.add_argument("--crs", help="projected CRS for a raster without georeferencing, "
                                 "e.g. EPSG:32633")
    p.add_argument("--quicklook", type=Path, help="also draw a PNG of the result")

    p = add("snakes", cmd_snakes, "road boundaries along a road map (Boyko & Funkhouser)",
            "Fit the roads of an approximate road map to a LAS/LAZ point cloud: register "
            "the map in 3D, cut a subcloud per road, build a curb attractor map, its "
            "gradient vector flow, and fit a ribbon snake from kerb to kerb. Writes road "
            "centre lines with widths, road polygons (with their level), junctions from the "
            "map's topology and the QA layers ribbon_patches and registered_map to a "
            "GeoPackage in the cloud's CRS.")
    add_source_and_out(p, "input", "LAS/LAZ point cloud")
    p.add_argument("map", type=Path, help="road map lines (GeoPackage, GeoJSON, any OGR "
                                          "line layer, any CRS)")
    p.add_argument("--curb-detector", choices=("exp", "step", "none"),
                   default=_default(snakes_job, "curb_detector"),
                   help="height weighting of the curb detector: exp (Gaussian, 15 cm mean, "
                        "5 cm deviation; default), step (10-20 cm) or none")
    p.add_argument("--tagged-las", type=Path,
                   help="also write the cloud with road points classified 11")
    p.add_argument("--attractor", type=Path, help="also write the attractor map (GeoTIFF)")
    add_parallel_options(p, "road patches")
    add_database_options(p)

    p = add("demo", cmd_demo, "run both road pipelines on the bundled real data",
            "Run the imagery pipeline on a bundled SpaceNet Paris tile (scored against its "
            "OpenStreetMap centre lines) and the LiDAR pipeline on a bundled IGN LiDAR HD "
            "tile; write their GeoPackages and PNG quick-looks. Sources and licences: "
            "the README.md beside the data (data/demo/ in the repository, gisroads/_demo/ "
            "in an installed gisroads).")
    p.add_argument("-o", "--out", type=Path, default=Path("out/demo"), help="output folder")
    add_update_parser(add)
    return parser


#: What the output options name: a file with one of these suffixes, or (None) a folder.
#: ``-o/--out`` names a folder for the commands in _FOLDER_OUT, a GeoPackage for the others.
_OUTPUTS = {"out": (".gpkg",), "qa": (".gpkg",), "changes": (".gpkg",),
            "tagged_las": (".las", ".laz"), "attractor": (".tif", ".tiff"),
            "quicklook": (".png",), "rasters": None, "work_dir": None,
            "probability": (".tif", ".tiff")}
_FOLDER_OUT = {"synth", "demo"}


def check_outputs(args) -> None:
    """Refuse, before any work, an output a job could only fail to write at its end: a
    wrong suffix (``-o roads.shp``), a folder where a file goes or a file where a folder
    goes, or a place that cannot be created or written. Missing folders are created."""
    for dest, suffixes in _OUTPUTS.items():
        path = getattr(args, dest, None)
        if path is None:
            continue
        path = Path(path)
        option = "-o/--out" if dest == "out" else "--" + dest.replace("_", "-")
        if suffixes is None or dest == "out" and args.command in _FOLDER_OUT:
            if path.exists() and not path.is_dir():
                raise GisroadsError(f"{option} {path}: is a file; give a folder")
            _check_writable(path, f"{option} {path}")
            continue
        if dest == "out" and args.command == "train":
            suffixes = (".onnx", ".npz")
        if path.suffix.lower() not in suffixes:
            raise GisroadsError(f"{option} {path}: must end in {' or '.join(suffixes)}")
        if path.is_dir():
            raise GisroadsError(f"{option} {path}: is a folder; give a file name")
        _check_writable(path.parent, f"{option} {path}")


def _check_writable(folder: Path, what: str) -> None:
    """``folder`` is a writable folder, or can be made as one in its nearest existing
    ancestor (``what`` names the option and path in the error)."""
    existing = folder.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise GisroadsError(f"{what}: cannot make the folder {folder}: {existing} is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise GisroadsError(f"{what}: cannot write in {existing}: permission denied")


def _error_text(err: Exception, args) -> str:
    """The one-line error, naming the command's own options where it has them."""
    from .io.raster import NotGeoreferencedError
    if isinstance(err, NotGeoreferencedError) and hasattr(args, "crs") \
            and err.path == Path(args.input):
        return (f"{err.path}: the image has no georeferencing; give its pixel size and "
                "projected CRS with --pixel METRES --crs CRS (e.g. --pixel 0.3 --crs "
                "EPSG:32633)")
    return str(err)


def _cancel_on_sigterm():
    """SIGTERM (``kill``, a program stopping its gisroads run) cancels like Ctrl-C: the
    outputs being written are removed (they are written to temporary files) and the exit
    status is 130. The job stops at its next progress report, where the cancel raises
    (raised in the handler itself it can land inside a C callback, which prints it and
    drops it: threadpoolctl's, or Dask's start-up). Returns the previous handler (None
    outside the main thread, where Python delivers no signal)."""
    import threading
    if threading.current_thread() is not threading.main_thread():
        return None

    def cancel(signum, frame):
        _ProgressBar.terminated = True
    return signal.signal(signal.SIGTERM, cancel)


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    notes = []
    _ProgressBar.json_lines = getattr(args, "progress_json", False)
    _ProgressBar.terminated = False
    previous = None
    try:
        check_outputs(args)
        previous = _cancel_on_sigterm()
        with reported_warnings(notes.append):
            status = args.func(args)
        for note in notes:  # after the progress bar and the result
            print(f"gisroads: warning: {note}", file=sys.stderr)
        return status
    except BrokenPipeError:
        # the reader went away (``gisroads info --json f | head``): stop quietly, as a
        # command killed by SIGPIPE does, and keep Python's exit flush from raising again
        devnull = os.open(os.devnull, os.O_WRONLY)
        for stream in (sys.stdout, sys.stderr):
            os.dup2(devnull, stream.fileno())
        return 141
    except INPUT_ERRORS as err:
        _ProgressBar.close_all()
        print(f"gisroads: error: {_error_text(err, args)}", file=sys.stderr)
        return 2
    except (Cancelled, KeyboardInterrupt):
        _ProgressBar.close_all()
        print("gisroads: cancelled; nothing written", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
