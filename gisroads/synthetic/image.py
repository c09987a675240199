"""Orthoimages (R, G, B, NIR) and digital surface models of synthetic scenes.

Each pixel shows the highest surface at its centre (a true orthoimage: tree crowns hide the
roads under them, a bridge deck hides the road below), coloured by material with per-object
variation (roof and car colours, shades of green) and Gaussian noise of ``NOISE_DN``. NIR
makes vegetation stand out: NDVI is about 0.45 on grass and 0.6 on foliage, below 0.05 on
asphalt. Shadows are cast from the DSM by a noon sun due south, ``SUN_ELEVATION_DEG`` high,
and darken every band by ``SHADOW_FACTOR``.

The DSM is float32 metres of that same highest surface (crown hulls, roofs, car roofs,
decks, ground), sampled at pixel centres.
"""
from __future__ import annotations

import numpy as np
from affine import Affine

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..io.raster import write_geotiff
from .network import Material, Scene, describe_surfaces, rasterize_surfaces

SUN_ELEVATION_DEG = 45.0
"""Of the sun, due south (local noon): shadows fall straight north."""
SHADOW_FACTOR = 0.5
NOISE_DN = 4.0
BAND_NAMES = ["red", "green", "blue", "nir"]
BLOCK_PX = 1024
"""Pixels per side of the blocks rendered at a time."""

#: (R, G, B, NIR) choices per Material; an object's tone picks one.
PALETTES = {
    Material.GRASS: [(78, 112, 52, 188), (86, 120, 58, 196), (72, 104, 50, 180)],
    Material.CONCRETE: [(176, 173, 166, 178)],
    Material.ASPHALT: [(86, 88, 91, 92)],
    Material.DARK_ASPHALT: [(60, 61, 64, 63)],
    Material.PAINT: [(236, 236, 230, 228)],
    Material.ROCK: [(148, 128, 102, 158)],
    Material.ROOF: [(168, 78, 60, 128), (150, 92, 70, 132), (120, 120, 126, 122),
                    (88, 90, 96, 94)],
    Material.CAR: [(200, 200, 205, 200), (30, 30, 34, 34), (150, 25, 25, 70),
                   (40, 60, 130, 62), (140, 142, 148, 146), (210, 180, 60, 170)],
    Material.FOLIAGE: [(44, 82, 38, 172), (52, 92, 40, 184), (38, 70, 34, 160)],
    Material.PAVERS: [(150, 128, 118, 150)],
    Material.WATER: [(46, 62, 66, 20)],
}
_COUNT = np.array([len(PALETTES[m]) for m in Material])
_PALETTE = np.zeros((len(Material), _COUNT.max(), 4))
for _m in Material:
    _PALETTE[_m, :_COUNT[_m]] = PALETTES[_m]


def _grid(scene: Scene, pixel_m: float) -> tuple[Affine, tuple[int, int]]:
    xmin, ymin, xmax, ymax = scene.extent
    # A few ulps over a whole number of pixels must not add a column.
    shape = (int(np.ceil((ymax - ymin) / pixel_m - 1e-6)),
             int(np.ceil((xmax - xmin) / pixel_m - 1e-6)))
    return Affine(pixel_m, 0, xmin, 0, -pixel_m, ymax), shape


def _blocks(shape):
    rows, cols = shape
    for r0 in range(0, rows, BLOCK_PX):
        for c0 in range(0, cols, BLOCK_PX):
            yield r0, min(r0 + BLOCK_PX, rows), c0, min(c0 + BLOCK_PX, cols)


def _shadows(dsm: np.ndarray, pixel_m: float) -> np.ndarray:
    """Pixels from which the sun, due south, is hidden by a higher DSM cell south of them.

    Pixel ``i`` of a column is shaded when some row ``j > i`` rises above the sun's ray,
    ``dsm[j] > dsm[i] + (j - i) * pixel_m * tan(elevation)``, that is when the running
    maximum of ``dsm[j] - j * pixel_m * tan(elevation)`` from the south exceeds its own.
    """
    rise = pixel_m * np.tan(np.radians(SUN_ELEVATION_DEG)) * np.arange(dsm.shape[0])[:, None]
    shadow = np.empty(dsm.shape, bool)
    for c0 in range(0, dsm.shape[1], BLOCK_PX):
        # float64: the ramp reaches kilometres, the heights compared differ by millimetres.
        level = dsm[:, c0:c0 + BLOCK_PX].astype(np.float64) - rise
        south = np.maximum.accumulate(level[::-1], axis=0)[::-1]
        shadow[:-1, c0:c0 + BLOCK_PX] = south[1:] > level[:-1] + 1e-3
        shadow[-1, c0:c0 + BLOCK_PX] = False
    return shadow


def render_image(scene: Scene, *, pixel_m: float = 0.25, seed: int = 0
                 ) -> tuple[GeoRaster, GeoRaster]:
    """Render an orthoimage and a DSM of a scene.

    Parameters
    ----------
    scene : Scene
    pixel_m : float
        Pixel side (metres); the grid starts at the scene's upper-left corner.
    seed : int
        Noise seed.

    Returns
    -------
    image : GeoRaster
        uint8, bands (R, G, B, NIR), shape ``(4, rows, cols)``.
    dsm : GeoRaster
        float32 metres, ``(rows, cols)``.

    Examples
    --------
    >>> from gisroads.synthetic import make_scene, render_image
    >>> scene = make_scene(seed=0, size_m=(300, 300))
    >>> image, dsm = render_image(scene, pixel_m=1.0)
    >>> image.data.shape, image.data.dtype.name, image.pixel_size
    ((4, 300, 300), 'uint8', 1.0)
    >>> dsm.shape == image.shape and dsm.crs == image.crs == scene.crs
    True
    """
    if pixel_m <= 0:
        raise GisroadsError("pixel_m must be positive")
    transform, shape = _grid(scene, pixel_m)
    image = np.empty((4, *shape), np.uint8)
    dsm = np.empty(shape, np.float32)
    blocks = list(_blocks(shape))
    for index, (r0, r1, c0, c1) in enumerate(blocks):
        rng = np.random.default_rng([seed, scene.seed, index])
        x0, y0 = transform.c + c0 * pixel_m, transform.f - r0 * pixel_m
        ground_id, over_id = rasterize_surfaces(
            scene, Affine(pixel_m, 0, x0, 0, -pixel_m, y0), (r1 - r0, c1 - c0))
        x, y = np.meshgrid(x0 + (np.arange(c1 - c0) + 0.5) * pixel_m,
                           y0 - (np.arange(r1 - r0) + 0.5) * pixel_m)
        x, y = x.ravel(), y.ravel()
        surfaces = describe_surfaces(scene, x, y, ground_id.ravel(), over_id.ravel())
        dsm[r0:r1, c0:c1] = surfaces.top_z.reshape(r1 - r0, c1 - c0)
        material = surfaces.top_material
        choice = np.minimum((surfaces.top_tone * _COUNT[material]).astype(int),
                            _COUNT[material] - 1)
        colour = _PALETTE[material, choice].T + NOISE_DN * rng.standard_normal(
            (4, len(x)), dtype=np.float32)
        image[:, r0:r1, c0:c1] = np.clip(np.round(colour), 0, 255).astype(np.uint8).reshape(
            4, r1 - r0, c1 - c0)
    shadow = _shadows(dsm, pixel_m)
    for band in image:
        band[shadow] = (band[shadow] * SHADOW_FACTOR).astype(np.uint8)
    return (GeoRaster(image, transform, scene.crs), GeoRaster(dsm, transform, scene.crs))


def write_image(scene: Scene, image_path, dsm_path, *, pixel_m: float = 0.25,
                seed: int = 0) -> None:
    """Render with :func:`render_image` and write both as GeoTIFFs, each atomically."""
    image, dsm = render_image(scene, pixel_m=pixel_m, seed=seed)
    write_geotiff(image_path, image, band_names=BAND_NAMES)
    write_geotiff(dsm_path, dsm, band_names=["dsm_m"])
