"""Normalized cuts (Shi & Malik 2000) on graphs and, over superpixels, on images.

One implementation serves the three users in this project:

- Zhu & Mordohai's LiDAR pipeline over-segments the 0.5 m ground-intensity image into
  100-200 regions "using intensity similarity as the only feature" (section 4.3):
  :func:`ncut_segmentation` without ``edge_magnitude``;
- Grote & Rottensteiner's imagery pipeline segments colour with the strength of intervening
  edges and a factor ``0 < w_NDVI << 1`` between pixels on opposite sides of an NDVI
  threshold (section 2.1.1): :func:`ncut_segmentation` with a multi-band image,
  ``edge_magnitude`` and ``extra_affinity`` (built on :func:`superpixel_graph`'s adjacency;
  beyond the paper, :func:`value_affinity` of a learned road probability);
- Zhu & Mordohai's city blocks: a graph of points with ``W = exp(-max L)`` along the segment
  between them (section 5): :func:`ncut` on the caller's sparse affinity matrix.

:func:`ncut` takes the eigenvectors of the normalized affinity ``D^-1/2 W D^-1/2`` for the
``k`` largest eigenvalues (the smallest of the normalized Laplacian ``L_sym``) and turns them
into ``k`` labels with Yu & Shi's multiclass spectral discretisation (2003), the method of
the Cour, Yu & Shi NCut code that Grote et al. adapted: the rotation of the row-normalised
eigenvectors closest to a discrete partition, found by alternating discretisation and SVD.

A full-pixel NCut of a 1000 x 1000 image is intractable (a million-node eigenproblem), so
images are cut over a graph of SLIC superpixels (Achanta et al. 2012; a few thousand, a
dozen pixels across): every segment is a union of superpixels, and SLIC boundaries, which
follow intensity edges, are the only places where segments can meet. The weight of two
adjacent superpixels is the number of pixel pairs across their shared border times the
similarity of the superpixels,

    W_ij = border_ij * exp(-|mean_i - mean_j|^2 / sigma_I^2) * exp(-edge_ij^2 / sigma_E^2),

so a cut costs, as in Shi & Malik's pixel graph of 4-neighbours, the summed weights of the
pixel pairs it separates, with each pixel's value replaced by its superpixel's mean; ``edge_ij``
is the strongest edge along the shared border, Leung & Malik's intervening contour.

``mask`` arguments follow numpy's masked arrays: True marks a cell that is masked out (no
data), like a NaN cell. Such cells belong to no superpixel and no segment (label -1).

References
----------
Shi, J., Malik, J. (2000). Normalized cuts and image segmentation. IEEE TPAMI 22 (8).
Yu, S. X., Shi, J. (2003). Multiclass spectral clustering. ICCV, 313-319.
Leung, T., Malik, J. (1998). Contour continuity in region based image segmentation. ECCV.
Achanta, R. et al. (2012). SLIC superpixels compared to state-of-the-art superpixel
methods. IEEE TPAMI 34 (11).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, sparse
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import eigsh
from skimage.measure import label as connected_label
from skimage.segmentation import slic

from ..errors import GisroadsError
from ..features.edges import fill_nearest
from ..parallel import pinned_threads

DENSE_EIGEN_NODES = 1000
"""Graphs up to this many nodes are solved with a dense eigendecomposition (faster and
exact there); larger ones with ARPACK in shift-invert mode."""

DISCRETISATION_ITERATIONS = 30
"""Most alternations of Yu & Shi's discretisation (their code: 20; it usually stops by 10)."""

DISCRETISATION_TIE = 1e-6
"""Similarities (cosines, and sums of them) of the discretisation closer than this are
ties, broken by node order rather than by rounding (see ``_discretise``)."""

RELIABLE_ROW_NORM = 1e-6
"""Embedding rows shorter than this times the longest have no reliable direction (the
eigenvectors are accurate to ~1e-13 per entry) and do not steer the discretisation."""

EMPTY_SEGMENT_PULL = 1e-6
"""Weight of the row an empty segment is reseeded with in the discretisation's Procrustes
step: it fixes the rotation of empty segments, which the SVD alone leaves arbitrary."""

SLIC_COMPACTNESS = 3.0
"""SLIC compactness with values in units of the image's pixel noise: one superpixel grid
step of distance weighs as much as three noise standard deviations of value, so noise alone
barely moves superpixel borders, while a step of a few noise deviations pulls them onto it."""

SLIC_CLIP = 5.0
"""Values are clipped to +-5 robust standard deviations of the image before SLIC, so a few
extreme cells (retro-reflective paint, specular returns) do not shape the superpixels."""


def _canonical(labels: np.ndarray) -> np.ndarray:
    """Labels renumbered 0..m-1 in order of first appearance, so results compare exactly."""
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inverse.ravel()].astype(np.int32)


def leading_eigenpairs(affinity: sparse.csr_matrix, k: int, *, seed: int = 0
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The k largest eigenvalues of ``D^-1/2 W D^-1/2`` (ascending) and their eigenvectors.

    The relaxed NCut problem (Shi & Malik): eigenvectors of the normalized affinity for its
    largest eigenvalues are those of the normalized Laplacian ``I - D^-1/2 W D^-1/2`` for
    its smallest. Every degree must be positive.

    Parameters
    ----------
    affinity : scipy.sparse matrix, shape (n, n)
        Symmetric, non-negative.
    k : int
    seed : int
        Start vector of the sparse solver; the result is deterministic for a given seed.

    Returns
    -------
    values : ndarray, shape (k,)
    vectors : ndarray, shape (n, k)
    """
    n = affinity.shape[0]
    inv_sqrt_degree = 1.0 / np.sqrt(np.asarray(affinity.sum(axis=1)).ravel())
    scaling = sparse.diags(inv_sqrt_degree)
    normalized = scaling @ affinity @ scaling
    if n <= DENSE_EIGEN_NODES or k >= n - 1:
        return linalg.eigh(normalized.toarray(), subset_by_index=[n - k, n - 1])
    laplacian = (sparse.identity(n, format="csc") - normalized).tocsc()
    start = np.random.default_rng(seed).uniform(0.5, 1.5, n)
    # shift-invert just below L's smallest eigenvalue 0 converges in a few iterations; at full
    # precision: near-degenerate eigenvalues near 0 need it (tol=1e-6 multiplied the NCut
    # value of a 600 x 600 intensity image's 150-way partition by 30)
    values, vectors = eigsh(laplacian, k=k, sigma=-1e-3, which="LM", v0=start)
    order = np.argsort(-values)  # largest Laplacian eigenvalue = smallest affinity one first
    return 1.0 - values[order], vectors[:, order]


def _first_within(values: np.ndarray, tolerance: float, axis: int | None = None):
    """Index of the first value within ``tolerance`` of the smallest: ``np.argmin`` with
    near-ties broken by position instead of by rounding."""
    return np.argmax(values <= values.min(axis=axis, keepdims=True) + tolerance, axis=axis)


def _reseed_empty(procrustes: np.ndarray, rows: np.ndarray, empty: np.ndarray) -> None:
    """Give the empty segments' rows of the Procrustes matrix ``procrustes`` (in place) the
    rows of the embedding farthest from the space the other segments span, one after the
    other, weighted by :data:`EMPTY_SEGMENT_PULL`.

    Without them the matrix is singular and the SVD rotates its null space arbitrarily; with
    them the rotation is unique, and the empty segments restart where no segment reaches
    (as k-means restarts an empty cluster at a far point). Distances to a subspace do not
    depend on the basis of the embedding."""
    if not len(empty):
        return
    _, singular, vt = np.linalg.svd(procrustes)
    spanned = vt[singular > 1e-9 * max(singular.max(), np.finfo(float).tiny)]
    residual = rows - (rows @ spanned.T) @ spanned
    for segment in empty:
        distance = np.linalg.norm(residual, axis=1)
        farthest = _first_within(-distance, DISCRETISATION_TIE)
        procrustes[segment] = EMPTY_SEGMENT_PULL * rows[farthest]
        if distance[farthest] > 0:
            direction = residual[farthest] / distance[farthest]
            residual -= np.outer(residual @ direction, direction)


def _discretise(embedding: np.ndarray, seed: int) -> np.ndarray:
    """Yu & Shi (2003) multiclass discretisation of an (n, k) spectral embedding.

    In exact arithmetic the result depends only on the subspace the eigenvectors span, not
    on which orthonormal basis of it the eigensolver returns (rotations and sign flips of
    the columns cancel out). Three places turn rounding into different labels, and each is
    made deterministic here, so that the same graph gives the same labels with any
    numpy/scipy/LAPACK (the two environments' ARPACK and LAPACK return bases that differ by
    rotations within near-degenerate eigenspaces, and ~1e-13 per entry):

    - the initial rotation picks, k times, the row least similar to those already picked;
      whole connected components are exactly orthogonal to each other, so the smallest
      similarities tie to 1e-17: values within :data:`DISCRETISATION_TIE` of the smallest
      tie, and the first of them is taken; the same for the labels' argmax;
    - rows of nearly zero norm (superpixels of nearly zero degree) have a direction known
      only to (solver error / norm): rows below :data:`RELIABLE_ROW_NORM` of the largest
      are neither picked nor used in the rotation; they get the label of their argmax at
      the end;
    - a segment left empty makes the Procrustes matrix singular, and the rotation of its
      null space is whatever the SVD returns: an empty segment is reseeded with the row
      farthest from the space the other segments span (:func:`_reseed_empty`).
    """
    n, k = embedding.shape
    norms = np.linalg.norm(embedding, axis=1)
    rows = embedding / np.maximum(norms, np.finfo(float).tiny)[:, None]
    reliable = norms >= RELIABLE_ROW_NORM * norms.max()
    used = rows[reliable]
    # initial rotation: k rows as orthogonal to each other as possible
    rotation = np.zeros((k, k))
    first = np.random.default_rng(seed).integers(n)
    first = np.flatnonzero(np.roll(reliable, -first))[0] + first  # the next reliable row
    rotation[:, 0] = rows[first % n]
    similarity = np.zeros(len(used))
    for j in range(1, k):
        similarity += np.abs(used @ rotation[:, j - 1])
        rotation[:, j] = used[_first_within(similarity, DISCRETISATION_TIE)]
    labels = None
    for _ in range(DISCRETISATION_ITERATIONS):
        previous, labels = labels, _first_within(-(used @ rotation), DISCRETISATION_TIE,
                                                 axis=1)
        if previous is not None and np.array_equal(labels, previous):
            break
        indicator = sparse.csr_matrix((np.ones(len(used)), (np.arange(len(used)), labels)),
                                      shape=(len(used), k))
        procrustes = np.asarray(indicator.T @ used)
        _reseed_empty(procrustes, used, np.flatnonzero(np.bincount(labels, minlength=k) == 0))
        u, _, vt = np.linalg.svd(procrustes)
        rotation = vt.T @ u.T
    return _first_within(-(rows @ rotation), DISCRETISATION_TIE, axis=1)


def ncut(affinity, n_segments: int, *, seed: int = 0) -> np.ndarray:
    """k-way normalized cut of a weighted graph (Shi & Malik 2000; Yu & Shi 2003).

    Parameters
    ----------
    affinity : scipy.sparse matrix or array_like, shape (n, n)
        Symmetric, non-negative edge weights ``W``; self-loops are allowed.
    n_segments : int
        Number of segments ``k``.
    seed : int
        Seed of the eigensolver's start vector and of the discretisation's first row: the
        result is deterministic for a given seed.

    Returns
    -------
    labels : ndarray of int32, shape (n,)
        ``0..m-1`` numbered in order of first appearance, with ``m <= k``: the
        discretisation can leave a segment empty. A graph with at least ``k`` connected
        components cannot be cut into ``k`` segments without joining unconnected nodes; each
        component is then one segment (``m`` = the number of components). Otherwise each
        isolated node (no edge) is a segment of its own and the rest of the graph gets the
        remaining segments.

    Raises
    ------
    ValueError
        A non-square, negative, non-finite or asymmetric ``affinity``, or ``n_segments < 1``.
    """
    weights = sparse.csr_matrix(affinity, dtype=float)
    n = weights.shape[0]
    if weights.shape != (n, n):
        raise GisroadsError(f"affinity must be square, got shape {weights.shape}")
    if n_segments < 1:
        raise GisroadsError(f"n_segments must be at least 1, got {n_segments}")
    if weights.nnz and (not np.isfinite(weights.data).all() or weights.data.min() < 0):
        raise GisroadsError("affinity must be finite and non-negative")
    if weights.nnz and abs(weights - weights.T).max() > 1e-9 * weights.data.max():
        raise GisroadsError("affinity must be symmetric")
    if n == 0:
        return np.zeros(0, np.int32)
    weights.eliminate_zeros()  # an explicit 0 is no edge, for components and degrees alike
    k = min(n_segments, n)
    n_components, component = connected_components(weights, directed=False)
    if n_components >= k:
        return _canonical(component)
    isolated = np.asarray(weights.sum(axis=1)).ravel() == 0
    connected = np.flatnonzero(~isolated)
    k_connected = k - int(isolated.sum())
    labels = np.empty(n, np.int64)
    labels[isolated] = k_connected + np.arange(int(isolated.sum()))
    if k_connected >= len(connected):
        labels[connected] = np.arange(len(connected))
    else:
        subgraph = weights[connected][:, connected]
        with pinned_threads(1):  # a few hundred nodes: more threads only spin
            _, vectors = leading_eigenpairs(subgraph, k_connected, seed=seed)
        # Shi & Malik's generalized eigenvectors are these scaled per node by D^-1/2; the
        # discretisation normalises every row, which undoes that scaling, so it is skipped
        # (a node of nearly zero degree would overflow it)
        labels[connected] = _discretise(vectors, seed)
    return _canonical(labels)


def _robust_std(values: np.ndarray, centre: float | None = None) -> float:
    """1.4826 x median absolute deviation (from ``centre``, default the median); the plain
    std if that is 0; 1 if both are."""
    values = values[np.isfinite(values)]
    if values.size == 0:
        return 1.0
    centre = np.median(values) if centre is None else centre
    mad = 1.4826 * float(np.median(np.abs(values - centre), overwrite_input=True))
    return mad if mad > 0 else (float(values.std()) or 1.0)


def typical_scale(values: np.ndarray) -> float:
    """A scale for affinities ``exp(-d^2 / sigma^2)``: the median of ``values`` (>= 0); of
    the positive ones if that is 0; 1 if there are none."""
    median = float(np.median(values)) if values.size else 0.0
    if median > 0:
        return median
    positive = values[values > 0]
    return float(np.median(positive)) if positive.size else 1.0


def _bands_and_valid(image, mask) -> tuple[np.ndarray, np.ndarray]:
    """``(bands, rows, cols)`` float array and the cells with data in every band."""
    bands = np.asarray(image, dtype=float)
    if bands.ndim == 2:
        bands = bands[None]
    if bands.ndim != 3:
        raise GisroadsError("image must be (rows, cols) or (bands, rows, cols), got "
                            f"{bands.shape}")
    valid = np.isfinite(bands).all(axis=0)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != valid.shape:
            raise GisroadsError(f"mask shape {mask.shape} differs from the image's "
                                f"{valid.shape}")
        valid &= ~mask
    return bands, valid


def _consecutive(superpixels: np.ndarray) -> tuple[np.ndarray, int]:
    """Superpixel ids renumbered 0..n-1 over the labelled cells, -1 elsewhere."""
    out = np.full(superpixels.shape, -1, np.int32)
    labelled = superpixels >= 0
    ids, inverse = np.unique(superpixels[labelled], return_inverse=True)
    out[labelled] = inverse.ravel()
    return out, len(ids)


@dataclass(frozen=True)
class _Borders:
    """Superpixel pairs across 4-neighbour pixel borders.

    ``first``/``second`` are the flat indices of the two pixels of each bordering pixel pair,
    ``pair`` its index into the unique superpixel pairs ``lower < upper``.
    """

    n_superpixels: int
    lower: np.ndarray
    upper: np.ndarray
    first: np.ndarray
    second: np.ndarray
    pair: np.ndarray

    @classmethod
    def of(cls, superpixels: np.ndarray, n_superpixels: int) -> _Borders:
        cols = superpixels.shape[1]
        pixel_pairs = []
        for here, there, step in ((superpixels[:, :-1], superpixels[:, 1:], 1),
                                  (superpixels[:-1, :], superpixels[1:, :], cols)):
            rows_, cols_ = np.nonzero((here != there) & (here >= 0) & (there >= 0))
            first = rows_ * cols + cols_
            pixel_pairs.append((first, first + step))
        first = np.concatenate([p[0] for p in pixel_pairs])
        second = np.concatenate([p[1] for p in pixel_pairs])
        flat = superpixels.ravel().astype(np.int64)
        a, b = flat[first], flat[second]
        keys = np.minimum(a, b) * n_superpixels + np.maximum(a, b)
        unique_keys, pair = np.unique(keys, return_inverse=True)
        return cls(n_superpixels, unique_keys // n_superpixels, unique_keys % n_superpixels,
                   first, second, pair.ravel())

    @property
    def length_px(self) -> np.ndarray:
        return np.bincount(self.pair, minlength=len(self.lower)).astype(float)

    def max_along(self, values: np.ndarray) -> np.ndarray:
        """Per pair, the largest of ``values`` on the pixels either side of the border."""
        flat = np.asarray(values, dtype=float).ravel()
        across = np.maximum(flat[self.first], flat[self.second])
        strongest = np.zeros(len(self.lower))
        np.maximum.at(strongest, self.pair, np.nan_to_num(across, nan=0.0))
        return strongest

    def matrix(self, values: np.ndarray) -> sparse.csr_matrix:
        """Symmetric sparse matrix with ``values`` on both ``(lower, upper)`` and its mirror."""
        rows = np.concatenate([self.lower, self.upper])
        cols = np.concatenate([self.upper, self.lower])
        shape = (self.n_superpixels, self.n_superpixels)
        return sparse.csr_matrix((np.concatenate([values, values]), (rows, cols)), shape=shape)

    def lookup(self, matrix) -> np.ndarray:
        """Entries of a sparse matrix at every pair; 1 where it stores none."""
        stored = sparse.csr_matrix(matrix, dtype=float).tocoo()
        if stored.shape != (self.n_superpixels,) * 2:
            raise GisroadsError(f"extra_affinity has shape {stored.shape}, expected "
                                f"{(self.n_superpixels,) * 2} (one row per superpixel)")
        pair_keys = self.lower * self.n_superpixels + self.upper
        keys = (np.minimum(stored.row, stored.col).astype(np.int64) * self.n_superpixels
                + np.maximum(stored.row, stored.col))
        position = np.minimum(np.searchsorted(pair_keys, keys), max(len(pair_keys) - 1, 0))
        on_pair = (pair_keys[position] == keys) if len(pair_keys) else np.zeros(0, bool)
        factor = np.ones(len(pair_keys))
        factor[position[on_pair]] = stored.data[on_pair]
        return factor


def _features(bands: np.ndarray, superpixels: np.ndarray, n: int) -> dict:
    labelled = superpixels >= 0
    ids = superpixels[labelled]
    count = np.bincount(ids, minlength=n)
    safe = np.maximum(count, 1)
    mean = np.stack([np.bincount(ids, band[labelled], minlength=n) / safe for band in bands],
                    axis=1)
    rows, cols = np.nonzero(labelled)
    centroid = np.stack([np.bincount(ids, rows, minlength=n) / safe,
                         np.bincount(ids, cols, minlength=n) / safe], axis=1)
    return {"mean": mean[:, 0] if len(bands) == 1 else mean, "pixel_count": count,
            "centroid": centroid}


def _noise_std(band: np.ndarray, valid: np.ndarray, spread: float) -> float:
    """Robust standard deviation of the pixel noise, from differences of 4-neighbours.

    Edges touch few neighbour pairs, so the MAD of the differences sees the noise only; a
    difference of two noisy cells has sqrt(2) times their noise. Falls back to 1% of the
    band's robust standard deviation ``spread`` for noise-free (piecewise constant) images.
    """
    differences = [(band[:, 1:] - band[:, :-1])[valid[:, 1:] & valid[:, :-1]],
                   (band[1:, :] - band[:-1, :])[valid[1:, :] & valid[:-1, :]]]
    differences = np.abs(np.concatenate(differences))
    noise = 0.0
    if differences.size:
        # the differences are a scratch array: partitioned in place, not copied
        noise = 1.4826 * float(np.median(differences, overwrite_input=True)) / np.sqrt(2)
    return max(noise, 0.01 * spread)


def _slic_superpixels(bands: np.ndarray, valid: np.ndarray, n_superpixels: int,
                      compactness: float) -> np.ndarray:
    """SLIC superpixels, -1 on invalid cells, each one 4-connected region (not numbered 0..n-1).

    SLIC runs on the whole grid with holes filled by their nearest values (slic's own mask
    option seeds with a k-means over every valid pixel, tens of seconds on a large image),
    then superpixels that a hole cuts in pieces are split.
    """
    standardised = np.zeros(bands.shape)
    for out, band in zip(standardised, bands):
        values = band[valid]
        centre = np.median(values)
        spread = _robust_std(values, centre)
        clipped = np.clip(values, centre - SLIC_CLIP * spread, centre + SLIC_CLIP * spread)
        out[valid] = (clipped - centre) / _noise_std(band, valid, spread)
    standardised = fill_nearest(standardised, valid)
    # slic rescales the image to [0, 1] by its range: scale the compactness alike so that it
    # stays in units of the noise
    value_range = float(standardised.max() - standardised.min()) or 1.0
    single = len(bands) == 1
    superpixels = slic(standardised[0] if single else np.moveaxis(standardised, 0, -1),
                       n_segments=n_superpixels, compactness=compactness / value_range,
                       start_label=0, convert2lab=False, channel_axis=None if single else -1)
    return connected_label(np.where(valid, superpixels, -1), background=-1,
                           connectivity=1) - 1


def superpixel_graph(image, *, n_superpixels: int = 3000, mask=None,
                     compactness: float = SLIC_COMPACTNESS):
    """SLIC superpixels and their adjacency graph: the nodes :func:`ncut_segmentation` cuts.

    Parameters
    ----------
    image : array_like, shape (rows, cols) or (bands, rows, cols)
        Grey values or a multi-band image; NaN cells are no data.
    n_superpixels : int
        Approximate number of superpixels (SLIC's ``n_segments``); 3000 on a 1000 x 1000
        image are about 18 pixels across, fine enough for road edges yet a small eigenproblem.
    mask : array_like of bool, shape (rows, cols), optional
        True where a cell is masked out (no data).
    compactness : float
        SLIC compactness, applied to the image standardised per band by its pixel noise
        (robust standard deviation of 4-neighbour differences over sqrt(2)), so it does not
        depend on the image's units: one grid step of distance weighs as much as
        ``compactness`` noise deviations of value. Larger is more regular; at 1 noise alone
        makes ragged superpixels, at 5 they start to cut across real boundaries.

    Returns
    -------
    superpixels : ndarray of int32, shape (rows, cols)
        ``0..n-1``, each a 4-connected region; -1 on no-data and masked cells.
    adjacency : scipy.sparse.csr_matrix, shape (n, n)
        Symmetric; entry ``(i, j)`` is the length of the border between superpixels ``i``
        and ``j`` in pixel edges (4-neighbour pixel pairs across it), 0 when not adjacent.
    features : dict of ndarray
        ``"mean"``: mean value, ``(n,)`` or ``(n, bands)``; ``"pixel_count"``: ``(n,)``;
        ``"centroid"``: ``(n, 2)`` as (row, col), pixels.
    """
    bands, valid = _bands_and_valid(image, mask)
    if not valid.any():
        raise GisroadsError("the image has no valid cell")
    superpixels, n = _consecutive(_slic_superpixels(bands, valid, n_superpixels, compactness))
    borders = _Borders.of(superpixels, n)
    return superpixels, borders.matrix(borders.length_px), _features(bands, superpixels, n)


def intervening_edge_strength(superpixels, adjacency, edge_magnitude) -> sparse.csr_matrix:
    """Strongest edge along the border of every pair of adjacent superpixels.

    Leung & Malik's intervening contour between two regions: two superpixels divided by a
    strong edge should not be grouped, however similar their values.

    Parameters
    ----------
    superpixels : array_like of int, shape (rows, cols)
        As returned by :func:`superpixel_graph` (-1 outside).
    adjacency : scipy.sparse matrix, shape (n, n)
        Its adjacency; only the number of superpixels ``n`` is taken from it.
    edge_magnitude : array_like, shape (rows, cols)
        Edge strength, e.g. :func:`gisroads.features.edges.local_energy`'s magnitude.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, n)
        Symmetric; for adjacent superpixels, the largest magnitude on the pixels either side
        of their shared border (stored even when 0); nothing for other pairs.
    """
    superpixels = np.asarray(superpixels)
    edge_magnitude = np.asarray(edge_magnitude)
    if edge_magnitude.shape != superpixels.shape:
        raise GisroadsError(f"edge_magnitude shape {edge_magnitude.shape} differs from the "
                            f"superpixels' {superpixels.shape}")
    n = adjacency.shape[0]
    if superpixels.size and superpixels.max() >= n:
        raise GisroadsError(f"superpixel id {superpixels.max()} is not below the adjacency's "
                            f"size {n}")
    borders = _Borders.of(superpixels, n)
    return borders.matrix(borders.max_along(edge_magnitude))


def value_affinity(adjacency, node_values, sigma: float) -> sparse.csr_matrix:
    """A per-pair factor ``exp(-(v_i - v_j)^2 / sigma^2)`` from one value per superpixel, as
    an ``extra_affinity`` of :func:`ncut_segmentation`: the colour term's form for a further
    feature, e.g. a learned road probability.

    Parameters
    ----------
    adjacency : scipy.sparse matrix, shape (n, n)
        The superpixel adjacency of :func:`superpixel_graph` (its pattern gives the pairs).
    node_values : array_like, shape (n,)
        One value per superpixel (e.g. its mean road probability); NaN (no value) leaves
        the pairs it is in at factor 1.
    sigma : float
        Scale of the value differences, in the values' units; positive.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, n)
        Symmetric, the factor at every adjacent pair, in (0, 1].
    """
    if not sigma > 0:
        raise GisroadsError(f"sigma must be positive, got {sigma}")
    node_values = np.asarray(node_values, dtype=float)
    pairs = sparse.triu(sparse.csr_matrix(adjacency), k=1).tocoo()
    if node_values.shape != (adjacency.shape[0],):
        raise GisroadsError(f"node_values has shape {node_values.shape}, expected "
                            f"({adjacency.shape[0]},): one value per superpixel")
    difference = np.nan_to_num(node_values[pairs.row] - node_values[pairs.col], nan=0.0)
    factor = np.exp(-(difference / sigma) ** 2)
    return sparse.csr_matrix((np.concatenate([factor, factor]),
                              (np.concatenate([pairs.row, pairs.col]),
                               np.concatenate([pairs.col, pairs.row]))),
                             shape=adjacency.shape)


def ncut_segmentation(image, *, n_segments: int = 150, n_superpixels: int = 3000,
                      sigma_intensity: float | None = None, edge_magnitude=None,
                      sigma_edge: float | None = None, mask=None, extra_affinity=None,
                      superpixels=None, compactness: float = SLIC_COMPACTNESS,
                      seed: int = 0) -> np.ndarray:
    """Normalized-cut segmentation of an image over a superpixel graph (module docstring).

    Parameters
    ----------
    image : array_like, shape (rows, cols) or (bands, rows, cols)
        Grey values (LiDAR intensity) or bands (colour); NaN cells are no data.
    n_segments : int
        Number of NCut segments; Zhu & Mordohai over-segment the intensity image into
        100-200 regions (section 4.3), hence 150.
    n_superpixels : int
        Graph nodes, see :func:`superpixel_graph`.
    sigma_intensity : float, optional
        ``sigma_I`` of the value term, in image units (for bands, of the Euclidean distance
        between mean vectors). Default: the median difference between the means of adjacent
        superpixels, so that the more different half of the neighbours is weakened by at
        least 1/e. (The image's robust standard deviation, dominated by the contrast between
        surfaces rather than within them, weakens real boundaries too little: NCut then cuts
        large uniform regions instead; on the fusa.laz intensity image the median
        rule put 42% instead of 29% of the road-edge cells within 1 m of a boundary.)
    edge_magnitude : array_like, shape (rows, cols), optional
        Edge strength; when given, the intervening-edge term
        ``exp(-edge_ij^2 / sigma_E^2)`` multiplies the weights.
    sigma_edge : float, optional
        ``sigma_E``, in the units of ``edge_magnitude``. Default: the median
        intervening-edge strength over adjacent pairs, the same rule as ``sigma_intensity``.
    mask : array_like of bool, shape (rows, cols), optional
        True where a cell is masked out (no data).
    extra_affinity : scipy.sparse matrix, shape (n, n), or a sequence of them, optional
        Further factors per pair of adjacent superpixels of ``superpixels`` (so pass
        those too), e.g. Grote & Rottensteiner's ``w_NDVI`` between superpixels on opposite
        sides of the NDVI threshold or :func:`value_affinity`; pairs a matrix stores no
        entry for keep their weight; several matrices multiply. Build them on the
        ``adjacency`` of :func:`superpixel_graph`; give them symmetric.
    superpixels : array_like of int, shape (rows, cols), optional
        Precomputed superpixels (:func:`superpixel_graph`), -1 outside; ``n_superpixels``
        and ``compactness`` are then unused.
    compactness : float
        SLIC compactness, see :func:`superpixel_graph`.
    seed : int
        See :func:`ncut`; the result is deterministic for a given seed.

    Returns
    -------
    labels : ndarray of int32, shape (rows, cols)
        Segments ``0..m-1``, numbered in raster order, each one 4-connected region: NCut
        segments whose superpixels form several separate regions are split, so ``m`` can
        exceed ``n_segments``. -1 on no-data and masked cells.
    """
    bands, valid = _bands_and_valid(image, mask)
    if not valid.any():
        raise GisroadsError("the image has no valid cell")
    if superpixels is None:
        nodes, n = _consecutive(_slic_superpixels(bands, valid, n_superpixels, compactness))
    else:  # keep the caller's ids: extra_affinity is indexed by them
        nodes = np.asarray(superpixels)
        if nodes.shape != valid.shape:
            raise GisroadsError(f"superpixels shape {nodes.shape} differs from the image's "
                                f"{valid.shape}")
        n = int(nodes.max()) + 1
        if n == 0:
            raise GisroadsError("superpixels holds no superpixel (all -1)")
        nodes = np.where(valid, nodes, -1)
    borders = _Borders.of(nodes, n)
    mean = _features(bands, nodes, n)["mean"].reshape(n, -1)

    difference = np.sqrt(((mean[borders.lower] - mean[borders.upper]) ** 2).sum(axis=1))
    if sigma_intensity is None:
        sigma_intensity = typical_scale(difference)
    weight = borders.length_px * np.exp(-(difference / sigma_intensity) ** 2)
    if edge_magnitude is not None:
        edge_magnitude = np.asarray(edge_magnitude, dtype=float)
        if edge_magnitude.shape != valid.shape:
            raise GisroadsError(f"edge_magnitude shape {edge_magnitude.shape} differs from the "
                                f"image's {valid.shape}")
        edge = borders.max_along(edge_magnitude)
        if sigma_edge is None:
            sigma_edge = typical_scale(edge)
        weight *= np.exp(-(edge / sigma_edge) ** 2)
    if extra_affinity is not None:
        for factor in ([extra_affinity] if sparse.issparse(extra_affinity)
                       else extra_affinity):
            weight *= borders.lookup(factor)

    # superpixels that touch no other (valid islands in no-data) are segments of their own,
    # on top of the n_segments that NCut makes of the rest
    n_islands = n - len(np.union1d(borders.lower, borders.upper))
    segment_of = ncut(borders.matrix(weight), n_segments + n_islands, seed=seed)
    labels = np.where(nodes >= 0, segment_of[np.maximum(nodes, 0)], -1)
    return (connected_label(labels, background=-1, connectivity=1) - 1).astype(np.int32)


def segment_boundaries(labels) -> np.ndarray:
    """Pixels on a border between two segments.

    Parameters
    ----------
    labels : array_like of int, shape (rows, cols)
        Segments ``>= 0``; negative labels are no segment (their borders are not marked).

    Returns
    -------
    ndarray of bool, shape (rows, cols)
        True where the right or lower 4-neighbour belongs to another segment: lines one
        pixel thick, on the upper/left side of each border (half a pixel off the true
        border), 4-connected along diagonal borders.
    """
    labels = np.asarray(labels)
    boundary = np.zeros(labels.shape, bool)
    boundary[:, :-1] |= ((labels[:, :-1] != labels[:, 1:])
                         & (labels[:, :-1] >= 0) & (labels[:, 1:] >= 0))
    boundary[:-1, :] |= ((labels[:-1, :] != labels[1:, :])
                         & (labels[:-1, :] >= 0) & (labels[1:, :] >= 0))
    return boundary
