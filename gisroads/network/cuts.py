"""Cuts across roads closed in the raster, before the skeleton.

A road mask cut across (a tree, a car, a shadow, a missed stretch of a segmentation) falls
into pieces whose facing ends are straight, as wide as the road, one in front of the
other, with background on both flanks of the gap. A piece between two cuts of a wide road
can be shorter than it is wide: its skeleton then runs across the road and no vector rule
can tell its direction. In the raster the cut is plain: the two ends facing each other and
the open flanks say where the road goes, so the gap is filled there and the skeleton of
the repaired mask runs along the road.

From every border pixel a ray runs off the mask along the outline's outward normal (the
gradient of the smoothed mask, so a stepped border of a slanted road points across the
road, not along its steps). Where rays from neighbouring border pixels meet road again
within the longest cut, on an outline facing them, they start from a road end facing
another. The pair is a cut when:

- both are road ends: behind each, the road stops to the sides within a few metres of
  the meeting rays (a road that goes on is a side: a block's, a median's, the side of a
  road that a dead end stops short of), and a few metres further back the road is no
  wider (a road's sides run along it; a blob widens behind its front);
- they are about as wide and one is in front of the other;
- both flanks of the gap are open: beside the gap and beside each end, no road (a block
  between two parallel roads is flanked by its cross streets).

A false blob beside a road, a block, a dual carriageway's median and a road ending short
of another's side are left alone (tests). A road end facing a blob of its own width and
direction is not told from a cut.
"""
from __future__ import annotations

import numpy as np
import shapely
from scipy import ndimage
from skimage.draw import polygon as fill_polygon

#: Gaps up to this long (between the two facing road ends) are closed, metres.
MAX_CUT_M = 20.0
#: A road's end facing another across a cut is at least this wide, metres.
MIN_EDGE_M = 2.5
#: And at most this wide (as the widest road part), metres.
MAX_EDGE_M = 40.0
#: The outlines at the two ends of a cut face each other within this angle, degrees.
MAX_ANGLE_DEG = 20.0
#: The two ends overlap, seen along the road, over at least this share of the wider.
MIN_OVERLAP = 0.6
#: At most this share of each flank of a cut is road (behind each end and beside the gap).
MAX_ROAD_SHARE = 0.25
#: The flanks are tested this deep behind each end, metres.
FLANK_DEPTH_M = 3.0
#: And from this far to the side of the ends (beyond their rounded corners), metres.
FLANK_MARGIN_M = 1.0
#: Outline directions from the gradient of the mask smoothed by this sigma, pixels (a
#: stepped border of a slanted road points along the road's normal, not the steps').
NORMAL_SIGMA_PX = 1.5
#: The rays from a road end's rounded corners do not meet the other end: the end is wider
#: than its meeting rays, by up to this on either side, metres.
END_ROUND_M = 5.0
#: The meeting rays of an end span at least this, metres.
MIN_RAYS_M = 1.5
#: Behind a road end (at the flanks' depth) the road is at most this wider on a side,
#: metres.
END_WIDEN_M = 1.0
#: Rays are cast for this many border pixels at a time (memory: about 40 bytes per pixel
#: and step).
RAYS_PER_BLOCK = 20000
#: A cut is filled over the convex hull of both road ends this deep, metres.
SLAB_M = 1.5


def _road(mask: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The mask at ``points`` (row, col, nearest pixel); outside the mask is background."""
    r = np.floor(points[..., 0] + 0.5).astype(np.int64)
    c = np.floor(points[..., 1] + 0.5).astype(np.int64)
    inside = (r >= 0) & (r < mask.shape[0]) & (c >= 0) & (c < mask.shape[1])
    out = np.zeros(r.shape, dtype=bool)
    out[inside] = mask[r[inside], c[inside]]
    return out


def _share(mask, origin, along, normal, u0, u1, v0, v1, n: int = 6) -> np.ndarray:
    """Per pair, the share of road on an ``n`` x ``n`` grid over the rectangle
    ``u0..u1`` x ``v0..v1`` of the frame (origin, along, normal)."""
    s = (np.arange(n) + 0.5) / n
    u0, u1, v0, v1 = np.broadcast_arrays(u0, u1, v0, v1)
    u = u0[:, None, None] + (u1 - u0)[:, None, None] * s[None, :, None]
    v = v0[:, None, None] + (v1 - v0)[:, None, None] * s[None, None, :]
    points = (origin[:, None, None, :] + u[..., None] * along[:, None, None, :]
              + v[..., None] * normal[:, None, None, :])
    return _road(mask, points).mean(axis=(1, 2))


def bridge_cuts(mask: np.ndarray, pixel_m: float, *, max_cut_m: float = MAX_CUT_M,
                min_edge_m: float = MIN_EDGE_M, max_edge_m: float = MAX_EDGE_M,
                max_angle_deg: float = MAX_ANGLE_DEG, min_overlap: float = MIN_OVERLAP,
                max_road_share: float = MAX_ROAD_SHARE,
                flank_depth_m: float = FLANK_DEPTH_M,
                flank_margin_m: float = FLANK_MARGIN_M) -> np.ndarray:
    """The mask with its cuts across roads filled (see the module docstring).

    From every border pixel a ray runs off the mask along the outline's outward normal;
    it meets a cut's other end when it reaches road within ``max_cut_m`` whose outline
    faces it. The rays that meet, grouped by the border pixels they start from, are the
    road ends facing each other; each group is tested and filled on its own.

    Parameters
    ----------
    mask : ndarray of bool, shape (rows, cols)
        Road pixels, cleaned (:func:`gisroads.network.rasters.road_mask`).
    pixel_m : float
        Pixel size, metres.
    max_cut_m : float
        Longest gap closed (between the facing ends), metres.
    min_edge_m, max_edge_m : float
        Width of a road end facing another, metres.
    max_angle_deg : float
        Largest angle between the outlines of the two ends, degrees.
    min_overlap : float
        Least overlap of the two ends, seen along the road, as a share of the wider: ends
        of the same width, one in front of the other.
    max_road_share : float
        Largest share of road in each flank of the cut: beside the gap and beside each
        end, on either side.
    flank_depth_m, flank_margin_m : float
        The flanks reach this deep behind each end and start this far to the side of the
        ends, metres.

    Returns
    -------
    ndarray of bool
        ``mask`` with each cut filled between the two ends.
    """
    mask = np.asarray(mask, bool)
    border = mask & ~ndimage.binary_erosion(mask)
    if not border.any() or max_cut_m <= 0:
        return mask
    smooth = ndimage.gaussian_filter(mask.astype(np.float32), NORMAL_SIGMA_PX)
    grad_r, grad_c = np.gradient(smooth)
    start = np.argwhere(border)
    outward = -np.column_stack([grad_r[border], grad_c[border]])
    norm = np.hypot(*outward.T)
    start, outward = start[norm > 0], outward[norm > 0] / norm[norm > 0, None]
    hit, meets = _cast(mask, start, outward, int(np.ceil(max_cut_m / pixel_m)) + 1)
    start, outward, hit = start[meets], outward[meets], hit[meets]
    facing = -np.column_stack([grad_r[hit[:, 0], hit[:, 1]], grad_c[hit[:, 0], hit[:, 1]]])
    facing /= np.maximum(np.hypot(*facing.T), 1e-12)[:, None]
    keep = (outward * facing).sum(axis=1) <= -np.cos(np.radians(max_angle_deg))
    start, outward, hit, facing = start[keep], outward[keep], hit[keep], facing[keep]
    if len(start) == 0:
        return mask
    # the ends: rays from neighbouring border pixels
    seeds = np.zeros(mask.shape, np.int64)
    seeds[start[:, 0], start[:, 1]] = np.arange(1, len(start) + 1)
    groups, count = ndimage.label(seeds > 0, structure=np.ones((3, 3)))
    group = groups[start[:, 0], start[:, 1]] - 1
    size = np.bincount(group, minlength=count)

    def mean(values):
        return np.bincount(group, weights=values, minlength=count) / size

    direction = np.column_stack([mean(outward[:, 0]), mean(outward[:, 1])])
    coherent = np.hypot(*direction.T)
    direction /= np.maximum(coherent, 1e-12)[:, None]
    across = np.column_stack([-direction[:, 1], direction[:, 0]])
    origin = np.column_stack([mean(start[:, 0]), mean(start[:, 1])])
    far = np.column_stack([mean(hit[:, 0]), mean(hit[:, 1])])
    far_normal = np.column_stack([mean(facing[:, 0]), mean(facing[:, 1])])
    far_normal /= np.maximum(np.hypot(*far_normal.T), 1e-12)[:, None]
    u_start = ((start - origin[group]) * across[group]).sum(axis=1)
    u_hit = ((hit - origin[group]) * across[group]).sum(axis=1)
    gap = mean(((hit - start) * direction[group]).sum(axis=1))
    u0, u1 = _extent(u_start, group, count)
    w0, w1 = _extent(u_hit, group, count)
    ok = ((coherent >= np.cos(np.radians(max_angle_deg))) & (u1 - u0 <= max_edge_m / pixel_m)
          & (np.minimum(u1, w1) - np.maximum(u0, w0) >= MIN_RAYS_M / pixel_m))
    keep = np.flatnonzero(ok)
    if len(keep) == 0:
        return mask
    origin, across, direction, far, far_normal, gap = (
        origin[keep], across[keep], direction[keep], far[keep], far_normal[keep], gap[keep])
    slab = max(2.0, SLAB_M / pixel_m)
    reach = max(2.0, END_ROUND_M / pixel_m)
    depth = flank_depth_m / pixel_m
    # both ends, a's behind the rays' starts and b's behind their hits, along a's edge
    shift = ((far - origin) * across).sum(axis=1)
    widen = max(2.0, END_WIDEN_M / pixel_m)
    u0, u1, end_a = _road_end(mask, origin, across, direction, u0[keep], u1[keep], slab,
                              reach, depth, widen)
    w0, w1, end_b = _road_end(mask, far, across, far_normal, w0[keep] - shift,
                              w1[keep] - shift, slab, reach, depth, widen)
    w0, w1 = w0 + shift, w1 + shift
    width, far_width = u1 - u0, w1 - w0
    overlap = np.minimum(u1, w1) - np.maximum(u0, w0)
    ok = (end_a & end_b & (np.minimum(width, far_width) >= min_edge_m / pixel_m)
          & (np.maximum(width, far_width) <= max_edge_m / pixel_m)
          & (overlap >= min_overlap * np.maximum(width, far_width)))
    u0, u1 = np.minimum(u0, w0), np.maximum(u1, w1)
    margin = flank_margin_m / pixel_m + 1.0
    strip = max(margin, 2.0)
    for v0, v1 in ((-depth, 0.0), (0.0, gap), (gap, gap + depth)):
        for lo, hi in ((u0 - margin - strip, u0 - margin), (u1 + margin, u1 + margin + strip)):
            ok &= _share(mask, origin, across, direction, lo, hi, v0, v1) <= max_road_share
    out = mask.copy()
    for k in np.flatnonzero(ok):
        _fill_between(out, mask, origin[k], across[k], direction[k], far[k], far_normal[k],
                      u0[k] - 1.0, u1[k] + 1.0, slab)
    return out


def _cast(mask, start, outward, steps: int):
    """Rays from ``start`` along ``outward``, one pixel a step, up to ``steps``: the
    first road pixel each meets, and whether it meets one after leaving the road at once.
    """
    hit = np.zeros_like(start)
    meets = np.zeros(len(start), dtype=bool)
    reach = np.arange(1, steps + 1, dtype=float)
    for k in range(0, len(start), RAYS_PER_BLOCK):
        block = slice(k, k + RAYS_PER_BLOCK)
        on_road = _road(mask, start[block, None, :]
                        + reach[None, :, None] * outward[block, None, :])
        first = np.argmax(on_road, axis=1)
        hit[block] = np.floor(start[block] + reach[first, None] * outward[block]
                              + 0.5).astype(np.int64)
        meets[block] = ~on_road[:, 0] & on_road.any(axis=1)
    return hit, meets


def _extent(values: np.ndarray, group: np.ndarray, count: int):
    """Per group, the least and the greatest of ``values``."""
    low = np.full(count, np.inf)
    high = np.full(count, -np.inf)
    np.minimum.at(low, group, values)
    np.maximum.at(high, group, values)
    return low, high


def _run(mask, origin, across, outward, edge, side, steps, depths):
    """Per road end, the number of ``steps`` (pixels along ``across`` on ``side`` of
    ``edge``) over which the road goes on at one of ``depths`` behind it, and whether it
    goes on over all of them."""
    u = edge[:, None] + side * steps[None, :]
    points = (origin[:, None, None, :] + u[:, :, None, None] * across[:, None, None, :]
              + depths[None, None, :, None] * outward[:, None, None, :])
    road = _road(mask, points).any(axis=2)
    return np.argmin(road, axis=1), road.all(axis=1)


def _road_end(mask, origin, across, outward, u0, u1, slab, reach, depth, widen):
    """Whether the road behind the rays ``u0..u1`` (pixels along ``across`` from
    ``origin``; ``outward`` points off the road) is a road's end, and how wide.

    The road behind the rays (within ``slab`` pixels) stops within ``reach`` of them on
    both sides (the rays from the end's rounded corners do not meet the other end; a road
    that goes on is a side: a block's, a median's). And ``depth`` pixels behind, the road
    is no wider than at its end, give or take ``widen`` on a side (a road's sides run
    along it, a blob widens), or there is none (a piece shorter than ``depth``).

    Returns
    -------
    e0, e1 : ndarray
        The end's extent along ``across``, pixels.
    is_end : ndarray of bool
    """
    steps = np.arange(1, int(np.ceil(reach)) + 1, dtype=float)
    near = np.linspace(-slab, -1.0, 3)
    run0, on0 = _run(mask, origin, across, outward, u0, -1.0, steps, near)
    run1, on1 = _run(mask, origin, across, outward, u1, 1.0, steps, near)
    e0, e1 = u0 - run0, u1 + run1
    centre, half = (e0 + e1) / 2, (e1 - e0) / 2
    deep = np.arange(0, int(np.ceil(half.max() + reach)) + 1, dtype=float)
    back = np.array([-depth])
    wide0, _ = _run(mask, origin, across, outward, centre, -1.0, deep, back)
    wide1, _ = _run(mask, origin, across, outward, centre, 1.0, deep, back)
    beside = np.maximum(wide0, wide1) <= half + widen
    shorter = ~_road(mask, origin + centre[:, None] * across - depth * outward)
    return e0, e1, ~on0 & ~on1 & (beside | shorter)


def _fill_between(out, mask, origin, along, normal, origin_b, normal_b, u0, u1, slab):
    """Set in ``out`` the convex hull of the two road ends: the road pixels of ``mask``
    within ``slab`` pixels behind each edge and ``u0..u1`` along a's edge. The hull's sides
    are the road's sides carried across the gap, whatever the precision of the edges'
    ends (the outline cuts the corners of the pixels)."""
    reach = np.abs(np.array([u0, u1])).max() + np.hypot(*(origin_b - origin)) + slab
    r0, c0 = np.maximum(np.floor(origin - reach).astype(int), 0)
    r1, c1 = np.minimum(np.ceil(origin + reach).astype(int) + 1, mask.shape)
    rows, cols = np.nonzero(mask[r0:r1, c0:c1])
    points = np.column_stack([rows + r0, cols + c0]).astype(float)
    u = (points - origin) @ along
    v_a = (points - origin) @ normal
    v_b = (points - origin_b) @ normal_b
    ends = points[(u >= u0) & (u <= u1) & (((v_a <= 0.5) & (v_a >= -slab))
                                          | ((v_b <= 0.5) & (v_b >= -slab)))]
    # pixel corners, so the hull holds the end pixels whole
    corners = (ends[:, None, :] + np.array([[-0.5, -0.5], [-0.5, 0.5], [0.5, -0.5],
                                            [0.5, 0.5]])).reshape(-1, 2)
    hull = shapely.convex_hull(shapely.multipoints(corners))
    if hull.geom_type != "Polygon":
        return
    ring = shapely.get_coordinates(hull.exterior)
    rr, cc = fill_polygon(ring[:, 0], ring[:, 1], shape=out.shape)
    out[rr, cc] = True
