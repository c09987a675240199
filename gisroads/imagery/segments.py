"""Initial over-segmentation of an aerial image by normalized cuts (Grote & Rottensteiner
2010, section 2.1.1), and the segments as a polygon layer and back.

The paper cuts a graph of pixels whose weights combine colour similarity and the strength of
edges between the pixels (Grote et al. 2007), lowered by a factor ``0 < w_NDVI << 1`` between
pixels on opposite sides of an NDVI threshold when a near-infrared band is available. The
over-segmentation must be fine enough that most road borders are segment borders; the
grouping stage (:mod:`gisroads.imagery.grouping`) merges the pieces again.

What makes it tractable
    A full-pixel NCut of a 1000 x 1000 image is a million-node eigenproblem. The paper keeps
    the weight matrix sparse (local neighbourhoods); we go one step further and cut the
    graph of SLIC superpixels of :func:`gisroads.segmentation.ncut.superpixel_graph` (a few
    pixels to a few metres across, following intensity edges), with the weights of
    :func:`gisroads.segmentation.ncut.ncut_segmentation`: border length x colour similarity
    x intervening-edge term, times ``w_NDVI`` (its ``extra_affinity``) across the NDVI
    threshold. Beyond the paper, a learned road probability (:mod:`gisroads.learn`) adds the
    factor ``exp(-(p_i - p_j)^2 / sigma_P^2)`` of the superpixels' mean probabilities
    (:func:`gisroads.segmentation.ncut.value_affinity`), so segment borders follow the
    borders between road and non-road as the model sees them, where the colours of a road
    and its neighbour (a dark roof, a shadow) are alike. An over-segmentation needs
    thousands of segments, and the cost of the eigenvectors grows with the cube of the nodes
    and the number of segments, so the superpixel graph is cut patch-wise: superpixels are
    grouped into square patches of about :data:`SUPERPIXELS_PER_PATCH` nodes by their
    centroids and each patch gets its own NCut (a dense eigenproblem of a few hundred nodes,
    milliseconds) into its share of the segments, with the colour and edge scales
    ``sigma_I``, ``sigma_E`` of the whole image. Each NCut is a genuine normalized cut of
    its patch; patch borders add a few segment borders along superpixel borders, which the
    grouping removes where nothing separates the two sides.

Defaults scale with the pixel size: the paper's images have 8-10 cm pixels
(:data:`PAPER_PIXEL_M`); segments of :data:`SEGMENT_AREA_M2` (about a road width squared)
and superpixels of :data:`SUPERPIXEL_AREA_M2` keep the same ground size at any resolution,
down to :data:`MIN_SEGMENT_PX` and :data:`MIN_SUPERPIXEL_PX` pixels on coarse images.

References
----------
Grote, A., Rottensteiner, F. (2010). Automatic road network extraction in suburban areas from
high resolution aerial images. PCV 2010, IAPRS 38 (3A), section 2.1.1.
Grote, A., Butenuth, M., Heipke, C. (2007). Road extraction in suburban areas based on
normalized cuts. PIA07, IAPRS 36 (3/W49A).
"""
from __future__ import annotations

import geopandas as gpd
import numpy as np
from pyproj import CRS
from scipy import ndimage, sparse
from skimage.measure import label as connected_regions

from ..errors import GisroadsError
from ..features.edges import local_energy
from ..geo import GeoRaster
from ..progress import report
from ..parallel import pinned_threads
from ..segmentation.ncut import (intervening_edge_strength, ncut_segmentation,
                                 superpixel_graph, typical_scale, value_affinity)
from ..vectorize.regions import segment_polygons
from .cues import ndvi, scale_bands, valid_mask, visible_mean
from .roadparts import rasterize_segments

PAPER_PIXEL_M = 0.1
"""Ground sampling distance of the paper's images (Grangemouth 10 cm, Vaihingen 8 cm)."""
SEGMENT_AREA_M2 = 36.0
"""Default ground area of one initial segment, 6 m x 6 m (3600 pixels at the paper's 10 cm):
about a road's width squared, so a road is several segments long and one or two wide."""
SUPERPIXEL_AREA_M2 = 9.0
"""Default ground area of one superpixel, 3 m x 3 m: four per segment, so that segment
borders have superpixel borders to choose from."""
MIN_SEGMENT_PX = 100
"""Smallest default segment, pixels (10 x 10), on coarse images."""
MIN_SUPERPIXEL_PX = 25
"""Smallest default superpixel, pixels (5 x 5): SLIC needs a few pixels per superpixel."""
SUPERPIXELS_PER_PATCH = 250
"""Nodes per patch-wise NCut (module docstring): a dense eigenproblem of this size takes a
few tens of milliseconds."""
NDVI_THRESHOLD = 0.2
"""Default NDVI threshold between vegetation and the rest; the paper adapts it per data set
(section 4). Grass and foliage lie above 0.3, asphalt, roofs and shadow below 0.1."""
W_NDVI = 0.01
"""Default factor on the weights across the NDVI threshold, ``0 < w_NDVI << 1``."""
SIGMA_P = 0.2
"""Default ``sigma_P`` of the road-probability term (beyond the paper): adjacent superpixels
whose mean learned road probabilities differ by 0.2 keep 1/e of their weight, by 0.4 2 %;
probability noise within a surface (differences under 0.1) costs less than a quarter."""


def pixel_size_m(raster: GeoRaster) -> float:
    """Side of a pixel in metres: CRS units times their metre factor; for a geographic CRS
    the degrees of latitude are converted at 111,320 m per degree (a default-sizing
    approximation only)."""
    size = raster.pixel_size
    if raster.crs is None:
        return size
    crs = CRS.from_user_input(raster.crs)
    if crs.is_geographic:
        return size * 111_320.0
    return size * float(crs.axis_info[0].unit_conversion_factor)


def default_counts(raster: GeoRaster) -> tuple[int, int]:
    """Default ``(n_segments, n_superpixels)`` of :func:`segment_image` for a raster."""
    valid_px = int(valid_mask(raster).sum())
    pixel_area = pixel_size_m(raster) ** 2
    segment_px = max(SEGMENT_AREA_M2 / pixel_area, MIN_SEGMENT_PX)
    superpixel_px = max(SUPERPIXEL_AREA_M2 / pixel_area, MIN_SUPERPIXEL_PX)
    return max(1, round(valid_px / segment_px)), max(1, round(valid_px / superpixel_px))


def ndvi_affinity(adjacency, superpixel_ndvi: np.ndarray, *,
                  ndvi_threshold: float = NDVI_THRESHOLD,
                  w_ndvi: float = W_NDVI) -> sparse.csr_matrix:
    """The NDVI factor of the paper as an ``extra_affinity`` of ``ncut_segmentation``.

    Parameters
    ----------
    adjacency : scipy.sparse matrix, shape (n, n)
        The superpixel adjacency of :func:`~gisroads.segmentation.ncut.superpixel_graph`.
    superpixel_ndvi : ndarray, shape (n,)
        Mean NDVI of each superpixel (NaN: no NIR data, never across the threshold).
    ndvi_threshold : float
    w_ndvi : float
        ``0 < w_NDVI <= 1``; applied to adjacent superpixels whose mean NDVI lies on
        opposite sides of the threshold. (The paper applies it per pixel pair; over
        superpixels, each superpixel's mean decides its side.)

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, n)
        ``w_ndvi`` at such pairs, no entry elsewhere.
    """
    if not 0 < w_ndvi <= 1:
        raise GisroadsError(f"w_ndvi must lie in (0, 1], got {w_ndvi}")
    pairs = sparse.triu(sparse.csr_matrix(adjacency), k=1).tocoo()
    vegetation = np.asarray(superpixel_ndvi) > ndvi_threshold
    across = vegetation[pairs.row] != vegetation[pairs.col]
    rows = np.concatenate([pairs.row[across], pairs.col[across]])
    cols = np.concatenate([pairs.col[across], pairs.row[across]])
    return sparse.csr_matrix((np.full(len(rows), float(w_ndvi)), (rows, cols)),
                             shape=adjacency.shape)


def edge_strength(image: GeoRaster, *, nir_band: int | None = None,
                  bands: np.ndarray | None = None) -> np.ndarray:
    """Edge magnitude of an image for the segmentation and grouping stages: the local energy
    (:func:`gisroads.features.edges.local_energy`) of its intensity, the mean of the
    stretched bands without the NIR band (:func:`gisroads.imagery.cues.intensity`).

    ``bands``: the image's :func:`~gisroads.imagery.cues.scale_bands`, when already at hand.
    """
    if bands is None:
        bands = scale_bands(image)
    return local_energy(visible_mean(bands, nir_band))[0]


def _checked_edges(edge_magnitude, shape) -> np.ndarray:
    edges = np.asarray(edge_magnitude, dtype=float)
    if edges.shape != tuple(shape):
        raise GisroadsError(f"edge_magnitude {edges.shape} and image {tuple(shape)} differ in "
                            "shape")
    return edges


def _node_means(superpixels: np.ndarray, values: np.ndarray, n_nodes: int) -> np.ndarray:
    """Mean of the finite ``values`` over each superpixel (NaN where it has none)."""
    inside = superpixels >= 0
    ids, values = superpixels[inside], values[inside]
    finite = np.isfinite(values)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (np.bincount(ids[finite], values[finite], minlength=n_nodes)
                / np.bincount(ids[finite], minlength=n_nodes))


def _patches(centroid: np.ndarray, shape: tuple[int, int], n_patches: int) -> np.ndarray:
    """Patch index of every superpixel: a grid of about ``n_patches`` square cells."""
    rows, cols = shape
    side = np.sqrt(rows * cols / max(n_patches, 1))
    grid_rows, grid_cols = max(1, round(rows / side)), max(1, round(cols / side))
    r = np.minimum((centroid[:, 0] / rows * grid_rows).astype(int), grid_rows - 1)
    c = np.minimum((centroid[:, 1] / cols * grid_cols).astype(int), grid_cols - 1)
    return r * grid_cols + c


def segment_image(image: GeoRaster, *, nir_band: int | None = None,
                  red_band: int | None = None, n_segments: int | None = None,
                  n_superpixels: int | None = None, ndvi_threshold: float = NDVI_THRESHOLD,
                  w_ndvi: float = W_NDVI, edge_magnitude=None, probability=None,
                  sigma_p: float = SIGMA_P, seed: int = 0, progress=None) -> np.ndarray:
    """Over-segment an aerial image by normalized cuts (paper section 2.1.1).

    Colour similarity uses every band of the image stretched to [0, 1]
    (:func:`gisroads.imagery.cues.scale_bands`), so RGB, CIR (NIR as a colour channel, as in
    the paper) and single-band panchromatic images work alike. Intervening edges are the
    local energy (:func:`gisroads.features.edges.local_energy`) of the intensity (the mean of
    the non-NIR bands). With ``nir_band``, weights between superpixels on opposite sides of
    ``ndvi_threshold`` are multiplied by ``w_ndvi``. The module docstring says how the cut is
    made tractable (superpixel graph, patch-wise NCut).

    Parameters
    ----------
    image : GeoRaster
        ``(rows, cols)`` or ``(bands, rows, cols)``; NaN cells and cells equal to
        ``image.nodata`` in every band are no data.
    nir_band, red_band : int, optional
        1-based band numbers (GDAL/QGIS convention); the red band defaults to
        :func:`gisroads.imagery.cues.default_red_band` (band 2 of a CIR image whose NIR is
        band 1, else band 1).
    n_segments : int, optional
        Target number of segments (the over-segmentation size). Default: one per
        :data:`SEGMENT_AREA_M2` of valid ground, at least :data:`MIN_SEGMENT_PX` pixels each.
        The result can hold somewhat more: segments split by no-data or patch borders are
        separate regions.
    n_superpixels : int, optional
        Graph nodes. Default: one per :data:`SUPERPIXEL_AREA_M2`, at least
        :data:`MIN_SUPERPIXEL_PX` pixels each; never fewer than ``2 * n_segments``.
    ndvi_threshold : float
        NDVI separating vegetation from the rest (used with ``nir_band`` only).
    w_ndvi : float
        ``0 < w_NDVI << 1``, the factor across the threshold (1 disables it).
    edge_magnitude : array_like, shape (rows, cols), optional
        Edge strength for the intervening-edge term; default: :func:`edge_strength` (pass
        it to share one computation with :func:`gisroads.imagery.grouping.group_segments`).
    probability : array_like, shape (rows, cols), optional
        A learned road probability in [0, 1] on the image grid (beyond the paper; NaN: no
        value); adds the factor ``exp(-(p_i - p_j)^2 / sigma_P^2)`` of the superpixels'
        mean probabilities to the weights.
    sigma_p : float
        ``sigma_P`` of that factor, probability units (:data:`SIGMA_P`).
    seed : int
        Seed of the eigensolver and discretisation: same seed, same segments.
    progress : callable, optional
        ``progress(fraction, message)``; may raise :class:`gisroads.progress.Cancelled`.

    Returns
    -------
    labels : ndarray of int32, shape (rows, cols)
        Segments ``0..m-1``, each one 4-connected region; -1 on no-data cells.

    Raises
    ------
    ValueError
        No valid pixel, a band number that does not exist, ``w_ndvi`` outside (0, 1], or
        ``n_segments`` below 1.
    """
    valid = valid_mask(image)
    if not valid.any():
        raise GisroadsError("the image has no valid pixel")
    default_segments, default_superpixels = default_counts(image)
    n_segments = default_segments if n_segments is None else int(n_segments)
    if n_segments < 1:
        raise GisroadsError(f"n_segments must be at least 1, got {n_segments}")
    n_superpixels = default_superpixels if n_superpixels is None else int(n_superpixels)
    n_superpixels = max(n_superpixels, 2 * n_segments)

    if not 0 < w_ndvi <= 1:
        raise GisroadsError(f"w_ndvi must lie in (0, 1], got {w_ndvi}")
    report(progress, 0.0, "edges")
    bands = scale_bands(image)
    edges = (edge_strength(image, nir_band=nir_band, bands=bands) if edge_magnitude is None
             else _checked_edges(edge_magnitude, image.shape))
    vegetation_index = None if nir_band is None else ndvi(image, nir_band, red_band)
    report(progress, 0.15, "superpixels")
    superpixels, adjacency, features = superpixel_graph(bands, n_superpixels=n_superpixels,
                                                        mask=~valid)
    n_nodes = adjacency.shape[0]
    report(progress, 0.4, "normalized cuts")

    # sigma_I and sigma_E of the whole image (ncut_segmentation's median rule), so that
    # every patch weighs colour and edges alike
    pairs = sparse.triu(adjacency, k=1).tocoo()
    mean = features["mean"].reshape(n_nodes, -1)
    sigma_intensity = typical_scale(np.linalg.norm(mean[pairs.row] - mean[pairs.col], axis=1))
    sigma_edge = typical_scale(sparse.triu(intervening_edge_strength(superpixels, adjacency,
                                                                edges), k=1).tocoo().data)
    extra = []
    if vegetation_index is not None and w_ndvi < 1:
        extra.append(ndvi_affinity(adjacency, _node_means(superpixels, vegetation_index, n_nodes),
                                   ndvi_threshold=ndvi_threshold, w_ndvi=w_ndvi))
    if probability is not None:
        probability = np.asarray(probability, dtype=float)
        if probability.shape != image.shape:
            raise GisroadsError(f"probability {probability.shape} and image {image.shape} "
                                "differ in shape")
        extra.append(value_affinity(adjacency, _node_means(superpixels, probability, n_nodes),
                                    sigma_p))

    n_patches = max(1, round(n_nodes / SUPERPIXELS_PER_PATCH))
    patch_of = _patches(features["centroid"], superpixels.shape, n_patches)
    used_patches = np.unique(patch_of)
    boxes = ndimage.find_objects(superpixels + 1)  # superpixel i is boxes[i]
    labels = np.full(superpixels.shape, -1, np.int32)
    next_label = 0
    # one thread: the patches' eigenproblems are small (see pinned_threads)
    with pinned_threads(1):
        for done, patch in enumerate(used_patches):
            nodes = np.flatnonzero(patch_of == patch)
            local_id = np.full(n_nodes + 1, -1, np.int32)  # index -1 (no superpixel) stays -1
            local_id[nodes] = np.arange(len(nodes))
            window = tuple(slice(min(boxes[i][axis].start for i in nodes),
                                 max(boxes[i][axis].stop for i in nodes)) for axis in (0, 1))
            local = local_id[superpixels[window]]
            k = max(1, round(n_segments * len(nodes) / n_nodes))
            patch_extra = [factor[nodes][:, nodes] for factor in extra]
            patch_labels = ncut_segmentation(bands[(slice(None),) + window], n_segments=k,
                                             superpixels=local, edge_magnitude=edges[window],
                                             sigma_intensity=sigma_intensity,
                                             sigma_edge=sigma_edge, extra_affinity=patch_extra,
                                             seed=seed)
            inside = local >= 0
            labels[window][inside] = patch_labels[inside] + next_label
            next_label += int(patch_labels.max()) + 1
            report(progress, 0.4 + 0.6 * (done + 1) / len(used_patches), "normalized cuts")
    return (connected_regions(labels, background=-1, connectivity=1) - 1).astype(np.int32)


def segments_to_frame(labels, raster: GeoRaster) -> gpd.GeoDataFrame:
    """Segments as polygons (pixel outlines) with their ``segment_id``.

    Parameters
    ----------
    labels : ndarray of int, shape (rows, cols)
        Segments ``>= 0``, -1 for no segment.
    raster : GeoRaster
        The grid of ``labels`` (its transform and CRS place the polygons).

    Returns
    -------
    GeoDataFrame
        One (Multi)Polygon per label present, ``segment_id`` (int64) = the label, and
        ``area_px``; ordered by ``segment_id``.
    """
    labels = np.asarray(labels)
    if labels.shape != raster.shape:
        raise GisroadsError(f"labels {labels.shape} and raster {raster.shape} differ in shape")
    present = np.unique(labels[labels >= 0])
    compact = np.full(labels.shape, -1, np.int32)
    compact[labels >= 0] = np.searchsorted(present, labels[labels >= 0])
    polygons = segment_polygons(compact, len(present), raster.transform) if len(present) else []
    area = np.bincount(compact[compact >= 0], minlength=len(present))
    return gpd.GeoDataFrame({"segment_id": present.astype(np.int64),
                             "area_px": area.astype(np.int64)},
                            geometry=gpd.GeoSeries(list(polygons), crs=raster.crs),
                            crs=raster.crs)


def frame_to_labels(frame: gpd.GeoDataFrame, raster: GeoRaster, *,
                    id_column: str = "segment_id") -> np.ndarray:
    """A segment layer (from :func:`segments_to_frame`, perhaps edited in QGIS) burnt back
    into labels on ``raster``'s grid, each segment one 4-connected region.

    Pixels are burnt by their centres with the polygons' ``id_column``
    (:func:`gisroads.imagery.roadparts.rasterize_segments`); a segment an edit left in
    several pieces becomes several segments, and the result is renumbered ``0..m-1`` in
    raster order, as :func:`segment_image` returns it. -1 outside every polygon.
    """
    burnt = rasterize_segments(frame, raster, id_column=id_column)
    return (connected_regions(burnt, background=-1, connectivity=1) - 1).astype(np.int32)
