"""City blocks from a road-likelihood map: normalized cuts with intervening contours.

Zhu & Mordohai (2009), section 5: the projected ground points are the nodes of a graph,
nodes closer than 80 m are joined, and the weight of an edge is the road likelihood it
crosses, Eq. (9):

    W(i, j) = exp(-max_{(x, y) on the segment i-j} L(x, y)),

so two places with a road between them are barely linked, however close, while a missed
road segment (a gap in L) leaves the two blocks it bounds linked only across the gap: the
normalized cut (:func:`gisroads.segmentation.ncut.ncut`, the project's one NCut) still
prefers to cut there, the narrowest place between two compact blocks. Road likelihood, not
a hard decision on roads, enters the graph.

The stages, each callable alone:

- :func:`road_likelihood`: one likelihood band in the LiDAR pipeline's units (0..L_max)
  from the pipeline's per-width bands or any road-probability raster;
- :func:`block_nodes`: graph nodes on the non-road places, from ground points or a regular
  sample of the raster;
- :func:`max_likelihood_between`: the intervening-contour term, the largest likelihood on
  each straight segment, sampled for all edges at once;
- :func:`block_affinity`: the sparse matrix W of Eq. (9) over node pairs within 80 m;
- :func:`block_segments`: the multiway NCut of W, region by region (groups of nodes that
  no road separates), with the number of blocks from the eigengaps when not given;
- :func:`city_blocks`: all of the above, then polygons: every non-road cell takes the
  segment of its nearest node reached without crossing a road (a watershed of the distance
  to the nodes, restricted to the non-road cells), and each connected region of one
  segment is a block, so blocks stop at the roads.

Reference
---------
Zhu, Q., Mordohai, P. (2009). A minimum cover approach for extracting the road network
from airborne LIDAR data. ICCV Workshops, section 5 and Fig. 6.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import geopandas as gpd
import numpy as np
import shapely
from rasterio import features as rio_features
from scipy import ndimage, sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from skimage.segmentation import watershed

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..progress import Progress, report, scaled
from ..segmentation.ncut import leading_eigenpairs, ncut
from .hypotheses import L_MAX

MAX_EDGE_M = 80.0
"""Nodes closer than this are joined (paper, section 5: 80 m)."""

SAMPLE_SPACING_M = 10.0
"""Spacing of the graph nodes. The paper takes the projected points subsampled; 10 m puts
about a hundred nodes in a 100 m block and some 200 neighbours within 80 m of each node,
a graph of a few thousand nodes per square kilometre."""

ROAD_FRACTION = 0.5
"""A cell is road where its likelihood reaches this fraction of L_max: no node is placed
there and no block covers it."""

MIN_BLOCK_AREA_M2 = 400.0
"""Regions smaller than this (20 m x 20 m) are no block: slivers between roads, traffic
islands, and leftovers of a block cut by a false road."""

EDGE_SAMPLES_PER_CHUNK = 4_000_000
"""Segment samples looked up at a time (about 100 MB of working arrays)."""


def _metres_per_unit(crs) -> float:
    if crs is None:
        raise GisroadsError("the likelihood raster has no CRS; city blocks need a projected "
                            "CRS in metres (or feet) to measure the 80 m neighbourhood")
    if crs.is_geographic:
        raise GisroadsError(f"the likelihood raster is in a geographic CRS ({crs.name}); "
                            "reproject it to a projected CRS in metres")
    return float(crs.axis_info[0].unit_conversion_factor)


def road_likelihood(raster: GeoRaster, *, l_max: float = L_MAX,
                    probability: bool | None = None) -> GeoRaster:
    """One road-likelihood band in [0, ``l_max``], NaN where the raster has no data.

    Parameters
    ----------
    raster : GeoRaster
        ``(rows, cols)`` or ``(bands, rows, cols)``. Several bands, such as the per-width
        maps L_k that ``gisroads lidar --rasters`` writes (``*_likelihood_level_*.tif``),
        are merged by their per-cell maximum: a road is a road whatever its width.
    l_max : float
        The likelihood cap L_max of Eq. (5), above which a cell is surely road (the LiDAR
        pipeline's 25). Values above it are capped.
    probability : bool, optional
        True: the values are a road probability in [0, 1], scaled to [0, ``l_max``] (a
        certain road then weighs like a LiDAR road). False: they are likelihoods in the
        LiDAR pipeline's units. None (default): a probability when every value lies in
        [0, 1], else a likelihood.

    Raises
    ------
    ValueError
        No CRS, a geographic CRS, no valid cell, negative values, or a probability above 1.
    """
    _metres_per_unit(raster.crs)
    data = np.asarray(raster.data, dtype=float)
    if data.ndim == 3:
        data = np.fmax.reduce(data, axis=0) if len(data) else np.full(data.shape[1:], np.nan)
    if data.ndim != 2:
        raise GisroadsError(f"a likelihood raster is (rows, cols) or (bands, rows, cols), "
                            f"got shape {data.shape}")
    valid = np.isfinite(data)
    if not valid.any():
        raise GisroadsError("the likelihood raster has no valid cell (all NaN or nodata)")
    low, high = float(data[valid].min()), float(data[valid].max())
    if low < 0:
        raise GisroadsError(f"a road likelihood is not negative; the raster holds {low:g}")
    if probability is None:
        probability = high <= 1.0
    if probability:
        if high > 1.0:
            raise GisroadsError(f"a road probability lies in [0, 1]; the raster holds {high:g}")
        data = data * l_max
    return GeoRaster(np.minimum(data, l_max), raster.transform, raster.crs)


def _cell_centres(likelihood: GeoRaster, rows, cols) -> np.ndarray:
    t = likelihood.transform
    u, v = np.asarray(cols, float) + 0.5, np.asarray(rows, float) + 0.5
    return np.column_stack([t.a * u + t.b * v + t.c, t.d * u + t.e * v + t.f])


def _pixel_coordinates(likelihood: GeoRaster, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fractional (row, col) of map points, cell centres at whole numbers."""
    inv = ~likelihood.transform
    x, y = xy[:, 0], xy[:, 1]
    return (inv.d * x + inv.e * y + inv.f - 0.5, inv.a * x + inv.b * y + inv.c - 0.5)


def thin_points(points_xy, spacing: float) -> np.ndarray:
    """The point nearest the centre of each ``spacing`` square (CRS units) that holds any.

    Parameters
    ----------
    points_xy : array_like, shape (n, 2) or (n, 3)
        Only x and y are used; rows with a NaN are dropped.

    Returns
    -------
    ndarray, shape (m, 2)
    """
    points = np.asarray(points_xy, dtype=float)
    if points.ndim != 2 or points.shape[1] < 2:
        raise GisroadsError(f"points_xy must be (n, 2), got shape {points.shape}")
    points = points[np.isfinite(points[:, :2]).all(axis=1), :2]
    square = np.floor(points / spacing).astype(np.int64)
    offset = np.linalg.norm(points - (square + 0.5) * spacing, axis=1)
    order = np.lexsort((offset, square[:, 1], square[:, 0]))
    first = np.ones(len(order), bool)
    first[1:] = (np.diff(square[order], axis=0) != 0).any(axis=1)
    return points[order[first]]


def block_nodes(likelihood: GeoRaster, *, points_xy=None,
                sample_spacing_m: float = SAMPLE_SPACING_M,
                road_threshold: float = ROAD_FRACTION * L_MAX) -> np.ndarray:
    """Graph nodes: places off the roads, about ``sample_spacing_m`` apart.

    Parameters
    ----------
    likelihood : GeoRaster
        One band (:func:`road_likelihood`).
    points_xy : array_like, shape (n, 2), optional
        Projected ground points in the raster's CRS, as in the paper; thinned to the one
        nearest the centre of each ``sample_spacing_m`` square. Default: the centres of a
        regular grid of that spacing over the raster.
    sample_spacing_m : float
        Node spacing, metres.
    road_threshold : float
        Cells at or above this likelihood are road and get no node.

    Returns
    -------
    ndarray, shape (m, 2)
        Node coordinates (x, y) in the raster's CRS, on valid non-road cells only.
    """
    if not sample_spacing_m > 0:
        raise GisroadsError(f"sample_spacing_m must be positive, got {sample_spacing_m}")
    spacing = sample_spacing_m / _metres_per_unit(likelihood.crs)
    values = np.asarray(likelihood.data, float)
    rows_n, cols_n = values.shape
    if points_xy is None:
        step = max(1, int(round(spacing / likelihood.pixel_size)))
        rows, cols = np.meshgrid(np.arange(step // 2, rows_n, step),
                                 np.arange(step // 2, cols_n, step), indexing="ij")
        xy = _cell_centres(likelihood, rows.ravel(), cols.ravel())
    else:
        xy = thin_points(points_xy, spacing)
    row, col = (np.rint(c).astype(np.int64) for c in _pixel_coordinates(likelihood, xy))
    inside = (row >= 0) & (row < rows_n) & (col >= 0) & (col < cols_n)
    xy, row, col = xy[inside], row[inside], col[inside]
    value = values[row, col]
    return xy[np.isfinite(value) & (value < road_threshold)]


def max_likelihood_between(likelihood: GeoRaster, start_xy, end_xy, *,
                           progress: Progress = None) -> np.ndarray:
    """The largest likelihood on each straight segment: the intervening contour of Eq. (9).

    Every segment is sampled at least once per pixel (nearest cell) from end to end; all
    segments are sampled at once on an (edges, samples) grid through
    ``scipy.ndimage.map_coordinates``, in chunks of similar length. NaN cells count as 0
    (no evidence of a road); samples off the raster take the nearest edge cell.

    Parameters
    ----------
    likelihood : GeoRaster
        One band.
    start_xy, end_xy : array_like, shape (e, 2)
        Segment ends in the raster's CRS.

    Returns
    -------
    ndarray, shape (e,)
    """
    values = np.nan_to_num(np.asarray(likelihood.data, float), nan=0.0)
    start = np.asarray(start_xy, float).reshape(-1, 2)
    end = np.asarray(end_xy, float).reshape(-1, 2)
    if start.shape != end.shape:
        raise GisroadsError(f"{len(start)} segment starts but {len(end)} ends")
    r0, c0 = _pixel_coordinates(likelihood, start)
    r1, c1 = _pixel_coordinates(likelihood, end)
    n_samples = np.ceil(np.hypot(r1 - r0, c1 - c0)).astype(np.int64) + 2
    order = np.argsort(n_samples, kind="stable")
    strongest = np.empty(len(start))
    done = 0
    while done < len(order):
        # one chunk: the next edges by length, as many as fit the sample budget (sorted by
        # length, so the second bound, by the longest of the first guess, is safe)
        size = max(1, EDGE_SAMPLES_PER_CHUNK // int(n_samples[order[done]]))
        longest = n_samples[order[min(done + size, len(order)) - 1]]
        size = max(1, min(size, EDGE_SAMPLES_PER_CHUNK // int(longest), len(order) - done))
        chunk = order[done:done + size]
        samples = int(n_samples[chunk].max())
        t = np.linspace(0.0, 1.0, samples)[None, :]
        rows = r0[chunk, None] + t * (r1 - r0)[chunk, None]
        cols = c0[chunk, None] + t * (c1 - c0)[chunk, None]
        sampled = ndimage.map_coordinates(values, [rows.ravel(), cols.ravel()], order=0,
                                          mode="nearest")
        strongest[chunk] = sampled.reshape(len(chunk), samples).max(axis=1)
        done += size
        report(progress, done / len(order), "intervening likelihood")
    return strongest


def block_affinity(likelihood: GeoRaster, nodes_xy, *, max_edge_m: float = MAX_EDGE_M,
                   progress: Progress = None) -> sparse.csr_matrix:
    """W of Eq. (9): ``exp(-max L on the segment)`` for node pairs closer than ``max_edge_m``.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (m, m)
        Symmetric, no diagonal.
    """
    if not max_edge_m > 0:
        raise GisroadsError(f"max_edge_m must be positive, got {max_edge_m}")
    nodes = np.asarray(nodes_xy, float)
    radius = max_edge_m / _metres_per_unit(likelihood.crs)
    pairs = cKDTree(nodes).query_pairs(radius, output_type="ndarray")
    weight = np.exp(-max_likelihood_between(likelihood, nodes[pairs[:, 0]], nodes[pairs[:, 1]],
                                            progress=progress))
    n = len(nodes)
    return sparse.csr_matrix((np.concatenate([weight, weight]),
                              (np.concatenate([pairs[:, 0], pairs[:, 1]]),
                               np.concatenate([pairs[:, 1], pairs[:, 0]]))), shape=(n, n))


MAX_BLOCKS_PER_REGION = 12
"""At most this many blocks in one region of nodes that no road separates (a region is
a group of blocks joined through missed road segments)."""


def block_segments(affinity, *, road_weight: float, n_blocks: int | None = None,
                   seed: int = 0) -> np.ndarray:
    """Multiway normalized cut of W into blocks, with the number of blocks from eigengaps.

    Edges that cross a road (weight at most ``road_weight``) couple the groups of nodes
    they join by almost nothing, so W is block diagonal to that precision over the
    *regions* that the other edges connect. The k-way normalized cut of such a graph cuts
    within the regions, and its spectrum is the union of theirs; so each region is cut
    alone by :func:`gisroads.segmentation.ncut.ncut`, into ``k_r`` blocks:

    - ``n_blocks`` None: ``k_r`` is the position of the largest gap among the region's
      leading eigenvalues of ``D^-1/2 W D^-1/2`` (von Luxburg 2007's eigengap heuristic,
      searched up to :data:`MAX_BLOCKS_PER_REGION`). A region that is one block has
      eigenvalues 1 then a steep drop (a 100 m block at 10 m node spacing: 1, 0.23); two
      blocks joined through a missed road segment have a second eigenvalue well above
      the rest (1, 0.78, 0.36 on the test grid);
    - ``n_blocks`` given: the regions share it as the top ``n_blocks`` eigenvalues of the
      whole graph fall among them, one block at least per region.

    Cutting regions alone is also what makes the cut reliable: one eigenproblem over the
    whole graph has the eigenvalue 1 once per region, a cluster that the eigensolver and
    the discretisation resolve badly (on a road-area raster of fusa, segments straddled
    regions and a 250 m open area came out in five pieces), and costs far more (a 1 km grid
    of 81 blocks: 45 s instead of a few).

    Parameters
    ----------
    affinity : scipy.sparse matrix, shape (m, m)
        W of :func:`block_affinity`.
    road_weight : float
        ``exp(-road threshold)``.
    n_blocks : int, optional
        Total number of NCut segments; raised to the number of regions if below it.
    seed : int
        See :func:`gisroads.segmentation.ncut.ncut`.

    Returns
    -------
    ndarray of int64, shape (m,)
        Segment of every node, numbered region by region from 0 (a segment that NCut's
        discretisation leaves empty leaves its number unused).
    """
    weights = sparse.csr_matrix(affinity, dtype=float)
    strong = weights.multiply(weights > road_weight).tocsr()
    n_regions, region = connected_components(strong, directed=False)
    regions = np.split(np.argsort(region, kind="stable"),
                       np.cumsum(np.bincount(region, minlength=n_regions))[:-1])
    spectra = []  # leading eigenvalues per region; 1 alone for regions too small to cut
    for members in regions:
        if len(members) < 4:
            spectra.append(np.ones(1))
        else:
            values, _ = leading_eigenpairs(weights[members][:, members],
                                           min(len(members) - 2, MAX_BLOCKS_PER_REGION + 1),
                                           seed=seed)
            spectra.append(values[::-1])
    if n_blocks is None:
        counts = [1 if len(ev) < 2 else int(np.argmax(ev[:-1] - ev[1:])) + 1
                  for ev in spectra]
    else:
        # beyond each region's first block, the largest remaining eigenvalues win
        extra = np.concatenate([ev[1:] for ev in spectra])
        owner = np.concatenate([np.full(len(ev) - 1, r) for r, ev in enumerate(spectra)])
        chosen = np.argsort(-extra, kind="stable")[:max(n_blocks - n_regions, 0)]
        counts = 1 + np.bincount(owner[chosen], minlength=n_regions)
    segment = np.empty(weights.shape[0], np.int64)
    offset = 0
    for members, k in zip(regions, counts):
        segment[members] = offset + ncut(weights[members][:, members], int(k), seed=seed)
        offset += int(k)
    return segment


@dataclass(frozen=True)
class BlockOptions:
    """The options of :func:`city_blocks` (section 5 of the paper): the graph's nodes and
    edges, the number of segments, how the likelihood is read and the smallest block.

    Attributes
    ----------
    sample_spacing_m : float
        Node spacing, metres (:data:`SAMPLE_SPACING_M`).
    max_edge_m : float
        Nodes closer than this are joined, metres (paper: 80 m).
    n_blocks : int, optional
        NCut segments ``k``. Default: from the largest eigengap of each region that no
        road cuts (:func:`block_segments`).
    l_max, probability
        See :func:`road_likelihood`.
    road_fraction : float
        Cells with a likelihood of at least ``road_fraction * l_max`` are road: they get no
        node and no block.
    min_block_area_m2 : float
        Smaller regions are dropped (:data:`MIN_BLOCK_AREA_M2`).
    seed : int
        Seed of NCut's eigensolver and discretisation: the result is deterministic.
    """

    sample_spacing_m: float = SAMPLE_SPACING_M
    max_edge_m: float = MAX_EDGE_M
    n_blocks: int | None = None
    l_max: float = L_MAX
    probability: bool | None = None
    road_fraction: float = ROAD_FRACTION
    min_block_area_m2: float = MIN_BLOCK_AREA_M2
    seed: int = 0


def city_blocks(likelihood: GeoRaster, options: BlockOptions = BlockOptions(), *,
                points_xy=None, progress: Progress = None, **changes) -> gpd.GeoDataFrame:
    """City blocks of a road-likelihood raster (Zhu & Mordohai, section 5).

    Nodes off the roads (:func:`block_nodes`), edges within ``max_edge_m`` weighted by
    Eq. (9) (:func:`block_affinity`), a multiway normalized cut (:func:`block_segments`
    over :func:`gisroads.segmentation.ncut.ncut`), then polygons: the non-road cells are
    flooded from the nodes in order of the distance to the nearest node (``skimage``
    watershed with the road cells masked out), so each cell takes the segment of its
    nearest node reached without crossing a road; every connected region of one segment
    of at least ``min_block_area_m2`` is a block.

    Parameters
    ----------
    likelihood : GeoRaster
        Road likelihood: the LiDAR pipeline's per-width maps (maximum over the bands) or
        any road-probability raster, see :func:`road_likelihood` for ``l_max`` and
        ``probability``. A projected CRS is required.
    points_xy : array_like, shape (n, 2), optional
        Projected ground points in the raster's CRS (the paper's nodes), thinned to one per
        ``sample_spacing_m`` square; blocks then cover only cells within two spacings of a
        node (no block where the cloud has no ground). Default: a regular sample of the
        raster, and blocks cover every valid non-road cell.
    options : BlockOptions
        Graph, segments and blocks (:class:`BlockOptions`).
    progress : callable, optional
        ``progress(fraction, message)``; raising :class:`gisroads.progress.Cancelled` stops.
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    GeoDataFrame
        Layer ``city_blocks``: Polygon (with holes where the roads or no-data leave them);
        ``block_id`` (numbered north to south, then west to east, from 0), ``segment`` (the
        NCut segment; a segment cut in several pieces by roads gives several blocks),
        ``area_m2``, ``perimeter_m``; in the raster's CRS.

    Raises
    ------
    ValueError
        A raster without CRS, in a geographic CRS, with no valid cell or no non-road
        cell; non-positive spacing or edge length; ``n_blocks < 1``.

    Examples
    --------
    The blocks of a synthetic scene's road areas, rasterised at 1 m as a probability:

    >>> import shapely
    >>> from affine import Affine
    >>> from rasterio.features import rasterize
    >>> from gisroads.geo import GeoRaster
    >>> from gisroads.lidar import city_blocks
    >>> from gisroads.synthetic import make_scene
    >>> scene = make_scene(seed=1, size_m=(300, 300))
    >>> x0, y0, x1, y1 = scene.extent
    >>> transform = Affine(1.0, 0.0, x0, 0.0, -1.0, y1)       # 1 m cells, north up
    >>> roads = rasterize(scene.truth.polygons.geometry, out_shape=(300, 300),
    ...                   transform=transform)
    >>> blocks = city_blocks(GeoRaster(roads.astype("float32"), transform, scene.crs))
    >>> list(blocks.columns)
    ['block_id', 'segment', 'area_m2', 'perimeter_m', 'geometry']
    >>> len(blocks) >= 10
    True
    >>> lines = scene.truth.centrelines.geometry.values      # no block crosses a road
    >>> inside = shapely.intersection(lines, shapely.union_all(blocks.geometry.values))
    >>> bool(shapely.length(inside).sum() < 0.01 * shapely.length(lines).sum())
    True
    """
    options = replace(options, **changes)
    if options.n_blocks is not None and options.n_blocks < 1:
        raise GisroadsError(f"n_blocks must be at least 1, got {options.n_blocks}")
    if not 0 < options.road_fraction <= 1:
        raise GisroadsError(f"road_fraction must lie in (0, 1], got {options.road_fraction}")
    report(progress, 0.0, "road likelihood")
    band = road_likelihood(likelihood, l_max=options.l_max, probability=options.probability)
    threshold = options.road_fraction * options.l_max
    unit = _metres_per_unit(band.crs)
    nodes = block_nodes(band, points_xy=points_xy, sample_spacing_m=options.sample_spacing_m,
                        road_threshold=threshold)
    if len(nodes) < 2:
        raise GisroadsError(f"only {len(nodes)} node(s) off the roads: the likelihood marks "
                            f"(nearly) everything as road (>= {threshold:g}), or no point of "
                            "points_xy lies on the raster")
    report(progress, 0.05, f"{len(nodes)} nodes: affinities")
    affinity = block_affinity(band, nodes, max_edge_m=options.max_edge_m,
                              progress=scaled(progress, 0.05, 0.6))
    report(progress, 0.6, "normalized cut")
    segment = block_segments(affinity, road_weight=np.exp(-threshold), n_blocks=options.n_blocks,
                             seed=options.seed)
    report(progress, 0.8, f"{segment.max() + 1} segments: polygons")
    return _block_polygons(band, nodes, segment, threshold=threshold,
                           reach=None if points_xy is None else 2 * options.sample_spacing_m / unit,
                           min_area=options.min_block_area_m2 / unit ** 2, unit=unit)


def _block_polygons(band: GeoRaster, nodes: np.ndarray, segment: np.ndarray, *,
                    threshold: float, reach: float | None, min_area: float,
                    unit: float) -> gpd.GeoDataFrame:
    values = np.asarray(band.data, float)
    land = np.isfinite(values) & (values < threshold)
    row, col = (np.rint(c).astype(np.int64) for c in _pixel_coordinates(band, nodes))
    markers = np.zeros(values.shape, np.int32)
    markers[row, col] = segment + 1
    distance = ndimage.distance_transform_edt(markers == 0)
    if reach is not None:
        land &= distance * band.pixel_size <= reach
    # flooding by the distance to the nearest node: every cell takes the segment of its
    # nearest node, or of the nearest one reachable around the roads (flooding by the
    # likelihood instead drew the cut across a missed road segment along its noise)
    flooded = watershed(distance, markers, mask=land)
    shapes = [(shapely.geometry.shape(geom), int(value)) for geom, value in
              rio_features.shapes(flooded, mask=flooded > 0, connectivity=4,
                                  transform=band.transform)]
    geoms = np.array([g for g, _ in shapes], dtype=object)
    segments = np.array([v - 1 for _, v in shapes], dtype=np.int64)
    keep = shapely.area(geoms) >= min_area if len(geoms) else np.zeros(0, bool)
    geoms, segments = geoms[keep], segments[keep]
    centroid = shapely.get_coordinates(shapely.centroid(geoms)) if len(geoms) else \
        np.zeros((0, 2))
    order = np.lexsort((centroid[:, 0], -centroid[:, 1]))
    geoms, segments = geoms[order], segments[order]
    return gpd.GeoDataFrame(
        {"block_id": np.arange(len(geoms), dtype=np.int64), "segment": segments,
         "area_m2": shapely.area(geoms) * unit ** 2 if len(geoms) else np.zeros(0),
         "perimeter_m": shapely.length(geoms) * unit if len(geoms) else np.zeros(0)},
        geometry=gpd.GeoSeries(geoms, crs=band.crs), crs=band.crs)
