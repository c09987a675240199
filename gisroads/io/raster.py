"""Rasters (rasterio): read GeoTIFFs and georeferenced images, write GeoTIFFs atomically.

A plain PNG/JPEG carries no georeferencing; it is read only when the caller gives its pixel
size and CRS explicitly, so nothing downstream ever guesses units.
"""
from __future__ import annotations

import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import rasterio
from affine import Affine
from pyproj import CRS
from pyproj.exceptions import CRSError
from rasterio.enums import ColorInterp
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

from ..errors import GisroadsError
from ..geo import GeoRaster
from .vector import atomic_path


class RasterError(GisroadsError):
    """A raster that cannot be used as given: unreadable, not georeferenced, or all NaN."""


class NotGeoreferencedError(RasterError):
    """An image without georeferencing (a plain PNG/JPEG) given without a pixel size and CRS.

    ``path`` is the image, so a caller can name its own options for them (the command line
    names ``--pixel`` and ``--crs``)."""

    def __init__(self, path):
        self.path = Path(path)
        super().__init__(f"{path}: the image has no georeferencing; give its pixel size "
                         "(metres) and CRS explicitly")


@contextmanager
def _opened(path):
    """``rasterio.open(path)`` without rasterio's NotGeoreferencedWarning: gisroads checks
    georeferencing itself and says what to do (:class:`NotGeoreferencedError`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path) as src:
            yield src


def _crs(rio_crs) -> CRS | None:
    return None if rio_crs is None else CRS.from_user_input(rio_crs.to_wkt())


def _is_mask(band: np.ndarray) -> bool:
    """Whether a band marked alpha is a mask: nearly all of it (95 %) transparent or opaque,
    the rest anti-aliased edges. GDAL marks the fourth band of any 4-band 8-bit GeoTIFF as
    alpha, a near-infrared band included."""
    return bool(((band == 0) | (band == band.max())).mean() >= 0.95)


def read_raster(path, *, pixel_size: float | None = None, crs=None,
                origin: tuple[float, float] = (0.0, 0.0), bands=None) -> GeoRaster:
    """Read a raster with its georeferencing.

    Parameters
    ----------
    path : str or Path
        GeoTIFF (or any GDAL raster with a geotransform and CRS); a plain PNG/JPEG needs
        ``pixel_size`` and ``crs``.
    pixel_size : float, optional
        Pixel side in CRS units, for images without georeferencing.
    crs : optional
        CRS for images without one (anything pyproj accepts: ``"EPSG:32633"``).
    origin : (x, y)
        Map coordinates of the upper-left corner, with ``pixel_size``.
    bands : list of int, optional
        1-based band numbers; all by default.

    Returns
    -------
    GeoRaster
        ``data`` of shape ``(bands, rows, cols)``; nodata cells of float rasters are NaN.

    Raises
    ------
    RasterError
        Unreadable file, missing georeferencing without ``pixel_size``/``crs``, a ``crs``
        pyproj does not know, or a raster with no valid cell.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from gisroads.io import read_raster
    >>> from gisroads.synthetic import make_scene, write_image
    >>> scene = make_scene(seed=0, size_m=(300, 300))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_image(scene, Path(folder) / "image.tif", Path(folder) / "dsm.tif", pixel_m=1.0)
    ...     image = read_raster(Path(folder) / "image.tif")
    ...     nir = read_raster(Path(folder) / "image.tif", bands=[4])
    >>> image.data.shape, nir.data.shape, image.pixel_size
    ((4, 300, 300), (1, 300, 300), 1.0)
    >>> image.bounds == scene.extent and image.crs == scene.crs
    True
    """
    path = Path(path)
    if not path.exists():
        raise RasterError(f"{path}: no such file")
    try:
        with _opened(path) as src:
            data = src.read(bands)
            transform, file_crs, nodata = src.transform, _crs(src.crs), src.nodata
            alpha = [k for k, kind in enumerate(src.colorinterp) if kind == ColorInterp.alpha]
    except RasterioIOError as err:
        raise RasterError(f"{path}: not a readable raster ({err})") from None
    if alpha and bands is None and _is_mask(data[alpha[0]]):
        # an alpha band is the image's mask, not a colour: transparent pixels are no data,
        # and so are those with the nodata value in every colour band, as without alpha
        empty = data[alpha[0]] < data[alpha[0]].max() / 2
        data = np.delete(data, alpha, axis=0)
        if nodata is not None and not np.isnan(nodata):
            empty |= (data == nodata).all(axis=0)
        data = data.astype(np.float32)
        data[:, empty] = np.nan
        nodata = float("nan")
    georeferenced = transform != Affine.identity() and file_crs is not None
    if pixel_size is not None or crs is not None:
        if pixel_size is None or crs is None:
            raise RasterError(f"{path}: give both a pixel size and a CRS")
        transform = Affine(pixel_size, 0, origin[0], 0, -pixel_size, origin[1])
        try:
            file_crs = CRS.from_user_input(crs)
        except CRSError as err:
            raise RasterError(f"{path}: {crs!r} is not a CRS ({err})") from None
    elif not georeferenced:
        raise NotGeoreferencedError(path)
    if np.issubdtype(data.dtype, np.floating):
        if nodata is not None and not np.isnan(nodata):
            data = np.where(data == nodata, np.nan, data)
        if np.isnan(data).all():
            raise RasterError(f"{path}: every cell is NaN or nodata")
    return GeoRaster(data, transform, file_crs, nodata)


def write_geotiff(path, raster: GeoRaster, *, nodata: float | None = None,
                  band_names: list[str] | None = None) -> Path:
    """Write a GeoRaster as a tiled, deflate-compressed GeoTIFF, atomically.

    Parameters
    ----------
    path : str or Path
    raster : GeoRaster
        2-D or ``(bands, rows, cols)`` data.
    nodata : float, optional
        Stored nodata value; defaults to ``raster.nodata``, and to NaN for float data.
    band_names : list of str, optional
        Band descriptions shown by QGIS.
    """
    data = raster.data[np.newaxis] if raster.data.ndim == 2 else raster.data
    with geotiff_writer(path, shape=data.shape, dtype=data.dtype, transform=raster.transform,
                        crs=raster.crs, nodata=raster.nodata if nodata is None else nodata,
                        band_names=band_names) as dst:
        dst.write(data)
    return Path(path)


#: GDAL's block cache while a GeoTIFF is written, MB: a raster written window by window
#: (:func:`geotiff_writer`) then holds at most this much of it in memory. GDAL's default,
#: 5 % of the machine's memory, kept the written blocks: 354 MB peak for a 6000 x 6000 x 2
#: float32 raster written in 400-cell windows, 70 MB with this cache.
WRITE_CACHE_MB = 64


@contextmanager
def geotiff_writer(path, *, shape: tuple[int, int, int], dtype, transform: Affine, crs,
                   nodata: float | None = None, band_names: list[str] | None = None):
    """An open GeoTIFF (a rasterio dataset) to write window by window, for a raster too
    large to hold; tiled and deflate-compressed as :func:`write_geotiff`, atomically (the
    file appears at ``path`` when the block ends without an exception).

    Parameters
    ----------
    path : str or Path
    shape : (bands, rows, cols)
    dtype : numpy dtype
    transform : Affine
    crs : pyproj CRS or None
    nodata : float, optional
        Stored nodata value; NaN for float data by default.
    band_names : list of str, optional
        Band descriptions shown by QGIS.
    """
    bands, rows, cols = shape
    if nodata is None and np.issubdtype(np.dtype(dtype), np.floating):
        nodata = np.nan
    profile = dict(driver="GTiff", height=rows, width=cols, count=bands, dtype=dtype,
                   transform=transform, nodata=nodata,
                   crs=None if crs is None else crs.to_wkt(), compress="deflate")
    if rows >= 256 and cols >= 256:
        profile.update(tiled=True, blockxsize=256, blockysize=256)
    with atomic_path(path, suffix=".tif") as tmp, rasterio.Env(GDAL_CACHEMAX=WRITE_CACHE_MB):
        with rasterio.open(tmp, "w", **profile) as dst:
            for i, name in enumerate(band_names or [], start=1):
                dst.set_band_description(i, name)
            yield dst


def raster_info(path) -> dict:
    """Header facts of a raster: size, bands, dtype, CRS, pixel size, extent.

    A raster without a geotransform (a plain PNG/JPEG) has no pixel size and no extent
    (None), not GDAL's pixel-grid stand-ins.
    """
    path = Path(path)
    if not path.exists():
        raise RasterError(f"{path}: no such file")
    try:
        with _opened(path) as src:
            crs = _crs(src.crs)
            placed = src.transform != Affine.identity()
            return {"path": str(path), "driver": src.driver, "width": src.width,
                    "height": src.height, "bands": src.count, "dtype": src.dtypes[0],
                    "crs": crs.name if crs else None, "epsg": crs.to_epsg() if crs else None,
                    "pixel_size": [abs(src.transform.a), abs(src.transform.e)] if placed
                    else None,
                    "georeferenced": crs is not None and placed,
                    "extent": [float(v) for v in src.bounds] if placed else None,
                    "nodata": None if src.nodata is None else float(src.nodata),
                    "band_names": list(src.descriptions)}
    except RasterioIOError as err:
        raise RasterError(f"{path}: not a readable raster ({err})") from None
