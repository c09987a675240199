"""Airborne LiDAR point clouds of synthetic scenes, rendered tile by tile, and point truth.

Each pulse is a vertical ray at a uniformly random position (a Poisson number per tile, so
the density is exact on average and tiles are independent): its first return is the
highest surface there (bridge deck, roof, car roof, tree crown, else the ground or road).
Foliage is porous: first returns come from inside the crown (an exponential depth under its
hull), and ``CANOPY_GAP_FRACTION`` of the canopy pulses also give a last return on what lies
beneath (road, ground, car roof). Decks, roofs and cars are opaque: no return under them.
Heights carry a ``Z_NOISE_M`` Gaussian noise.

Intensity is the surface's reflectance at 1064 nm times ``INTENSITY_SCALE`` (65535: the
16-bit scale LAS 1.4 asks for), with 8 % multiplicative and 0.01 additive noise; a pulse
split in two returns shares its energy 60/40 between them. Reflectances: asphalt 0.12,
parking asphalt 0.09, concrete 0.30, brick pavers 0.30 (as bright as the concrete
footways), paint 0.60, grass 0.45, foliage 0.45, rock 0.25, roofs 0.15-0.50 and cars
0.08-0.58 (per object). Open water returns nothing (specular at 1064 nm): a pulse whose
first surface is water is lost.

Classes (ASPRS): 2 ground (every ground surface, roads and sidewalks included, and bridge
ramps, which stand on embankments), 17 bridge deck, 6 building, 5 high vegetation, 1 cars
(unclassified).
"""
from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import shapely
from affine import Affine

from ..errors import GisroadsError
from ..io.las import BRIDGE_DECK_CLASS, GROUND_CLASS, LasPointWriter, PointCloud
from ..progress import Progress, report
from .network import (Kind, Material, Scene, SurfaceSample, describe_surfaces,
                      rasterize_surfaces)

INTENSITY_SCALE = 65535
"""LAS intensity of a surface of reflectance 1."""
CANOPY_GAP_FRACTION = 0.4
"""Share of the pulses hitting a tree crown first that also return from below it."""
Z_NOISE_M = 0.03
CROWN_PENETRATION_M = 0.4
"""Mean depth under the crown hull of first returns from foliage (metres)."""

#: Reflectance of each Material: (lowest, highest); objects spread over the range by tone.
REFLECTANCE = {
    Material.GRASS: (0.45, 0.45), Material.CONCRETE: (0.30, 0.30),
    Material.ASPHALT: (0.12, 0.12), Material.DARK_ASPHALT: (0.09, 0.09),
    Material.PAINT: (0.60, 0.60), Material.ROCK: (0.25, 0.25),
    Material.ROOF: (0.15, 0.50), Material.CAR: (0.08, 0.58), Material.FOLIAGE: (0.45, 0.45),
    Material.PAVERS: (0.30, 0.30), Material.WATER: (0.0, 0.0),
}
_LOW = np.array([REFLECTANCE[m][0] for m in Material])
_SPAN = np.array([REFLECTANCE[m][1] - REFLECTANCE[m][0] for m in Material])

LAS_CLASS = {Kind.GROUND: GROUND_CLASS, Kind.BUILDING: 6, Kind.CAR: 1, Kind.TREE: 5,
             Kind.DECK: BRIDGE_DECK_CLASS}
_CLASS = np.array([LAS_CLASS[k] for k in Kind], dtype=np.uint8)


def label_pixel_m(density_per_m2: float) -> float:
    """Pixel side (metres) on which surfaces are rasterised for a given pulse density.

    A quarter of the mean pulse spacing, at most 10 cm: where a point falls within that
    distance of a polygon edge it may take the surface on the other side.
    """
    return float(min(0.1, 0.25 / np.sqrt(density_per_m2)))


def _tiles(extent, tile_m: float) -> list[tuple[float, float, float, float]]:
    """Tile bounds covering the extent row by row from its lower-left corner."""
    xmin, ymin, xmax, ymax = extent
    return [(x0, y0, min(x0 + tile_m, xmax), min(y0 + tile_m, ymax))
            for y0 in np.arange(ymin, ymax, tile_m) for x0 in np.arange(xmin, xmax, tile_m)]


def _intensity(rng, material, tone, energy) -> np.ndarray:
    reflectance = (_LOW[material] + _SPAN[material] * tone) * energy
    noisy = reflectance * (1 + 0.08 * rng.standard_normal(len(material)))
    noisy += 0.01 * rng.standard_normal(len(material))
    return np.round(np.clip(noisy, 0, 1) * INTENSITY_SCALE).astype(np.uint16)


def _returns(rng, surfaces: SurfaceSample, x, y, crs) -> PointCloud:
    """First returns of every pulse, then the last returns of the pulses split by foliage."""
    n = len(x)
    canopy = surfaces.over_on_top & (surfaces.over_kind == Kind.TREE)
    first_z = surfaces.top_z
    first_z[canopy] -= np.minimum(rng.exponential(CROWN_PENETRATION_M, int(canopy.sum())),
                                  4 * CROWN_PENETRATION_M)
    split = canopy & (rng.random(n) < CANOPY_GAP_FRACTION)
    below = np.flatnonzero(split)

    xyz = np.empty((n + len(below), 3))
    xyz[:n, 0], xyz[:n, 1], xyz[:n, 2] = x, y, first_z
    xyz[n:, 0], xyz[n:, 1], xyz[n:, 2] = x[below], y[below], surfaces.base_z[below]
    xyz[:, 2] += Z_NOISE_M * rng.standard_normal(len(xyz))
    kind = np.concatenate([surfaces.top_kind, surfaces.base_kind[below]])
    intensity = np.concatenate([
        _intensity(rng, surfaces.top_material, surfaces.top_tone, np.where(split, 0.6, 1.0)),
        _intensity(rng, surfaces.base_material[below], surfaces.base_tone[below], 0.4)])
    return PointCloud(
        xyz=xyz, intensity=intensity, classification=_CLASS[kind],
        return_number=np.concatenate([np.ones(n, np.uint8), np.full(len(below), 2, np.uint8)]),
        number_of_returns=np.concatenate([split + 1, np.full(len(below), 2)]).astype(np.uint8),
        crs=crs, source_crs=crs)


def render_cloud(scene: Scene, *, density_per_m2: float = 10.0, seed: int = 0,
                 tile_m: float = 100.0, progress: Progress = None) -> Iterator[PointCloud]:
    """Simulate an airborne LiDAR survey of a scene, one tile at a time.

    Parameters
    ----------
    scene : Scene
    density_per_m2 : float
        Pulses (first returns) per square metre; canopy pulses add their last returns.
    seed : int
        Noise and sampling seed; each tile draws from its own stream, so a chunk depends
        only on the scene, the seed and the tile.
    tile_m : float
        Tile side (metres): memory is bounded by one tile's points whatever the scene size.
    progress : callable, optional
        ``progress(fraction, message)`` before each tile; it may raise to cancel.

    Yields
    ------
    PointCloud
        One chunk per non-empty tile, first returns then the extra last returns, in
        ``scene.crs`` (also its ``source_crs``).
    """
    if density_per_m2 <= 0 or tile_m <= 0:
        raise GisroadsError("density_per_m2 and tile_m must be positive")
    pixel = label_pixel_m(density_per_m2)
    tiles = _tiles(scene.extent, tile_m)
    for index, (x0, y0, x1, y1) in enumerate(tiles):
        report(progress, index / len(tiles), f"LiDAR tile {index + 1} of {len(tiles)}")
        rng = np.random.default_rng([seed, scene.seed, index])
        n = rng.poisson(density_per_m2 * (x1 - x0) * (y1 - y0))
        if n == 0:
            continue
        x, y = rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)
        shape = (int(np.ceil((y1 - y0) / pixel)), int(np.ceil((x1 - x0) / pixel)))
        ground_id, over_id = rasterize_surfaces(scene, Affine(pixel, 0, x0, 0, -pixel, y1),
                                                shape)
        row = np.minimum(((y1 - y) / pixel).astype(np.intp), shape[0] - 1)
        col = np.minimum(((x - x0) / pixel).astype(np.intp), shape[1] - 1)
        ground_id, over_id = ground_id[row, col], over_id[row, col]
        surfaces = describe_surfaces(scene, x, y, ground_id, over_id)
        dry = surfaces.top_material != Material.WATER
        if not dry.all():
            x, y, ground_id, over_id = x[dry], y[dry], ground_id[dry], over_id[dry]
            surfaces = describe_surfaces(scene, x, y, ground_id, over_id)
        if len(x):
            yield _returns(rng, surfaces, x, y, scene.crs)


def write_cloud(scene: Scene, path, *, density_per_m2: float = 10.0, seed: int = 0,
                tile_m: float = 100.0, progress: Progress = None) -> int:
    """Stream :func:`render_cloud` into a LAS/LAZ file (``.laz``: compressed), atomically.

    A failure or a cancel (``progress`` raising) leaves no file behind.

    Returns
    -------
    int
        Number of points written.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from gisroads.io import las_info
    >>> from gisroads.synthetic import make_scene, write_cloud
    >>> scene = make_scene(seed=0, size_m=(300, 300))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     count = write_cloud(scene, Path(folder) / "cloud.laz", density_per_m2=2)
    ...     info = las_info(Path(folder) / "cloud.laz")
    >>> info["format"], info["epsg"], info["point_count"] == count
    ('LAZ', 32633, True)
    >>> 2 * 300 * 300 < count < 1.2 * 2 * 300 * 300  # pulses, and the canopy's last returns
    True
    """
    xmin, ymin = scene.extent[:2]
    with LasPointWriter(path, crs=scene.crs, offset=(xmin, ymin, 0.0)) as writer:
        for chunk in render_cloud(scene, density_per_m2=density_per_m2, seed=seed,
                                  tile_m=tile_m, progress=progress):
            writer.write(chunk.xyz, intensity=chunk.intensity,
                         classification=chunk.classification,
                         return_number=chunk.return_number,
                         number_of_returns=chunk.number_of_returns)
    report(progress, 1.0, f"{writer.count} points written")
    return writer.count


def road_surface_mask(scene: Scene, xyz, *, tolerance_m: float = 0.3) -> np.ndarray:
    """Which points lie on the surface of a truth road, on the right level.

    A point is on a road when it falls inside the road's truth polygon and within
    ``tolerance_m`` of that road's surface elevation: a point on the lower road under a
    bridge deck is, a point on the deck is on the upper road, a car roof or a canopy return
    above a road is not.

    Parameters
    ----------
    scene : Scene
    xyz : ndarray, shape (n, 3)
        Metres, in ``scene.crs``.
    tolerance_m : float
        Vertical tolerance; keep it under the 1.4 m of a car and over the point noise.
    """
    xyz = np.asarray(xyz, float)
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    areas = scene.areas
    on_road = np.zeros(len(xyz), bool)
    for road_id, area in [(None, areas.grade_roads), *areas.bridge_roads.items()]:
        inside = np.flatnonzero(shapely.contains_xy(area, x, y))
        surface = (scene.relief.terrain_z(x[inside], y[inside]) if road_id is None
                   else scene.relief.road_z(x[inside], y[inside], road_id))
        on_road[inside[np.abs(z[inside] - surface) <= tolerance_m]] = True
    return on_road
