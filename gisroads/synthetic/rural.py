"""Rural aerial tiles: earth tracks on bare ground, villages, gullies and fields.

None of the labelled training sources shows rural scenes of arid and semi-arid land (the
training README lists them as missing): unpaved tracks a little lighter or darker than the
bare earth around them, a village's grid of lanes between small houses, and line-like
features that are no roads (dry river beds, gullies lined with shrubs, field boundaries).
:func:`render_rural_tile` draws such a tile with its exact road mask, seeded, so that a
convolutional road model can learn that a track is a road whatever its surface, and that a
river bed is not.
"""
from __future__ import annotations

import numpy as np
from affine import Affine
from rasterio.features import rasterize
from scipy import ndimage
from shapely.affinity import rotate, translate
from shapely.geometry import LineString, box

#: bare-earth colours (R, G, B): ochre, red-brown, sand, khaki, dark soil, dry savanna
EARTH_RGB = np.array([(170, 135, 95), (150, 105, 75), (195, 175, 140), (140, 130, 105),
                      (110, 90, 70), (125, 120, 80)], float)
ROOF_RGB = np.array([(225, 225, 220), (175, 172, 168), (160, 82, 62), (150, 160, 175),
                     (120, 110, 100)], float)
SHRUB_RGB = np.array((62, 74, 42), float)
ASPHALT_RGB = np.array((98, 98, 100), float)
GRASS_RGB = np.array([(80, 112, 52), (105, 125, 70), (140, 150, 95)], float)
PLAIN_SHARE = 0.08
"""Tiles of one colour and sensor noise alone (a bare field, a lawn): nothing in them is
a road, however their contrast is stretched."""
ROADLESS_SHARE = 0.12
"""Rural tiles without tracks: fields, shrubs, gullies and river beds only."""


def _fractal(rng: np.random.Generator, shape, scales_px) -> np.ndarray:
    """Smooth noise of unit spread: Gaussian-filtered white noise summed over scales."""
    field = np.zeros(shape)
    for scale in scales_px:
        layer = ndimage.gaussian_filter(rng.standard_normal(shape), scale, mode="wrap")
        field += (layer - layer.mean()) / max(layer.std(), 1e-9)
    return field / np.sqrt(len(scales_px))


def _wandering(rng: np.random.Generator, start, heading: float, length_px: float,
               turn_sd: float) -> LineString:
    """A smooth random curve: its heading a smoothed random walk, steps of 4 pixels."""
    steps = max(int(length_px / 4), 2)
    headings = heading + ndimage.gaussian_filter1d(np.cumsum(rng.normal(0, turn_sd, steps)), 6)
    xy = np.asarray(start, float) + np.cumsum(4 * np.c_[np.cos(headings), np.sin(headings)],
                                              axis=0)
    return LineString(np.vstack([start, xy]))


def _edge_start(rng: np.random.Generator, size: int) -> tuple[np.ndarray, float]:
    """A point on the tile's border and a heading into the tile."""
    side = rng.integers(4)
    t = rng.uniform(0.1, 0.9) * size
    start = [(t, 0.0), (size, t), (t, size), (0.0, t)][side]
    inward = [np.pi / 2, np.pi, -np.pi / 2, 0.0][side]
    return np.array(start), inward + rng.uniform(-0.5, 0.5)


def _burn(shapes, size: int) -> np.ndarray:
    shapes = [(g, 1) for g in shapes if not g.is_empty]
    if not shapes:
        return np.zeros((size, size), bool)
    return rasterize(shapes, out_shape=(size, size), transform=Affine.identity(),
                     dtype="uint8").astype(bool)


def _village(rng: np.random.Generator, size: int, pixel_m: float):
    """Lanes of a village grid (pixel coordinates) and the village's footprint."""
    angle = rng.uniform(0, 180)
    extent = rng.uniform(0.4, 0.9) * size
    centre = rng.uniform(0.3, 0.7, 2) * size
    spacing = rng.uniform(50, 130, 2) / pixel_m
    lanes = []
    for axis in (0, 1):
        offsets = np.arange(-extent / 2, extent / 2 + 1, spacing[axis])
        offsets += rng.uniform(0, spacing[axis])
        for offset in offsets[np.abs(offsets) < extent / 2]:
            reach = extent / 2 * rng.uniform(0.7, 1.0)
            ends = ((-reach, offset), (reach, offset)) if axis == 0 else \
                ((offset, -reach), (offset, reach))
            lanes.append(LineString(np.asarray(ends) + centre))
    footprint = box(*(centre - extent / 2), *(centre + extent / 2))
    return ([rotate(lane, angle, origin=tuple(centre)) for lane in lanes],
            rotate(footprint, angle, origin=tuple(centre)), angle)


def _houses(rng: np.random.Generator, footprint, angle: float, roads: np.ndarray,
            pixel_m: float, count: int):
    """House polygons inside ``footprint``, clear of the road mask, aligned with the grid."""
    xmin, ymin, xmax, ymax = footprint.bounds
    clearance = ndimage.distance_transform_edt(~roads) * pixel_m
    x, y = rng.uniform(xmin, xmax, count), rng.uniform(ymin, ymax, count)
    size = roads.shape[0]
    rows, cols = np.clip(y.astype(int), 0, size - 1), np.clip(x.astype(int), 0, size - 1)
    sides = rng.uniform(5, 14, (count, 2)) / pixel_m
    keep = clearance[rows, cols] > sides.max(axis=1) * pixel_m * 0.75 + 2
    return [rotate(box(px - a / 2, py - b / 2, px + a / 2, py + b / 2), angle)
            for px, py, (a, b), k in zip(x, y, sides, keep) if k and footprint.contains(
                box(px - 1, py - 1, px + 1, py + 1))]


def render_rural_tile(seed: int, *, size_px: int = 448, pixel_m: float = 0.5
                      ) -> tuple[np.ndarray, np.ndarray]:
    """A rural aerial tile and its road mask.

    Bare earth of one of :data:`EARTH_RGB`'s colours with smooth brightness variation,
    sometimes fields of different tones; earth tracks 3-8 m wide (through tracks across the
    tile and, most of the time, a village's grid of lanes) 15-40 % lighter or 15-30 %
    darker than the ground, now and then asphalt; houses with shadows beside the lanes;
    shrubs; and road-like features that are not roads: gullies and dry river beds (darker,
    shrub-lined, or pale sand) and lines of shrubs along field edges. :data:`ROADLESS_SHARE`
    of the tiles have no track, :data:`PLAIN_SHARE` are one colour with sensor noise.

    Parameters
    ----------
    seed : int
        The same seed gives the same tile.
    size_px : int
        Pixels per side.
    pixel_m : float
        Ground size of a pixel, metres.

    Returns
    -------
    rgb : ndarray of uint8, shape (3, size_px, size_px)
    road : ndarray of bool, shape (size_px, size_px)
        The tracks' surfaces.

    Examples
    --------
    >>> from gisroads.synthetic.rural import render_rural_tile
    >>> rgb, road = render_rural_tile(0, size_px=256)
    >>> rgb.shape, rgb.dtype.name, bool(0.01 < road.mean() < 0.5)
    ((3, 256, 256), 'uint8', True)
    """
    rng = np.random.default_rng(seed)
    size = size_px
    shape = (size, size)
    kind = rng.random()
    if kind < PLAIN_SHARE:
        colours = np.vstack([EARTH_RGB, GRASS_RGB])
        colour = colours[rng.integers(len(colours))] + rng.uniform(-15, 15, 3)
        image = colour[:, None, None] + rng.normal(0, rng.uniform(2, 8), (3, size, size))
        return np.clip(image, 0, 255).astype(np.uint8), np.zeros(shape, bool)
    earth = EARTH_RGB[rng.integers(len(EARTH_RGB))] + rng.uniform(-15, 15, 3)
    tone = 1 + 0.12 * _fractal(rng, shape, [40 / pixel_m, 12 / pixel_m]) \
        + 0.04 * _fractal(rng, shape, [1.0, 3.0])
    image = earth[:, None, None] * tone[None]
    if rng.random() < 0.4:
        rows, cols = np.mgrid[0:size, 0:size]
        theta = rng.uniform(0, np.pi)
        u = (cols * np.cos(theta) + rows * np.sin(theta)) // (rng.uniform(30, 90) / pixel_m)
        v = (-cols * np.sin(theta) + rows * np.cos(theta)) // (rng.uniform(30, 90) / pixel_m)
        parcel = ((u * 7919 + v * 104729).astype(np.int64)) % 97
        factors = rng.uniform(0.82, 1.15, 97)
        green = rng.uniform(0, 0.25, 97) * (rng.random(97) < 0.4)
        image = image * factors[parcel][None] + green[parcel][None] * (
            SHRUB_RGB - earth)[:, None, None]

    tracks, widths, paved = [], [], []
    roadless = kind < PLAIN_SHARE + ROADLESS_SHARE
    for _ in range(0 if roadless else rng.integers(1, 4)):
        start, heading = _edge_start(rng, size)
        tracks.append(_wandering(rng, start, heading, size * 1.6, rng.uniform(0.01, 0.05)))
        widths.append(rng.uniform(4, 8))
        paved.append(rng.random() < 0.15)
    footprint = angle = None
    if rng.random() < 0.65 and not roadless:
        lanes, footprint, angle = _village(rng, size, pixel_m)
        tracks += lanes
        widths += list(rng.uniform(3, 6, len(lanes)))
        paved += [False] * len(lanes)
    frame = box(0, 0, size, size)
    surfaces = [t.buffer(w / pixel_m / 2).intersection(frame) for t, w in zip(tracks, widths)]
    road = _burn(surfaces, size)

    for _ in range(rng.integers(0, 3)):
        start, heading = _edge_start(rng, size)
        bed = _wandering(rng, start, heading, size * 1.6, rng.uniform(0.05, 0.15))
        width = rng.uniform(2, 10) / pixel_m
        channel = _burn([bed.buffer(width / 2)], size) & ~road
        if rng.random() < 0.4:
            factor = rng.uniform(1.1, 1.3)
            image = np.where(channel[None], image * factor, image)
        else:
            image = np.where(channel[None], image * rng.uniform(0.6, 0.85), image)
            banks = _burn([bed.buffer(width / 2 + 4 / pixel_m)], size) & ~road
            shrubs = banks & (rng.random(shape) < 0.25)
            image = np.where(ndimage.binary_dilation(shrubs, iterations=2)[None],
                             SHRUB_RGB[:, None, None], image)

    for surface, is_paved in zip(surfaces, paved):
        mask = ndimage.gaussian_filter(_burn([surface], size).astype(float),
                                       rng.uniform(0.6, 1.5))
        if is_paved:
            target = ASPHALT_RGB[:, None, None] * (1 + 0.03 * rng.standard_normal(shape))
        else:
            factor = rng.uniform(1.15, 1.4) if rng.random() < 0.6 else rng.uniform(0.7, 0.85)
            # worn tracks fade and return along their length
            wear = np.clip(0.85 + 0.25 * _fractal(rng, shape, [15 / pixel_m]), 0.6, 1.3)
            target = image * (1 + (factor - 1) * wear)[None]
        image = image * (1 - mask[None]) + target * mask[None]

    if footprint is not None:
        houses = _houses(rng, footprint, angle, road, pixel_m, int(rng.integers(20, 120)))
        if houses:
            sun = rng.uniform(0, 2 * np.pi)
            reach = rng.uniform(2, 4) / pixel_m
            shadow = _burn([translate(h, reach * np.cos(sun), reach * np.sin(sun))
                            for h in houses], size) & ~road
            image = np.where(shadow[None], image * 0.55, image)
            roof_ids = _burn_ids(houses, size)
            colours = ROOF_RGB[rng.integers(len(ROOF_RGB), size=len(houses) + 1)]
            image = np.where(roof_ids[None] > 0, colours[roof_ids].transpose(2, 0, 1), image)

    density = np.clip(0.004 + 0.01 * _fractal(rng, shape, [30 / pixel_m]), 0, None)
    crowns = ndimage.binary_dilation(rng.random(shape) < density * 0.3,
                                     iterations=int(rng.integers(1, 4)))
    image = np.where((crowns & ~road)[None], SHRUB_RGB[:, None, None] * rng.uniform(0.8, 1.1),
                     image)
    if rng.random() < 0.3:
        start, heading = _edge_start(rng, size)
        hedge = _wandering(rng, start, heading, size * 1.6, 0.005)
        line = _burn([hedge.buffer(1.0 / pixel_m)], size) & ~road & (rng.random(shape) < 0.6)
        image = np.where(ndimage.binary_dilation(line)[None], SHRUB_RGB[:, None, None], image)

    image = ndimage.gaussian_filter(image, (0, 0.6, 0.6)) + rng.normal(0, 3, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8), road


def _burn_ids(polygons, size: int) -> np.ndarray:
    """Each polygon burnt with its 1-based index."""
    return rasterize([(p, k) for k, p in enumerate(polygons, start=1)], out_shape=(size, size),
                     transform=Affine.identity(), dtype="int32")
