"""PNG quick-looks: vector layers drawn over the raster they came from, to look at results."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geo import GeoRaster
from .vector import atomic_path


def _display_rgb(raster: GeoRaster) -> np.ndarray:
    """(rows, cols, 4) RGBA floats in [0, 1], each band stretched between its 2nd-98th
    percentile; cells without data (NaN) transparent, whatever matplotlib's version makes
    of NaN colours."""
    data = raster.data if raster.data.ndim == 3 else raster.data[np.newaxis]
    bands = data[:3] if len(data) >= 3 else np.repeat(data[:1], 3, axis=0)
    bands = bands.astype(float)
    lo = np.nanpercentile(bands, 2, axis=(1, 2), keepdims=True)
    hi = np.nanpercentile(bands, 98, axis=(1, 2), keepdims=True)
    rgb = np.clip((bands - lo) / np.maximum(hi - lo, 1e-9), 0, 1)
    valid = np.isfinite(rgb).all(axis=0)
    return np.concatenate([np.nan_to_num(rgb), valid[np.newaxis]]).transpose(1, 2, 0)


def write_quicklook(path, layers, *, background: GeoRaster | None = None, title: str = "",
                    size_px: int = 1400) -> Path:
    """Draw layers over an optional background raster into a PNG, atomically.

    Parameters
    ----------
    path : str or Path
    layers : list of (GeoDataFrame, dict)
        Frames in the background's CRS with matplotlib style keywords (``color``,
        ``linewidth``, ``label``, ``alpha``, ``markersize``).
    background : GeoRaster, optional
        RGB(+), or one band shown grey.
    title : str
    size_px : int
        Width and height of the image in pixels.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dpi = 100
    fig, ax = plt.subplots(figsize=(size_px / dpi, size_px / dpi), dpi=dpi)
    try:
        if background is not None:
            xmin, ymin, xmax, ymax = background.bounds
            ax.imshow(_display_rgb(background), extent=(xmin, xmax, ymin, ymax),
                      interpolation="nearest")
        for frame, style in layers:
            if len(frame):
                frame.plot(ax=ax, **style)
        if any("label" in style and len(frame) for frame, style in layers):  # drawn ones
            ax.legend(loc="upper right", fontsize=9, framealpha=0.8)
        ax.set_title(title)
        ax.set_aspect("equal")
        ax.ticklabel_format(useOffset=False, style="plain")
        ax.tick_params(labelsize=7)
        fig.tight_layout()
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
    return Path(path)


def evaluation_layers(qa: dict) -> list:
    """The QA layers of :func:`gisroads.evaluate.match_layers` styled for
    :func:`write_quicklook` in Boyko & Funkhouser's colours: missed reference red, matched
    extraction green, false extraction magenta."""
    reference, extracted = qa["eval_reference"], qa["eval_extracted"]
    return [
        (reference[reference.status == "FN"],
         dict(color="red", linewidth=3, label="missed reference (FN)")),
        (extracted[extracted.status == "TP"],
         dict(color="lime", linewidth=1.5, label="extracted, matched (TP)")),
        (extracted[extracted.status == "FP"],
         dict(color="magenta", linewidth=2, label="extracted, false (FP)")),
    ]
