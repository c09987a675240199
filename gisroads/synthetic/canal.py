"""A seeded synthetic canal town: brick-paved streets along canals, with exact truth.

What a Dutch town block shows an airborne scanner, and what defeats the usual LiDAR road
cues: the streets are laid in brick pavers as bright at 1064 nm as the concrete footways,
one flank of each canal street is open water (no returns), and the only geometric cue is
the kerb, 8-12 cm, between the street and the footway on its building side.

:func:`make_canal_scene` lays out canals running west-east (one per 150 m of height,
14-22 m wide), a paver street of 5-6.5 m on each bank (the street runs to the quay edge,
a 2 m footway a kerb higher on its other side, then houses on lawns), and north-south paver
streets of 5-7 m (footways on both sides) that cross the canals on bridges at street level,
where the water stops. Its :class:`~gisroads.synthetic.network.Scene` renders like any
other (:func:`~gisroads.synthetic.cloud.render_cloud`,
:func:`~gisroads.synthetic.image.render_image`).
"""
from __future__ import annotations

import numpy as np
import shapely

from .network import (SIDEWALK_M, Scene, _buildings, _gdf, _make_relief, _node_same_level,
                      _Road, _road_frame, _stable_seed, scene_frame)

CANAL_KERB_RANGE_M = (0.08, 0.12)
"""Kerb height between a canal town's streets and footways, metres."""
CANAL_WIDTH_M = (14.0, 22.0)
CANAL_STREET_WIDTH_M = (5.0, 6.5)
CROSS_STREET_WIDTH_M = (5.0, 7.0)


def make_canal_scene(*, seed: int = 0, size_m: tuple[float, float] = (300.0, 300.0),
                     origin: tuple[float, float] = (500000.0, 4500000.0), crs="EPSG:32631"
                     ) -> Scene:
    """Lay out a canal town (see the module docstring).

    Parameters
    ----------
    seed : int
        Same seed, same scene.
    size_m : (width, height)
        Metres; at least 300 each.
    origin : (x, y)
        Lower-left corner in map units (metres).
    crs : anything pyproj accepts
        A projected CRS in metres.

    Returns
    -------
    Scene
        Its roads are ``surface`` 'pavers'; ``water`` holds the canals.

    Examples
    --------
    >>> from gisroads.synthetic import make_canal_scene
    >>> scene = make_canal_scene(seed=0)
    >>> sorted(set(scene.roads["surface"]))
    ['pavers']
    >>> len(scene.water), len(scene.truth.junctions)
    (6, 8)
    """
    extent, crs = scene_frame(size_m, origin, crs)
    xmin, ymin, xmax, ymax = extent
    rng = _stable_seed(seed, "canals")
    canal_count = max(1, int((ymax - ymin) // 150))
    cross_count = max(1, int((xmax - xmin) // 130))
    canals, roads = [], []
    for k in range(canal_count):
        y = ymin + (ymax - ymin) * (k + 0.5) / canal_count + rng.uniform(-10, 10)
        half = rng.uniform(*CANAL_WIDTH_M) / 2
        canals.append(shapely.box(xmin, y - half, xmax, y + half))
        for side in (-1, 1):
            width = rng.uniform(*CANAL_STREET_WIDTH_M)
            at = y + side * (half + width / 2)
            roads.append(_Road(f"canal_{k}_{'south' if side < 0 else 'north'}",
                               np.array([[xmin, at], [xmax, at]]), width, surface="pavers"))
    for k in range(cross_count):
        x = xmin + (xmax - xmin) * (k + 0.5) / cross_count + rng.uniform(-12, 12)
        roads.append(_Road(f"cross_{k}", np.array([[x, ymin], [x, ymax]]),
                           rng.uniform(*CROSS_STREET_WIDTH_M), surface="pavers"))
    _node_same_level(roads)
    relief = _make_relief(seed, (xmin, ymin), cliff_line=((xmin, ymax), (xmax, ymax)),
                          cliff_height_m=0.0, cliff_slope_m=1.0, ramps=(),
                          kerb_range_m=CANAL_KERB_RANGE_M)
    lines = np.array([r.line for r in roads], dtype=object)
    widths = np.array([r.width_m for r in roads])
    polys = shapely.buffer(lines, widths / 2, cap_style="flat", join_style="round")
    bridges = shapely.union_all(shapely.buffer(
        lines[-cross_count:], widths[-cross_count:] / 2 + SIDEWALK_M, cap_style="flat"))
    water = [part for canal in canals
             for part in shapely.get_parts(shapely.difference(canal, bridges))]
    footprints, height, roof_z, tone = _buildings(
        _stable_seed(seed, "buildings"), extent, lines, polys, np.array(canals, dtype=object),
        lambda xy: np.zeros(len(xy), bool), relief)
    none = np.empty(0)
    return Scene(
        roads=_road_frame(roads, relief, crs),
        parking_lots=_gdf({"lot_id": none.astype(np.int64), "aspect": none}, [], crs),
        parking_access=_gdf({"lot_id": none.astype(np.int64)}, [], crs),
        buildings=_gdf({"building_id": np.arange(len(footprints), dtype=np.int64),
                        "height_m": height, "roof_z": roof_z, "tone": tone}, footprints, crs),
        trees=_gdf({"tree_id": none.astype(np.int64), "crown_radius_m": none,
                    "height_m": none, "crown_depth_m": none, "top_z": none, "tone": none},
                   [], crs),
        cars=_gdf({"car_id": none.astype(np.int64), "height_m": none, "roof_z": none,
                   "tone": none, "where": none.astype(object)}, [], crs),
        markings=_gdf({"road_id": none.astype(np.int64), "kind": none.astype(object)}, [],
                      crs),
        cliff=_gdf({"height_m": none, "slope_m": none}, [], crs),
        bridges=_gdf({"bridge_id": none.astype(np.int64), "road_id": none.astype(np.int64),
                      "under_road_id": none.astype(np.int64), "height_m": none,
                      "crossing_x": none, "crossing_y": none}, [], crs),
        extent=extent, crs=crs, seed=int(seed), relief=relief,
        water=_gdf({"water_id": np.arange(len(water), dtype=np.int64)}, water, crs))
