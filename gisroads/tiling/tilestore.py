"""Read the input once: one streaming pass buckets the points into the tile grid on disk.

A road tile reads only its points: instead of decoding the whole file once per tile (a cost
growing with tiles x points, i.e. with the square of the area), the input (one LAS/LAZ file,
several, a folder of them or a glob: the 1 km² tiles agencies deliver) is decoded once,
chunk by chunk, and every point is appended to the file of its *stride cell*: the cells of
side ``tile_m - overlap_m`` from the grid's origin. A tile of the grid starts on a cell
corner and spans ``floor(tile_m / stride) + 1`` cells along each axis, so it reads those
cells and keeps the points inside its bounds (edges included, as ``read_las(bbox=...)``).
Each point is stored once however many tiles hold it, and the points of several files that
overlap fall into the same cells: a tile over two files sees both.

The pass is cut into *parts* of :data:`PART_POINTS` consecutive points of one file, which
run as tasks like the tiles (:func:`gisroads.parallel.for_each_result`: in this process, or
one per worker at a time), each decoding its own range of the file (a LAZ file from the
compressed chunk holding its first point) into its own cell files. The parts do not depend
on the number of workers, and a cell's points are its parts' files read in their order: the
store, and every tile's points in their order, are the same however many workers read it.

Memory stays flat: a part holds one chunk, a tile read holds one tile and one cell.
The store lives in a folder (``work_dir``) under a key of the inputs (path, size, mtime)
and the grid; it appears under its name only once complete (built in a temporary folder,
then renamed), so a killed pass leaves nothing that a later run would trust.

Cell files are raw little-endian records (:data:`RECORD`), the coordinates in metres of
the working CRS exactly as :func:`gisroads.io.las.read_las` gives them.
"""
from __future__ import annotations

import glob as _glob
import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from pyproj import CRS

from ..errors import GisroadsError
from ..io.las import DEFAULT_CHUNK, LasError, PointCloud, cloud_crs, iter_las_chunks, las_info
from ..progress import Progress, report
from .tiles import OVERLAP_M, TILE_M, Tile, tile_grid

#: One stored point.
RECORD = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("intensity", "<u2"),
                   ("classification", "u1"), ("return_number", "u1"),
                   ("number_of_returns", "u1"), ("index", "<i8")])
"""``index``: the point's position in the inputs (file after file, in their sorted order),
which classifies points back into a copy of the file."""
LAS_SUFFIXES = (".las", ".laz")
STORE_VERSION = 3
#: Points of the input one task of the reading pass decodes and buckets.
PART_POINTS = 4_000_000


def las_inputs(source) -> list[Path]:
    """The LAS/LAZ files of ``source``: a file, a folder (its ``*.las``/``*.laz``), a glob
    pattern, or a list of any of those; sorted, without duplicates.

    Raises
    ------
    LasError
        When nothing matches, or a named file does not exist.
    """
    items = list(source) if isinstance(source, (list, tuple)) else [source]
    found: list[Path] = []
    for item in items:
        text = str(item)
        path = Path(item)
        if path.is_dir():
            found += [p for p in path.iterdir() if p.suffix.lower() in LAS_SUFFIXES
                      and p.is_file()]
        elif path.exists():
            found.append(path)
        elif _glob.has_magic(text):
            found += [Path(p) for p in _glob.glob(text)
                      if Path(p).suffix.lower() in LAS_SUFFIXES and Path(p).is_file()]
        else:
            raise LasError(f"{path}: no such file")
    unique = sorted({p.resolve(): p for p in found}.items())
    if not unique:
        raise LasError(f"{source}: no LAS/LAZ file found")
    return [p for _, p in unique]


def inputs_key(paths: list[Path]) -> list[list]:
    """What identifies the inputs: resolved path, size and modification time of each."""
    out = []
    for p in paths:
        st = Path(p).stat()
        out.append([str(Path(p).resolve()), st.st_size, st.st_mtime_ns])
    return out


def digest(value) -> str:
    """A short stable hash of a JSON-able value."""
    text = json.dumps(value, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def file_digest(path) -> str:
    """A short hash of a file's bytes."""
    return hashlib.sha1(Path(path).read_bytes()).hexdigest()[:16]


def code_fingerprint(sources, modules=()) -> str:
    """A short hash of gisroads' own source files and of libraries' versions, for the key
    of finished work kept in a work folder: work done by another version of the code is not
    reused.

    Parameters
    ----------
    sources : sequence of str
        Glob patterns relative to the ``gisroads`` package folder (``"lidar/*.py"``).
    modules : sequence of module
        Libraries whose ``__version__`` the work depends on.
    """
    sha = hashlib.sha1()
    root = Path(__file__).resolve().parents[1]
    for source in sorted({p for pattern in sources for p in root.glob(pattern) if p.is_file()}):
        sha.update(str(source.relative_to(root)).encode())
        sha.update(source.read_bytes())
    for module in modules:
        sha.update(f"{module.__name__} {module.__version__}".encode())
    return sha.hexdigest()[:16]


def inputs_crs(paths: list[Path]) -> tuple[CRS | None, CRS | None]:
    """``(working metre CRS, file CRS)`` shared by all inputs (LasError when they differ)."""
    first = cloud_crs(paths[0])
    for p in paths[1:]:
        other = cloud_crs(p)
        if other[0] != first[0]:
            raise LasError(f"{p}: its CRS ({other[1].name if other[1] else None}) differs "
                           f"from {paths[0]}'s ({first[1].name if first[1] else None})")
    return first


def _cell_name(row: int, col: int, part: int) -> str:
    return f"{row}_{col}.{part}.bin"


@dataclass
class TileStore:
    """The points of one or several LAS/LAZ files bucketed by stride cell on disk.

    Attributes
    ----------
    folder : Path
    inputs : list of Path
    extent : (xmin, ymin, xmax, ymax)
        Union of the inputs' header extents, metres.
    point_count : int
        Points stored.
    tile_m, overlap_m : float
    crs : (working CRS, file CRS)
    cells : dict (row, col) -> number of points
    parts : dict (row, col) -> tuple of int
        The parts of the reading pass that hold points of the cell, in order.
    key : str
        Hash of the inputs and the grid: what a result computed from this store is keyed by.
    """

    folder: Path
    inputs: list[Path]
    extent: tuple[float, float, float, float]
    point_count: int
    tile_m: float
    overlap_m: float
    crs: tuple[CRS | None, CRS | None]
    cells: dict
    parts: dict
    key: str
    temporary: Path | None = None
    """The temporary folder holding the store, when no work folder was given."""

    @property
    def stride(self) -> float:
        return self.tile_m - self.overlap_m

    @property
    def reach(self) -> int:
        """Cells a tile spans along each axis."""
        return int(np.floor(self.tile_m / self.stride)) + 1

    @property
    def tiles(self) -> list[Tile]:
        """The tiles holding points (:func:`gisroads.tiling.tiles.tile_grid`), row by row."""
        if not self.cells:
            return []
        cells = np.array(sorted(self.cells), float)
        centres = (cells[:, ::-1] + 0.5) * self.stride + np.array(self.extent[:2])
        return tile_grid(self.extent, tile_m=self.tile_m, overlap_m=self.overlap_m,
                         points_xy=[centres])

    def tile_point_count(self, tile: Tile) -> int:
        """Points in the cells the tile reads (an upper bound of its points)."""
        return sum(self.cells.get((r, c), 0) for r in range(tile.row, tile.row + self.reach)
                   for c in range(tile.col, tile.col + self.reach))

    def cells_near(self, xy, reach_m: float) -> list[tuple[int, int]]:
        """The stored cells holding points within ``reach_m`` (XY) of any position ``xy``."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        if len(xy) == 0 or not self.cells:
            return []
        cells = np.unique(np.floor((xy - np.array(self.extent[:2])) / self.stride)
                          .astype(np.int64)[:, ::-1], axis=0)
        k = int(np.ceil(reach_m / self.stride))
        ring = np.stack(np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1)), -1)
        near = np.unique((cells[:, None, :] + ring.reshape(1, -1, 2)).reshape(-1, 2), axis=0)
        return [(int(r), int(c)) for r, c in near if (int(r), int(c)) in self.cells]

    def iter_cells(self, cells=None):
        """``(index, cloud)`` of every stored cell (or of ``cells``), row by row: the points
        of the cell and their positions in the inputs (:data:`RECORD`)."""
        for r, c in sorted(self.cells if cells is None else cells):
            points = self._cell(r, c)
            yield np.ascontiguousarray(points["index"]), self._cloud(points)

    def _cell(self, row: int, col: int) -> np.ndarray:
        """The records of a cell: those of each part holding it, in the parts' order."""
        parts = [np.fromfile(self.folder / "cells" / _cell_name(row, col, part), RECORD)
                 for part in self.parts[(row, col)]]
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def _cloud(self, points: np.ndarray) -> PointCloud:
        xyz = np.empty((len(points), 3))
        xyz[:, 0], xyz[:, 1], xyz[:, 2] = points["x"], points["y"], points["z"]
        return PointCloud(xyz, np.ascontiguousarray(points["intensity"]),
                          np.ascontiguousarray(points["classification"]),
                          np.ascontiguousarray(points["return_number"]),
                          np.ascontiguousarray(points["number_of_returns"]),
                          crs=self.crs[0], source_crs=self.crs[1])

    def read(self, tile: Tile) -> PointCloud | None:
        """The points inside the tile's bounds (edges included), or None when it has none.

        ``intensity`` is None when all of them have intensity 0, as in ``read_las``.
        """
        xmin, ymin, xmax, ymax = tile.bounds
        parts = []
        for r in range(tile.row, tile.row + self.reach):
            for c in range(tile.col, tile.col + self.reach):
                if (r, c) not in self.cells:
                    continue
                points = self._cell(r, c)
                keep = ((points["x"] >= xmin) & (points["y"] >= ymin)
                        & (points["x"] <= xmax) & (points["y"] <= ymax))
                if keep.any():
                    parts.append(points[keep])
                del points
        if not parts:
            return None
        points = np.concatenate(parts)
        del parts
        cloud = self._cloud(points)
        if not cloud.intensity.any():
            cloud.intensity = None
        return cloud

    def remove(self) -> None:
        """Delete the store (and its temporary folder)."""
        shutil.rmtree(self.folder, ignore_errors=True)
        if self.temporary is not None:
            shutil.rmtree(self.temporary, ignore_errors=True)


def _manifest(store: TileStore) -> dict:
    return {"version": STORE_VERSION, "inputs": [str(p) for p in store.inputs],
            "extent": list(store.extent), "point_count": store.point_count,
            "tile_m": store.tile_m, "overlap_m": store.overlap_m, "key": store.key,
            "cells": [[r, c, n, list(store.parts[(r, c)])]
                      for (r, c), n in sorted(store.cells.items())]}


def _load(folder: Path, paths: list[Path], crs) -> TileStore:
    manifest = json.loads((folder / "manifest.json").read_text())
    return TileStore(folder, paths, tuple(manifest["extent"]), manifest["point_count"],
                     manifest["tile_m"], manifest["overlap_m"], crs,
                     {(r, c): n for r, c, n, _ in manifest["cells"]},
                     {(r, c): tuple(parts) for r, c, _, parts in manifest["cells"]},
                     manifest["key"])


def open_store(source, work_dir=None, *, tile_m: float = TILE_M, overlap_m: float = OVERLAP_M,
               chunk_size: int = DEFAULT_CHUNK, workers: int = 1, scheduler: str | None = None,
               progress: Progress = None) -> TileStore:
    """The tile store of ``source`` in ``work_dir``: reused when a complete store of the
    same inputs (path, size, mtime) and grid is there, else built in one streaming pass.

    Parameters
    ----------
    source : path, folder, glob or list of them
        LAS/LAZ inputs (see :func:`las_inputs`); they must share one CRS.
    work_dir : path, optional
        Where the store is kept; by default a new temporary folder (remove it with
        :meth:`TileStore.remove`).
    tile_m, overlap_m : float
        The tile grid (:func:`gisroads.tiling.tiles.tile_grid`).
    chunk_size : int
        Points decoded at a time.
    workers, scheduler
        Where the parts of the reading pass run (:func:`gisroads.parallel.for_each_result`);
        the workers of a scheduler must see ``work_dir``.

    Raises
    ------
    LasError
        Missing, unreadable or corrupt inputs, or inputs in different CRSs.
    """
    if not 0 <= overlap_m < tile_m:
        raise GisroadsError(f"overlap_m ({overlap_m}) must be in [0, tile_m={tile_m})")
    paths = las_inputs(source)
    infos = [las_info(p) for p in paths]
    crs = inputs_crs(paths)
    extents = np.array([i["extent_m"] for i in infos], float)
    extent = (float(extents[:, 0].min()), float(extents[:, 1].min()),
              float(extents[:, 2].max()), float(extents[:, 3].max()))
    key = digest({"version": STORE_VERSION, "inputs": inputs_key(paths), "tile_m": tile_m,
                  "overlap_m": overlap_m})
    if work_dir is None:
        root = Path(tempfile.mkdtemp(prefix="gisroads-tiles-"))
        folder = root / "store"
    else:
        root = Path(work_dir)
        root.mkdir(parents=True, exist_ok=True)
        folder = root / f"store-{key}"
        if (folder / "manifest.json").exists():
            return _load(folder, paths, crs)
    building = Path(tempfile.mkdtemp(prefix=f".store-{key}-", dir=root))
    try:
        store = _build(building, paths, infos, extent, crs, key, tile_m=tile_m,
                       overlap_m=overlap_m, chunk_size=chunk_size, workers=workers,
                       scheduler=scheduler, progress=progress)
        try:
            os.rename(building, folder)
        except OSError:  # another run finished the same store first
            if not (folder / "manifest.json").exists():
                raise
            shutil.rmtree(building, ignore_errors=True)
        store.folder = folder
        store.temporary = root if work_dir is None else None
        return store
    except BaseException:
        shutil.rmtree(building, ignore_errors=True)
        if work_dir is None:
            shutil.rmtree(root, ignore_errors=True)
        raise


def _bucket_part(folder: Path, origin, stride: float, chunk_size: int,
                 parallel_decoding: bool, part) -> dict:
    """Decode the points ``start:stop`` of one input and append each to the file of its
    stride cell and this part; ``{(row, col): points}``."""
    number, path, start, stop, first_index = part
    cells: dict = {}
    done = first_index
    for chunk in iter_las_chunks(path, chunk_size=chunk_size, start=start, stop=stop,
                                 parallel_decoding=parallel_decoding):
        cell = np.floor((chunk.xyz[:, :2] - origin) / stride).astype(np.int64)
        # one key per cell, ordered row by row; points keep their file order inside
        lo = cell.min(axis=0)
        span = cell.max(axis=0) - lo + 1
        flat = (cell[:, 1] - lo[1]) * span[0] + (cell[:, 0] - lo[0])
        order = np.argsort(flat, kind="stable")
        flat = flat[order]
        starts = np.flatnonzero(np.r_[True, flat[1:] != flat[:-1]])
        ends = np.r_[starts[1:], len(flat)]
        records = np.empty(len(order), RECORD)
        for axis, name in enumerate("xyz"):
            records[name] = chunk.xyz[order, axis]
        records["intensity"] = chunk.intensity[order]
        records["index"] = done + order
        for name in ("classification", "return_number", "number_of_returns"):
            records[name] = getattr(chunk, name)[order]
        for s, e in zip(starts, ends):  # one write per cell the chunk touches
            col = int(flat[s] % span[0] + lo[0])
            row = int(flat[s] // span[0] + lo[1])
            with open(folder / "cells" / _cell_name(row, col, number), "ab") as f:
                records[s:e].tofile(f)
            cells[(row, col)] = cells.get((row, col), 0) + int(e - s)
        done += len(chunk)
    return cells


def _build(folder: Path, paths, infos, extent, crs, key, *, tile_m, overlap_m, chunk_size,
           workers, scheduler, progress) -> TileStore:
    from ..parallel import for_each_result

    (folder / "cells").mkdir()
    parts, first_index = [], 0
    for path, info in zip(paths, infos):
        count = info["point_count"]
        for start in range(0, count, PART_POINTS):
            parts.append((len(parts), path, start, min(start + PART_POINTS, count),
                          first_index + start))
        first_index += count
    cells: dict = {}
    holding: dict = {}

    def bucketed(number, counts):
        for cell, n in counts.items():
            cells[cell] = cells.get(cell, 0) + n
            holding.setdefault(cell, []).append(number)
    report(progress, 0.0, f"bucketing {first_index} points into tiles")
    # one thread per worker when the parts run on several (as the tiles' BLAS threads);
    # in this process alone, the file's chunks are decoded on every core
    alone = workers == 1 and scheduler is None
    for_each_result(partial(_bucket_part, folder, np.array(extent[:2]), tile_m - overlap_m,
                            chunk_size, alone), parts, bucketed, workers=workers,
                    scheduler=scheduler, progress=progress, what="parts of the input read")
    report(progress, 1.0, "points bucketed")
    store = TileStore(folder, list(paths), extent, int(sum(cells.values())), float(tile_m),
                      float(overlap_m), crs, cells,
                      {cell: tuple(sorted(numbers)) for cell, numbers in holding.items()}, key)
    manifest = folder / "manifest.json.tmp"
    manifest.write_text(json.dumps(_manifest(store)))
    os.replace(manifest, folder / "manifest.json")  # the store is complete
    return store
