"""Per-pixel multiscale features for the learned road cue, measured in metres.

Every scale is a length on the ground: a filter of ``s`` metres has a width of
``s / pixel_m`` pixels, and derivatives are scale-normalised (an ``n``-th derivative is
multiplied by ``sigma_px ** n``), so a road 6 m wide gives the same feature values on a
0.3 m and on a 1 m image. Images finer than :data:`WORK_PIXEL_M` are first block-averaged
by an integer factor (:func:`work_factor`): 0.3 m images are read at 0.6 m, which serves
roads of 3 m and more and keeps the filters short.

Radiometry is normalised per image (the main defence against sensor and season shift):
each band is divided by its median over the image's valid pixels, and every intensity
feature is taken on ``z = (g / median(g) - 1) / RELATIVE_SPREAD``, ``g`` the mean of the
divided bands: brightness relative to the image's median, so that 8-bit, 11-bit and
differently exposed images agree (:func:`image_statistics`, computed once per image so
that tiles of one image share them). Scaling by the image's own spread (interquartile
range) was tried and dropped: it depends on what the image shows (a forest scene has a
narrow range that inflates every contrast) and cost 0.06 of mean held-out pixel AUC
(DeepGlobe 0.40 against 0.71). Colour enters only as ratios of the recorded bands
(chromaticity, saturation, excess green), independent of exposure; balancing the bands to
grey first was tried and dropped (Massachusetts pixel AUC 0.57 against 0.77: it turns a
desert or a field grey, the colour of roads). See the model card for every figure. A one-band
(panchromatic) image has
chromaticity 1/3 and saturation 0; bands past the third are ignored.

Features (names as in :func:`feature_names`), for each ``s`` in :data:`SCALES_M`:

``smooth_s``       Gaussian of ``z``
``gradient_s``     scale-normalised gradient magnitude of the smoothed ``z``
``ridge_s``,       scale-normalised Hessian eigenvalues (``ridge`` the larger: a dark
``valley_s``       line gives a large ``ridge``, a bright line a very negative ``valley``)
``stddev_s``       local standard deviation of ``z`` (texture)

and for each ``s`` in :data:`COLOUR_SCALES_M` the Gaussian of ``saturation``, ``chroma_r``,
``chroma_g`` and ``excess_green``; then ``contrast`` (``smooth`` at the smallest scale
minus a :data:`CONTEXT_M` box mean), the unsmoothed ``z`` and the oriented line features of
:func:`line_features`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pyproj import CRS
from scipy import ndimage

from ..errors import GisroadsError
from ..geo import GeoRaster

SCALES_M = (0.5, 1.0, 2.0, 4.0, 8.0)
"""Gaussian sigmas of the intensity features, metres."""
COLOUR_SCALES_M = (1.0, 4.0)
"""Gaussian sigmas of the colour features, metres."""
CONTEXT_M = 32.0
"""Side of the box mean the ``contrast`` feature compares with, metres."""
LINE_LENGTHS_M = (24.0, 48.0)
"""Lengths of the oriented line means, metres (each a power-of-two multiple of the first:
the longer lines are doublings of the shorter, :func:`_line_means`)."""
LINE_OFFSETS_M = (5.0, 10.0)
"""Distances of the side lines a line mean is compared with, metres."""
ORIENTATIONS = 8
"""Directions of the oriented line means (every 22.5 degrees)."""
TRUNCATE = 3.0
"""Gaussian kernels are cut at this many sigmas."""
WORK_PIXEL_M = 0.6
"""Images finer than this are block-averaged towards it by an integer factor."""
RELATIVE_SPREAD = 0.25
"""Intensity is measured relative to the image median, in units of this share of it."""
_SAMPLE = 500_000
"""Image statistics are taken on at most this many evenly spaced valid pixels."""


@dataclass(frozen=True)
class ImageStatistics:
    """Per-image radiometric normalisation (see the module docstring).

    Attributes
    ----------
    band_median : ndarray of float64, shape (3,) or (1,)
        Median of each band used (RGB or the single band), in image units.
    median, spread : float
        Median of the balanced intensity and the unit ``z`` is measured in
        (``RELATIVE_SPREAD * median``).
    """

    band_median: np.ndarray
    median: float
    spread: float


def feature_names() -> tuple[str, ...]:
    """Names of the features :func:`compute_features` returns, in order."""
    names = []
    for s in SCALES_M:
        names += [f"{kind}_{s:g}m" for kind in ("smooth", "gradient", "ridge", "valley",
                                                 "stddev")]
    for s in COLOUR_SCALES_M:
        names += [f"{kind}_{s:g}m" for kind in ("saturation", "chroma_r", "chroma_g",
                                                 "excess_green")]
    return (*names, "contrast", "intensity", *line_feature_names())


def line_feature_names(*, extremes: bool = False, lengths_m=None) -> tuple[str, ...]:
    """Names of the arrays :func:`line_features` returns, in order."""
    names = []
    for length in LINE_LENGTHS_M if lengths_m is None else lengths_m:
        names += [f"line_{kind}_{length:g}m" for kind in ("std_min", "std_max", "mean_along")]
        for d in LINE_OFFSETS_M:
            names += [f"line_bright_{d:g}m_{length:g}m", f"line_dark_{d:g}m_{length:g}m"]
        if extremes:
            names += [f"line_max_{length:g}m", f"line_min_{length:g}m"]
    return tuple(names)


def metric_pixel_size(image: GeoRaster) -> float:
    """Pixel side of a north-up, square-pixel image in a projected metre CRS, metres.

    Raises
    ------
    ValueError
        Rotated or non-square pixels, no CRS, or a CRS that is not projected in metres.
    """
    t = image.transform
    if t.b or t.d or not np.isclose(abs(t.a), abs(t.e)):
        raise GisroadsError("the road model needs square, north-up pixels; warp the image "
                            "first")
    if image.crs is None:
        raise GisroadsError("the image has no CRS: the road model measures its features in "
                            "metres")
    crs = CRS.from_user_input(image.crs)
    if not crs.is_projected or any(axis.unit_conversion_factor != 1.0
                                   for axis in crs.axis_info[:2]):
        raise GisroadsError(f"the road model measures its features in metres; {crs.name} "
                            "is not a projected metre CRS (warp the image to one, e.g. its "
                            "UTM zone)")
    return image.pixel_size


def work_factor(pixel_m: float) -> int:
    """Block size that brings a pixel of ``pixel_m`` closest to :data:`WORK_PIXEL_M`
    without going coarser than it needs to (1 for pixels of 0.45 m and more)."""
    return max(1, int(np.floor(WORK_PIXEL_M / pixel_m + 0.25)))


def halo_px(pixel_m: float) -> int:
    """Pixels (at ``pixel_m``) a feature reaches beyond its own pixel: tiles overlap by
    this much so that their seams do not show."""
    reach_m = max(TRUNCATE * max(SCALES_M + COLOUR_SCALES_M), CONTEXT_M / 2,
                  max(LINE_LENGTHS_M) / 2 + max(LINE_OFFSETS_M))
    return int(np.ceil(reach_m / pixel_m)) + 2


def rgb_bands(data: np.ndarray) -> np.ndarray:
    """The bands the features use: the first three of a 3+ band image (taken as R, G, B)
    or the single band of a one-band image, as float32 ``(bands, rows, cols)``.

    Raises
    ------
    ValueError
        Two-band images (neither grey nor colour).
    """
    data = np.asarray(data)
    if data.ndim == 2:
        data = data[None]
    if data.ndim != 3 or data.shape[0] == 2 or data.shape[0] == 0:
        raise GisroadsError(f"expected a 1-band or 3+-band image, got shape {data.shape}")
    return data[:3].astype(np.float32) if data.shape[0] >= 3 else data.astype(np.float32)


def valid_pixels(image: GeoRaster) -> np.ndarray:
    """Pixels with data in every band used: finite and, when the raster declares a nodata
    value, not equal to it in all of them. Shape ``(rows, cols)``."""
    data = np.asarray(image.data)
    bands = data[None] if data.ndim == 2 else data[:3]
    valid = np.ones(bands.shape[1:], bool)
    if np.issubdtype(bands.dtype, np.floating):
        valid &= np.isfinite(bands).all(axis=0)
    if image.nodata is not None and not np.isnan(image.nodata):
        valid &= ~(bands == image.nodata).all(axis=0)
    return valid


def block_mean(bands: np.ndarray, valid: np.ndarray, factor: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Bands averaged over ``factor x factor`` blocks of valid pixels (edge blocks padded).

    Returns
    -------
    bands : ndarray of float32, shape ``(bands, ceil(rows/f), ceil(cols/f))``
        Zero where a block has no valid pixel.
    valid : ndarray of bool
        Blocks with at least one valid pixel.
    """
    if factor == 1:
        return np.where(valid, bands, 0).astype(np.float32), valid
    rows, cols = valid.shape
    pad = ((0, -rows % factor), (0, -cols % factor))
    weight = np.pad(valid, pad).astype(np.float32)
    shape = (weight.shape[0] // factor, factor, weight.shape[1] // factor, factor)
    count = weight.reshape(shape).sum(axis=(1, 3))
    out = np.empty((len(bands), *count.shape), np.float32)
    for band, target in zip(bands, out):
        total = (np.pad(np.where(valid, band, 0), pad) * weight).reshape(shape).sum(axis=(1, 3))
        target[...] = total / np.maximum(count, 1)
    return out, count > 0


def image_statistics(bands: np.ndarray, valid: np.ndarray) -> ImageStatistics:
    """Radiometric normalisation of one image from its valid pixels (module docstring).

    Parameters
    ----------
    bands : ndarray, shape (bands, rows, cols)
        From :func:`rgb_bands` (or :func:`block_mean` of them).
    valid : ndarray of bool, shape (rows, cols)

    Raises
    ------
    ValueError
        No valid pixel.
    """
    count = int(valid.sum())
    if count == 0:
        raise GisroadsError("the image has no valid pixel")
    step = max(1, count // _SAMPLE)
    sample = bands[:, valid][:, ::step].astype(np.float64)
    band_median = np.median(sample, axis=1)
    band_median = np.where(band_median > 0, band_median, np.maximum(sample.mean(axis=1), 1e-6))
    grey = (sample / band_median[:, None]).mean(axis=0)
    median = float(np.median(grey))
    return ImageStatistics(band_median, median, RELATIVE_SPREAD * median)


def _gaussian(values: np.ndarray, sigma_px: float) -> np.ndarray:
    return ndimage.gaussian_filter(values, sigma_px, mode="reflect", truncate=TRUNCATE)


def compute_features(bands: np.ndarray, valid: np.ndarray, pixel_m: float,
                     stats: ImageStatistics) -> np.ndarray:
    """The features of :func:`feature_names` for every pixel of an array.

    Parameters
    ----------
    bands : ndarray, shape (bands, rows, cols)
        1 or 3 bands at ``pixel_m`` (from :func:`rgb_bands`, block-averaged if need be).
    valid : ndarray of bool, shape (rows, cols)
        Pixels with data; the others are filled with the image median before filtering.
    pixel_m : float
        Pixel side, metres.
    stats : ImageStatistics
        Of the whole image the array is cut from (:func:`image_statistics`).

    Returns
    -------
    ndarray of float32, shape (n_features, rows, cols)
    """
    if len(bands) != len(stats.band_median):
        raise GisroadsError(f"{len(bands)} band(s) but statistics of "
                            f"{len(stats.band_median)}")
    balanced = bands.astype(np.float32) / stats.band_median.astype(np.float32)[:, None, None]
    balanced = np.where(valid, balanced, np.float32(1.0))
    z = (balanced.mean(axis=0) - np.float32(stats.median)) / np.float32(stats.spread)
    np.clip(z, -8.0, 8.0, out=z)
    if len(balanced) == 3:
        # colour from the bands as recorded, each scaled by the image's mean median
        raw = balanced * (stats.band_median / stats.band_median.mean()).astype(
            np.float32)[:, None, None]
        total = raw.sum(axis=0) + np.float32(1e-3)
        chroma_r, chroma_g = raw[0] / total, raw[1] / total
        high, low = raw.max(axis=0), raw.min(axis=0)
        saturation = (high - low) / (high + np.float32(1e-3))
        excess_green = (2 * raw[1] - raw[0] - raw[2]) / total
    else:
        chroma_r = chroma_g = np.full(z.shape, 1 / 3, np.float32)
        saturation = excess_green = np.zeros(z.shape, np.float32)
    out = []
    for s in SCALES_M:
        sigma = s / pixel_m
        smooth = _gaussian(z, sigma)
        dy, dx = np.gradient(smooth)
        dyy, dyx = np.gradient(dy)
        dxx = np.gradient(dx, axis=1)
        half_trace, half_diff = (dxx + dyy) / 2, (dxx - dyy) / 2
        root = np.sqrt(half_diff ** 2 + dyx ** 2)
        variance = _gaussian(z * z, sigma) - smooth * smooth
        out += [smooth, np.hypot(dx, dy) * sigma, (half_trace + root) * sigma ** 2,
                (half_trace - root) * sigma ** 2, np.sqrt(np.maximum(variance, 0))]
    for s in COLOUR_SCALES_M:
        out += [_gaussian(v, s / pixel_m) for v in (saturation, chroma_r, chroma_g,
                                                     excess_green)]
    context = ndimage.uniform_filter(z, max(1, int(round(CONTEXT_M / pixel_m))),
                                     mode="reflect")
    out += [out[0] - context, z, *line_features(z, pixel_m)]
    return np.stack(out).astype(np.float32, copy=False)


def _moved(values: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """``values`` read ``(dy, dx)`` pixels ahead: ``out[r, c] = values[r + dy, c + dx]``,
    edges repeated (the row and column indices clipped to the array)."""
    if dy == 0 and dx == 0:
        return values
    rows, cols = values.shape
    if abs(dy) >= rows or abs(dx) >= cols:
        r = np.clip(np.arange(rows) + dy, 0, rows - 1)
        c = np.clip(np.arange(cols) + dx, 0, cols - 1)
        return values[r[:, None], c]
    # slices and edge copies: np.pad's general machinery took a fifth of the line features
    out = np.empty_like(values)
    r0, r1 = max(0, -dy), rows - max(0, dy)
    c0, c1 = max(0, -dx), cols - max(0, dx)
    out[r0:r1, c0:c1] = values[r0 + dy:r1 + dy, c0 + dx:c1 + dx]
    out[:r0, c0:c1] = values[0, c0 + dx:c1 + dx]
    out[r1:, c0:c1] = values[rows - 1, c0 + dx:c1 + dx]
    out[:, :c0] = out[:, c0:c0 + 1]
    out[:, c1:] = out[:, c1 - 1:c1]
    return out


def _line_means(z: np.ndarray, pixel_m: float, angle: float, lengths_m=None
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Means of ``z`` and ``z ** 2`` along a centred line at ``angle`` (radians from the
    x axis), one pair for each length of ``lengths_m`` (metres, ascending; default
    :data:`LINE_LENGTHS_M`).

    The line of ``2 l`` starting at a pixel is the mean of the line of ``l`` starting there
    and the one starting ``l`` further on, so the lines are built by doubling a segment of
    4-8 pixels (a correlation) with one shifted copy per step, then centred: the cost grows
    with the logarithm of the length, not with the length (the 48 m line at 0.6 m would be
    an 80-pixel kernel, 4 times the time of every other feature together).
    """
    lengths_m = LINE_LENGTHS_M if lengths_m is None else lengths_m
    step = np.array([-np.sin(angle), np.cos(angle)])  # one pixel along the line, (dy, dx)
    shortest = lengths_m[0] / pixel_m
    length = shortest / 2 ** max(0, int(np.floor(np.log2(shortest / 4))))
    lengths = [length * 2 ** max(0, int(np.ceil(np.log2(target / pixel_m / length - 1e-6))))
               for target in lengths_m]
    # a centred line is the line starting (l - 1) / 2 behind the pixel; z is padded with its
    # edge values behind, so that a line near the border reads repeated pixels there, as a
    # centred kernel would, and not a line starting at the border and reaching its length inward
    # (further than a tile's halo)
    behind = [np.round(-(length - 1) / 2 * step).astype(int) for length in lengths]
    pad = [(max(0, -d), max(0, d)) for d in behind[-1]]
    padded = np.pad(z, pad, mode="edge")
    taps = max(1, int(round(length)))
    offsets = np.round(np.arange(taps)[:, None] * step).astype(int) + taps - 1
    kernel = np.zeros((2 * taps - 1, 2 * taps - 1), np.float32)
    kernel[offsets[:, 0], offsets[:, 1]] = 1
    kernel /= kernel.sum()
    mean = ndimage.correlate(padded, kernel, mode="reflect")
    square = ndimage.correlate(padded * padded, kernel, mode="reflect")
    rows, cols = z.shape
    out = []
    for final, (dy, dx) in zip(lengths, behind):
        while length < final - 1e-6:
            sy, sx = np.round(length * step).astype(int)
            mean = (mean + _moved(mean, sy, sx)) * np.float32(0.5)
            square = (square + _moved(square, sy, sx)) * np.float32(0.5)
            length *= 2
        window = (slice(pad[0][0] + dy, pad[0][0] + dy + rows),
                  slice(pad[1][0] + dx, pad[1][0] + dx + cols))
        out.append((mean[window], square[window]))
    return out


def line_features(z: np.ndarray, pixel_m: float, *, extremes: bool = False,
                  lengths_m=None) -> list[np.ndarray]:
    """Oriented line means of ``z`` in :data:`ORIENTATIONS` directions, for each length of
    ``lengths_m`` (metres, ascending; default :data:`LINE_LENGTHS_M`, 24 m: a street
    between two junctions; 48 m: a road, longer than most forest gaps and driveways).

    Returns, for each length in :func:`feature_names` order: the smallest and largest
    standard deviation of ``z`` along a line through the pixel (a road is homogeneous
    along itself), the mean along the most homogeneous line, and for each side offset
    ``d`` the most positive (``bright``) and most negative (``dark``) difference between
    a line mean and the mean of the two parallel lines ``d`` to either side; with
    ``extremes``, then the largest and the smallest line mean.
    """
    lengths_m = LINE_LENGTHS_M if lengths_m is None else lengths_m
    n = len(lengths_m)
    std_min, std_max, along = [None] * n, [None] * n, [None] * n
    largest, smallest = [None] * n, [None] * n
    bright = [[None] * len(LINE_OFFSETS_M) for _ in range(n)]
    dark = [[None] * len(LINE_OFFSETS_M) for _ in range(n)]
    for k in range(ORIENTATIONS):
        angle = np.pi * k / ORIENTATIONS
        for j, (mean, square) in enumerate(_line_means(z, pixel_m, angle, lengths_m)):
            # in place where it can be: these full-image operations are most of the time
            std = square - mean * mean
            np.sqrt(np.maximum(std, 0, out=std), out=std)
            if std_min[j] is None:
                std_min[j], std_max[j], along[j] = std, std.copy(), mean.copy()
                largest[j], smallest[j] = mean.copy(), mean.copy()
            else:
                np.copyto(along[j], mean, where=std < std_min[j])
                np.minimum(std_min[j], std, out=std_min[j])
                np.maximum(std_max[j], std, out=std_max[j])
                np.maximum(largest[j], mean, out=largest[j])
                np.minimum(smallest[j], mean, out=smallest[j])
            for i, offset in enumerate(LINE_OFFSETS_M):
                # the normal of the line, in pixels
                dy = int(round(offset / pixel_m * np.cos(angle)))
                dx = int(round(offset / pixel_m * np.sin(angle)))
                # mean - (the two side lines' mean), summed in the same order as written so
                contrast = _moved(mean, dy, dx) + _moved(mean, -dy, -dx)
                contrast *= -0.5
                contrast += mean
                if bright[j][i] is None:
                    bright[j][i], dark[j][i] = contrast, contrast.copy()
                else:
                    np.maximum(bright[j][i], contrast, out=bright[j][i])
                    np.minimum(dark[j][i], contrast, out=dark[j][i])
    out = []
    for j in range(n):
        out += [std_min[j], std_max[j], along[j]]
        for b, d in zip(bright[j], dark[j]):
            out += [b, d]
        if extremes:
            out += [largest[j], smallest[j]]
    return out
