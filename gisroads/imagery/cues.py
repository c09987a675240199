"""Per-pixel cues every imagery stage uses: scaled bands, intensity, NDVI, normalised DSM.

Grote & Rottensteiner (2010) work on colour-infrared images with a DSM; the data of this
project is mostly RGB or panchromatic without either. Every cue here is therefore optional
past the image itself, and :class:`ImageCues` records which ones a run used, so an output
can say ``rgb``, ``rgb+nir``, ``pan+dsm`` ...

Band numbers are 1-based, as in GDAL, QGIS and :func:`gisroads.io.raster.read_raster`.

Radiometric scaling
    Thresholds on brightness (the paper's "intensity neither very low nor very high",
    Section 2.1.3) must mean the same on 8-bit, 11-bit-in-16-bit and 16-bit images, so every
    band is stretched linearly between two percentiles of its valid pixels
    (:data:`STRETCH_PERCENTILES`) and clipped to [0, 1]. A linear change of the input
    (8-bit values times 257 in a 16-bit file) leaves the scaled bands unchanged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import GisroadsError
from ..geo import GeoRaster

STRETCH_PERCENTILES = (1.0, 99.0)
"""Percentiles of each band's valid pixels mapped to 0 and 1."""
_STRETCH_SAMPLE = 1_000_000
"""Percentiles are taken on at most this many evenly spaced valid pixels."""


def _bands(image: GeoRaster) -> np.ndarray:
    data = np.asarray(image.data)
    return data[None] if data.ndim == 2 else data


def _check_band(number, count: int, what: str) -> int:
    if number is None or not 1 <= int(number) <= count:
        raise GisroadsError(f"{what} band {number} does not exist: the image has {count} "
                            f"band(s), numbered from 1")
    return int(number)


def valid_mask(image: GeoRaster) -> np.ndarray:
    """Pixels with data: not NaN in any band and, when the raster declares a nodata value,
    not equal to it in every band. Shape ``(rows, cols)``."""
    bands = _bands(image)
    valid = np.ones(bands.shape[1:], bool)
    if np.issubdtype(bands.dtype, np.floating):
        valid &= ~np.isnan(bands).any(axis=0)
    if image.nodata is not None and not np.isnan(image.nodata):
        valid &= ~(bands == image.nodata).all(axis=0)
    return valid


def scale_bands(image: GeoRaster, *, percentiles=STRETCH_PERCENTILES) -> np.ndarray:
    """Every band stretched to [0, 1] between two percentiles of its valid pixels.

    Parameters
    ----------
    image : GeoRaster
        ``(rows, cols)`` or ``(bands, rows, cols)``, any numeric dtype.
    percentiles : (low, high)
        Percentiles mapped to 0 and 1; values beyond are clipped.

    Returns
    -------
    ndarray of float32, shape ``(bands, rows, cols)``
        NaN where the image has no data.
    """
    low, high = percentiles
    if not 0 <= low < high <= 100:
        raise GisroadsError("percentiles must satisfy 0 <= low < high <= 100, got "
                            f"{percentiles}")
    bands = _bands(image)
    valid = valid_mask(image)
    if not valid.any():
        raise GisroadsError("the image has no valid pixel")
    step = max(1, int(valid.sum()) // _STRETCH_SAMPLE)
    scaled = np.empty(bands.shape, np.float32)
    for band, out in zip(bands, scaled):
        sample = band[valid][::step].astype(np.float64)
        lo, hi = np.percentile(sample, [low, high])
        span = hi - lo if hi > lo else 1.0  # a constant band scales to 0
        np.clip((band - lo) / span, 0.0, 1.0, out=out, casting="unsafe")
        out[~valid] = np.nan
    return scaled


def intensity(image: GeoRaster, *, nir_band: int | None = None,
              percentiles=STRETCH_PERCENTILES) -> np.ndarray:
    """Brightness in [0, 1]: the mean of the scaled bands, the NIR band left out.

    Works on RGB, CIR (NIR, R, G: give ``nir_band=1``) and single-band panchromatic
    images alike; see the module docstring for the scaling.

    Parameters
    ----------
    image : GeoRaster
    nir_band : int, optional
        1-based number of a near-infrared band to leave out (vegetation is bright in NIR,
        which is no cue for road brightness).
    percentiles : (low, high)
        See :func:`scale_bands`.

    Returns
    -------
    ndarray of float32, shape ``(rows, cols)``; NaN where the image has no data.
    """
    return visible_mean(scale_bands(image, percentiles=percentiles), nir_band)


def visible_mean(scaled: np.ndarray, nir_band: int | None) -> np.ndarray:
    """Mean of the scaled bands other than the NIR band (1-based ``nir_band``): the
    brightness of a visible or panchromatic image."""
    keep = np.ones(len(scaled), bool)
    if nir_band is not None:
        keep[_check_band(nir_band, len(scaled), "NIR") - 1] = False
        if not keep.any():
            raise GisroadsError("the only band of the image is the NIR band: no intensity")
    return scaled[keep].mean(axis=0)


def default_red_band(nir_band: int, band_count: int) -> int:
    """The red band that goes with a NIR band: band 2 of a CIR image (NIR, R, G) when NIR
    is band 1, else band 1 (R, G, B, NIR)."""
    return 2 if nir_band == 1 and band_count >= 2 else 1


def ndvi(image: GeoRaster, nir_band: int, red_band: int | None = None) -> np.ndarray:
    """Normalised difference vegetation index ``(NIR - R) / (NIR + R)`` in [-1, 1].

    Computed on the raw values (the index is a ratio, so a common scale cancels). Asphalt
    is about 0, vegetation 0.3 and more.

    Parameters
    ----------
    image : GeoRaster
    nir_band, red_band : int
        1-based band numbers; ``red_band`` defaults to :func:`default_red_band`.

    Returns
    -------
    ndarray of float32, shape ``(rows, cols)``
        NaN where the image has no data or both bands are 0.
    """
    bands = _bands(image)
    nir_band = _check_band(nir_band, len(bands), "NIR")
    red_band = default_red_band(nir_band, len(bands)) if red_band is None else red_band
    red_band = _check_band(red_band, len(bands), "red")
    if red_band == nir_band:
        raise GisroadsError(f"the NIR and red bands are the same band ({nir_band})")
    nir, red = _float_bands(image, (nir_band, red_band), ("NIR", "red"))
    total = nir + red
    with np.errstate(invalid="ignore", divide="ignore"):
        index = np.where(total != 0, (nir - red) / total, np.nan)
    return _without_nodata(image, index)


def excess_green(image: GeoRaster, bands=(1, 2, 3)) -> np.ndarray:
    """Excess green ``(2G - R - B) / (R + G + B)`` in [-1, 2]: the vegetation cue of an RGB
    image without NIR (Woebbecke et al. 1995). Asphalt, concrete and roofs are near 0,
    lawns and trees 0.1 and more.

    Computed on the raw values (a ratio: a common scale cancels).

    Parameters
    ----------
    image : GeoRaster
    bands : (red, green, blue)
        1-based band numbers.

    Returns
    -------
    ndarray of float32, shape ``(rows, cols)``; NaN where the image has no data or is black.
    """
    red, green, blue = _float_bands(image, bands, ("red", "green", "blue"))
    total = red + green + blue
    with np.errstate(invalid="ignore", divide="ignore"):
        index = np.where(total > 0, (2 * green - red - blue) / total, np.nan)
    return _without_nodata(image, index)


def saturation(image: GeoRaster, bands=(1, 2, 3)) -> np.ndarray:
    """HSV saturation ``(max - min) / max`` of three bands in [0, 1]: the road-surface colour
    cue of an RGB image. Asphalt, concrete and gravel are grey (about 0.1 and below), soil,
    tiles, coloured roofs and vegetation are not.

    Computed on the raw values, like :func:`excess_green` (a ratio: a common scale cancels;
    a per-band stretch would turn the grey of a scene with few colours into a colour).

    Parameters
    ----------
    image : GeoRaster
    bands : (int, int, int)
        1-based band numbers.

    Returns
    -------
    ndarray of float32, shape ``(rows, cols)``; NaN where the image has no data, 0 where
    it is black.
    """
    rgb = np.stack(_float_bands(image, bands, ("colour",) * 3))
    top = rgb.max(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        value = np.where(top > 0, (top - rgb.min(axis=0)) / top, 0.0)
    return _without_nodata(image, value)


def _float_bands(image: GeoRaster, bands, names) -> list[np.ndarray]:
    """The 1-based ``bands`` of ``image`` as float32 arrays (``names`` for the errors)."""
    data = _bands(image)
    return [data[_check_band(b, len(data), name) - 1].astype(np.float32)
            for b, name in zip(bands, names)]


def _without_nodata(image: GeoRaster, values: np.ndarray) -> np.ndarray:
    """``values`` as float32, NaN where ``image`` has no data."""
    values = values.astype(np.float32)
    values[~valid_mask(image)] = np.nan
    return values


def resample_to(raster: GeoRaster, like: GeoRaster, *, order: int = 1) -> np.ndarray:
    """A single-band raster sampled at the pixel centres of another raster's grid.

    Same CRS (or no CRS on either side): bilinear (``order=1``) or nearest (``order=0``)
    interpolation through the two affine transforms. Different CRS: a
    :func:`rasterio.warp.reproject` onto ``like``'s grid. Cells outside ``raster`` or next
    to its NaN cells are NaN.
    """
    data = np.asarray(raster.data, np.float32)
    if data.ndim == 3:
        if data.shape[0] != 1:
            raise GisroadsError(f"expected a single-band raster, got {data.shape[0]} bands")
        data = data[0]
    if raster.nodata is not None and not np.isnan(raster.nodata):
        data = np.where(data == raster.nodata, np.nan, data)
    if raster.transform == like.transform and data.shape == like.shape:
        return data
    if raster.crs is not None and like.crs is not None and raster.crs != like.crs:
        from rasterio.warp import Resampling, reproject
        out = np.full(like.shape, np.nan, np.float32)
        reproject(data, out, src_transform=raster.transform, src_crs=raster.crs.to_wkt(),
                  dst_transform=like.transform, dst_crs=like.crs.to_wkt(), src_nodata=np.nan,
                  dst_nodata=np.nan,
                  resampling=Resampling.bilinear if order else Resampling.nearest)
        return out
    rows, cols = np.mgrid[0:like.shape[0], 0:like.shape[1]].astype(np.float64) + 0.5
    t, inverse = like.transform, ~raster.transform  # like's pixel -> map -> raster's pixel
    x, y = t.a * cols + t.b * rows + t.c, t.d * cols + t.e * rows + t.f
    src_cols = inverse.a * x + inverse.b * y + inverse.c - 0.5
    src_rows = inverse.d * x + inverse.e * y + inverse.f - 0.5
    # NaN spreads through the interpolation, so cells next to missing data stay missing
    return ndimage.map_coordinates(data, [src_rows, src_cols], order=order, mode="constant",
                                   cval=np.nan).astype(np.float32)


def ground_surface(dsm: np.ndarray, pixel_m: float, *, window_m: float = 30.0,
                   cell_m: float = 1.0) -> np.ndarray:
    """Ground estimate of a DSM: a grey-scale opening wider than the buildings.

    The DSM is reduced to its minimum over ``cell_m`` blocks (so the opening stays cheap at
    any resolution), opened with a ``window_m`` square (objects narrower than the window
    disappear; planes, slopes and plateaus wider than it are kept exactly), and expanded
    back to the DSM's grid by nearest block. Within half a window of an edge that a slope
    rises to, the ground sinks by up to slope x ``window_m`` / 2 (the DSM is continued
    flat past its edges: mirroring it instead would mirror buildings into deep pits).

    Parameters
    ----------
    dsm : ndarray, shape (rows, cols)
        Heights (metres); NaN for no data.
    pixel_m : float
        DSM pixel side (metres).
    window_m : float
        Side of the opening window: larger than the widest building or tree group.
    cell_m : float
        Block size of the reduction (metres); never smaller than one pixel.

    Returns
    -------
    ndarray of float32, DSM shape; NaN where no valid cell lies within half a window.
    """
    if window_m <= 0 or cell_m <= 0 or pixel_m <= 0:
        raise GisroadsError("window_m, cell_m and pixel_m must be positive")
    block = max(1, int(round(cell_m / pixel_m)))
    rows, cols = dsm.shape
    blocks = np.full((-(-rows // block) * block, -(-cols // block) * block), np.inf,
                     np.float32)
    blocks[:rows, :cols] = np.where(np.isnan(dsm), np.inf, dsm)
    coarse = blocks.reshape(blocks.shape[0] // block, block, -1, block).min(axis=(1, 3))
    coarse[np.isnan(coarse)] = np.inf  # no data: no constraint on the erosion
    # odd size: an even window's off-centre origin would shift the dilation
    size = 2 * int(round(window_m / (2 * block * pixel_m))) + 1
    eroded = ndimage.minimum_filter(coarse, size=size, mode="nearest")
    eroded[np.isinf(eroded)] = -np.inf  # windows without data must not win the dilation
    ground = ndimage.maximum_filter(eroded, size=size, mode="nearest")
    ground[np.isinf(ground)] = np.nan
    return np.repeat(np.repeat(ground, block, axis=0), block, axis=1)[:rows, :cols]


def normalised_dsm(dsm: GeoRaster, like: GeoRaster, *, window_m: float = 30.0,
                   cell_m: float = 1.0) -> np.ndarray:
    """Height above ground (metres) on the grid of ``like``: the DSM minus its
    :func:`ground_surface`, resampled bilinearly.

    Roads lie low in it (Section 2.1.3: "road parts ... should lie in low regions in the
    normalised DSM"); roofs and tree crowns stand metres high.

    Parameters
    ----------
    dsm : GeoRaster
        Single band, metres, in a metric CRS.
    like : GeoRaster
        The image whose grid the result takes.
    window_m, cell_m : float
        See :func:`ground_surface`.

    Returns
    -------
    ndarray of float32, shape ``like.shape``; NaN outside the DSM.
    """
    data = np.asarray(dsm.data, np.float32)
    if data.ndim == 3:
        if data.shape[0] != 1:
            raise GisroadsError(f"a DSM has one band, got {data.shape[0]}")
        data = data[0]
    if dsm.nodata is not None and not np.isnan(dsm.nodata):
        data = np.where(data == dsm.nodata, np.nan, data)
    if np.isnan(data).all():
        raise GisroadsError("the DSM has no valid cell")
    height = data - ground_surface(data, dsm.pixel_size, window_m=window_m, cell_m=cell_m)
    return resample_to(GeoRaster(height, dsm.transform, dsm.crs), like)


@dataclass(frozen=True)
class ImageCues:
    """The per-pixel cues of one image, each on the image's grid.

    Attributes
    ----------
    bands : ndarray of float32, shape (bands, rows, cols)
        :func:`scale_bands`.
    intensity : ndarray of float32, shape (rows, cols)
        :func:`intensity`.
    ndvi : ndarray or None
        :func:`ndvi`, when a NIR band was given.
    ndsm : ndarray or None
        :func:`normalised_dsm`, when a DSM was given.
    kind : str
        ``"pan"`` (one band), ``"cir"`` (three bands, one of them NIR) or ``"rgb"``.
    nir_band : int or None
    exg : ndarray or None
        :func:`excess_green` of bands 1-3, for ``"rgb"`` images (the vegetation cue when
        there is no NIR band).
    saturation : ndarray or None
        :func:`saturation` of bands 1-3, for the same images as ``exg``.
    probability : ndarray or None
        A learned road probability in [0, 1] (:func:`gisroads.learn.predict_probability`),
        NaN where unknown; when given it replaces the colour tests of the road parts and the
        radiometric context of the gaps (beyond the papers).
    """

    bands: np.ndarray
    intensity: np.ndarray
    ndvi: np.ndarray | None
    ndsm: np.ndarray | None
    kind: str
    nir_band: int | None = None
    exg: np.ndarray | None = None
    saturation: np.ndarray | None = None
    probability: np.ndarray | None = None

    def record(self) -> dict:
        """What a run used (see :func:`cues_used`)."""
        record = _record(len(self.bands), self.nir_band, self.ndvi is not None,
                         self.ndsm is not None)
        if self.probability is not None:  # a learned road probability (gisroads.learn)
            record["cues"] += "+model"
            record["model"] = True
        return record


def _record(band_count: int, nir_band: int | None, ndvi: bool, dsm: bool) -> dict:
    kind = image_kind(band_count, nir_band)
    used = [kind] + (["nir"] if ndvi else []) + (["dsm"] if dsm else [])
    return {"cues": "+".join(used), "image": kind, "bands": band_count,
            "nir_band": nir_band, "ndvi": ndvi, "dsm": dsm}


def cues_used(image: GeoRaster, *, nir_band: int | None = None,
              dsm: GeoRaster | None = None) -> dict:
    """Which cues a run on ``image`` uses, for an output's metadata, without computing them.

    Returns
    -------
    dict
        e.g. ``{"cues": "rgb+nir+dsm", "image": "rgb", "bands": 4, "nir_band": 4,
        "ndvi": True, "dsm": True}``; ``image`` is ``"pan"``, ``"cir"`` or ``"rgb"``
        (:func:`image_kind`).
    """
    count = len(_bands(image))
    if nir_band is not None:
        nir_band = _check_band(nir_band, count, "NIR")
    return _record(count, nir_band, nir_band is not None, dsm is not None)


def image_kind(band_count: int, nir_band: int | None) -> str:
    """``"pan"``, ``"cir"`` or ``"rgb"`` (see :class:`ImageCues`)."""
    if band_count == 1:
        return "pan"
    return "cir" if band_count == 3 and nir_band is not None else "rgb"


def image_cues(image: GeoRaster, *, nir_band: int | None = None,
               red_band: int | None = None, dsm: GeoRaster | None = None,
               ground_window_m: float = 30.0,
               percentiles=STRETCH_PERCENTILES) -> ImageCues:
    """All cues of an image at once (see :class:`ImageCues`).

    Parameters
    ----------
    image : GeoRaster
    nir_band, red_band : int, optional
        1-based; NDVI is computed when ``nir_band`` is given.
    dsm : GeoRaster, optional
        Heights (metres); the normalised DSM is computed when given.
    ground_window_m : float
        See :func:`ground_surface`.
    percentiles : (low, high)
        See :func:`scale_bands`.
    """
    bands = scale_bands(image, percentiles=percentiles)
    kind = image_kind(len(bands), nir_band)
    return ImageCues(
        bands=bands, intensity=visible_mean(bands, nir_band),
        ndvi=None if nir_band is None else ndvi(image, nir_band, red_band),
        ndsm=None if dsm is None else normalised_dsm(dsm, image, window_m=ground_window_m),
        kind=kind, nir_band=nir_band,
        **(dict(exg=excess_green(image), saturation=saturation(image))
           if kind == "rgb" and nir_band not in (1, 2, 3) else {}))


def context_rasters(cues) -> dict:
    """The rasters of :func:`gisroads.network.subgraph.gap_context` from a :class:`ImageCues`:
    ``ndvi``, ``ndsm``, ``intensity``, and ``rgb`` (the first three non-NIR bands, taken as
    red, green, blue) for an RGB image; panchromatic and CIR images have no ``rgb``."""
    visible = [band for number, band in enumerate(cues.bands, start=1)
               if number != cues.nir_band]
    rgb = np.stack(visible[:3]) if cues.kind == "rgb" and len(visible) >= 3 else None
    return {"ndvi": cues.ndvi, "ndsm": cues.ndsm, "intensity": cues.intensity, "rgb": rgb}
