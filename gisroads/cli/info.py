"""``gisroads info``: what a point cloud, raster or vector file holds."""
from pathlib import Path

from .options import add_command
from .report import as_text, print_result


def add_parser(subparsers) -> None:
    p = add_command(
        subparsers, "info", run, "describe a point cloud, raster or vector file",
        "Print what a file holds: for LAS/LAZ its version, point format, point count, "
        "CRS and units (feet are reported and converted), extent; for rasters the size, "
        "bands, CRS and pixel size; for vector files each layer's features and CRS.")
    p.add_argument("file", type=Path, help="LAS/LAZ, GeoTIFF or vector file")


def run(args) -> int:
    from ..jobs import describe_file
    info = describe_file(args.file)
    print_result(info, args.json, _format_info(info))
    return 0


def _format_info(info: dict) -> str:
    if info["kind"] == "vector":
        return "\n".join(
            f"{layer['layer']}: {layer['features']} features, "
            f"{'/'.join(layer['geometry']) or 'no geometry type'}"
            f"{' (declared)' if layer['geometry'] and not layer['features'] else ''}, "
            f"CRS {layer['crs']} (EPSG {layer['epsg']}), "
            + (f"extent {as_text(layer['extent'])}" if layer["extent"] else "no extent")
            for layer in info["layers"])
    lines = [f"{info['path']} ({info['kind']})"]
    for key, value in info.items():
        if key in {"kind", "path"}:
            continue
        if key == "georeferenced" and not value:
            missing = [what for what, there in (("geotransform", info.get("extent")),
                                                ("CRS", info.get("crs"))) if there is None]
            value = (f"no (no {' and no '.join(missing)}; give the road commands its pixel "
                     "size and CRS with --pixel and --crs)")
        lines.append(f"  {key}: {as_text(value)}")
    return "\n".join(lines)
