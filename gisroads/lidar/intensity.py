"""Intensity images of the ground, one per ground level (Zhu & Mordohai, end of section 4.1).

"Since height variations are small in these surfaces, the z coordinate is dropped and 2D
LIDAR intensity images are generated with a resolution of 0.5 m per pixel." Every ground
level of :func:`gisroads.lidar.ground.ground_planes` gets its own band, so a bridge deck and
the road under it are two images rather than one muddle.

Rules, all vectorised:

* **Normalisation.** Over the ground points inside the image, the ``percentiles`` (1st and
  99th) of the raw intensity map to 0 and 1; every point is clipped to [0, 1] *before* cells
  average it, so a few specular returns do not brighten a cell.
* **Cell value**: the mean normalised intensity of the cell's points of that level
  (:func:`numpy.bincount`).
* **Hole filling.** An empty cell is filled when it lies in a gap of at most
  ``fill_radius_m`` between data cells of its level along its row or its column (a
  scan-line gap, up to ~0.6 m in real data, or the cells a thin object hid); it takes the
  Gaussian-weighted mean (normalised convolution, sigma = ``fill_radius_m / 2``, truncated
  at ``fill_radius_m``) of the data cells around it. Wider holes and the outside of the
  data stay NaN. The default radius is 1.5 m, or 2.5 cells when cells are coarser than
  0.6 m: a thinned cloud's coarse cells hold about one ground point each, and a third of
  them are empty by chance (on the 0.29 pts/m² IGN tile at 1.9 m cells, 1.5 m filled
  nothing and 34 % of the cells had a value; 5 m at 2 m cells gave 58 %).
* **Split pulses.** A pulse that gives several returns shares its energy between them: the
  ground seen through a tree crown returns a fraction of a single return's intensity, and
  grass under street trees looks as dark as asphalt (roads seemed 5-7 m wider on the
  synthetic scenes). Given which points are single returns, the intensity of the others
  is divided by that fraction, measured on the data (:func:`split_share`: 0.40 on the
  synthetic scenes, which use 0.4; 0.54 on fusa.laz).
* **Level index**: the highest level with a value (after filling) at each cell, the ground
  seen from above; -1 where no level has one.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from affine import Affine
from pyproj import CRS
from scipy import ndimage

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..io.raster import write_geotiff


@dataclass(frozen=True)
class IntensityImages:
    """Per-level ground intensity rasters on one grid.

    Attributes
    ----------
    image : GeoRaster
        ``(n_levels, rows, cols)`` float32 normalised intensity in [0, 1], NaN for no data.
    level_index : GeoRaster
        ``(rows, cols)`` int16: the highest level with a value at each cell, -1 for none
        (``nodata`` -1).
    count : ndarray of int32, shape (n_levels, rows, cols)
        Points of each level per cell (before filling).
    intensity_range : (float, float)
        Raw intensities mapped to 0 and 1.
    """

    image: GeoRaster
    level_index: GeoRaster
    count: np.ndarray
    intensity_range: tuple[float, float]


def image_grid(bounds, cell_m: float) -> tuple[Affine, tuple[int, int]]:
    """North-up grid of ``cell_m`` cells over ``bounds`` snapped outward to multiples of
    ``cell_m`` (so that the grids of all tiles align).

    Parameters
    ----------
    bounds : (xmin, ymin, xmax, ymax)
        Metres.
    cell_m : float

    Returns
    -------
    transform : affine.Affine
        Upper-left corner at (snapped xmin, snapped ymax), rows going south.
    shape : (rows, cols)
    """
    xmin = np.floor(bounds[0] / cell_m) * cell_m
    ymax = np.ceil(bounds[3] / cell_m) * cell_m
    cols = max(1, int(np.ceil((bounds[2] - xmin) / cell_m - 1e-9)))
    rows = max(1, int(np.ceil((ymax - bounds[1]) / cell_m - 1e-9)))
    return Affine(cell_m, 0.0, xmin, 0.0, -cell_m, ymax), (rows, cols)


CELL_M = 0.5
"""The intensity image cell, metres (Zhu & Mordohai, section 4.2)."""


def auto_cell_m(point_count: int, area_m2: float) -> float:
    """The intensity image cell for a cloud: the paper's 0.5 m, or about one mean point
    spacing (1 / sqrt(density)) for sparser clouds, rounded up to 5 cm."""
    spacing = 1.0 / np.sqrt(max(point_count, 1) / max(area_m2, 1e-9))
    return float(max(CELL_M, np.ceil(spacing * 20.0) / 20.0))


def intensity_images(xyz, intensity, level, *, cell_m: float = CELL_M, bounds=None,
                     crs: CRS | None = None, fill_radius_m: float | None = None,
                     single_return=None,
                     percentiles: tuple[float, float] = (1.0, 99.0)) -> IntensityImages:
    """Project the intensities of the ground points to one image per ground level.

    Rules (normalisation, cell value, hole filling, level index): see the module docstring.

    Parameters
    ----------
    xyz : ndarray, shape (n, 3)
        Metres.
    intensity : ndarray, shape (n,)
        Raw intensities (any unit).
    level : ndarray of int, shape (n,)
        Ground level of every point, -1 for points that are not ground (ignored); from
        :func:`gisroads.lidar.ground.ground_planes`. There are ``level.max() + 1`` bands.
    cell_m : float
        Cell side, metres (paper section 4.1: 0.5 m).
    bounds : (xmin, ymin, xmax, ymax), optional
        Metres, snapped outward to the cell grid; points outside are ignored. Default: the
        ground points' bounds, every ground point inside.
    crs : pyproj.CRS, optional
        Stored with the rasters.
    fill_radius_m : float, optional
        Widest gap filled, and reach of the data that fill it (metres); 0 fills nothing.
        Default: ``max(1.5, 2.5 * cell_m)`` (see the module docstring).
    percentiles : (float, float)
        Percentiles of the raw intensity (0-100) mapped to 0 and 1.
    single_return : ndarray of bool, shape (n,), optional
        True for a point that is the only return of its pulse. When given, only these
        points make the image (see the module docstring, *Split pulses*).

    Returns
    -------
    IntensityImages
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    intensity = np.asarray(intensity, dtype=np.float64)
    level = np.asarray(level)
    if not (len(xyz) == len(intensity) == len(level)):
        raise GisroadsError("xyz, intensity and level must have one entry per point")
    if cell_m <= 0:
        raise GisroadsError("cell_m must be positive")
    if fill_radius_m is None:
        fill_radius_m = max(1.5, 2.5 * cell_m)
    ground = level >= 0
    n_levels = int(level.max()) + 1 if ground.any() else 0
    if bounds is None:
        if not ground.any():
            raise GisroadsError("no ground point, and no bounds to make an empty image over")
        low, high = xyz[ground, :2].min(axis=0), xyz[ground, :2].max(axis=0)
        xmin, ymax = np.floor(low[0] / cell_m) * cell_m, np.ceil(high[1] / cell_m) * cell_m
        # Cells are closed on their west and north sides: a point on a grid line at the
        # east or south end of the data needs one more column or row.
        cols = int(np.floor((high[0] - xmin) / cell_m)) + 1
        rows = int(np.floor((ymax - low[1]) / cell_m)) + 1
        bounds = (xmin, ymax - rows * cell_m, xmin + cols * cell_m, ymax)
    transform, (rows, cols) = image_grid(bounds, cell_m)

    col = np.floor((xyz[:, 0] - transform.c) / cell_m).astype(np.int64)
    row = np.floor((transform.f - xyz[:, 1]) / cell_m).astype(np.int64)
    inside = ground & (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
    gain = np.ones(len(xyz))
    if single_return is not None:
        single_return = np.asarray(single_return, dtype=bool)
        if len(single_return) != len(xyz):
            raise GisroadsError("single_return must have one entry per point")
        gain[~single_return] = 1.0 / split_share(intensity, single_return, inside,
                                                  (level * rows + row) * cols + col)
    intensity = intensity * gain
    if inside.any():
        lo, hi = np.percentile(intensity[inside], percentiles)
    else:
        lo, hi = 0.0, 1.0
    value = np.clip((intensity[inside] - lo) / max(hi - lo, np.finfo(float).tiny), 0.0, 1.0)
    flat = (level[inside].astype(np.int64) * rows + row[inside]) * cols + col[inside]
    size = n_levels * rows * cols
    count = np.bincount(flat, minlength=size).reshape(n_levels, rows, cols)
    total = np.bincount(flat, weights=value, minlength=size).reshape(n_levels, rows, cols)
    with np.errstate(invalid="ignore", divide="ignore"):
        image = (total / count).astype(np.float32)  # NaN where count is 0
    for k in range(n_levels):  # a few levels
        image[k] = fill_holes(image[k], radius_cells=fill_radius_m / cell_m)

    level_index = np.full((rows, cols), -1, np.int16)
    for k in range(n_levels):  # upwards, so the highest level with a value wins
        level_index[np.isfinite(image[k])] = k
    return IntensityImages(
        image=GeoRaster(image, transform, crs, nodata=np.nan),
        level_index=GeoRaster(level_index, transform, crs, nodata=-1),
        count=count.astype(np.int32), intensity_range=(float(lo), float(hi)))


def split_share(intensity, single_return, use, cell) -> float:
    """Share of a pulse's energy that a return of a split pulse keeps, measured on the data.

    In cells holding both single returns and returns of split pulses of one ground level
    (the edge of a tree crown), both see the same ground: the median over such cells of
    the ratio of the split returns' mean intensity to the single returns' is the share.
    1 when no cell holds both.
    """
    single_return = np.asarray(single_return, bool)
    cells, index = np.unique(cell[use], return_inverse=True)
    value, single = intensity[use], single_return[use]
    n_single = np.bincount(index, single, len(cells))
    n_split = np.bincount(index, ~single, len(cells))
    sum_single = np.bincount(index, np.where(single, value, 0.0), len(cells))
    sum_split = np.bincount(index, np.where(single, 0.0, value), len(cells))
    both = (n_single > 0) & (n_split > 0) & (sum_single > 0)
    if not both.any():
        return 1.0
    ratio = (sum_split[both] / n_split[both]) / (sum_single[both] / n_single[both])
    return float(np.clip(np.median(ratio), 0.05, 1.0))


def fill_holes(image: np.ndarray, *, radius_cells: float) -> np.ndarray:
    """Fill the NaN cells of an image that lie in narrow gaps (see the module docstring).

    Parameters
    ----------
    image : ndarray, 2-D float
        NaN marks no data.
    radius_cells : float
        Widest gap filled, and reach of the data that fill it, in cells.

    Returns
    -------
    ndarray
        A copy with the enclosed holes filled by the normalised convolution of the data.
    """
    data = np.isfinite(image)
    reach = int(np.floor(radius_cells))
    if reach < 1 or data.all() or not data.any():
        return image.copy()
    holes = np.zeros(image.shape, bool)
    # Along rows and columns only: a gap w wide at any angle is at most w * sqrt(2) wide
    # along one of them, and diagonals would nibble the corners of large holes.
    for step in ((0, 1), (1, 0)):
        ahead = _steps_to_data(data, step, reach)
        behind = _steps_to_data(data, (-step[0], -step[1]), reach)
        holes |= ahead + behind - 1 <= reach
    holes &= ~data

    offsets = np.arange(-reach, reach + 1)
    distance2 = offsets[:, None] ** 2 + offsets[None, :] ** 2
    sigma = radius_cells / 2.0
    kernel = np.where(distance2 <= radius_cells ** 2, np.exp(-distance2 / (2 * sigma ** 2)), 0)
    weight = ndimage.correlate(data.astype(np.float64), kernel, mode="constant")
    total = ndimage.correlate(np.where(data, image, 0.0).astype(np.float64), kernel,
                              mode="constant")
    filled = image.copy()
    filled[holes] = (total[holes] / weight[holes]).astype(image.dtype)
    return filled


def data_extent(image: np.ndarray, *, cell_m: float, reach_m: float = 2.0) -> np.ndarray:
    """Cells inside what the cloud covers: those within ``reach_m`` (metres) of a cell with
    data, and every area they enclose (buildings, water); not the empty margin of a tile
    past the cloud's edge.

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
        NaN where a cell has no data (an intensity image's level).
    cell_m : float
        Cell side, metres.

    Examples
    --------
    >>> import numpy as np
    >>> from gisroads.lidar.intensity import data_extent
    >>> image = np.full((6, 8), np.nan)
    >>> image[:, :4] = 1.0; image[2:4, 1:3] = np.nan   # a building inside, a margin right
    >>> data_extent(image, cell_m=1.0, reach_m=1.0).astype(int)
    array([[1, 1, 1, 1, 1, 0, 0, 0],
           [1, 1, 1, 1, 1, 0, 0, 0],
           [1, 1, 1, 1, 1, 0, 0, 0],
           [1, 1, 1, 1, 1, 0, 0, 0],
           [1, 1, 1, 1, 1, 0, 0, 0],
           [1, 1, 1, 1, 1, 0, 0, 0]])
    """
    valid = np.isfinite(image)
    near = ndimage.distance_transform_edt(~valid) * cell_m <= reach_m
    return ndimage.binary_fill_holes(near)


def _steps_to_data(data: np.ndarray, step: tuple[int, int], longest: int) -> np.ndarray:
    """Steps of ``(d_row, d_col)`` from every cell to the nearest data cell that way;
    ``longest + 1`` where there is none within ``longest`` steps."""
    steps = np.full(data.shape, longest + 1)
    rows, cols = data.shape
    for k in range(longest, 0, -1):  # nearer data overwrite farther
        d_row, d_col = k * step[0], k * step[1]
        target = steps[max(0, -d_row):rows - max(0, d_row), max(0, -d_col):cols - max(0, d_col)]
        seen = data[max(0, d_row):rows - max(0, -d_row), max(0, d_col):cols - max(0, -d_col)]
        target[seen] = k
    return steps


def write_intensity_images(path, images: IntensityImages) -> tuple[Path, Path]:
    """Write the intensity bands and the level index as GeoTIFFs, atomically.

    Parameters
    ----------
    path : str or Path
        The intensity GeoTIFF (bands ``level_0``, ``level_1``, ..., nodata NaN); the level
        index goes beside it as ``<stem>_level_index.tif`` (int16, nodata -1).

    Returns
    -------
    (Path, Path)
        The two files.
    """
    path = Path(path)
    n_levels = images.image.data.shape[0]
    intensity = write_geotiff(path, images.image,
                              band_names=[f"level_{k}" for k in range(n_levels)])
    index = write_geotiff(path.with_name(f"{path.stem}_level_index.tif"), images.level_index,
                          nodata=-1, band_names=["level_index"])
    return intensity, index
