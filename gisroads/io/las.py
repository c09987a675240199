"""LAS/LAZ point clouds (laspy + lazrs): read in chunks, report CRS and units, write streamed.

Coordinates are handed to the algorithms in metres. A file whose CRS is in feet (Autzen's
Oregon Lambert in US survey feet) is scaled to metres, and the CRS is rewritten with metre
axes (the same projection: scaling projected coordinates is exactly a change of axis unit),
so ``PointCloud.crs`` always matches ``PointCloud.xyz``. ``PointCloud.source_crs`` keeps the
file's own CRS, which is the CRS outputs are written in.
"""
from __future__ import annotations

from copy import deepcopy
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable, Iterator

import laspy
import numpy as np
from pyproj import CRS

from ..errors import GisroadsError
from .vector import atomic_path

DEFAULT_CHUNK = 2_000_000
"""Points per chunk when streaming (about 100 MB of working arrays)."""

#: ASPRS point classes (LAS 1.4, table 17) that gisroads reads or writes: ground, road
#: surface (what the road tagging writes), bridge deck; low vegetation, building and water,
#: which are never the road level; low and high noise.
GROUND_CLASS, ROAD_SURFACE_CLASS, BRIDGE_DECK_CLASS = 2, 11, 17
NOT_ROAD_CLASSES = (3, 6, 9)
NOISE_CLASSES = (7, 18)

#: GeoTIFF VerticalUnitsGeoKey codes (EPSG unit codes) seen in LAS files.
_GEOTIFF_VERTICAL_UNITS = {9001: ("metre", 1.0), 9002: ("foot", 0.3048),
                           9003: ("US survey foot", 0.3048006096012192)}


class LasError(GisroadsError):
    """A LAS/LAZ file that cannot be used: missing, empty, truncated or corrupt."""


@dataclass(frozen=True)
class LasUnits:
    """Linear units of a LAS file and their factors to metres (None: unknown or angular)."""

    horizontal: str
    horizontal_to_m: float | None
    vertical: str
    vertical_to_m: float | None


@dataclass
class PointCloud:
    """Points in metres with the attributes the road methods use.

    Attributes
    ----------
    xyz : ndarray, shape (n, 3), float64
        Metres, in ``crs``.
    intensity : ndarray of uint16 or None
        None when the file has no intensity (all zero).
    classification, return_number, number_of_returns : ndarray of uint8
    crs : pyproj.CRS or None
        The metre-based working CRS of ``xyz``.
    source_crs : pyproj.CRS or None
        The file's CRS (outputs are written in it).
    units : LasUnits
    """

    xyz: np.ndarray
    intensity: np.ndarray | None
    classification: np.ndarray
    return_number: np.ndarray
    number_of_returns: np.ndarray
    crs: CRS | None = None
    source_crs: CRS | None = None
    units: LasUnits = field(default_factory=lambda: LasUnits("metre", 1.0, "metre", 1.0))

    def __len__(self) -> int:
        return len(self.xyz)


#: LASzip's first compressor: the points of the whole file form one stream that starts right
#: at the point-data offset, with no chunk table and no offset to one (LAS 1.0-1.2 era).
_LASZIP_POINTWISE = 1
#: Byte offset of the chunk size (uint32) in the LASzip VLR's record data.
_LASZIP_CHUNK_SIZE_AT = 12


def _laszip_compressor(header: laspy.LasHeader) -> int | None:
    """The compressor code of a LAZ file's LASzip VLR (1 pointwise, 2 pointwise chunked,
    3 layered chunked), or None when the file has no LASzip VLR."""
    laszip = header.vlrs.get("LasZipVlr")
    return int.from_bytes(laszip[0].record_data[:2], "little") if laszip else None


def _check_structure(path: Path, header: laspy.LasHeader) -> None:
    """Refuse empty and truncated files from the header alone (no point is decoded).

    A chunked LAZ file cut short has lost the chunk table its first 8 point bytes point to.
    A pointwise LAZ file has no chunk table, so its truncation shows only when its points
    are decoded (:func:`iter_las_chunks` reports it as corrupt point data).
    """
    size = path.stat().st_size
    if header.point_count == 0:
        raise LasError(f"{path}: the file holds no points")
    start = header.offset_to_point_data
    if header.are_points_compressed:
        if _laszip_compressor(header) == _LASZIP_POINTWISE:
            # Its first point is stored raw: at least that much must follow the header.
            if size < start + header.point_format.size:
                raise LasError(f"{path}: truncated LAZ file (no point data)")
            return
        with open(path, "rb") as f:
            f.seek(start)
            raw = f.read(8)
        if len(raw) < 8:
            raise LasError(f"{path}: truncated LAZ file (no point data)")
        chunk_table = int.from_bytes(raw, "little", signed=True)
        # LAZ writers put the chunk table after the points and its offset before them;
        # a file cut short loses the table, so the offset points past the end.
        if chunk_table != -1 and not start < chunk_table < size:
            raise LasError(f"{path}: truncated LAZ file ({size} bytes; its chunk table"
                           f" should start at byte {chunk_table})")
    else:
        expected = start + header.point_count * header.point_format.size
        if size < expected:
            raise LasError(f"{path}: truncated LAS file ({size} bytes, "
                           f"{expected} expected for {header.point_count} points)")


#: What a :class:`PointCloud` holds of a point (the layers of LAS 1.4's point formats 6-10
#: that are decoded; GPS time, scan angle, colours and the rest are skipped: a third less
#: decoding on an IGN LiDAR HD tile).
_DECODED = (laspy.DecompressionSelection.XY_RETURNS_CHANNEL | laspy.DecompressionSelection.Z
            | laspy.DecompressionSelection.CLASSIFICATION
            | laspy.DecompressionSelection.INTENSITY)


def _open(path, *, decoded=laspy.DecompressionSelection.all()) -> laspy.LasReader:
    """A reader of ``path``, checked; ``decoded``: the LAZ layers to decode."""
    path = Path(path)
    if not path.exists():
        raise LasError(f"{path}: no such file")
    try:
        reader = laspy.open(path, decompression_selection=decoded)
    except Exception as err:  # laspy raises several unrelated types for a bad header
        raise LasError(f"{path}: not a readable LAS/LAZ file ({err})") from None
    try:
        _check_structure(path, reader.header)
    except LasError:
        reader.close()
        raise
    if reader.header.are_points_compressed and \
            _laszip_compressor(reader.header) == _LASZIP_POINTWISE:
        _decode_pointwise(reader)
    return reader


def _decode_pointwise(reader: laspy.LasReader) -> None:
    """Set up an opened pointwise LAZ file for lazrs's sequential decoder (made on the
    first read): its parallel decoder needs a chunk table, and laspy would try it first and
    log its failure. A pointwise stream is one chunk whatever its VLR's chunk size says, but
    lazrs takes the 0 that the first LASzip releases wrote (like 2**32 - 1) for variable-size
    chunks, which need a chunk table: such a size is replaced, in memory, by LASzip's default.
    """
    reader.laz_backend = laspy.LazBackend.Lazrs
    laszip = reader.header.vlrs.get("LasZipVlr")[0]
    record = bytearray(laszip.record_data)
    at = slice(_LASZIP_CHUNK_SIZE_AT, _LASZIP_CHUNK_SIZE_AT + 4)
    if int.from_bytes(record[at], "little") in (0, 2**32 - 1):
        record[at] = (50_000).to_bytes(4, "little")
        laszip.record_data = bytes(record)


def _vertical_unit_from_geokeys(header: laspy.LasHeader) -> tuple[str, float] | None:
    for vlr in header.vlrs:
        if getattr(vlr, "record_id", None) == 34735 and hasattr(vlr, "geo_keys"):
            for key in vlr.geo_keys:
                if key.id == 4099:
                    return _GEOTIFF_VERTICAL_UNITS.get(key.value_offset)
    return None


def las_crs(header: laspy.LasHeader) -> CRS | None:
    """The file's CRS from its WKT or GeoTIFF VLRs, or None."""
    try:
        return header.parse_crs()
    except Exception:  # a malformed CRS VLR is the same, to a user, as no CRS
        return None


def las_units(header: laspy.LasHeader, crs: CRS | None) -> LasUnits:
    """Horizontal and vertical units, from the CRS (compound or not) and the GeoTIFF keys."""
    if crs is None:
        horizontal, h_factor = "unknown (assumed metre)", 1.0
        vertical, v_factor = horizontal, 1.0
    else:
        horizontal_crs = crs.sub_crs_list[0] if crs.is_compound else crs
        axis = horizontal_crs.axis_info[0]
        horizontal = axis.unit_name
        h_factor = axis.unit_conversion_factor if axis.unit_code != "9122" and \
            not horizontal_crs.is_geographic else None
        vertical, v_factor = horizontal, h_factor if h_factor is not None else 1.0
        if crs.is_compound and len(crs.sub_crs_list) > 1:
            v_axis = crs.sub_crs_list[1].axis_info[0]
            vertical, v_factor = v_axis.unit_name, v_axis.unit_conversion_factor
    from_keys = _vertical_unit_from_geokeys(header)
    if from_keys is not None and not (crs is not None and crs.is_compound):
        vertical, v_factor = from_keys
    return LasUnits(horizontal, h_factor, vertical, v_factor)


def metre_crs(crs: CRS | None, units: LasUnits) -> CRS | None:
    """The same CRS with metre axes when its axes are in another linear unit."""
    if crs is None or units.horizontal_to_m in (None, 1.0):
        return crs
    horizontal = crs.sub_crs_list[0] if crs.is_compound else crs
    spec = horizontal.to_json_dict()
    for axis in spec.get("coordinate_system", {}).get("axis", []):
        axis["unit"] = "metre"
    spec.pop("id", None)
    spec["name"] = f"{spec.get('name', 'CRS')} (metre axes)"
    return CRS.from_json_dict(spec)


def _cloud_from_points(points, crs, source_crs, units: LasUnits) -> PointCloud:
    h = units.horizontal_to_m or 1.0
    v = units.vertical_to_m or 1.0
    xyz = np.column_stack([np.asarray(points.x) * h, np.asarray(points.y) * h,
                           np.asarray(points.z) * v])
    intensity = np.asarray(points.intensity, dtype=np.uint16)
    return PointCloud(
        xyz=xyz, intensity=intensity, classification=np.asarray(points.classification, np.uint8),
        return_number=np.asarray(points.return_number, np.uint8),
        number_of_returns=np.asarray(points.number_of_returns, np.uint8),
        crs=crs, source_crs=source_crs, units=units)


def iter_las_chunks(path, *, chunk_size: int = DEFAULT_CHUNK,
                    bbox: tuple[float, float, float, float] | None = None,
                    start: int = 0, stop: int | None = None,
                    parallel_decoding: bool = True) -> Iterator[PointCloud]:
    """Stream a LAS/LAZ file as :class:`PointCloud` chunks, so any file size fits in memory.

    Parameters
    ----------
    path : str or Path
    chunk_size : int
        Points decoded at a time.
    bbox : (xmin, ymin, xmax, ymax), optional
        In metres of the working CRS; only points inside are yielded (empty chunks skipped).
    start, stop : int, optional
        Only the points ``start:stop`` of the file, in its order (a LAZ file is decoded
        from the compressed chunk holding ``start``, not from its beginning).
    parallel_decoding : bool
        Decode a LAZ file's compressed chunks on every core (False: on this thread only,
        as a task on one worker of several should).

    Raises
    ------
    LasError
        Missing, empty, truncated or corrupt file (also mid-stream, for a corrupt chunk).
    """
    with _open(path, decoded=_DECODED) as reader:
        if not parallel_decoding:
            reader.laz_backend = laspy.LazBackend.Lazrs
        source_crs = las_crs(reader.header)
        units = las_units(reader.header, source_crs)
        crs = metre_crs(source_crs, units)
        try:
            left = reader.header.point_count if stop is None else stop
            left = min(left, reader.header.point_count) - start
            if start:
                reader.seek(start)
            while left > 0:
                points = reader.read_points(min(chunk_size, left))
                if len(points) == 0:
                    break
                left -= len(points)
                cloud = _cloud_from_points(points, crs, source_crs, units)
                if bbox is not None:
                    x, y = cloud.xyz[:, 0], cloud.xyz[:, 1]
                    keep = (x >= bbox[0]) & (y >= bbox[1]) & (x <= bbox[2]) & (y <= bbox[3])
                    cloud = subset(cloud, keep)
                if len(cloud):
                    yield cloud
        except LasError:
            raise
        except Exception as err:
            raise LasError(f"{path}: corrupt point data ({err})") from None


def subset(cloud: PointCloud, keep) -> PointCloud:
    """Points selected by a boolean mask or index array."""
    return PointCloud(cloud.xyz[keep], None if cloud.intensity is None else cloud.intensity[keep],
                      cloud.classification[keep], cloud.return_number[keep],
                      cloud.number_of_returns[keep], cloud.crs, cloud.source_crs, cloud.units)


def concatenate(clouds: list[PointCloud]) -> PointCloud:
    """One cloud from chunks of the same file."""
    first = clouds[0]
    has_intensity = all(c.intensity is not None for c in clouds)
    return PointCloud(
        np.concatenate([c.xyz for c in clouds]),
        np.concatenate([c.intensity for c in clouds]) if has_intensity else None,
        *(np.concatenate([getattr(c, a) for c in clouds])
          for a in ("classification", "return_number", "number_of_returns")),
        crs=first.crs, source_crs=first.source_crs, units=first.units)


def read_las(path, *, bbox=None, chunk_size: int = DEFAULT_CHUNK) -> PointCloud:
    """Read a whole LAS/LAZ file (or the part inside ``bbox``) into memory.

    ``intensity`` is None when every point has intensity 0 (the file records none).
    See :func:`iter_las_chunks` for the parameters and errors.
    """
    chunks = list(iter_las_chunks(path, chunk_size=chunk_size, bbox=bbox))
    if not chunks:
        raise LasError(f"{path}: no points inside {bbox}")
    cloud = concatenate(chunks)
    if cloud.intensity is not None and not cloud.intensity.any():
        cloud.intensity = None
    return cloud


def cloud_crs(path) -> tuple[CRS | None, CRS | None]:
    """``(working CRS in metres, the file's own CRS)`` of a LAS/LAZ file, from its header."""
    with _open(path) as reader:
        source = las_crs(reader.header)
        return metre_crs(source, las_units(reader.header, source)), source


def las_info(path) -> dict:
    """What a GIS user asks of a LAS/LAZ file first, from its header (no point decoded).

    Returns
    -------
    dict
        ``path, format ('LAS'|'LAZ'), version, point_format, point_count, crs (name),
        epsg, horizontal_unit, vertical_unit, unit_to_metre, extent (xmin, ymin, xmax, ymax
        in file units), extent_m (in metres), z_range, z_range_m, extra_dimensions``.
    """
    with _open(path) as reader:
        h = reader.header
        crs = las_crs(h)
        units = las_units(h, crs)
    hf, vf = units.horizontal_to_m or 1.0, units.vertical_to_m or 1.0
    mins, maxs = np.asarray(h.mins, float), np.asarray(h.maxs, float)
    standard = set(laspy.PointFormat(h.point_format.id).dimension_names)
    return {
        "path": str(path),
        "format": "LAZ" if h.are_points_compressed else "LAS",
        "version": f"{h.version.major}.{h.version.minor}",
        "point_format": h.point_format.id,
        "point_count": int(h.point_count),
        "crs": crs.name if crs is not None else None,
        "epsg": crs.to_epsg() if crs is not None else None,
        "horizontal_unit": units.horizontal,
        "vertical_unit": units.vertical,
        "unit_to_metre": units.horizontal_to_m,
        "extent": [mins[0], mins[1], maxs[0], maxs[1]],
        "extent_m": [mins[0] * hf, mins[1] * hf, maxs[0] * hf, maxs[1] * hf],
        "z_range": [mins[2], maxs[2]],
        "z_range_m": [mins[2] * vf, maxs[2] * vf],
        "extra_dimensions": [d for d in h.point_format.dimension_names if d not in standard],
    }


class LasPointWriter:
    """Stream points into a new LAS/LAZ file (format 6, LAS 1.4, WKT CRS), atomically.

    Use as a context manager; :meth:`write` takes metre coordinates chunk by chunk. The file
    appears under its name only when the context exits without error.

    Parameters
    ----------
    path : str or Path
        ``.laz`` is compressed with lazrs (parallel), ``.las`` is not.
    crs : pyproj.CRS or None
    offset : (x, y, z)
        Coordinate offset; keep it near the data so 1 mm scale fits in 32 bits.
    scale : float
        Coordinate resolution in metres.
    """

    def __init__(self, path, *, crs: CRS | None, offset=(0.0, 0.0, 0.0), scale: float = 0.001):
        self.path = Path(path)
        self.crs = crs
        self.offset = np.asarray(offset, float)
        self.scale = scale
        self.count = 0

    def __enter__(self):
        self._atomic = atomic_path(self.path)
        tmp = self._atomic.__enter__()
        header = laspy.LasHeader(point_format=6, version="1.4")
        header.offsets = self.offset
        header.scales = np.full(3, self.scale)
        if self.crs is not None:
            header.add_crs(self.crs)
        compressed = self.path.suffix.lower() == ".laz"
        self._writer = laspy.open(tmp, mode="w", header=header, do_compress=compressed,
                                  laz_backend=laspy.LazBackend.LazrsParallel if compressed
                                  else None)
        return self

    def write(self, xyz, *, intensity=None, classification=None, return_number=None,
              number_of_returns=None) -> None:
        """Append points; absent attributes get 0 (intensity, class) or 1 (returns)."""
        n = len(xyz)
        if n == 0:
            return
        record = laspy.ScaleAwarePointRecord.zeros(n, header=self._writer.header)
        record.x, record.y, record.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        if intensity is not None:
            record.intensity = intensity
        if classification is not None:
            record.classification = classification
        record.return_number = np.ones(n, np.uint8) if return_number is None else return_number
        record.number_of_returns = (np.ones(n, np.uint8) if number_of_returns is None
                                    else number_of_returns)
        self._writer.write_points(record)
        self.count += n

    def __exit__(self, *exc):
        self._writer.close()
        return self._atomic.__exit__(*exc)


def write_classified(source, target, classify: Callable[[PointCloud], np.ndarray], *,
                     chunk_size: int = DEFAULT_CHUNK) -> int:
    """Copy a LAS/LAZ file with a new classification, chunk by chunk, atomically.

    Every other attribute, VLR and the point format are kept as they are; a LAS 1.0 file
    is written as LAS 1.2 (the same point layouts; laspy writes no 1.0).

    Parameters
    ----------
    source, target : str or Path
        ``target`` is compressed when it ends in ``.laz``.
    classify : callable
        Gets each chunk as a :class:`PointCloud` (metres) and returns its new class codes.

    Returns
    -------
    int
        Number of points whose class changed.
    """
    target = Path(target)
    changed = 0
    with _open(source) as reader, atomic_path(target) as tmp:
        source_crs = las_crs(reader.header)
        units = las_units(reader.header, source_crs)
        crs = metre_crs(source_crs, units)
        compressed = target.suffix.lower() == ".laz"
        header = reader.header
        if header.version.minor == 0:  # laspy writes no LAS 1.0; 1.2 has its point layouts
            header = deepcopy(header)
            header.version = laspy.header.Version(1, 2)
        with laspy.open(tmp, mode="w", header=header, do_compress=compressed) as writer:
            for points in reader.chunk_iterator(chunk_size):
                new = np.asarray(classify(_cloud_from_points(points, crs, source_crs, units)),
                                 dtype=np.uint8)
                if new.shape != (len(points),):
                    raise ValueError(f"classify returned {new.shape} classes for "
                                     f"{len(points)} points")
                changed += int(np.count_nonzero(np.asarray(points.classification) != new))
                points.classification = new
                writer.write_points(points)
    return changed

