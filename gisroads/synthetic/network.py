"""Seeded synthetic scenes: a road layout with its surroundings, elevation model and exact truth.

:func:`make_scene` lays a street grid out over any extent of at least 300 x 300 m (rows
about 85-170 m apart, verticals 85-150 m apart, nodes jittered) and places the special
features once:

* a 20-24 m avenue (the first row), crossed by a dual carriageway (two 7-8 m carriageways
  whose centre lines are 10.5-13 m apart, a raised median between them) and by a curved
  street, both running from the lower border up to the foot of a cliff;
* a diagonal street leaving the avenue at 35-50 degrees and meeting the curved street at an
  acute angle, and a 4-4.8 m cul-de-sac lane ending in the block south of the avenue, beside
  a parking lot joined to the avenue by a short access;
* a plateau raised by 7-11 m behind a steep cliff (a 3-5 m wide slope) along the upper
  border, with a road on its top, 6-12 m above another along its foot (the foot road ends
  every vertical in a T junction);
* a bridge: a straight road climbs on ramps from the lower border, crosses the avenue on a
  deck 6.5-7.5 m above it and comes down to end on the next row; it has no junction with
  the avenue;
* buildings (5-25 m) set back from the roads, street trees whose crowns overhang the roads,
  park trees, parked and moving cars, cars in the parking lot, dashed lane markings on
  roads of 7 m and more, zebra crossings near some junctions.

Larger scenes repeat the grid (some vertical segments dropped, which makes T junctions)
and add a few more cul-de-sacs and parking lots.

Truth (:attr:`Scene.truth`): the centre lines (LineString Z, the road surface elevation at
vertices at most 2 m apart) with their widths, their polygons, and the junctions of the
graph :attr:`Scene.truth_edges`, where roads meet only on the same level: the bridge
crossing is no junction.

Elevation model (metres, :class:`Relief`): a smooth terrain of three long waves (a few
metres over a kilometre) plus the plateau; every paved surface (roads, parking lots,
accesses) lies on that terrain, every other ground (sidewalks, verges, medians, the ground
under buildings) is raised by the kerb height, 10-20 cm, a slowly varying field, so each
road edge is a sharp 10-20 cm step. The bridge road is raised by its ramp profile.

Surfaces (:func:`rasterize_surfaces`, :func:`describe_surfaces`): two painter's-order
tables, the ground layer (ground materials, roofs, cars) and the overhead layer (tree crowns,
bridge decks), rasterised tile by tile and turned into heights and materials at any points;
the point cloud and the image are both rendered from them.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass
from enum import IntEnum
from functools import cached_property
from typing import NamedTuple

import geopandas as gpd
import numpy as np
import pandas as pd
import rasterio.features
import shapely
from affine import Affine
from pyproj import CRS

from ..errors import GisroadsError
from ..geo import RoadNetwork, line_end_degrees, network_from_centrelines

FEATURES = ("cliff", "bridge", "dual_carriageway", "diagonal", "cul_de_sac", "parking",
            "buildings", "trees", "cars", "markings")
"""Everything :func:`make_scene` can place; pass a subset as ``features`` to leave some out."""

MIN_SIZE_M = 300.0
SIDEWALK_M = 2.0
"""Width of the concrete sidewalk along each street (metres)."""
VERTEX_SPACING_M = 2.0
"""Largest distance between consecutive vertices of the truth centre lines (metres)."""
KERB_RANGE_M = (0.10, 0.20)
MARKING_MIN_ROAD_M = 7.0
"""Roads at least this wide carry a dashed centre line (metres)."""


class Material(IntEnum):
    """What a surface is made of; the renderers map it to reflectance and colour."""

    GRASS = 0
    CONCRETE = 1
    ASPHALT = 2
    DARK_ASPHALT = 3
    PAINT = 4
    ROCK = 5
    ROOF = 6
    CAR = 7
    FOLIAGE = 8
    PAVERS = 9
    WATER = 10


class Kind(IntEnum):
    """What kind of object a surface belongs to (decides the LiDAR class)."""

    GROUND = 0
    BUILDING = 1
    CAR = 2
    TREE = 3
    DECK = 4


class Base(IntEnum):
    """How the height of a ground-layer surface follows the relief."""

    RAISED = 0  # terrain + kerb height: sidewalks, verges, medians, ground under buildings
    PAVED = 1   # terrain: roads, parking lots, accesses, markings, ground under cars
    RAMP = 2    # terrain + the ramp profile of a bridge road


# ---------------------------------------------------------------------------------------
# Elevation model


def _sin(angle):
    """Sine in single precision: eight times faster, and its micrometre error on a few metres
    of relief is far below any noise; every height of a scene goes through it alike."""
    return np.sin(np.asarray(angle, np.float32))


def _ease(t):
    """0 -> 1 with zero slope at both ends (half a cosine)."""
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(t, 0.0, 1.0))


@dataclass(frozen=True)
class Ramp:
    """Height profile of a straight road that climbs onto a bridge deck and down again.

    The road rises from ``knots_m[0]`` to ``knots_m[1]`` (distance along the road from
    ``start``), stays ``height_m`` above the terrain over the deck up to ``knots_m[2]`` and
    comes down by ``knots_m[3]``.
    """

    road_id: int
    start: tuple[float, float]
    direction: tuple[float, float]
    knots_m: tuple[float, float, float, float]
    height_m: float

    def along(self, x, y):
        """Distance along the road from its start (metres) of map points."""
        return ((np.asarray(x, float) - self.start[0]) * self.direction[0]
                + (np.asarray(y, float) - self.start[1]) * self.direction[1])

    def height(self, x, y):
        """Height of the road surface above the terrain (metres) at map points on the road."""
        s = self.along(x, y)
        k0, k1, k2, k3 = self.knots_m
        return self.height_m * np.minimum(_ease((s - k0) / (k1 - k0)),
                                          _ease((k3 - s) / (k3 - k2)))


@dataclass(frozen=True)
class Relief:
    """Elevation model of a scene; every function takes map ``x, y`` arrays, returns metres.

    Attributes
    ----------
    origin : (x, y)
        Lower-left corner of the scene; the waves are phased from it.
    waves : tuple of (amplitude_m, kx, ky, phase)
        Terrain undulation (wave numbers in radians per metre).
    kerb_waves : tuple of (kx, ky, phase)
        Two waves whose mean sets the kerb height within ``kerb_range_m``.
    cliff_point, cliff_normal : (x, y)
        A point on the mid-slope line of the cliff, and its unit normal towards the plateau.
    cliff_height_m, cliff_slope_m : float
        Rise of the plateau and horizontal width of its slope (0 height: no cliff).
    ramps : tuple of Ramp
    kerb_range_m : (low, high)
        Range of the kerb height, metres.
    """

    origin: tuple[float, float]
    waves: tuple
    kerb_waves: tuple
    cliff_point: tuple[float, float]
    cliff_normal: tuple[float, float]
    cliff_height_m: float
    cliff_slope_m: float
    ramps: tuple = ()
    kerb_range_m: tuple[float, float] = KERB_RANGE_M

    def cliff_distance(self, x, y):
        """Signed distance (metres) from the cliff's mid-slope line, positive on the plateau."""
        return ((np.asarray(x, float) - self.cliff_point[0]) * self.cliff_normal[0]
                + (np.asarray(y, float) - self.cliff_point[1]) * self.cliff_normal[1])

    def terrain_z(self, x, y):
        """Bare terrain: undulation plus the plateau (paved surfaces lie exactly on it)."""
        u = np.asarray(x, float) - self.origin[0]
        v = np.asarray(y, float) - self.origin[1]
        z = np.zeros(np.broadcast(u, v).shape)
        for amplitude, kx, ky, phase in self.waves:
            z += amplitude * _sin(kx * u + ky * v + phase)
        if self.cliff_height_m:
            t = self.cliff_distance(x, y) / self.cliff_slope_m + 0.5
            t = np.clip(t, 0.0, 1.0)
            z += self.cliff_height_m * t * t * (3.0 - 2.0 * t)
        return z

    def kerb_m(self, x, y):
        """Height of unpaved ground above the paved level (metres), in ``kerb_range_m``."""
        u = np.asarray(x, float) - self.origin[0]
        v = np.asarray(y, float) - self.origin[1]
        mean = sum(_sin(kx * u + ky * v + phase) for kx, ky, phase in self.kerb_waves)
        low, high = self.kerb_range_m
        return (low + high) / 2 + (high - low) / 2 * mean / len(self.kerb_waves)

    def road_z(self, x, y, road_id: int):
        """Surface elevation (metres) road ``road_id`` has, or would have, at map points."""
        x = np.asarray(x, float)
        ramp = [i for i, r in enumerate(self.ramps) if r.road_id == road_id]
        base = np.full(x.shape, Base.RAMP if ramp else Base.PAVED)
        return self.base_z(x, y, base, np.full(x.shape, ramp[0] if ramp else -1))

    def base_z(self, x, y, base, ramp_index=None):
        """Surface height of ground-layer points given how each follows the relief.

        Parameters
        ----------
        x, y : ndarray
        base : ndarray of Base
        ramp_index : ndarray of int, optional
            Index into ``ramps`` for ``Base.RAMP`` points.
        """
        x, y, base = np.asarray(x, float), np.asarray(y, float), np.asarray(base)
        z = self.terrain_z(x, y)
        raised = base == Base.RAISED
        z[raised] += self.kerb_m(x[raised], y[raised])
        on_ramp = base == Base.RAMP
        for i, ramp in enumerate(self.ramps):
            sel = on_ramp & (ramp_index == i)
            z[sel] += ramp.height(x[sel], y[sel])
        return z


def _stable_seed(seed: int, name: str) -> np.random.Generator:
    """An independent generator per layout stage, so leaving a feature out moves nothing else."""
    return np.random.default_rng([int(seed), zlib.crc32(name.encode())])


def _make_relief(seed, origin, *, cliff_line, cliff_height_m, cliff_slope_m, ramps,
                 kerb_range_m=KERB_RANGE_M) -> Relief:
    rng = _stable_seed(seed, "relief")
    waves = []
    for amplitude, wavelength in ((1.2, (700, 1100)), (0.7, (350, 600)), (0.35, (200, 350))):
        k = 2 * np.pi / rng.uniform(*wavelength)
        angle = rng.uniform(0, 2 * np.pi)
        waves.append((amplitude * rng.uniform(0.7, 1.3), k * np.cos(angle), k * np.sin(angle),
                      rng.uniform(0, 2 * np.pi)))
    kerb_waves = []
    for _ in range(2):
        k = 2 * np.pi / rng.uniform(150, 300)
        angle = rng.uniform(0, 2 * np.pi)
        kerb_waves.append((k * np.cos(angle), k * np.sin(angle), rng.uniform(0, 2 * np.pi)))
    (x0, y0), (x1, y1) = cliff_line
    length = np.hypot(x1 - x0, y1 - y0)
    normal = (-(y1 - y0) / length, (x1 - x0) / length)
    return Relief(origin=tuple(map(float, origin)), waves=tuple(waves),
                  kerb_waves=tuple(kerb_waves), cliff_point=(float(x0), float(y0)),
                  cliff_normal=(float(normal[0]), float(normal[1])),
                  cliff_height_m=float(cliff_height_m), cliff_slope_m=float(cliff_slope_m),
                  ramps=tuple(ramps), kerb_range_m=tuple(map(float, kerb_range_m)))


# ---------------------------------------------------------------------------------------
# Road layout


@dataclass(eq=False)  # roads are told apart by identity
class _Road:
    name: str
    xy: np.ndarray
    width_m: float
    level: int = 0
    bridge: bool = False
    sidewalk: bool = True
    street_trees: bool = False
    kerb_parking: bool = False
    surface: str = "asphalt"

    @property
    def line(self):
        return shapely.linestrings(self.xy)


def _insert_points(xy: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Vertices of a polyline with points lying on it inserted in order (exact coordinates)."""
    points = np.asarray(points, float).reshape(-1, 2)
    line = shapely.linestrings(xy)
    at = shapely.line_locate_point(line, shapely.points(points))
    vertex_at = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    new = ~(np.abs(at[:, None] - vertex_at[None, :]) < 1e-9).any(axis=1)
    merged = np.concatenate([xy, points[new]])
    order = np.argsort(np.concatenate([vertex_at, at[new]]), kind="stable")
    return merged[order]


def _end_on(xy: np.ndarray, target: _Road) -> np.ndarray:
    """Cut a polyline where it first meets ``target`` and make that point a vertex of both."""
    line = shapely.linestrings(xy)
    hits = shapely.get_coordinates(shapely.intersection(line, target.line))
    if len(hits) == 0:
        raise ValueError(f"the new road does not reach {target.name}")
    at = shapely.line_locate_point(line, shapely.points(hits))
    point = hits[np.argmin(at)]
    vertex_at = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    target.xy = _insert_points(target.xy, point)
    return np.vstack([xy[vertex_at < at.min() - 1e-9], point])


def _start_on(target: _Road, x: float) -> np.ndarray:
    """The point of an x-monotonic road at map ``x``, made a vertex of it."""
    point = np.array([x, np.interp(x, target.xy[:, 0], target.xy[:, 1])])
    target.xy = _insert_points(target.xy, point)
    return point


def _bulge(xy: np.ndarray, amplitude_m: float) -> np.ndarray:
    """Replace every segment by a half-sine arc (alternating sides) sampled every 2 m or
    less; the vertices stay exact."""
    out = [xy[:1]]
    for k, (a, b) in enumerate(zip(xy[:-1], xy[1:])):
        d = b - a
        t = np.linspace(0, 1, int(np.ceil(np.hypot(*d) / VERTEX_SPACING_M)) + 1)[1:-1, None]
        normal = np.array([-d[1], d[0]]) / np.hypot(*d)
        sign = 1 if k % 2 == 0 else -1
        out += [a + t * d + sign * amplitude_m * np.sin(np.pi * t) * normal, b[None]]
    return np.vstack(out)


def _bezier(p0, p1, p2, samples: int = 16) -> np.ndarray:
    t = np.linspace(0, 1, samples)[:, None]
    return (1 - t) ** 2 * p0 + 2 * (1 - t) * t * p1 + t ** 2 * p2


def _corridor(road: _Road, margin_m: float = 0.0):
    return shapely.buffer(road.line, road.width_m / 2 + margin_m, cap_style="flat")


def _clear_of_roads(geom, roads: list[_Road], skip=()) -> bool:
    polys = [_corridor(r) for r in roads if r not in skip]
    return not shapely.intersects(geom, np.array(polys, dtype=object)).any()


@dataclass
class _Frame:
    """What the road layout decided besides the roads, for the stages that follow."""

    lots: list           # (lot polygon, access polygon)
    cliff_line: np.ndarray
    cliff_height_m: float
    cliff_slope_m: float
    ramp: tuple | None   # (road, start, direction, knots, height)
    lower_road: _Road | None


def _parallel(line: np.ndarray, offset_m: float) -> np.ndarray:
    """A west-east border-to-border line moved sideways (positive: northwards), its ends
    kept on the same borders."""
    d = line[1] - line[0]
    return line + [0.0, offset_m * np.hypot(*d) / d[0]]


def _place_parking(rng, row: _Road, x_centre: float, side: int, roads: list[_Road],
                   frame_lots: list) -> bool:
    """A lot beside ``row`` (side -1: south, +1: north) joined to it by a short access."""
    width, depth = rng.uniform(34, 42), rng.uniform(24, 30)
    gap = rng.uniform(10, 13)
    y_row = np.interp(x_centre, row.xy[:, 0], row.xy[:, 1])
    y_near = y_row + side * (row.width_m / 2 + SIDEWALK_M + gap)
    y_far = y_near + side * depth
    # Slide along the row, alternately west and east, until the lot is clear of the roads.
    for shift in [0.0] + [sign * k for k in range(2, 22, 2) for sign in (-1, 1)]:
        xc = x_centre + shift
        lot = shapely.box(xc - width / 2, min(y_near, y_far), xc + width / 2, max(y_near, y_far))
        if not _clear_of_roads(shapely.buffer(lot, 8.0), roads):
            continue
        if any(shapely.intersects(shapely.buffer(lot, 8.0), other) for other, _ in frame_lots):
            continue
        road_edge = y_row + side * (row.width_m / 2 - 0.5)
        access = shapely.box(xc - 3.0, min(road_edge, y_near), xc + 3.0, max(road_edge, y_near))
        frame_lots.append((lot, access))
        return True
    return False


def _place_cul_de_sac(rng, row: _Road, x_start: float, side: int, depth_m: float,
                      bend_m: float, roads: list[_Road], lots: list) -> _Road | None:
    """A lane leaving ``row`` sideways, bending by ``bend_m``, dead-ending ``depth_m`` away."""
    width = rng.uniform(4.0, 4.8)
    y_row = np.interp(x_start, row.xy[:, 0], row.xy[:, 1])
    p0 = np.array([x_start, y_row])
    p1 = p0 + [0.0, side * depth_m * 0.5]
    p2 = p0 + [bend_m, side * depth_m]
    xy = _bezier(p0, p1, p2)
    lane = _Road("cul_de_sac", xy, width)
    tail = shapely.difference(_corridor(lane, 8.0),
                              shapely.buffer(shapely.points(p0), row.width_m / 2 + 12.0))
    if not _clear_of_roads(tail, roads, skip=(row,)):
        return None
    if any(shapely.intersects(tail, lot) or shapely.intersects(tail, access)
           for lot, access in lots):
        return None
    lane.xy = np.vstack([_start_on(row, x_start), xy[1:]])
    return lane


def _first_vertical(rng, x: float, ymin: float, ymax: float, foot: _Road, *, dual: bool
                    ) -> tuple[list[_Road], float]:
    """The first south-north road at ``x``, a dual carriageway or a street, ending on the
    foot road, and its half width from the axis to its outer edge, metres."""
    if dual:
        w_c = rng.uniform(7.0, 8.0)
        separation = w_c + rng.uniform(3.5, 5.0)
        roads = []
        for side, name in ((-1, "dual_carriageway_a"), (1, "dual_carriageway_b")):
            x_side = x + side * separation / 2
            xy = _end_on(np.array([[x_side, ymin], [x_side, ymax + 50]]), foot)
            roads.append(_Road(name, xy, w_c))
        return roads, separation / 2 + w_c / 2
    w_0 = rng.uniform(8.0, 10.0)
    xy = _end_on(np.array([[x, ymin], [x, ymax + 50]]), foot)
    return [_Road("street", xy, w_0, kerb_parking=True)], w_0 / 2


def _diagonal(rng, x_west: float, avenue_y: float, avenue: _Road, curved_street: _Road,
              next_row: _Road) -> list[_Road]:
    """A diagonal street from the avenue, east of ``x_west``, to the curved street, at the
    steepest angle that meets it well below the next row (none if no angle does)."""
    start_x = x_west + rng.uniform(22, 30)
    for theta in np.radians(np.arange(rng.uniform(35, 50), 24, -5.0)):
        ray = np.array([[start_x, avenue_y],
                        [start_x + 500 * np.cos(theta), avenue_y + 500 * np.sin(theta)]])
        hit = shapely.intersection(shapely.linestrings(ray), curved_street.line)
        if shapely.is_empty(hit):
            continue
        end = shapely.get_coordinates(hit)
        end = end[np.argmin(end[:, 1])]
        if end[1] < np.interp(end[0], next_row.xy[:, 0], next_row.xy[:, 1]) - 25:
            xy = _end_on(np.vstack([_start_on(avenue, start_x), ray[1]]), curved_street)
            return [_Road("diagonal", xy, rng.uniform(6.5, 8.0))]
    return []


def _vertical_streets(rng, i: int, vertical, bridge_edges, has_rows: bool, ymax: float,
                      foot: _Road) -> list[_Road]:
    """The streets of vertical ``i`` (the curved street when ``i`` is 1): its node chain,
    with some inner segments dropped (T junctions) where no special feature needs them."""
    curved = i == 1 or rng.random() < 0.3
    width = rng.uniform(7.5, 10.0) if i == 1 else rng.uniform(6.0, 11.0)
    chain = vertical(i)
    amplitude = rng.uniform(6, 10) if i == 1 else rng.uniform(4, 8)
    keep = np.ones(len(chain) - 1, bool)
    if i > 1 and i not in bridge_edges and has_rows:
        keep[1:-1] = rng.random(len(chain) - 3) > 0.2
    pieces, start = [], 0
    for k in range(len(keep) + 1):
        if k == len(keep) or not keep[k]:
            if k > start:
                pieces.append(chain[start:k + 1])
            start = k + 1
    trees, parking = rng.random() < 0.4, rng.random() < 0.6
    streets = []
    for piece in pieces:
        xy = _bulge(piece, amplitude) if curved else piece
        if piece[-1, 1] > ymax:
            xy = _end_on(xy, foot)
        streets.append(_Road("curved_street" if curved else "street", xy, width,
                             street_trees=trees, kerb_parking=parking))
    return streets


def _place_extras(extras, rows, node_x, bridge_edges, features, roads, lots) -> None:
    """A few more cul-de-sacs and parking lots in big scenes, each in its own block."""
    for j, row in enumerate(rows):
        for i in range(1, len(node_x) - 1):
            if i in bridge_edges or i + 1 in bridge_edges:
                continue
            x_mid = 0.5 * (node_x[i, j] + node_x[i + 1, j])
            draw = extras.random()
            if draw < 0.06 and "cul_de_sac" in features:
                depth = extras.uniform(40, 55)
                lane = _place_cul_de_sac(extras, row, x_mid, 1, depth,
                                         extras.uniform(-0.2, 0.2) * depth, roads, lots)
                if lane is not None:
                    roads.append(lane)
            elif 0.06 <= draw < 0.12 and "parking" in features:
                _place_parking(extras, row, x_mid, 1, roads, lots)


def _layout_roads(seed, origin, size, features) -> tuple[list[_Road], _Frame]:
    rng = _stable_seed(seed, "roads")
    xmin, ymin = origin
    W, H = size
    xmax, ymax = xmin + W, ymin + H
    roads: list[_Road] = []

    # Cliff along the upper border; the foot road is the top row of the grid either way.
    angle = rng.uniform(-1, 1) * min(np.radians(3.0), np.arctan(40.0 / W))
    w_top, w_foot = rng.uniform(6.0, 7.5), rng.uniform(7.0, 10.0)
    # 7-11 m, so that with the terrain undulation the top road stays 6-12 m up.
    slope_m, cliff_height = rng.uniform(3.0, 5.0), rng.uniform(7.0, 11.0)
    top_offset = w_top / 2 + slope_m / 2 + rng.uniform(10, 14)
    foot_offset = w_foot / 2 + SIDEWALK_M + slope_m / 2 + rng.uniform(8, 11)
    tan = np.tan(angle)
    cliff_y = ymax - (w_top / 2 + 6.0) - top_offset / np.cos(angle) - W / 2 * abs(tan)
    cliff_line = np.array([[xmin, cliff_y - W / 2 * tan], [xmax, cliff_y + W / 2 * tan]])
    has_cliff = "cliff" in features
    foot = _Road("cliff_foot" if has_cliff else "street", _parallel(cliff_line, -foot_offset),
                 w_foot, street_trees=True)
    roads.append(foot)
    if has_cliff:
        roads.append(_Road("cliff_top", _parallel(cliff_line, top_offset), w_top,
                           sidewalk=False))

    # Rows (west-east): the avenue first, then evenly spread below the foot road.
    avenue_y = ymin + rng.uniform(105, 120)
    span = foot.xy[:, 1].min() - avenue_y
    n_gaps = max(1, int(round(span / 125.0)))
    gaps = np.full(n_gaps, span / n_gaps)
    if n_gaps > 1 and gaps[0] < 115:  # the bridge ramps need the first gap
        gaps[0] = 115.0
        gaps[1:] = (span - 115.0) / (n_gaps - 1)
    row_y = avenue_y + np.concatenate([[0.0], np.cumsum(gaps)[:-1]])

    # Verticals (south-north): dual carriageway axis, curved street, then a jittered grid.
    xs = [xmin + rng.uniform(45, 60)]
    xs.append(xs[0] + rng.uniform(115, 145))
    while True:
        nxt = xs[-1] + rng.uniform(85, 150)
        if nxt > xmax - 60:
            break
        xs.append(nxt)
    node_x = np.array([[x + (rng.uniform(-6, 6) if i else 0.0) for _ in row_y]
                       for i, x in enumerate(xs)])
    node_y = np.array([[y + (rng.uniform(-5, 5) if j else 0.0) for j, y in enumerate(row_y)]
                       for _ in xs])

    avenue = _Road("avenue", None, rng.uniform(20.0, 24.0), street_trees=True,
                   kerb_parking=True)
    rows = [avenue] + [_Road("street", None, rng.uniform(7.0, 12.0),
                             street_trees=rng.random() < 0.4,
                             kerb_parking=rng.random() < 0.6) for _ in row_y[1:]]
    for j, row in enumerate(rows):
        ends = [row_y[j] + (rng.uniform(-5, 5) if j else 0.0) for _ in range(2)]
        row.xy = np.vstack([[xmin, ends[0]],
                            np.column_stack([node_x[1:, j], node_y[1:, j]]),
                            [xmax, ends[1]]])
    roads += rows

    def vertical(i, x_bottom=None, top_overshoot=20.0):
        """Node chain of vertical ``i`` from the lower border (by default a few metres
        beside its first node) past the foot road."""
        if x_bottom is None:
            x_bottom = node_x[i, 0] + rng.uniform(-6, 6)
        nodes = np.column_stack([node_x[i], node_y[i]])
        top = [nodes[-1, 0] + rng.uniform(-6, 6), ymax + top_overshoot]
        return np.vstack([[x_bottom, ymin], nodes, top])

    # Bridge block: the last one wide enough, away from the specials in block 0-1.
    if xmax - xs[-1] >= 75:
        bridge_lo, bridge_hi = xs[-1], xmax
    else:
        bridge_lo, bridge_hi = xs[-2], xs[-1]
    bridge_x = bridge_lo + rng.uniform(0.45, 0.55) * (bridge_hi - bridge_lo)
    bridge_edges = {i for i, x in enumerate(xs) if x in (bridge_lo, bridge_hi)}

    axis, half_axis = _first_vertical(rng, xs[0], ymin, ymax, foot,
                                      dual="dual_carriageway" in features)
    roads += axis

    for i in range(1, len(xs)):
        roads += _vertical_streets(rng, i, vertical, bridge_edges, len(rows) > 1, ymax, foot)
    curved_street = next(r for r in roads if r.name == "curved_street")

    lots: list = []
    if "diagonal" in features:
        roads += _diagonal(rng, xs[0] + half_axis, avenue_y, avenue, curved_street,
                           rows[1] if len(rows) > 1 else foot)

    if "cul_de_sac" in features:
        depth = avenue.width_m / 2 + rng.uniform(48, 56)
        # Bent west, away from the parking lot that shares its block.
        lane = _place_cul_de_sac(rng, avenue, xs[0] + half_axis + rng.uniform(24, 30), -1,
                                 depth, -rng.uniform(0.05, 0.15) * depth, roads, lots)
        if lane is not None:
            roads.append(lane)
    if "parking" in features:
        _place_parking(rng, avenue, xs[1] - rng.uniform(35, 45), -1, roads, lots)

    ramp, lower = None, None
    if "bridge" in features:
        end_row = rows[1] if len(rows) > 1 else foot
        heading = np.radians(90 + rng.uniform(-4, 4))
        direction = np.array([np.cos(heading), np.sin(heading)])
        start = np.array([bridge_x, ymin])
        xy = _end_on(np.vstack([start, start + 2 * H * direction]), end_row)
        road = _Road("bridge", xy, rng.uniform(6.0, 6.8), level=1, bridge=True,
                     sidewalk=False)
        crossing = shapely.get_coordinates(shapely.intersection(road.line, avenue.line))[0]
        s_cross = float(np.dot(crossing - start, direction))
        s_end = float(np.dot(xy[-1] - start, direction))
        sin_cross = abs(direction[1])  # the avenue runs west-east
        half_span = ((avenue.width_m / 2 + SIDEWALK_M + 3.0) / sin_cross
                     + road.width_m / 2 * abs(direction[0]) / sin_cross)
        k1, k2 = s_cross - half_span, s_cross + half_span
        knots = (max(3.0, k1 - 110.0), k1, k2, min(s_end - end_row.width_m / 2 - 4.0, k2 + 110.0))
        ramp = (road, tuple(start), tuple(direction), knots, rng.uniform(6.5, 7.5))
        lower = avenue
        roads.append(road)

    _place_extras(_stable_seed(seed, "extras"), rows, node_x, bridge_edges, features, roads,
                  lots)

    frame = _Frame(lots=lots, cliff_line=cliff_line,
                   cliff_height_m=cliff_height if has_cliff else 0.0, cliff_slope_m=slope_m,
                   ramp=ramp, lower_road=lower)
    return roads, frame


def _node_same_level(roads: list[_Road]) -> None:
    """Make every crossing of two roads on the same level a vertex of both."""
    lines = np.array([r.line for r in roads], dtype=object)
    tree = shapely.STRtree(lines)
    pairs = tree.query(lines, predicate="intersects")
    inserts: dict[int, list] = {i: [] for i in range(len(roads))}
    for a, b in pairs.T:
        if a < b and roads[a].level == roads[b].level:
            points = shapely.get_coordinates(shapely.intersection(lines[a], lines[b]))
            inserts[a].append(points)
            inserts[b].append(points)
    for i, found in inserts.items():
        if found:
            roads[i].xy = _insert_points(roads[i].xy, np.vstack(found))


def _nodes(polylines: list[np.ndarray]) -> np.ndarray:
    """Graph nodes as complex x + iy: line ends and vertices shared by two or more lines.

    Roads on one level share the exact coordinates of their junctions
    (:func:`_node_same_level`), and nothing else.
    """
    coords = [np.unique(xy[:, 0] + 1j * xy[:, 1]) for xy in polylines]
    values, counts = np.unique(np.concatenate(coords), return_counts=True)
    ends = np.concatenate([[xy[0, 0] + 1j * xy[0, 1], xy[-1, 0] + 1j * xy[-1, 1]]
                           for xy in polylines])
    return np.union1d(values[counts >= 2], ends)


# ---------------------------------------------------------------------------------------
# Things around the roads


def _tangents(lines, at):
    """Unit tangents of lines at distances ``at`` along them (vectorised)."""
    length = shapely.length(lines)
    a = shapely.get_coordinates(shapely.line_interpolate_point(lines, np.clip(at - 1, 0, length)))
    b = shapely.get_coordinates(shapely.line_interpolate_point(lines, np.clip(at + 1, 0, length)))
    d = b - a
    return d / np.hypot(d[:, 0], d[:, 1])[:, None]


def _rectangles(centre, tangent, length, width):
    """Rotated rectangles (vectorised): ``length`` along ``tangent``, ``width`` across."""
    centre, tangent = np.atleast_2d(centre), np.atleast_2d(tangent)
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    half_l = (np.asarray(length, float) / 2)[..., None] * tangent
    half_w = (np.asarray(width, float) / 2)[..., None] * normal
    corners = np.stack([centre - half_l - half_w, centre + half_l - half_w,
                        centre + half_l + half_w, centre - half_l + half_w,
                        centre - half_l - half_w], axis=1)
    return shapely.polygons(corners)


def _hits(geoms, obstacles) -> np.ndarray:
    """Which geometries intersect any obstacle (STRtree, vectorised)."""
    geoms = np.asarray(geoms, dtype=object)
    hit = np.zeros(len(geoms), bool)
    obstacles = [o for o in obstacles if o is not None and not shapely.is_empty(o)]
    if len(geoms) and obstacles:
        pairs = shapely.STRtree(np.asarray(obstacles, dtype=object)).query(
            geoms, predicate="intersects")
        hit[pairs[0]] = True
    return hit


def _inside(geoms, extent, margin_m) -> np.ndarray:
    xmin, ymin, xmax, ymax = extent
    return shapely.within(geoms, shapely.box(xmin + margin_m, ymin + margin_m,
                                             xmax - margin_m, ymax - margin_m))


def _junction_zones(lines, polys, margin_m):
    """Per road: the other roads' polygons it touches, grown by ``margin_m`` (or None)."""
    pairs = shapely.STRtree(lines).query(lines, predicate="intersects")
    zones = []
    for i in range(len(lines)):
        others = pairs[1][(pairs[0] == i) & (pairs[1] != i)]
        zones.append(shapely.buffer(shapely.union_all(polys[others]), margin_m)
                     if len(others) else None)
    return zones


def _dashes(line, *, dash_m=3.0, gap_m=5.0, width_m=0.15, phase_m=1.0):
    """Dash polygons along a line (straight chords; roads bend far less over 3 m)."""
    length = shapely.length(line)
    start = np.arange(phase_m, length - dash_m, dash_m + gap_m)
    if len(start) == 0:
        return np.empty(0, dtype=object)
    a = shapely.get_coordinates(shapely.line_interpolate_point(line, start))
    b = shapely.get_coordinates(shapely.line_interpolate_point(line, start + dash_m))
    return shapely.buffer(shapely.linestrings(np.stack([a, b], axis=1)), width_m / 2,
                          cap_style="flat")


def _zebra(centre, tangent, road_width_m):
    """Bars of a zebra crossing centred on ``centre``, across a road running along ``tangent``."""
    normal = np.array([-tangent[1], tangent[0]])
    # 0.5 m bars every metre, from a metre inside one kerb to a metre inside the other.
    across = np.arange(-road_width_m / 2 + 1.0, road_width_m / 2 - 1.0 + 1e-9, 1.0)
    centres = centre + across[:, None] * normal
    return _rectangles(centres, np.repeat(tangent[None], len(across), 0),
                       np.full(len(across), 3.0), np.full(len(across), 0.5))


def _cliff_strip(relief: Relief, extent, low_m: float, high_m: float):
    """Where the signed distance from the cliff's mid-slope line is within [low_m, high_m]
    (metres, positive on the plateau), clipped to the extent."""
    xmin, ymin, xmax, ymax = extent
    reach = np.hypot(xmax - xmin, ymax - ymin)
    normal = np.array(relief.cliff_normal)
    along = np.array([normal[1], -normal[0]])
    p = np.array(relief.cliff_point)
    low, high = max(low_m, -reach), min(high_m, reach)
    ring = [p - reach * along + low * normal, p + reach * along + low * normal,
            p + reach * along + high * normal, p - reach * along + high * normal]
    return shapely.intersection(shapely.polygons(ring), shapely.box(*extent))


# ---------------------------------------------------------------------------------------
# The scene


def _gdf(columns: dict, geometry, crs) -> gpd.GeoDataFrame:
    geometry = np.asarray(geometry, dtype=object)
    frame = pd.DataFrame({k: np.asarray(v) for k, v in columns.items()},
                         index=pd.RangeIndex(len(geometry)))
    return gpd.GeoDataFrame(frame, geometry=gpd.GeoSeries(geometry, crs=crs), crs=crs)


@dataclass
class PaintTable:
    """Surfaces in painter's order; row 0 is the background (no geometry).

    Columns are arrays of the table's length: ``material`` (Material), ``kind`` (Kind),
    ``base`` (Base: how the surface follows the relief), ``ramp`` (index into
    ``Relief.ramps`` or -1), ``top_z`` (flat top of roofs and cars, NaN otherwise), ``tone``
    (0-1, per-object colour variation), and for tree crowns ``centre_x, centre_y,
    radius_m, crown_depth_m`` (crown surface: a half ellipsoid under ``top_z``).
    """

    geometry: np.ndarray
    material: np.ndarray
    kind: np.ndarray
    base: np.ndarray
    ramp: np.ndarray
    top_z: np.ndarray
    tone: np.ndarray
    centre_x: np.ndarray
    centre_y: np.ndarray
    radius_m: np.ndarray
    crown_depth_m: np.ndarray

    @classmethod
    def build(cls, background: dict, groups: list[tuple]) -> PaintTable:
        """``groups``: (geometries, column values: scalars or arrays) in painter's order."""
        names = [f for f in cls.__dataclass_fields__ if f != "geometry"]
        defaults = dict(material=0, kind=0, base=0, ramp=-1, top_z=np.nan, tone=0.5,
                        centre_x=np.nan, centre_y=np.nan, radius_m=np.nan,
                        crown_depth_m=np.nan)
        geoms = [np.array([None], dtype=object)]
        columns = {n: [np.atleast_1d({**defaults, **background}[n])] for n in names}
        for items, values in groups:
            items = np.asarray(items, dtype=object).ravel()
            geoms.append(items)
            for n in names:
                columns[n].append(np.broadcast_to({**defaults, **values}[n], len(items)))
        dtypes = dict(material=np.uint8, kind=np.uint8, base=np.uint8, ramp=np.int16)
        return cls(np.concatenate(geoms), **{n: np.concatenate(columns[n]).astype(
            dtypes.get(n, np.float64)) for n in names})

    @cached_property
    def index(self) -> shapely.STRtree:
        return shapely.STRtree(self.geometry[1:])

    @cached_property
    def shapes(self) -> list:
        """GeoJSON-like mappings of the geometries, converted once for the rasteriser."""
        return [None] + [g.__geo_interface__ for g in self.geometry[1:]]


class Areas(NamedTuple):
    """Prepared (fast to test) unions of a scene's surfaces, by level.

    Attributes
    ----------
    grade_roads : Polygon or MultiPolygon
        Truth polygons of the roads on the ground (every road but the bridge roads).
    paved : Polygon or MultiPolygon
        ``grade_roads`` plus the parking lots and their accesses: the surfaces a kerb lower.
    decks : Polygon or MultiPolygon
        Bridge decks (overhead; the ground below them goes on).
    bridge_roads : dict of int to Polygon
        Truth polygon of each bridge road by ``road_id``, ramps and deck.
    ramps : list of Polygon
        Each bridge road off its deck (on embankments), in ``Relief.ramps`` order.
    """

    grade_roads: object
    paved: object
    decks: object
    bridge_roads: dict
    ramps: list


@dataclass
class Scene:
    """A synthetic scene: vector layers in a metre CRS, its relief and its road truth.

    Attributes
    ----------
    roads : GeoDataFrame
        LineString Z centre lines (vertices at most ``VERTEX_SPACING_M`` apart, Z = road
        surface elevation); ``road_id, name, kind ('road'), width_m, level (0 ground, 1 on a
        bridge), bridge (bool), sidewalk (bool), surface ('asphalt', 'pavers'), z_min,
        z_max``.
    parking_lots, parking_access : GeoDataFrame
        Lot polygons (``lot_id, aspect``) and the short access joining each to its road;
        neither is part of the road truth.
    buildings : GeoDataFrame
        Rectangles; ``height_m`` above the ground, ``roof_z``.
    trees : GeoDataFrame
        Trunk points; ``crown_radius_m, height_m, crown_depth_m, top_z``.
    cars : GeoDataFrame
        Rotated 4.2-4.8 x 1.75-1.9 m rectangles; ``height_m, roof_z, where ('kerb', 'lane',
        'lot')``.
    markings : GeoDataFrame
        Paint polygons; ``kind ('dash', 'zebra'), road_id``.
    cliff : GeoDataFrame
        The plateau polygon (mid-slope outline); ``height_m, slope_m`` (empty: no cliff).
    bridges : GeoDataFrame
        Deck polygons; ``road_id`` (upper), ``under_road_id``, ``height_m`` above the lower
        road, ``crossing_x, crossing_y``.
    extent : (xmin, ymin, xmax, ymax)
    crs : pyproj.CRS
    seed : int
    relief : Relief
    water : GeoDataFrame, optional
        Open water polygons (canals); a LiDAR pulse on water gives no return.
    """

    roads: gpd.GeoDataFrame
    parking_lots: gpd.GeoDataFrame
    parking_access: gpd.GeoDataFrame
    buildings: gpd.GeoDataFrame
    trees: gpd.GeoDataFrame
    cars: gpd.GeoDataFrame
    markings: gpd.GeoDataFrame
    cliff: gpd.GeoDataFrame
    bridges: gpd.GeoDataFrame
    extent: tuple
    crs: CRS
    seed: int
    relief: Relief
    water: gpd.GeoDataFrame | None = None

    def __post_init__(self):
        if self.water is None:
            self.water = _gdf({}, [], self.crs)

    def object_layers(self) -> dict[str, gpd.GeoDataFrame]:
        """The scene's layers besides the road truth, by name, ready for a GeoPackage.

        ``roads`` (the centre lines with their name, level and bridge flag),
        ``truth_edges``, ``parking_lots``, ``parking_access``, ``buildings``, ``trees``,
        ``cars``, ``markings``, ``bridges``, ``cliff``, and ``water`` where the scene has
        some.
        """
        layers = {"roads": self.roads, "truth_edges": self.truth_edges,
                  "parking_lots": self.parking_lots, "parking_access": self.parking_access,
                  "buildings": self.buildings, "trees": self.trees, "cars": self.cars,
                  "markings": self.markings, "bridges": self.bridges, "cliff": self.cliff}
        if len(self.water):
            layers["water"] = self.water
        return layers

    @cached_property
    def truth_edges(self) -> gpd.GeoDataFrame:
        """The road graph's edges: centre lines split at junctions of roads on the same level.

        A bridge crossing is no node. LineString Z; ``edge_id, road_id, level``.
        """
        xyz = [shapely.get_coordinates(g, include_z=True) for g in self.roads.geometry.values]
        edges = _edge_slices([c[:, :2] for c in xyz])
        pieces = [shapely.linestrings(xyz[i][a:b + 1]) for i, a, b in edges]
        road_ids = self.roads["road_id"].to_numpy()[[i for i, _, _ in edges]]
        levels = self.roads["level"].to_numpy()[[i for i, _, _ in edges]]
        return _gdf({"edge_id": np.arange(len(pieces), dtype=np.int64),
                     "road_id": np.asarray(road_ids, np.int64),
                     "level": np.asarray(levels, np.int64)}, pieces, self.crs)

    @cached_property
    def truth(self) -> RoadNetwork:
        """The road truth as a :class:`~gisroads.geo.RoadNetwork` (``method='truth'``).

        Junctions come from :attr:`truth_edges`, so the bridge crossing is not one.
        """
        net = network_from_centrelines(self.roads[["road_id", "width_m", "geometry"]],
                                       method="truth")
        nodes, degree = line_end_degrees(self.truth_edges.geometry.values)
        keep = degree >= 3
        junctions = gpd.GeoDataFrame(
            {"junction_id": np.arange(int(keep.sum()), dtype=np.int64),
             "degree": degree[keep].astype(np.int64)},
            geometry=shapely.points(nodes[keep]), crs=self.crs)
        return RoadNetwork(net.centrelines, net.polygons, junctions, net.qa)

    @cached_property
    def areas(self) -> Areas:
        """Prepared unions of the truth polygons by level (see :class:`Areas`)."""
        polygons = self.truth.polygons
        road_id = polygons["road_id"].to_numpy()
        geoms = polygons.geometry.values
        bridge_ids = self.roads.loc[self.roads["bridge"], "road_id"].to_numpy()
        grade = shapely.union_all(geoms[~np.isin(road_id, bridge_ids)])
        paved = shapely.union_all(np.concatenate([
            [grade], self.parking_lots.geometry.values, self.parking_access.geometry.values]))
        decks = shapely.union_all(self.bridges.geometry.values)
        bridge_roads = {int(r): shapely.union_all(geoms[road_id == r]) for r in bridge_ids}
        ramps = [shapely.difference(bridge_roads[r.road_id], decks) for r in self.relief.ramps]
        for geom in [grade, paved, decks, *bridge_roads.values(), *ramps]:
            shapely.prepare(geom)
        return Areas(grade, paved, decks, bridge_roads, ramps)

    def ground_z(self, x, y) -> np.ndarray:
        """Elevation (metres) of the lowest surface: bare ground, road, ramp; not decks.

        Under a bridge deck this is the ground or road below it. Exact point-in-polygon
        tests, so the kerb step sits exactly on the road polygon edges.
        """
        x, y = np.asarray(x, float), np.asarray(y, float)
        areas = self.areas
        base = np.where(shapely.contains_xy(areas.paved, x, y), Base.PAVED, Base.RAISED)
        ramp_index = np.full(x.shape, -1)
        for i, area in enumerate(areas.ramps):
            on = shapely.contains_xy(area, x, y)
            base[on], ramp_index[on] = Base.RAMP, i
        return self.relief.base_z(x, y, base, ramp_index)

    def deck_z(self, x, y) -> np.ndarray:
        """Elevation (metres) of bridge deck surfaces; NaN off the decks."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        z = np.full(np.broadcast(x, y).shape, np.nan)
        for ramp, deck in zip(self.relief.ramps, self.bridges.geometry.values):
            on = shapely.contains_xy(deck, x, y)
            z[on] = self.relief.terrain_z(x[on], y[on]) + ramp.height(x[on], y[on])
        return z

    @cached_property
    def surfaces(self) -> tuple[PaintTable, PaintTable]:
        """The ground layer and the overhead layer, in painter's order (see the module doc)."""
        roads = self.roads
        lines2d = np.array([shapely.linestrings(shapely.get_coordinates(g))
                            for g in roads.geometry.values], dtype=object)
        width = roads["width_m"].to_numpy()
        sidewalk = roads["sidewalk"].to_numpy()
        polygons = self.truth.polygons
        on_grade = ~polygons["road_id"].isin(roads.loc[roads["bridge"], "road_id"]).to_numpy()
        pavers = polygons["road_id"].isin(
            roads.loc[roads["surface"] == "pavers", "road_id"]).to_numpy()
        ramp_groups = [([area], dict(material=Material.ASPHALT, base=Base.RAMP, ramp=i))
                       for i, area in enumerate(self.areas.ramps)]
        cliff = []
        if len(self.cliff):
            half = self.relief.cliff_slope_m / 2 + 0.5
            cliff = [_cliff_strip(self.relief, self.extent, -half, half)]
        ground = PaintTable.build(dict(material=Material.GRASS, base=Base.RAISED), [
            (cliff, dict(material=Material.ROCK, base=Base.RAISED)),
            (shapely.buffer(lines2d[sidewalk], width[sidewalk] / 2 + SIDEWALK_M,
                            cap_style="flat", join_style="round"),
             dict(material=Material.CONCRETE, base=Base.RAISED)),
            # Accesses reach into their road: the road's own asphalt is painted over them.
            (self.parking_lots.geometry.values, dict(material=Material.DARK_ASPHALT,
                                                     base=Base.PAVED)),
            (self.parking_access.geometry.values, dict(material=Material.DARK_ASPHALT,
                                                       base=Base.PAVED)),
            (self.water.geometry.values, dict(material=Material.WATER, base=Base.RAISED)),
            (polygons.geometry.values[on_grade & ~pavers],
             dict(material=Material.ASPHALT, base=Base.PAVED)),
            (polygons.geometry.values[on_grade & pavers],
             dict(material=Material.PAVERS, base=Base.PAVED)),
            *ramp_groups,
            (self.markings.geometry.values, dict(material=Material.PAINT, base=Base.PAVED)),
            (self.buildings.geometry.values, dict(
                material=Material.ROOF, kind=Kind.BUILDING, base=Base.RAISED,
                top_z=self.buildings["roof_z"].to_numpy(),
                tone=self.buildings["tone"].to_numpy())),
            (self.cars.geometry.values, dict(
                material=Material.CAR, kind=Kind.CAR, base=Base.PAVED,
                top_z=self.cars["roof_z"].to_numpy(), tone=self.cars["tone"].to_numpy())),
        ])
        # Taller crowns are painted last, so where crowns overlap the higher one is seen.
        trees = self.trees.iloc[np.argsort(self.trees["top_z"].to_numpy(), kind="stable")]
        xy = shapely.get_coordinates(trees.geometry.values)
        radius = trees["crown_radius_m"].to_numpy()
        overhead = PaintTable.build(dict(), [
            (shapely.buffer(trees.geometry.values, radius, quad_segs=8), dict(
                material=Material.FOLIAGE, kind=Kind.TREE, top_z=trees["top_z"].to_numpy(),
                tone=trees["tone"].to_numpy(), centre_x=xy[:, 0], centre_y=xy[:, 1],
                radius_m=radius, crown_depth_m=trees["crown_depth_m"].to_numpy())),
            *[([deck], dict(material=Material.ASPHALT, kind=Kind.DECK, base=Base.RAMP,
                            ramp=i)) for i, deck in enumerate(self.bridges.geometry.values)],
        ])
        return ground, overhead


# ---------------------------------------------------------------------------------------
# Surfaces at points


@dataclass
class SurfaceSample:
    """What lies at given map points, from the ground up (arrays of the points' length).

    Attributes
    ----------
    ground_z : ndarray
        Bare ground or road surface (metres), the lowest level.
    base_z : ndarray
        Top of the ground layer: roof, car roof, else ``ground_z``.
    base_material, base_kind : ndarray of uint8
        Material and Kind of that top.
    base_tone : ndarray
        Per-object variation (0-1) of roofs and cars.
    over_z : ndarray
        Tree crown or deck surface above (metres); NaN under open sky.
    over_kind, over_material : ndarray of uint8
    over_tone : ndarray
    """

    ground_z: np.ndarray
    base_z: np.ndarray
    base_material: np.ndarray
    base_kind: np.ndarray
    base_tone: np.ndarray
    over_z: np.ndarray
    over_kind: np.ndarray
    over_material: np.ndarray
    over_tone: np.ndarray

    @property
    def over_on_top(self) -> np.ndarray:
        """Where the overhead surface is the highest one (NaN compares False)."""
        return self.over_z > self.base_z

    @property
    def top_z(self) -> np.ndarray:
        """Highest surface: what a vertical ray from above hits first (metres)."""
        return np.where(self.over_on_top, self.over_z, self.base_z)

    @property
    def top_material(self) -> np.ndarray:
        return np.where(self.over_on_top, self.over_material, self.base_material)

    @property
    def top_kind(self) -> np.ndarray:
        return np.where(self.over_on_top, self.over_kind, self.base_kind)

    @property
    def top_tone(self) -> np.ndarray:
        return np.where(self.over_on_top, self.over_tone, self.base_tone)


def rasterize_surfaces(scene: Scene, transform: Affine, shape: tuple[int, int]
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Row indices of the ground and overhead :attr:`Scene.surfaces` on a pixel grid.

    A pixel takes the last surface (painter's order) that covers its centre; 0 is the
    background. Only the surfaces that reach the grid are drawn.

    Returns
    -------
    ground_id, over_id : ndarray of uint32, ``shape``
    """
    rows, cols = shape
    x0, y0 = transform.c, transform.f  # north-up grids only: the corners are enough
    x1, y1 = x0 + transform.a * cols, y0 + transform.e * rows
    window = shapely.box(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1))
    out = []
    for table in scene.surfaces:
        ids = np.sort(table.index.query(window)) + 1
        if len(ids) == 0:
            out.append(np.zeros(shape, np.uint32))
            continue
        out.append(rasterio.features.rasterize(
            ((table.shapes[i], i) for i in ids.tolist()), out_shape=shape, transform=transform,
            fill=0, dtype="uint32"))
    return out[0], out[1]


def describe_surfaces(scene: Scene, x, y, ground_id, over_id) -> SurfaceSample:
    """Heights and materials at map points whose surface rows are known (vectorised).

    Parameters
    ----------
    scene : Scene
    x, y : ndarray
        Map coordinates (metres).
    ground_id, over_id : ndarray of int
        Rows of the two :attr:`Scene.surfaces` tables at the points
        (see :func:`rasterize_surfaces`).
    """
    ground, over = scene.surfaces
    relief = scene.relief
    x, y = np.asarray(x, float), np.asarray(y, float)
    base_ramp = ground.ramp[ground_id]
    ground_z = relief.base_z(x, y, ground.base[ground_id], base_ramp)
    roof = ground.top_z[ground_id]
    base_z = np.where(np.isnan(roof), ground_z, roof)

    over_z = np.full(x.shape, np.nan)
    kind = over.kind[over_id]
    tree = np.flatnonzero(kind == Kind.TREE)
    if len(tree):
        t = over_id[tree]
        d2 = (x[tree] - over.centre_x[t]) ** 2 + (y[tree] - over.centre_y[t]) ** 2
        depth = over.crown_depth_m[t]
        # Upper half of an ellipsoid: top_z at the stem, top_z - depth at the crown's rim.
        over_z[tree] = (over.top_z[t] - depth
                        + depth * np.sqrt(np.clip(1.0 - d2 / over.radius_m[t] ** 2, 0, 1)))
    deck = np.flatnonzero(kind == Kind.DECK)
    if len(deck):
        over_z[deck] = relief.base_z(x[deck], y[deck], np.full(len(deck), Base.RAMP),
                                     over.ramp[over_id[deck]])
    return SurfaceSample(ground_z=ground_z, base_z=base_z,
                         base_material=ground.material[ground_id],
                         base_kind=ground.kind[ground_id], base_tone=ground.tone[ground_id],
                         over_z=over_z, over_kind=kind, over_material=over.material[over_id],
                         over_tone=over.tone[over_id])


# ---------------------------------------------------------------------------------------
# Building the scene


def _edge_slices(polylines: list[np.ndarray]) -> list[tuple[int, int, int]]:
    """(line index, first vertex, last vertex) of every edge between consecutive nodes."""
    nodes = _nodes(polylines)
    edges = []
    for i, xy in enumerate(polylines):
        cut = np.union1d(np.flatnonzero(np.isin(xy[:, 0] + 1j * xy[:, 1], nodes)),
                         [0, len(xy) - 1])
        edges += [(i, int(a), int(b)) for a, b in zip(cut[:-1], cut[1:])]
    return edges


def _park_cells(seed: int, extent, *, cell_m: float = 110.0, share: float = 0.25):
    """A function telling which map points fall in park cells (no buildings, many trees)."""
    rng = _stable_seed(seed, "parks")
    xmin, ymin, xmax, ymax = extent
    flags = rng.random((int((xmax - xmin) // cell_m) + 1, int((ymax - ymin) // cell_m) + 1))
    flags = flags < share

    def is_park(xy):
        i = ((xy[:, 0] - xmin) // cell_m).astype(int)
        j = ((xy[:, 1] - ymin) // cell_m).astype(int)
        return flags[np.clip(i, 0, flags.shape[0] - 1), np.clip(j, 0, flags.shape[1] - 1)]
    return is_park


def _lattice(rng, extent, pitch_m: float, jitter_m: float) -> np.ndarray:
    xmin, ymin, xmax, ymax = extent
    gx, gy = np.meshgrid(np.arange(xmin + pitch_m / 2, xmax, pitch_m),
                         np.arange(ymin + pitch_m / 2, ymax, pitch_m))
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    return xy + rng.uniform(-jitter_m, jitter_m, xy.shape)


def _points_along(line, spacing_m: float, start_m: float, end_trim_m: float):
    """Stations, points and unit tangents every ``spacing_m`` along a line."""
    at = np.arange(start_m, shapely.length(line) - end_trim_m, spacing_m)
    if len(at) == 0:
        return at, np.empty((0, 2)), np.empty((0, 2))
    lines = np.full(len(at), line, dtype=object)
    return (at, shapely.get_coordinates(shapely.line_interpolate_point(lines, at)),
            _tangents(lines, at))


def _left(tangent):
    return np.column_stack([-tangent[:, 1], tangent[:, 0]])


def _crossing_sites(roads: list[_Road], widths: np.ndarray) -> list:
    """(road index, station along it) of each possible zebra crossing's centre: on each arm
    of a junction, clear of the crossing roads."""
    edges = _edge_slices([r.xy for r in roads])
    pieces = [shapely.linestrings(roads[i].xy[a:b + 1]) for i, a, b in edges]
    nodes, degree = line_end_degrees(pieces)
    junction = nodes[degree >= 3, 0] + 1j * nodes[degree >= 3, 1]
    arms: dict[complex, list] = {}  # junction -> (road index, vertex index) of its roads
    for i, road in enumerate(roads):
        xy = road.xy[:, 0] + 1j * road.xy[:, 1]
        for k in np.flatnonzero(np.isin(xy, junction)):
            arms.setdefault(xy[k], []).append((i, k))
    sites = []  # (road index, station along it): the centre of a possible crossing
    for incident in arms.values():
        for i, k in incident:
            road = roads[i]
            if road.bridge or road.name == "cul_de_sac" or road.width_m < 6.0:
                continue
            reach = max(widths[m] for m, _ in incident if m != i) / 2 + 4.0 + 1.5
            at_vertex = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(road.xy, axis=0).T))])
            for sign in (-1, 1):
                station = at_vertex[k] + sign * reach
                if 1.5 <= station <= at_vertex[-1] - 1.5:
                    sites.append((i, station))
    return sites


def _markings(rng, roads: list[_Road], lines, polys, zones, decks, extent):
    """Zebra crossings near some junctions, then dashed lane lines clear of junctions."""
    widths = np.array([r.width_m for r in roads])
    sites = _crossing_sites(roads, widths)
    valid = []  # (road index, centre, tangent, band) of crossings clear of other roads
    for i, station in sites:
        centre = shapely.get_coordinates(shapely.line_interpolate_point(lines[i], station))[0]
        tangent = _tangents(np.array([lines[i]]), np.array([station]))[0]
        band = _rectangles(centre, tangent, 3.0, widths[i] - 1.0)[0]
        if not (shapely.intersects(shapely.buffer(band, 1.0), np.delete(polys, i)).any()
                or _hits([band], [shapely.buffer(decks, 2.0)])[0]
                or not _inside([band], extent, 1.0)[0]):
            valid.append((i, centre, tangent, band))
    chosen = rng.random(len(valid)) < 0.35
    if len(valid) and not chosen.any():
        chosen[rng.integers(len(valid))] = True
    crossings = [site for site, keep in zip(valid, chosen) if keep]
    bands = [(i, band) for i, _, _, band in crossings]
    stripes = [(i, _zebra(centre, tangent, widths[i])) for i, centre, tangent, _ in crossings]

    dashes = []
    for i, road in enumerate(roads):
        if road.bridge or road.width_m < MARKING_MIN_ROAD_M:
            continue
        crossings = [shapely.buffer(band, 1.5) for owner, band in bands if owner == i]
        keep_out = shapely.union_all([g for g in (zones[i], *crossings) if g is not None])
        paths = [lines[i]]
        if road.width_m >= 2 * MARKING_MIN_ROAD_M:  # wide roads: two lanes each way
            paths += [shapely.offset_curve(lines[i], side * road.width_m / 4) for side in (-1, 1)]
        for path in paths:
            for part in shapely.get_parts(shapely.difference(path, keep_out)):
                dashes.append((i, _dashes(part)))
    rows = [(i, "zebra", g) for i, group in stripes for g in group]
    rows += [(i, "dash", g) for i, group in dashes for g in group]
    return rows, [band for _, band in bands]


def _buildings(rng, extent, lines, polys, obstacles, is_park, relief):
    centres = _lattice(rng, extent, 30.0, 2.5)
    n = len(centres)
    # Sizes keep every rotated footprint inside its 30 m lattice cell: no two overlap.
    length, depth = rng.uniform(10, 19, n), rng.uniform(8, 13, n)
    height = 5.0 + 20.0 * rng.random(n) ** 1.6
    tone = rng.random(n)
    points = shapely.points(centres)
    nearest = shapely.STRtree(lines).nearest(points)
    at = shapely.line_locate_point(lines[nearest], points)
    footprints = _rectangles(centres, _tangents(lines[nearest], at), length, depth)
    keep = (~is_park(centres) & _inside(footprints, extent, 3.0)
            & ~_hits(shapely.buffer(footprints, SIDEWALK_M + 4.0), polys)
            & ~_hits(shapely.buffer(footprints, 4.0), obstacles))
    footprints, height, tone = footprints[keep], height[keep], tone[keep]
    corners = shapely.get_coordinates(footprints).reshape(-1, 5, 2)[:, :4].reshape(-1, 2)
    ground = relief.base_z(corners[:, 0], corners[:, 1],
                           np.full(len(corners), Base.RAISED)).reshape(-1, 4)
    # Flat roofs: the building stands on its highest corner.
    return footprints, height, ground.max(axis=1) + height, tone


def _trees(rng, roads, lines, polys, zones, extent, is_park, obstacles):
    """Street trees in the sidewalks (crowns overhang the road) and park trees."""
    trunks, radius, height, street = [], [], [], []
    for i, road in enumerate(roads):
        if not road.street_trees or road.bridge:
            continue
        _, xy, tangent = _points_along(lines[i], rng.uniform(9, 13), rng.uniform(3, 8), 2.0)
        offset = road.width_m / 2 + (1.0 if road.sidewalk else 2.5)
        for side in (-1, 1):
            trunk = xy + side * offset * _left(tangent)
            near_junction = (shapely.intersects(zones[i], shapely.points(trunk))
                             if zones[i] is not None else np.zeros(len(trunk), bool))
            trunk = trunk[~near_junction]
            trunks.append(trunk)
            radius.append(rng.uniform(3.0, 5.0, len(trunk)))
            height.append(rng.uniform(8.0, 14.0, len(trunk)))
            street.append(np.ones(len(trunk), bool))
    park = _lattice(rng, extent, 9.0, 3.0)
    park = park[is_park(park) & (rng.random(len(park)) < 0.55)]
    trunks.append(park)
    radius.append(rng.uniform(2.5, 5.5, len(park)))
    height.append(rng.uniform(6.0, 18.0, len(park)))
    street.append(np.zeros(len(park), bool))
    trunks, radius, height = np.vstack(trunks), np.concatenate(radius), np.concatenate(height)
    street = np.concatenate(street)
    crowns = shapely.buffer(shapely.points(trunks), radius, quad_segs=8)
    sidewalks = [shapely.buffer(line, road.width_m / 2 + SIDEWALK_M, cap_style="flat")
                 for line, road in zip(lines, roads)]
    # Street trees stand in the sidewalk and reach over the road; park trees keep off both.
    keep = (_inside(shapely.points(trunks), extent, 1.0) & ~_hits(crowns, obstacles)
            & ~_hits(shapely.buffer(shapely.points(trunks), 0.8), polys)
            & (street | ~_hits(crowns, sidewalks)))
    return (trunks[keep], radius[keep], height[keep],
            height[keep] * rng.uniform(0.55, 0.7, int(keep.sum())), rng.random(int(keep.sum())))


def _cars(rng, roads, lines, zones, lots, keep_out):
    """Cars parked along kerbs, driving in lanes, and parked in the lots."""
    centres, tangents, where, owner = [], [], [], []  # owner: road index, -1 in a lot
    for i, road in enumerate(roads):
        if road.bridge or road.width_m < 6.5:
            continue
        if road.kerb_parking:
            _, xy, tangent = _points_along(lines[i], rng.uniform(6.2, 7.2), 8.0, 8.0)
            for side in (-1, 1):
                sel = rng.random(len(xy)) < 0.45
                offset = side * (road.width_m / 2 - 1.15)
                centres.append(xy[sel] + offset * _left(tangent[sel]))
                tangents.append(tangent[sel])
                where += ["kerb"] * int(sel.sum())
                owner += [i] * int(sel.sum())
        elif road.width_m >= MARKING_MIN_ROAD_M and road.name != "cul_de_sac":
            _, xy, tangent = _points_along(lines[i], 35.0, rng.uniform(10, 30), 10.0)
            sel = rng.random(len(xy)) < 0.35
            side = rng.choice([-1, 1], int(sel.sum()))[:, None]
            centres.append(xy[sel] + side * road.width_m / 4 * _left(tangent[sel]))
            tangents.append(tangent[sel] * side)
            where += ["lane"] * int(sel.sum())
            owner += [i] * int(sel.sum())
    for lot, access in lots:
        x0, y0, x1, y1 = shapely.bounds(lot)
        ax0, _, ax1, _ = shapely.bounds(access)
        rows, offset, step = [], 3.0, 11.5
        while y0 + offset + 2.5 <= y1 - 0.5:
            rows.append(y0 + offset)
            offset += step
            step = 16.5 - step  # back-to-back rows (5 m) alternate with aisles (11.5 m)
        xs = np.arange(x0 + 1.75, x1 - 1.25, 2.5)
        xs = xs[(xs < ax0 - 2.0) | (xs > ax1 + 2.0)]  # keep the drive from the access free
        gx, gy = np.meshgrid(xs, rows)
        xy = np.column_stack([gx.ravel(), gy.ravel()])
        xy = xy[rng.random(len(xy)) < 0.65]
        heading = np.radians(90 + rng.uniform(-3, 3, len(xy)))
        centres.append(xy)
        tangents.append(np.column_stack([np.cos(heading), np.sin(heading)]))
        where += ["lot"] * len(xy)
        owner += [-1] * len(xy)
    if not centres:
        return np.empty(0, dtype=object), np.empty(0), np.empty(0), np.empty(0, dtype=object)
    centres, tangents = np.vstack(centres), np.vstack(tangents)
    where, owner = np.array(where, dtype=object), np.array(owner)
    n = len(centres)
    cars = _rectangles(centres, tangents, rng.uniform(4.2, 4.8, n), rng.uniform(1.75, 1.9, n))
    blocked = _hits(shapely.buffer(cars, 1.0), keep_out)
    # Cars on a road keep clear of its junctions.
    for i in np.unique(owner[owner >= 0]):
        if zones[i] is not None:
            mine = owner == i
            blocked[mine] |= shapely.intersects(zones[i], cars[mine])
    keep = ~blocked
    return cars[keep], rng.uniform(1.4, 1.6, n)[keep], rng.random(n)[keep], where[keep]


def scene_frame(size_m, origin, crs) -> tuple[tuple, CRS]:
    """The extent ``(xmin, ymin, xmax, ymax)`` and CRS of a scene, checked: at least
    :data:`MIN_SIZE_M` a side, a projected CRS in metres."""
    width, height = map(float, size_m)
    if min(width, height) < MIN_SIZE_M:
        raise GisroadsError(f"a scene needs at least {MIN_SIZE_M:.0f} x {MIN_SIZE_M:.0f} m, "
                            f"got {width} x {height}")
    crs = CRS.from_user_input(crs)
    if not crs.is_projected or crs.axis_info[0].unit_name not in ("metre", "meter"):
        raise GisroadsError(f"scenes are laid out in metres; {crs.name} is not a metre CRS")
    xmin, ymin = map(float, origin)
    return (xmin, ymin, xmin + width, ymin + height), crs


def make_scene(*, seed: int = 0, size_m: tuple[float, float] = (400.0, 400.0),
               origin: tuple[float, float] = (500000.0, 4500000.0), crs="EPSG:32633",
               features=FEATURES) -> Scene:
    """Lay out a synthetic scene (see the module docstring for what it contains).

    Parameters
    ----------
    seed : int
        Same seed, same scene; the layout stages draw from independent streams, so
        leaving a feature out does not move the others.
    size_m : (width, height)
        Metres; at least 300 each.
    origin : (x, y)
        Lower-left corner in map units (metres).
    crs : anything pyproj accepts
        A projected CRS in metres.
    features : collection of str
        Subset of :data:`FEATURES` to place.

    Returns
    -------
    Scene

    Examples
    --------
    >>> from gisroads.synthetic import make_scene
    >>> scene = make_scene(seed=0, size_m=(300, 300))
    >>> scene.extent
    (500000.0, 4500000.0, 500300.0, 4500300.0)
    >>> scene.roads["name"].tolist()
    ['cliff_foot', 'cliff_top', 'avenue', 'dual_carriageway_a', 'dual_carriageway_b',
     'curved_street', 'diagonal', 'cul_de_sac', 'bridge']
    >>> truth = scene.truth                   # a RoadNetwork: the exact answer
    >>> len(truth.centrelines), len(truth.junctions)
    (9, 10)
    >>> make_scene(seed=0, size_m=(300, 300)).roads.equals(scene.roads)  # same seed
    True
    >>> make_scene(seed=0, size_m=(300, 300), features=()).buildings.empty
    True
    """
    unknown = set(features) - set(FEATURES)
    if unknown:
        raise GisroadsError(f"unknown features {sorted(unknown)}; choose from {FEATURES}")
    extent, crs = scene_frame(size_m, origin, crs)
    xmin, ymin, xmax, ymax = extent
    width, height = xmax - xmin, ymax - ymin

    roads, frame = _layout_roads(seed, (xmin, ymin), (width, height), features)
    _node_same_level(roads)
    ramps, decks, bridge_rows = [], [], []
    if frame.ramp is not None:
        road, start, direction, knots, deck_height = frame.ramp
        road_id = roads.index(road)
        ramps.append(Ramp(road_id, start, direction, knots, deck_height))
        band = _rectangles(np.asarray(start) + np.asarray(direction) * (knots[1] + knots[2]) / 2,
                           np.asarray(direction), knots[2] - knots[1], road.width_m + 2.0)[0]
        decks.append(shapely.intersection(_corridor(road), band))
        crossing = shapely.get_coordinates(
            shapely.intersection(road.line, frame.lower_road.line))[0]
        bridge_rows.append((road_id, roads.index(frame.lower_road), deck_height, *crossing))
    relief = _make_relief(seed, (xmin, ymin), cliff_line=frame.cliff_line,
                          cliff_height_m=frame.cliff_height_m, cliff_slope_m=frame.cliff_slope_m,
                          ramps=ramps)

    lines = np.array([r.line for r in roads], dtype=object)
    widths = np.array([r.width_m for r in roads])
    polys = shapely.buffer(lines, widths / 2, cap_style="flat", join_style="round")
    zones = _junction_zones(lines, polys, 3.0)
    deck_union = shapely.union_all(decks) if decks else shapely.Polygon()
    lots = frame.lots
    lot_geoms = np.array([g for g, _ in lots], dtype=object)
    access_geoms = np.array([a for _, a in lots], dtype=object)
    bridge_polys = [p for p, r in zip(polys, roads) if r.bridge]
    cliff_zone = (_cliff_strip(relief, extent, -relief.cliff_slope_m / 2 - 4.0,
                               relief.cliff_slope_m / 2 + 4.0)
                  if relief.cliff_height_m else None)

    marking_rows, zebra_bands = [], []
    if "markings" in features:
        marking_rows, zebra_bands = _markings(_stable_seed(seed, "markings"), roads, lines,
                                              polys, zones, deck_union, extent)
    is_park = _park_cells(seed, extent)
    none, no_geoms = np.empty(0), np.empty(0, dtype=object)  # for features left out
    building_geoms, building_h, roof_z, building_tone = no_geoms, none, none, none
    lot_obstacles = [*lot_geoms, *access_geoms, cliff_zone,
                     *[shapely.buffer(p, 4.0) for p in bridge_polys]]
    if "buildings" in features:
        building_geoms, building_h, roof_z, building_tone = _buildings(
            _stable_seed(seed, "buildings"), extent, lines, polys, lot_obstacles, is_park,
            relief)
    tree_xy, crown_r, tree_h, crown_depth, tree_tone = np.empty((0, 2)), none, none, none, none
    if "trees" in features:
        tree_xy, crown_r, tree_h, crown_depth, tree_tone = _trees(
            _stable_seed(seed, "trees"), roads, lines, polys, zones, extent, is_park,
            [*building_geoms, *[shapely.buffer(g, 1.0) for g in lot_obstacles if g is not None]])
    tree_ground = relief.base_z(tree_xy[:, 0], tree_xy[:, 1],
                                np.full(len(tree_xy), Base.RAISED))
    car_geoms, car_h, car_tone, car_where = no_geoms, none, none, no_geoms
    if "cars" in features:
        car_geoms, car_h, car_tone, car_where = _cars(
            _stable_seed(seed, "cars"), roads, lines, zones, lots,
            [*access_geoms, *[shapely.buffer(b, 1.0) for b in zebra_bands],
             *[shapely.buffer(p, 3.0) for p in bridge_polys]])
    car_centre = shapely.get_coordinates(shapely.centroid(car_geoms)).reshape(-1, 2)
    car_roof = relief.terrain_z(car_centre[:, 0], car_centre[:, 1]) + car_h

    road_frame = _road_frame(roads, relief, crs)
    lot_frame = _gdf({"lot_id": np.arange(len(lots), dtype=np.int64),
                      "aspect": np.array([_aspect(g) for g in lot_geoms])}, lot_geoms, crs)
    access_frame = _gdf({"lot_id": np.arange(len(lots), dtype=np.int64)}, access_geoms, crs)
    plateau = ([_cliff_strip(relief, extent, 0.0, np.inf)] if relief.cliff_height_m else [])
    cliff_frame = _gdf({"height_m": np.full(len(plateau), relief.cliff_height_m),
                        "slope_m": np.full(len(plateau), relief.cliff_slope_m)}, plateau, crs)
    bridge_cols = np.array(bridge_rows, float).reshape(-1, 5)
    bridge_frame = _gdf({"bridge_id": np.arange(len(decks), dtype=np.int64),
                         "road_id": bridge_cols[:, 0].astype(np.int64),
                         "under_road_id": bridge_cols[:, 1].astype(np.int64),
                         "height_m": bridge_cols[:, 2], "crossing_x": bridge_cols[:, 3],
                         "crossing_y": bridge_cols[:, 4]}, decks, crs)
    return Scene(
        roads=road_frame, parking_lots=lot_frame, parking_access=access_frame,
        buildings=_gdf({"building_id": np.arange(len(building_geoms), dtype=np.int64),
                        "height_m": building_h, "roof_z": roof_z, "tone": building_tone},
                       building_geoms, crs),
        trees=_gdf({"tree_id": np.arange(len(tree_xy), dtype=np.int64),
                    "crown_radius_m": crown_r, "height_m": tree_h,
                    "crown_depth_m": crown_depth, "top_z": tree_ground + tree_h,
                    "tone": tree_tone}, shapely.points(tree_xy), crs),
        cars=_gdf({"car_id": np.arange(len(car_geoms), dtype=np.int64), "height_m": car_h,
                   "roof_z": car_roof, "tone": car_tone, "where": car_where}, car_geoms, crs),
        markings=_gdf({"road_id": np.array([r[0] for r in marking_rows], np.int64),
                       "kind": np.array([r[1] for r in marking_rows], dtype=object)},
                      [r[2] for r in marking_rows], crs),
        cliff=cliff_frame, bridges=bridge_frame, extent=extent, crs=crs, seed=int(seed),
        relief=relief)


def _road_frame(roads: list[_Road], relief: Relief, crs) -> gpd.GeoDataFrame:
    """The truth centre lines (:attr:`Scene.roads`): densified, with the road surface
    elevation as Z."""
    dense = shapely.segmentize(np.array([r.line for r in roads], dtype=object),
                               VERTEX_SPACING_M)
    geoms3d, z_min, z_max = [], [], []
    for i, line in enumerate(dense):
        xy = shapely.get_coordinates(line)
        z = relief.road_z(xy[:, 0], xy[:, 1], i)
        geoms3d.append(shapely.linestrings(np.column_stack([xy, z])))
        z_min.append(z.min())
        z_max.append(z.max())
    return _gdf({
        "road_id": np.arange(len(roads), dtype=np.int64),
        "name": np.array([r.name for r in roads], dtype=object),
        "kind": np.full(len(roads), "road", dtype=object),
        "width_m": np.array([r.width_m for r in roads]),
        "level": np.array([r.level for r in roads], np.int64),
        "bridge": np.array([r.bridge for r in roads]),
        "sidewalk": np.array([r.sidewalk for r in roads]),
        "surface": np.array([r.surface for r in roads], dtype=object),
        "z_min": np.array(z_min), "z_max": np.array(z_max)}, geoms3d, crs)


def _aspect(polygon) -> float:
    """Long side over short side of a polygon's minimum rotated rectangle."""
    xy = shapely.get_coordinates(shapely.oriented_envelope(polygon))[:3]
    sides = np.hypot(*np.diff(xy, axis=0).T)
    return float(sides.max() / sides.min())
