"""Attractor map of a road patch (Boyko & Funkhouser, 2011, section 2.3).

The attractor map is large where a road boundary is likely and small elsewhere:

    a(x, y) = alpha_attr * e(x, y) + beta_attr * c(x, y)

``e`` is the extent term, 1 between one and six lane widths from the map line and 0
elsewhere; ``c`` is the curb detector, the per-point response

    c(p) = f(dh) * (1 - (n_p . n_s)^2)        (Eq. 1)

averaged over grid cells. ``n_p`` is the PCA normal of the point's ``k`` nearest neighbours
(at least 20), ``n_s`` the normal of the road's support plane, and ``f`` weights the local
height step ``dh``: ``f_n = 1`` (Eq. 2), ``f_nStep = 1`` on [10, 20] cm (Eq. 3) or
``f_nExp``, a Gaussian of 15 cm mean and 5 cm deviation (Eq. 4).

The local height step ``dh`` is the spread of the neighbours' heights along ``n_s``, taken
between their 10th and 90th percentiles rather than from the plain range, so that one noisy
point does not make a kerb (the paper says only "a function of the local elevation
variance").

Airborne clouds scale the normal term. The paper's merged cloud samples the kerb's vertical
face, so ``n_p`` turns horizontal there and ``1 - (n_p . n_s)^2`` reaches 1. From the air a
kerb only tilts the plane fitted to a neighbourhood that straddles it: a ``dh`` step across
a disc of radius ``r`` tilts a least-squares plane by the slope ``s = 8 dh / (3 pi r)``,
so at 10 points/m2 (r = 0.8 m for 20 neighbours) a 15 cm kerb gives
``1 - (n_p . n_s)^2 = s^2 / (1 + s^2) = 0.025``, against 0.0003 on flat asphalt, and the extent
term (0.2) would drown it. With ``scale_tilt=True`` (the default) the normal term is divided
by that of an ideal ``dh_avg`` kerb seen by the point's own neighbourhood radius and clipped
to 1, so ``c`` is again a probability-like value in [0, 1] whatever the density; where the
face is sampled the clip leaves the paper's value of 1.

Kerbs from the ground surface are this module's addition too (``kerbs=True``): at airborne
densities the normal term of a kerb is a faint tilt, but the lowest point of each cell
traces the ground, and its detail steps up across a kerb
(:func:`gisroads.features.kerbs.kerb_steps`, the kerb the LiDAR road evidence reads). The
curb term is at least that step's kerb membership. With a map 3 m off, the road-area quality
went from 0.894 to 0.960 on a synthetic scene (300 m, 10 points/m2), and from 0.684 to 0.745
on fusa (a test, not a choice). The membership's ramp (from half the kerb gradient to all of
it) was chosen on the synthetic scene, with the term taken as a floor of the whole map:
0.966 against 0.954 from three quarters, 0.856 from none and 0.837 for a ramp to twice it.

Drop-offs are this module's addition. A bridge deck has no kerb: its edge is where the
surface leaves the subcloud's 0.5 m window (the ground is metres below), and an airborne
cloud has no points on the parapet's face either. So the edge of the area the patch's
points cover (after closing car-sized gaps and filling enclosed holes) takes the curb value
``drop_off_weight`` where it is larger, except at the subcloud's own reach.

References
----------
Boyko, A., Funkhouser, T. (2011). Extracting roads from dense point clouds in large scale
urban environment. ISPRS Journal of Photogrammetry and Remote Sensing 66 (6), S2-S12.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import shapely
from affine import Affine
from scipy import ndimage
from scipy.spatial import cKDTree

from ..errors import GisroadsError
from ..features.kerbs import kerb_membership, kerb_steps
from ..geo import GeoRaster

#: Standard lane width (RTAC 1986), metres: the unit of the extent term (Sec. 2.2-2.3).
LANE_M = 3.66
#: Table 1 of the paper.
ALPHA_ATTR = 0.2
BETA_ATTR = 1.0
DH_AVG_M = 0.15
DH_SIGMA_M = 0.05
DH_MIN_M = 0.10
DH_MAX_M = 0.20
MIN_NEIGHBOURS = 20
DETECTORS = ("exp", "step", "none")
#: A road surface that drops out of the subcloud's window (a deck's edge) bounds the road as
#: a kerb does: its cells get this curb value. Gaps up to about twice CLOSE_M (metres) in
#: the points (a parked car, sparse sampling) do not count as edges.
DROP_OFF_WEIGHT = 0.5
CLOSE_M = 1.25

_SPREAD_PERCENTILES = (10.0, 90.0)


def pca_normals(points_xyz: np.ndarray, *, k_neighbours: int = MIN_NEIGHBOURS,
                tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals by principal component analysis of each point's nearest neighbours.

    Parameters
    ----------
    points_xyz : ndarray, shape (n, 3)
        Metres.
    k_neighbours : int
        Neighbourhood size, the point itself included (the paper: at least 20).
    tree : cKDTree, optional
        A tree over ``points_xyz`` already built.

    Returns
    -------
    normals : ndarray, shape (n, 3)
        Eigenvector of the smallest eigenvalue of the neighbourhood covariance, pointing up.
    neighbours : ndarray of int, shape (n, k)
        Indices of the neighbourhood of each point.
    """
    xyz = np.asarray(points_xyz, float)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise GisroadsError(f"points_xyz must have shape (n, 3), got {xyz.shape}")
    if len(xyz) < k_neighbours:
        raise GisroadsError(f"{len(xyz)} points: at least k_neighbours={k_neighbours} are "
                            "needed")
    tree = cKDTree(xyz) if tree is None else tree
    _, neighbours = tree.query(xyz, k=k_neighbours)
    local = xyz[neighbours]
    local -= local.mean(axis=1, keepdims=True)
    covariance = np.matmul(local.transpose(0, 2, 1), local) / k_neighbours
    _, vectors = np.linalg.eigh(covariance)   # eigenvalues ascending
    normals = vectors[:, :, 0]
    return normals * np.where(normals[:, 2] < 0, -1.0, 1.0)[:, None], neighbours


def height_step(points_xyz: np.ndarray, neighbours: np.ndarray,
                support_normal: np.ndarray) -> np.ndarray:
    """``dh`` of each point: the 10-90 percentile spread of its neighbours' heights measured
    along the support-plane normal (metres)."""
    heights = np.einsum("nkj,nj->nk", np.asarray(points_xyz, float)[neighbours],
                        np.broadcast_to(support_normal, (len(neighbours), 3)))
    low, high = np.percentile(heights, _SPREAD_PERCENTILES, axis=1)
    return high - low


def step_weight(dh_m: np.ndarray, detector: str = "exp", *, dh_avg_m: float = DH_AVG_M,
                dh_sigma_m: float = DH_SIGMA_M, dh_min_m: float = DH_MIN_M,
                dh_max_m: float = DH_MAX_M) -> np.ndarray:
    """``f(dh)``: Eq. 2 (``"none"``: f_n), Eq. 3 (``"step"``: f_nStep) or Eq. 4 (``"exp"``:
    f_nExp) of the paper."""
    dh_m = np.asarray(dh_m, float)
    if detector == "none":
        return np.ones_like(dh_m)
    if detector == "step":
        return ((dh_m >= dh_min_m) & (dh_m <= dh_max_m)).astype(float)
    if detector == "exp":
        return np.exp(-(dh_m - dh_avg_m) ** 2 / (2 * dh_sigma_m ** 2))
    raise GisroadsError(f"unknown curb detector {detector!r}; choose from {DETECTORS}")


def curb_response(points_xyz: np.ndarray, support_normal=(0.0, 0.0, 1.0), *,
                  k_neighbours: int = MIN_NEIGHBOURS, detector: str = "exp",
                  dh_avg_m: float = DH_AVG_M, dh_sigma_m: float = DH_SIGMA_M,
                  dh_min_m: float = DH_MIN_M, dh_max_m: float = DH_MAX_M,
                  scale_tilt: bool = True) -> np.ndarray:
    """Curb detector ``c(p) = f(dh) (1 - (n_p . n_s)^2)`` at every point (Eq. 1).

    Parameters
    ----------
    points_xyz : ndarray, shape (n, 3)
        The points of one road patch (metres).
    support_normal : array_like, shape (3,) or (n, 3)
        ``n_s``: the support-plane normal of the patch, or of each point's nearest sample.
    k_neighbours : int
        Size of the neighbourhood ``N(p)`` (>= 20 in the paper).
    detector : {"exp", "step", "none"}
        Which ``f(dh)`` (see :func:`step_weight`).
    dh_avg_m, dh_sigma_m : float
        Mean and deviation of f_nExp (metres; 0.15, 0.05).
    dh_min_m, dh_max_m : float
        Bounds of f_nStep (metres; 0.10, 0.20).
    scale_tilt : bool
        Divide the normal term by that of an ideal ``dh_avg_m`` kerb at the point's
        neighbourhood radius (see the module docstring); False gives the paper's raw term.

    Returns
    -------
    ndarray, shape (n,)
        In [0, 1].
    """
    if detector not in DETECTORS:
        raise GisroadsError(f"unknown curb detector {detector!r}; choose from {DETECTORS}")
    if k_neighbours < 3:
        raise GisroadsError("k_neighbours must be at least 3 to define a plane")
    xyz = np.asarray(points_xyz, float)
    tree = cKDTree(xyz) if len(xyz) >= k_neighbours else None
    normals, neighbours = pca_normals(xyz, k_neighbours=k_neighbours, tree=tree)
    support = np.asarray(support_normal, float)
    support = support / np.linalg.norm(support, axis=-1, keepdims=True)
    support = np.broadcast_to(support, xyz.shape)
    dh = height_step(xyz, neighbours, support)
    tilt = 1.0 - np.einsum("ij,ij->i", normals, support) ** 2
    if scale_tilt:
        radius = np.linalg.norm(xyz[neighbours[:, -1]] - xyz, axis=1)
        slope = 8 * dh_avg_m / (3 * np.pi * np.maximum(radius, 1e-3))
        tilt = tilt / (slope ** 2 / (1 + slope ** 2))
    weight = step_weight(dh, detector, dh_avg_m=dh_avg_m, dh_sigma_m=dh_sigma_m,
                         dh_min_m=dh_min_m, dh_max_m=dh_max_m)
    return np.clip(weight * tilt, 0.0, 1.0)


def extent_term(x, y, line_xy, *, lane_m: float = LANE_M, min_lanes: float = 1.0,
                max_lanes: float = 6.0) -> np.ndarray:
    """Extent constraint ``e``: 1 where the distance to the map line lies within
    ``[min_lanes, max_lanes]`` lane widths, else 0 (Sec. 2.3).

    Parameters
    ----------
    x, y : array_like
        Map coordinates (metres).
    line_xy : ndarray, shape (k, 2)
        The map line of the patch.
    """
    distance = line_distance(x, y, line_xy)
    return ((distance >= min_lanes * lane_m) & (distance <= max_lanes * lane_m)).astype(float)


def line_distance(x, y, line_xy) -> np.ndarray:
    """Distance (metres) of points to a polyline, shaped like ``x`` and ``y`` broadcast."""
    line = shapely.linestrings(np.asarray(line_xy, float)[:, :2])
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    return shapely.distance(shapely.points(x.ravel(), y.ravel()), line).reshape(x.shape)


def drop_off_edges(counts: np.ndarray, cell_m: float, *, close_m: float = CLOSE_M
                   ) -> np.ndarray:
    """Cells on the edge of the area a patch's points cover: where its surface drops out of
    the subcloud's window (a bridge deck's edge, an embankment), 1.0, else 0.0.

    Gaps narrower than about ``2 close_m`` (cars on the road, sparse sampling) are closed
    first, and enclosed holes (building footprints, the shadow of a deck) filled.
    """
    radius = max(1, int(np.ceil(close_m / cell_m)))
    rr, cc = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    disk = rr ** 2 + cc ** 2 <= radius ** 2
    padded = np.pad(counts > 0, radius, mode="edge")
    covered = ndimage.binary_fill_holes(
        ndimage.binary_closing(padded, structure=disk))[radius:-radius, radius:-radius]
    inner = ndimage.binary_erosion(covered, structure=ndimage.generate_binary_structure(2, 1),
                                   border_value=1)
    return (covered & ~inner).astype(float)


def patch_grid(line_xy: np.ndarray, *, cell_m: float, reach_m: float) -> tuple[Affine, tuple]:
    """North-up grid aligned to multiples of ``cell_m`` covering the map line grown by
    ``reach_m`` (metres); ``(transform, (rows, cols))``."""
    xy = np.asarray(line_xy, float)[:, :2]
    xmin, ymin = np.floor((xy.min(axis=0) - reach_m) / cell_m) * cell_m
    xmax, ymax = np.ceil((xy.max(axis=0) + reach_m) / cell_m) * cell_m
    shape = (int(round((ymax - ymin) / cell_m)), int(round((xmax - xmin) / cell_m)))
    return Affine(cell_m, 0.0, xmin, 0.0, -cell_m, ymax), shape


def _cells(x, y, transform: Affine, shape) -> tuple[np.ndarray, np.ndarray]:
    """Flat cell index of the points inside a north-up grid, and which points those are."""
    rows, cols = shape
    col = np.floor((np.asarray(x) - transform.c) / transform.a).astype(np.int64)
    row = np.floor((np.asarray(y) - transform.f) / transform.e).astype(np.int64)
    inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
    return row[inside] * cols + col[inside], inside


def cell_means(x, y, values, transform: Affine, shape, *, with_counts: bool = False):
    """Mean of ``values`` per cell of a north-up grid, 0 in empty cells (and the number of
    points per cell with ``with_counts``)."""
    rows, cols = shape
    flat, inside = _cells(x, y, transform, shape)
    total = np.bincount(flat, weights=np.asarray(values, float)[inside], minlength=rows * cols)
    count = np.bincount(flat, minlength=rows * cols)
    means = (total / np.maximum(count, 1)).reshape(shape)
    return (means, count.reshape(shape)) if with_counts else means


def kerb_term(x, y, z, transform: Affine, shape) -> np.ndarray:
    """Kerb membership per cell of a north-up grid (:func:`gisroads.features.kerbs.kerb_membership`
    of the steps of the lowest point per cell), 0 where unknown."""
    flat, inside = _cells(x, y, transform, shape)
    lowest = np.full(shape[0] * shape[1], np.inf)
    np.minimum.at(lowest, flat, np.asarray(z, float)[inside])
    lowest[np.isinf(lowest)] = np.nan
    return kerb_membership(kerb_steps(lowest.reshape(shape), abs(transform.a)))


@dataclass(frozen=True)
class AttractorOptions:
    """The options of :func:`attractor_map` (Table 1 of the paper, and the curb term beyond it).

    Attributes
    ----------
    alpha, beta : float
        ``alpha_attr`` and ``beta_attr`` (0.2 and 1, Table 1).
    detector : {"exp", "step", "none"}
        The curb detector's ``f(dh)`` (:func:`curb_response`).
    k_neighbours : int
        Neighbourhood of the PCA normals (>= 20).
    lane_m, min_lanes, max_lanes : float
        The extent term's lane width (metres) and band (:func:`extent_term`).
    drop_off_weight : float
        Curb value given to the edge of the area the points cover (:func:`drop_off_edges`;
        see the module docstring); 0 gives the paper's map.
    kerbs : bool
        The curb term is at least the kerb membership of the ground surface's steps
        (:func:`kerb_term`; see the module docstring); False gives the paper's map.
    """

    alpha: float = ALPHA_ATTR
    beta: float = BETA_ATTR
    detector: str = "exp"
    k_neighbours: int = MIN_NEIGHBOURS
    lane_m: float = LANE_M
    min_lanes: float = 1.0
    max_lanes: float = 6.0
    drop_off_weight: float = DROP_OFF_WEIGHT
    kerbs: bool = True


def attractor_map(points_xyz: np.ndarray, line_xy: np.ndarray, plane_normal=(0.0, 0.0, 1.0),
                  options: AttractorOptions = AttractorOptions(), *, cell_m: float = 0.5,
                  curb=None, crs=None, **changes) -> GeoRaster:
    """Attractor map ``a = alpha e + beta c`` of one road patch on a grid (Sec. 2.3).

    Parameters
    ----------
    points_xyz : ndarray, shape (n, 3)
        The patch's points (metres).
    line_xy : ndarray, shape (k, 2) or (k, 3)
        The patch's map line (its registered samples).
    plane_normal : array_like, shape (3,) or (n, 3)
        Support-plane normal ``n_s`` of the patch, or per point (that of its sample).
    options : AttractorOptions
        Weights, curb detector, extent band and curb additions (:class:`AttractorOptions`).
    cell_m : float
        Grid cell (metres); the grid covers the map line grown by ``max_lanes`` lanes plus
        a cell.
    curb : ndarray, shape (n,), optional
        ``c(p)`` already computed (:func:`curb_response`); computed here otherwise.
    crs : optional
        CRS of the returned raster.
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    GeoRaster
        ``(rows, cols)`` float32; empty cells hold ``alpha e`` only.
    """
    options = replace(options, **changes)
    xyz = np.asarray(points_xyz, float)
    line = np.asarray(line_xy, float)[:, :2]
    if len(line) < 2:
        raise GisroadsError("the map line needs at least two vertices")
    if cell_m <= 0:
        raise GisroadsError("cell_m must be positive")
    reach_m = options.max_lanes * options.lane_m
    transform, shape = patch_grid(line, cell_m=cell_m, reach_m=reach_m + cell_m)
    if curb is None:
        curb = (curb_response(xyz, plane_normal, k_neighbours=options.k_neighbours,
                              detector=options.detector)
                if len(xyz) >= options.k_neighbours else np.zeros(len(xyz)))
    c, counts = cell_means(xyz[:, 0], xyz[:, 1], curb, transform, shape, with_counts=True)
    if options.kerbs and len(xyz):
        c = np.maximum(c, kerb_term(xyz[:, 0], xyz[:, 1], xyz[:, 2], transform, shape))
    rows, cols = shape
    cx = transform.c + (np.arange(cols) + 0.5) * transform.a
    cy = transform.f + (np.arange(rows) + 0.5) * transform.e
    distance = line_distance(cx[None, :], cy[:, None], line)
    e = ((distance >= options.min_lanes * options.lane_m) & (distance <= reach_m)).astype(float)
    if options.drop_off_weight > 0:
        # the subcloud's own cut at its reach is no edge of the surface
        c = np.maximum(c, options.drop_off_weight * drop_off_edges(counts, cell_m)
                       * (distance < reach_m - 1.0))
    return GeoRaster((options.alpha * e + options.beta * c).astype(np.float32), transform, crs)
