"""Normalized cuts: exact answers on small graphs, then images with known regions."""
import numpy as np
import pytest
from scipy import sparse
from skimage.measure import label as connected_label

from gisroads.features.edges import local_energy
from gisroads.segmentation.ncut import (intervening_edge_strength, ncut, ncut_segmentation,
                                        segment_boundaries, superpixel_graph, value_affinity)


def cliques(*sizes, links=()):
    """Affinity of complete graphs of weight 1 with ``(i, j, weight)`` links between nodes."""
    weights = sparse.block_diag([np.ones((s, s)) - np.eye(s) for s in sizes]).tolil()
    for i, j, w in links:
        weights[i, j] = weights[j, i] = w
    return weights.tocsr()


def purity(labels, truth):
    """For each true region, the share of its cells in its most common label."""
    return np.array([np.bincount(labels[truth == t]).max() / (truth == t).sum()
                     for t in np.unique(truth)])


def is_one_region_per_label(labels):
    return connected_label(labels, background=-1, connectivity=1).max() == labels.max() + 1


# ---------------------------------------------------------------- ncut on graphs


def test_two_cliques_joined_by_one_weak_edge():
    labels = ncut(cliques(5, 5, links=[(4, 5, 0.01)]), 2)
    assert labels.dtype == np.int32
    np.testing.assert_array_equal(labels, [0, 0, 0, 0, 0, 1, 1, 1, 1, 1])


def test_three_cliques_of_different_sizes():
    weights = cliques(4, 6, 5, links=[(3, 4, 0.02), (9, 10, 0.02), (0, 14, 0.01)])
    np.testing.assert_array_equal(ncut(weights, 3), [0] * 4 + [1] * 6 + [2] * 5)


def test_isolated_node_is_a_segment_of_its_own():
    weights = cliques(4, 1, 4, links=[(3, 5, 0.01)])
    np.testing.assert_array_equal(ncut(weights, 3), [0, 0, 0, 0, 1, 2, 2, 2, 2])


def test_more_components_than_segments_gives_the_components():
    np.testing.assert_array_equal(ncut(cliques(3, 2, 3), 2), [0, 0, 0, 1, 1, 2, 2, 2])


def test_one_segment_and_as_many_segments_as_nodes():
    weights = cliques(3, 3, links=[(2, 3, 0.1)])
    np.testing.assert_array_equal(ncut(weights, 1), np.zeros(6))
    np.testing.assert_array_equal(ncut(weights, 10), np.arange(6))
    assert ncut(sparse.csr_matrix((0, 0)), 3).size == 0


def test_dense_input_and_explicit_zero_weights_are_accepted():
    weights = cliques(5, 5).toarray()
    weights[4, 5] = weights[5, 4] = 0.01
    np.testing.assert_array_equal(ncut(weights, 2), [0] * 5 + [1] * 5)
    rows, cols = np.nonzero(cliques(5, 5, links=[(4, 5, 1.0)]).toarray())
    stored = sparse.csr_matrix((np.where((rows + cols) == 9, 0.0, 1.0), (rows, cols)))
    assert stored.nnz == 42  # with two stored zeros, (4, 5) and (5, 4): no edge
    np.testing.assert_array_equal(ncut(stored, 2), [0] * 5 + [1] * 5)


@pytest.mark.parametrize("bad", [np.array([[0, 1.0], [0.5, 0]]), np.array([[0, -1.0], [-1.0, 0]]),
                                 np.ones((2, 3)), np.array([[0, np.nan], [np.nan, 0]])])
def test_invalid_affinity_is_rejected(bad):
    with pytest.raises(ValueError):
        ncut(bad, 2)


def test_large_graph_is_deterministic_and_cuts_along_weak_links():
    # a 40 x 40 grid graph (1600 nodes: the sparse eigensolver) whose left and right halves
    # are joined by weak links, and 4 segments
    side = 40
    index = np.arange(side * side).reshape(side, side)
    rows = np.concatenate([index[:, :-1].ravel(), index[:-1, :].ravel()])
    cols = np.concatenate([index[:, 1:].ravel(), index[1:, :].ravel()])
    weight = np.ones(len(rows))
    weight[:side * (side - 1)][(np.arange(side * (side - 1)) % (side - 1)) == side // 2 - 1] = 1e-3
    weights = sparse.coo_matrix((weight, (rows, cols)), shape=(side * side,) * 2)
    weights = (weights + weights.T).tocsr()
    first = ncut(weights, 4, seed=3)
    np.testing.assert_array_equal(first, ncut(weights, 4, seed=3))
    grid = first.reshape(side, side)
    assert len(np.unique(grid)) == 4
    assert not set(np.unique(grid[:, :side // 2])) & set(np.unique(grid[:, side // 2:]))


# ---------------------------------------------------------------- superpixel graph


def test_intervening_edge_strength_on_hand_made_superpixels():
    superpixels = np.array([[0, 0, 1],
                            [0, 0, 1],
                            [2, 2, -1]])
    edges = np.array([[0.0, 0.5, 0.1],
                      [0.2, 0.0, 0.3],
                      [0.7, 0.0, 0.9]])
    strength = intervening_edge_strength(superpixels, sparse.csr_matrix((3, 3)), edges)
    # 0|1 across (0,1)-(0,2) and (1,1)-(1,2): max(0.5, 0.1, 0.0, 0.3); 0|2 across
    # (1,0)-(2,0) and (1,1)-(2,1): max(0.2, 0.7, 0.0, 0.0); 1 and 2 only touch -1 and diagonally
    np.testing.assert_allclose(strength.toarray(), [[0, 0.5, 0.7], [0.5, 0, 0], [0.7, 0, 0]])


def test_superpixel_graph_features_and_adjacency():
    rng = np.random.default_rng(0)
    image = rng.normal(size=(60, 80))
    image[:, 40:] += 5.0
    mask = np.zeros(image.shape, bool)
    mask[:10, :10] = True
    image[50:, 70:] = np.nan
    superpixels, adjacency, features = superpixel_graph(image, n_superpixels=48, mask=mask)
    n = superpixels.max() + 1
    assert superpixels.dtype == np.int32 and 30 <= n <= 80
    assert (superpixels[mask] == -1).all() and (superpixels[50:, 70:] == -1).all()
    assert (superpixels[~mask & np.isfinite(image)] >= 0).all()
    assert np.array_equal(np.unique(superpixels[superpixels >= 0]), np.arange(n))
    assert is_one_region_per_label(superpixels)
    assert abs(adjacency - adjacency.T).max() == 0
    differing = ((superpixels[:, 1:] != superpixels[:, :-1])
                 & (superpixels[:, 1:] >= 0) & (superpixels[:, :-1] >= 0)).sum() + \
                ((superpixels[1:] != superpixels[:-1])
                 & (superpixels[1:] >= 0) & (superpixels[:-1] >= 0)).sum()
    assert adjacency.sum() == 2 * differing
    assert (features["pixel_count"] == np.bincount(superpixels[superpixels >= 0])).all()
    some = 7
    rows, cols = np.nonzero(superpixels == some)
    assert features["mean"][some] == pytest.approx(image[rows, cols].mean())
    np.testing.assert_allclose(features["centroid"][some], [rows.mean(), cols.mean()])
    # superpixels follow the step at column 40
    assert np.all((features["mean"] > 2.5) == (features["centroid"][:, 1] > 40))


def test_superpixel_graph_of_bands_has_mean_vectors():
    image = np.stack([np.zeros((30, 30)), np.ones((30, 30))])
    _, _, features = superpixel_graph(image, n_superpixels=9)
    np.testing.assert_allclose(features["mean"], np.tile([0.0, 1.0], (len(features["mean"]), 1)))


# ---------------------------------------------------------------- ncut_segmentation


def blobs(seed, layout):
    """Three regions of intensities 1, 0, 2 with Gaussian noise of 0.3."""
    rng = np.random.default_rng(seed)
    if layout == "tiled":  # two halves split by a wavy line, and a disc across it
        rows, cols = np.mgrid[:120, :180]
        truth = np.where(cols < 90 + 12 * np.sin(rows / 15), 0, 1)
        truth[(rows - 60) ** 2 + (cols - 90) ** 2 < 38 ** 2] = 2
    else:  # two discs on a background
        rows, cols = np.mgrid[:160, :240]
        truth = np.zeros(rows.shape, int)
        truth[(rows - 80) ** 2 + (cols - 70) ** 2 < 35 ** 2] = 1
        truth[(rows - 80) ** 2 + (cols - 170) ** 2 < 35 ** 2] = 2
    return np.choose(truth, [1.0, 0.0, 2.0]) + rng.normal(0, 0.3, truth.shape), truth


@pytest.mark.parametrize("seed,layout", [(0, "tiled"), (1, "tiled"), (0, "discs"), (2, "discs")])
def test_three_noisy_blobs_are_recovered(seed, layout):
    image, truth = blobs(seed, layout)
    labels = ncut_segmentation(image, n_segments=3, n_superpixels=1000)
    assert labels.dtype == np.int32 and labels.shape == image.shape
    assert labels.max() == 2
    assert purity(labels, truth).min() > 0.95
    assert purity(truth, labels).min() > 0.95  # and no region shares a label


def test_intervening_edges_separate_equal_regions_divided_by_a_thin_line():
    rng = np.random.default_rng(0)
    image = 0.5 + rng.normal(0, 0.05, (100, 160))
    image[:, 40:42] = 1.5  # off-centre: a cut through the middle would balance better
    left = np.zeros(image.shape, bool)
    left[:, :40] = True
    right = np.zeros(image.shape, bool)
    right[:, 42:] = True
    magnitude, _ = local_energy(image)
    # a wide sigma_I takes intensity out of the weights: only the edge term can see the line
    labels = ncut_segmentation(image, n_segments=2, n_superpixels=300, sigma_intensity=10.0,
                               edge_magnitude=magnitude)
    assert np.bincount(labels[left]).max() > 0.95 * left.sum()
    assert np.bincount(labels[right]).max() > 0.95 * right.sum()
    assert np.bincount(labels[left]).argmax() != np.bincount(labels[right]).argmax()
    without = ncut_segmentation(image, n_segments=2, n_superpixels=300, sigma_intensity=10.0)
    assert min(np.bincount(without[left]).max() / left.sum(),
               np.bincount(without[right]).max() / right.sum()) < 0.9


def test_extra_affinity_cuts_where_it_says():
    rng = np.random.default_rng(1)
    image = rng.normal(0, 0.1, (90, 150))
    superpixels, adjacency, features = superpixel_graph(image, n_superpixels=150)
    pairs = sparse.triu(adjacency).tocoo()
    east = features["centroid"][:, 1] > 100
    across = east[pairs.row] != east[pairs.col]
    # only the pairs across the line are stored: the others keep their weight
    factor = sparse.coo_matrix((np.full(across.sum(), 1e-6),
                                (pairs.row[across], pairs.col[across])), shape=adjacency.shape)
    labels = ncut_segmentation(image, n_segments=2, superpixels=superpixels,
                               extra_affinity=factor + factor.T)
    east_cells = east[superpixels]
    assert labels.max() == 1
    assert (labels[east_cells] == labels[east_cells][0]).all()
    assert (labels[~east_cells] != labels[east_cells][0]).all()


def test_value_affinity_weakens_pairs_by_their_value_difference():
    adjacency = sparse.csr_matrix(np.array([[0, 2, 0, 0], [2, 0, 3, 0], [0, 3, 0, 1],
                                            [0, 0, 1, 0]]))
    factor = value_affinity(adjacency, np.array([0.9, 0.7, 0.1, np.nan]), 0.2).toarray()
    np.testing.assert_allclose(factor, factor.T)
    np.testing.assert_allclose([factor[0, 1], factor[1, 2], factor[2, 3]],
                               [np.exp(-1), np.exp(-9), 1.0])  # NaN: no value, factor 1
    assert factor[0, 2] == 0 and factor[0, 3] == 0  # not adjacent: no entry
    with pytest.raises(ValueError, match="sigma"):
        value_affinity(adjacency, np.zeros(4), 0.0)
    with pytest.raises(ValueError, match="one value per superpixel"):
        value_affinity(adjacency, np.zeros(3), 0.2)


def test_several_extra_affinities_multiply():
    """A cut line east-west from one factor, north-south from another: four segments
    follow both lines; each factor alone gives its own halves."""
    rng = np.random.default_rng(3)
    image = rng.normal(0, 0.1, (120, 120))
    superpixels, adjacency, features = superpixel_graph(image, n_superpixels=200)
    east = (features["centroid"][:, 1] > 60).astype(float)
    south = (features["centroid"][:, 0] > 60).astype(float)
    factors = [value_affinity(adjacency, east, 0.05), value_affinity(adjacency, south, 0.05)]
    labels = ncut_segmentation(image, n_segments=4, superpixels=superpixels,
                               extra_affinity=factors)
    quadrant = (east * 2 + south)[superpixels]
    assert labels.max() == 3
    for q in range(4):
        assert len(np.unique(labels[quadrant == q])) == 1
    halves = ncut_segmentation(image, n_segments=2, superpixels=superpixels,
                               extra_affinity=factors[0])
    assert all(len(np.unique(halves[east[superpixels] == side])) == 1 for side in (0, 1))


def test_bands_are_compared_as_vectors():
    rng = np.random.default_rng(2)
    truth = np.zeros((80, 120), int)
    truth[:, 50:] = 1
    bands = rng.normal(0, 0.1, (3, 80, 120))
    bands[1] += truth  # the regions differ in the second band only
    labels = ncut_segmentation(bands, n_segments=2, n_superpixels=200)
    assert purity(labels, truth).min() > 0.95 and labels.max() == 1


def test_masked_and_nan_cells_are_minus_one_and_segments_are_connected():
    image, truth = blobs(3, "tiled")
    image[:20, :20] = np.nan
    mask = np.zeros(image.shape, bool)
    mask[60:64, :] = True  # a masked band cutting every region in two
    labels = ncut_segmentation(image, n_segments=3, n_superpixels=600, mask=mask)
    invalid = mask | np.isnan(image)
    assert (labels[invalid] == -1).all() and (labels[~invalid] >= 0).all()
    assert is_one_region_per_label(labels)
    assert not set(np.unique(labels[:60])) & set(np.unique(labels[64:]))
    assert np.array_equal(np.unique(labels[labels >= 0]), np.arange(labels.max() + 1))


def test_segmentation_is_deterministic_and_rejects_bad_input():
    image, _ = blobs(4, "tiled")
    first = ncut_segmentation(image, n_segments=8, n_superpixels=400, seed=5)
    np.testing.assert_array_equal(first, ncut_segmentation(image, n_segments=8,
                                                           n_superpixels=400, seed=5))
    with pytest.raises(ValueError):
        ncut_segmentation(np.full((10, 10), np.nan))
    with pytest.raises(ValueError):
        ncut_segmentation(image, edge_magnitude=np.zeros((3, 3)))
    with pytest.raises(ValueError):
        ncut_segmentation(image, mask=np.zeros((3, 3), bool))


def test_many_segments_over_segment_along_region_borders():
    image, truth = blobs(5, "tiled")
    labels = ncut_segmentation(image, n_segments=40, n_superpixels=800)
    assert 30 <= labels.max() + 1 <= 60
    assert purity(truth, labels).mean() > 0.97  # segments do not straddle the regions


def test_segment_boundaries_are_one_pixel_on_the_upper_left_side():
    labels = np.array([[0, 0, 1],
                       [0, 0, 1],
                       [2, 2, -1]])
    np.testing.assert_array_equal(segment_boundaries(labels), [[0, 1, 0],
                                                               [1, 1, 0],
                                                               [0, 0, 0]])
