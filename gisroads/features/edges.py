"""Edge strength and orientation from local energy (Morrone & Owens 1987).

Zhu & Mordohai detect edges in the ground-intensity image "using [16]", Morrone & Owens'
local energy (Algorithm 1 step 3, section 4.2): an edge or a line is where the Fourier
components of the signal are in phase, which is where the energy of a quadrature pair of
filters peaks. As in Kovesi's phase congruency work, the pairs are log-Gabor filters built in
the frequency domain: each filter keeps one half of the frequency plane only, so its inverse
FFT is complex with the even (cosine) response as real part and the odd (sine) response as
imaginary part. Per orientation ``o`` the responses of all scales are summed and the local
energy is ``E_o = sqrt((sum_s even_s)^2 + (sum_s odd_s)^2)``; a step edge and a thin line
both give a peak of ``E_o`` on them, at the orientation across them.

Conventions
-----------
Orientations are angles of the edge LINE in ``[0, pi)`` radians, counter-clockwise from the
+column axis (east) with north up, i.e. with rows drawn downwards as usual: an edge line at
angle ``theta`` runs along the pixel step ``(d_col, d_row) = (cos theta, -sin theta)``. A
vertical step (the edge line runs along the rows) has orientation ``pi/2``; a horizontal one
``0``; a line rising to the right on the displayed image ``0 < theta < pi/2``. This is the
convention of :mod:`gisroads.features.rectangles`.

``mask`` arguments follow numpy's masked arrays: True marks a cell that is masked out (no
data), like a NaN cell.

References
----------
Morrone, M. C., Owens, R. A. (1987). Feature detection from local energy. Pattern
Recognition Letters 6 (5), 303-313.
Kovesi, P. (1999). Image features from phase congruency. Videre 1 (3), 1-26.
Zhu, Q., Mordohai, P. (2009). A minimum cover approach for extracting the road network from
airborne LIDAR data. ICCV workshops, section 4.2.
"""
from __future__ import annotations

import numpy as np
from scipy import fft, ndimage

from ..errors import GisroadsError

ANGULAR_SPACING_ON_SIGMA = 1.2
"""Orientation spacing over the angular Gaussian's sigma (Kovesi's dThetaOnSigma, 1.2-1.5):
neighbouring orientations overlap enough that the energy varies smoothly with angle."""


def _valid_cells(image: np.ndarray, mask) -> np.ndarray:
    valid = np.isfinite(image)
    if mask is not None:
        valid &= ~np.asarray(mask, dtype=bool)
    return valid


def fill_nearest(image: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``image`` with every invalid cell set to the value of its nearest valid cell.

    Nearest-value filling continues the data across a hole without creating a step at the
    hole's rim, so filters see no edge there.

    Parameters
    ----------
    image : ndarray, shape (..., rows, cols)
        One image or a stack of bands.
    valid : ndarray of bool, shape (rows, cols)
        Cells with data; at least one.
    """
    if valid.all():
        return image
    rows, cols = ndimage.distance_transform_edt(~valid, return_distances=False,
                                                return_indices=True)
    return image[..., rows, cols]


def _exp(values) -> np.ndarray:
    """``exp`` computed in float64 and rounded to float32.

    numpy's float32 ``exp``/``log`` (and float64 ones) are SIMD kernels that differ by an ulp
    between numpy versions and CPUs (numpy 1.24 and 2.x on AVX-512 do); a float64 result one
    ulp off almost never rounds to another float32 (about 2^-29 of the values), so the
    edges are the same bits in both environments of the README."""
    return np.exp(np.asarray(values, np.float64)).astype(np.float32)


def _log(values) -> np.ndarray:
    """``log`` computed in float64 and rounded to float32 (see :func:`_exp`)."""
    return np.log(np.asarray(values, np.float64)).astype(np.float32)


def _frequency_grid(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Radius (cycles per pixel) and angle (radians, north-up) of each FFT frequency."""
    f_col = fft.fftfreq(shape[1]).astype(np.float32)[None, :]
    f_north = -fft.fftfreq(shape[0]).astype(np.float32)[:, None]
    return np.hypot(f_col, f_north), np.arctan2(f_north, f_col)


def local_energy(image, *, wavelengths_px=(4, 8, 16), n_orientations: int = 8,
                 sigma_on_f: float = 0.55, mask=None) -> tuple[np.ndarray, np.ndarray]:
    """Edge magnitude and edge-line orientation from multi-scale log-Gabor local energy.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Grey values, e.g. ground intensity on a 0.5 m grid (paper section 4.1). NaN cells
        are no data.
    wavelengths_px : sequence of float
        Centre wavelengths of the log-Gabor scales, pixels (3 scales, one octave apart, as in
        Kovesi's defaults; at 0.5 m cells they span 2-8 m, kerbs to lane widths).
    n_orientations : int
        Filter orientations evenly spread over ``[0, pi)`` (Kovesi: 6-8).
    sigma_on_f : float
        Log-Gabor radial width, sigma over centre frequency in log space (Kovesi: 0.55,
        about two octaves).
    mask : array_like of bool, optional
        True where a cell is masked out (no data), as NaN cells are.

    Returns
    -------
    magnitude : ndarray of float32, shape (rows, cols)
        Local energy at the orientation of its maximum, in the image's units (with the
        default filters a step of height ``h`` gives about ``0.7 h`` on the step); 0 on
        no-data cells.
    orientation_rad : ndarray of float32, shape (rows, cols)
        Orientation of the edge line in ``[0, pi)`` (module docstring); 0 on no-data cells.

    Notes
    -----
    No-data cells are filled with their nearest valid value before filtering, and the image
    is mirrored at its borders, so neither holes nor the FFT's wrap-around make edges. The
    orientation is refined between the sampled filter orientations by fitting a parabola to
    the logarithm of the three energies around the maximum (exact for the Gaussian angular
    profile of the filters); the magnitude is the parabola's peak, so it does not depend on
    how the edge falls between two filter orientations.
    """
    image = np.asarray(image, dtype=np.float32)
    if image.ndim != 2:
        raise GisroadsError(f"local_energy needs a (rows, cols) image, got shape {image.shape}")
    if n_orientations < 3:
        raise GisroadsError("n_orientations must be at least 3")
    valid = _valid_cells(image, mask)
    magnitude = np.zeros(image.shape, np.float32)
    orientation = np.zeros(image.shape, np.float32)
    if not valid.any():
        return magnitude, orientation
    pad = int(np.ceil(2 * max(wavelengths_px)))
    fft_shape = tuple(fft.next_fast_len(n + 2 * pad) for n in image.shape)
    padded = np.pad(fill_nearest(image, valid),
                    [(pad, size - n - pad) for n, size in zip(image.shape, fft_shape)],
                    mode="symmetric")
    spectrum = fft.fft2(padded)

    radius, angle = _frequency_grid(fft_shape)
    radius = radius.astype(np.float64)
    radius[0, 0] = 1.0  # the log below; the DC term is zeroed afterwards
    log_width = 2 * float(np.log(sigma_on_f)) ** 2
    # the filters in float64, rounded to float32 (see _exp): numpy's float32 exp and log
    # differ by an ulp between versions and CPUs (SIMD kernels), and so would the edges
    radial = sum(_exp(-np.log(radius * wavelength) ** 2 / log_width)
                 for wavelength in wavelengths_px)
    radial[0, 0] = 0.0
    spectrum *= radial

    spacing = np.pi / n_orientations
    angular_sigma = spacing / ANGULAR_SPACING_ON_SIGMA
    core = (slice(pad, pad + image.shape[0]), slice(pad, pad + image.shape[1]))
    energies = np.empty((n_orientations,) + image.shape, np.float32)
    for o in range(n_orientations):
        # one half-plane only, around the normal direction o*spacing: an analytic filter
        offset = np.mod(angle.astype(np.float64) - o * spacing + np.pi, 2 * np.pi) - np.pi
        angular = np.where(np.abs(offset) < np.pi / 2,
                           _exp(-offset ** 2 / (2 * angular_sigma ** 2)), np.float32(0))
        energies[o] = np.abs(fft.ifft2(spectrum * angular)[core])

    best = np.argmax(energies, axis=0)
    before, centre, after = (
        _log(np.maximum(np.take_along_axis(energies, ((best + step) % n_orientations)[None],
                                           axis=0)[0], np.finfo(np.float32).tiny))
        for step in (-1, 0, 1))
    curvature = before - 2 * centre + after
    concave = curvature < 0
    shift = np.where(concave, 0.5 * (before - after) / np.where(concave, curvature, -1), 0)
    shift = np.clip(shift, -0.5, 0.5)
    peak = centre - 0.25 * (before - after) * shift
    normal = (best + shift) * spacing
    magnitude[valid] = _exp(peak[valid])
    orientation[valid] = np.mod(normal[valid] + np.pi / 2, np.pi)
    orientation[orientation >= np.float32(np.pi)] = 0.0  # float32 rounding at the wrap
    return magnitude, orientation


def orientation_histogram(magnitude, orientation_rad, *, n_bins: int = 36,
                          smooth_bins: float = 1) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of edge-line orientations weighted by edge magnitude, circular over pi.

    Parameters
    ----------
    magnitude, orientation_rad : array_like
        Same shape; as returned by :func:`local_energy`. NaN or non-positive magnitudes
        count nothing.
    n_bins : int
        Bins over ``[0, pi)``: 36 bins are 5 degrees wide.
    smooth_bins : float
        Sigma of a circular Gaussian smoothing of the histogram, bins; 0 for none.

    Returns
    -------
    bin_centres_rad : ndarray, shape (n_bins,)
        ``i * pi / n_bins``: bin 0 is centred on orientation 0 (east-west lines).
    weights : ndarray, shape (n_bins,)
        Summed magnitude per bin. Each orientation's vote is split linearly between the two
        nearest bin centres, so a shift of the orientation moves weight gradually.
    """
    magnitude = np.asarray(magnitude, dtype=float).ravel()
    orientation = np.asarray(orientation_rad, dtype=float).ravel()
    counted = np.isfinite(magnitude) & np.isfinite(orientation) & (magnitude > 0)
    magnitude, orientation = magnitude[counted], orientation[counted]
    position = np.mod(orientation, np.pi) / (np.pi / n_bins)
    lower = np.floor(position)
    upper_share = position - lower
    lower = lower.astype(np.int64) % n_bins
    weights = (np.bincount(lower, magnitude * (1 - upper_share), minlength=n_bins)
               + np.bincount((lower + 1) % n_bins, magnitude * upper_share, minlength=n_bins))
    if smooth_bins > 0:
        weights = ndimage.gaussian_filter1d(weights, smooth_bins, mode="wrap")
    return np.arange(n_bins) * (np.pi / n_bins), weights


def dominant_orientations(magnitude, orientation_rad, *, n_bins: int = 36, max_peaks: int = 6,
                          min_share: float = 0.05, smooth_bins: float = 1) -> np.ndarray:
    """Dominant edge-line orientations: peaks of the magnitude-weighted orientation histogram.

    Zhu & Mordohai take the orientations of road hypotheses "from the local maxima in the
    histogram of edge orientations weighted by edge magnitude" (section 4.3).

    Parameters
    ----------
    magnitude, orientation_rad : array_like
        As returned by :func:`local_energy`.
    n_bins, smooth_bins : int, float
        As in :func:`orientation_histogram`.
    max_peaks : int
        At most this many orientations, the strongest first.
    min_share : float
        Smallest share of a peak in the total weight. A peak's share is the weight of its
        lobe, the bins that climb to it (between the minima on either side), over the total,
        so it measures how much of the edge evidence the orientation explains, whatever
        ``n_bins``.

    Returns
    -------
    ndarray of float
        Orientations in ``[0, pi)``, radians, strongest lobe first. Each is refined between
        bin centres by a parabola through the peak bin and its two neighbours.
    """
    centres, weights = orientation_histogram(magnitude, orientation_rad, n_bins=n_bins,
                                             smooth_bins=smooth_bins)
    total = weights.sum()
    if total <= 0:
        return np.zeros(0)
    bins = np.arange(n_bins)
    before, after = weights[(bins - 1) % n_bins], weights[(bins + 1) % n_bins]
    is_peak = (weights > before) & (weights >= after)
    # every bin climbs to its higher neighbour until a peak: pointer jumping gives its lobe
    uphill = np.where(is_peak, bins,
                      np.where(after > before, (bins + 1) % n_bins, (bins - 1) % n_bins))
    for _ in range(int(np.ceil(np.log2(n_bins))) + 1):
        uphill = uphill[uphill]
    share = np.bincount(uphill, weights, minlength=n_bins) / total
    peaks = bins[is_peak & (share >= min_share)]
    peaks = peaks[np.argsort(-share[peaks], kind="stable")][:max_peaks]
    curvature = before[peaks] - 2 * weights[peaks] + after[peaks]
    shift = np.where(curvature < 0, 0.5 * (before[peaks] - after[peaks])
                     / np.where(curvature < 0, curvature, -1), 0)
    return np.mod(centres[peaks] + np.clip(shift, -0.5, 0.5) * (np.pi / n_bins), np.pi)
