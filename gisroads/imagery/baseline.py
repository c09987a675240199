"""A naive imagery road baseline, to measure the real method against: road-coloured pixels,
cleaned morphologically and skeletonised.

Pixels of low colour saturation and middling brightness (grey asphalt or gravel, neither
shadow nor white roof) are road candidates; an opening drops what is narrower than a road, a
closing bridges cars and markings, small blobs are removed, and the skeleton of what is left
becomes centre lines whose width comes from the distance transform. No segmentation, no
shape model, no gap closing, no junction reasoning.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage
from skimage.filters import threshold_otsu

from ..errors import GisroadsError
from ..geo import GeoRaster, RoadNetwork, network_from_centrelines
from ..vectorize.skeleton import skeleton_lines

METHOD = "baseline-threshold-skeleton"


def _valid_pixels(data: np.ndarray, nodata) -> np.ndarray:
    """Pixels with data: finite in every band, not the nodata value in every band, not
    saturated in every band."""
    valid = np.ones(data.shape[1:], bool)
    if np.issubdtype(data.dtype, np.floating):
        valid &= np.isfinite(data).all(axis=0)
    if nodata is not None and not np.isnan(nodata):
        valid &= ~(data == nodata).all(axis=0)
    if np.issubdtype(data.dtype, np.integer):
        valid &= ~(data == np.iinfo(data.dtype).max).all(axis=0)
    return valid


def _open_close(mask: np.ndarray, open_px: float, close_px: float) -> np.ndarray:
    """Opening then closing by discs of the given radii (pixels), via exact distance maps;
    the image border neither erodes nor bounds the mask."""
    if open_px > 0:
        mask = _dilate(_erode(mask, open_px), open_px)
    if close_px > 0:
        mask = _erode(_dilate(mask, close_px), close_px)
    return mask


# A distance map of an input without background is undefined: those inputs are returned
# unchanged (nothing to erode, or nothing to grow).
def _erode(mask: np.ndarray, radius_px: float) -> np.ndarray:
    return mask if mask.all() else ndimage.distance_transform_edt(mask) > radius_px


def _dilate(mask: np.ndarray, radius_px: float) -> np.ndarray:
    return mask if not mask.any() else ndimage.distance_transform_edt(~mask) <= radius_px


def road_colour_mask(image: GeoRaster, *, smooth_m: float = 1.0,
                     max_saturation: float = 0.15,
                     brightness_quantiles: tuple[float, float] = (0.3, 0.95)) -> np.ndarray:
    """Pixels whose colour looks like a road surface.

    The bands are smoothed with a Gaussian of ``smooth_m``; a pixel is a candidate when its
    brightness (band mean) lies above the lower and at most the upper quantile of the
    image's brightness, and, for images of three bands or more, its HSV saturation
    ``(max - min) / max`` of the first three bands is at most the Otsu threshold of the
    saturation and at most ``max_saturation``.

    Parameters
    ----------
    image : GeoRaster
        One band (panchromatic) or RGB(+) in a metric CRS.
    smooth_m : float
        Gaussian sigma, metres.
    max_saturation : float
        Upper bound on the saturation threshold, so a scene without grey surfaces yields
        nothing.
    brightness_quantiles : (float, float)
        Quantiles of the valid pixels' brightness bounding the candidates.

    Returns
    -------
    ndarray of bool, shape (rows, cols)
    """
    data = image.data[np.newaxis] if image.data.ndim == 2 else image.data
    valid = _valid_pixels(data, image.nodata)
    if not valid.any():
        return valid
    sigma = smooth_m / image.pixel_size
    # no-data pixels (NaN in a half-empty image) must not bleed into their valid neighbours
    weight = ndimage.gaussian_filter(valid.astype(np.float32), sigma)
    bands = np.stack([ndimage.gaussian_filter(np.where(valid, band, 0).astype(np.float32),
                                              sigma) for band in data[:3]])
    bands /= np.maximum(weight, 1e-6)
    brightness = bands.mean(axis=0)
    low, high = np.quantile(brightness[valid], brightness_quantiles)
    candidates = valid & (brightness > low) & (brightness <= high)
    if len(bands) >= 3:
        top = bands.max(axis=0)
        saturation = (top - bands.min(axis=0)) / np.maximum(top, 1e-6)
        threshold = min(float(threshold_otsu(saturation[valid])), max_saturation)
        candidates &= saturation <= threshold
    return candidates


def baseline_roads(image: GeoRaster, *, smooth_m: float = 1.0, max_saturation: float = 0.15,
                   brightness_quantiles: tuple[float, float] = (0.3, 0.95),
                   min_width_m: float = 4.0, close_m: float = 1.0,
                   min_area_m2: float = 300.0, min_length_m: float = 20.0) -> RoadNetwork:
    """Road centre lines from a road-colour threshold, cleaned and skeletonised.

    The defaults are the best of a small sweep on the real benchmark
    (:mod:`gisroads.imagery.datasets`; ``max_saturation`` 0.10/0.15/0.25, brightness
    quantiles, opening width 3/4/5 m): the baseline is given its best chance.

    Parameters
    ----------
    image : GeoRaster
        One band or RGB(+), in a metric CRS.
    smooth_m, max_saturation, brightness_quantiles
        See :func:`road_colour_mask`.
    min_width_m : float
        Candidate structures narrower than this disappear in an opening, metres.
    close_m : float
        Radius of the closing that bridges cars and markings, metres.
    min_area_m2 : float
        Smaller candidate blobs are removed, square metres.
    min_length_m : float
        Shorter skeleton lines are dropped, metres.

    Returns
    -------
    RoadNetwork
        ``method`` is :data:`METHOD`; empty when nothing road-like is found.

    Raises
    ------
    ValueError
        An image in a geographic CRS (its pixel size is not in metres).
    """
    if image.crs is not None and image.crs.is_geographic:
        raise GisroadsError("the image is in a geographic CRS; warp it to a metric CRS first "
                            "(see gisroads.imagery.datasets.warp_to_utm)")
    pixel_m = image.pixel_size
    mask = road_colour_mask(image, smooth_m=smooth_m, max_saturation=max_saturation,
                            brightness_quantiles=brightness_quantiles)
    mask = _open_close(mask, min_width_m / 2 / pixel_m, close_m / pixel_m)
    blobs, count = ndimage.label(mask)
    area_m2 = np.bincount(blobs.ravel(), minlength=count + 1) * pixel_m ** 2
    large = area_m2 >= min_area_m2
    large[0] = False
    lines = skeleton_lines(large[blobs], image.transform, image.crs,
                           min_length_m=min_length_m, simplify_m=pixel_m)
    return network_from_centrelines(lines, method=METHOD)
