"""Road rectangles that best explain the likelihood maps: Zhu & Mordohai's minimum cover
(Sec. 4.4, Algorithm 2).

Elements, sets and costs
------------------------
Seeds ``s_j`` are points sampled every ``seed_step_m`` along the centre lines of the
hypotheses (:func:`cover_seeds`). Hypothesis ``R_i`` of width index ``k_i`` covers the seeds
inside its rectangle. With ``p_k(s_j) = min(L_k(s_j), L_max) / L_max`` (the likelihood map of
width ``k`` at the seed, :func:`seed_likelihood`):

- covering ``s_j`` by ``R_i`` costs ``C_i(s_j) = 1 - p_{k_i}(s_j)``, the likelihood of the
  covering rectangle's own width, so rectangles of the right width cover more cheaply
  (the width competition of Fig. 3, case 3);
- a rectangle costs ``Cost(R_i) = sum_{s_j in R_i} C_i(s_j) + A`` (Eq. 6);
- a seed left uncovered (its dummy set) costs ``max_k p_k(s_j)``, the loss of missing it
  whatever its width;
- seeds where every map is NaN or nodata, or off the maps, are no elements at all;
- a selection ``R_S`` costs ``Cost_cover = sum_{R_i in R_S} Cost(R_i) + sum_{s_j uncovered}
  max_k p_k(s_j)`` (Eq. 7, :func:`cover_cost`). Seeds inside several selected rectangles
  are paid by each, as Eq. 6 sums over all seeds of a rectangle.

Two solvers
-----------
:func:`greedy_min_cover` is Algorithm 2: repeatedly take the hypothesis of least density
``(sum of C_i over its new seeds + A) / (number of new seeds)`` and stop when every seed is
covered or the least density exceeds ``d_max``; the seeds left over go to their dummy sets.
Eq. 8 as printed puts ``A`` inside the sum over new seeds, which would add the same ``A``
to every density and let it play no part; we use ``A`` once per rectangle, as the text
explains it (a fixed cost per rectangle). Unlike the textbook greedy for weighted set cover
(Vazirani 2004, ch. 2), whose density is ``Cost(R_i) / |new|``, Eq. 8 charges only the new
seeds' costs, so overlaps cost nothing while choosing; the ``H(max |R_i|)`` guarantee of the
textbook greedy is therefore not a theorem here, and the tests check it empirically.
:func:`exact_min_cover` solves Eq. 7 exactly as an integer program (PuLP with CBC).

Defaults (the paper gives none)
-------------------------------
``A = 10`` (:data:`A`): with seeds every 2 m, a rectangle on perfect road (``C = 0``) reaches
density 0.5 at 20 seeds, i.e. 40 m, the shortest hypothesis of Sec. 4.3; so
shorter stretches are not taken on their own, and an occlusion gap of up to ~``A`` seeds
inside a long rectangle is cheaper to cover than to split the road at. ``d_max = 1``
(:data:`D_MAX`): a seed costs at most 1 to cover (``p = 0``), so a rectangle of density
above 1 costs more per new seed than covering ground with no evidence at all; at or below
it, its new seeds' mean ``p`` pays for the fixed cost ``A``. The break-even of covering
(``1 - p``) against missing (about ``p``) would be 0.5, but real roads rarely saturate the
maps. Measured end to end (stages 4-6 on one 300 m tile, buffer 3 m, once the hypotheses
had to sit on the road's edges): d_max 0.7 / 0.85 / 1.0 gave completeness / correctness
0.96/0.98, 0.99/0.97, 0.99/0.97 on a grid with buildings and trees, 0.90/0.98, 0.91/0.98,
0.93/0.97 with every feature, and 0.39/1.0, 0.47/1.0, 0.54/0.88 on fusa.laz; no road on
zurich.laz, crop_1.laz or Megaplot.laz at any of them.
``l_max`` defaults to the maps' maximum, which is ``L_max`` for maps capped at it (Sec. 4.3).

References
----------
Zhu, Q., Mordohai, P. (2009). A minimum cover approach for extracting the road network from
airborne LIDAR data. ICCV Workshops, 1582-1589.
Vazirani, V. (2004). *Approximation Algorithms*. Springer.
"""
from __future__ import annotations

from dataclasses import dataclass

import geopandas as gpd
import numpy as np
import pulp
import shapely
from scipy.sparse import csr_matrix

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..optimize import solver, variable
from ..progress import Progress, report
from ..vectorize.ribbons import rectangle_centrelines

#: Fixed cost of a rectangle, in units of one seed's cost (Eq. 6); see the module docstring.
A = 10.0
#: Greatest density the greedy cover accepts (Algorithm 2); see the module docstring.
D_MAX = 1.0
#: Spacing of the seeds along the hypotheses' centre lines, metres.
SEED_STEP_M = 2.0

def cover_seeds(hypotheses: gpd.GeoDataFrame, *, seed_step_m: float = SEED_STEP_M):
    """Seeds along the hypotheses' centre lines and which hypotheses cover which seeds.

    Each centre line (:func:`gisroads.vectorize.rectangle_centrelines`) of length ``l`` gets
    ``n = max(1, round(l / seed_step_m))`` seeds at the middles of ``n`` equal parts. Samples
    falling in the same cell of a ``seed_step_m`` grid (cells ``floor(xy / seed_step_m)``)
    are one seed, placed at the first of them, so overlapping centre lines share seeds
    instead of counting the same ground twice. A hypothesis covers the seeds inside or on
    its rectangle (its polygon); every seed is covered by at least the hypothesis it was
    sampled from.

    Parameters
    ----------
    hypotheses : GeoDataFrame
        Rectangles (polygons, metre CRS) with ``theta_rad``.
    seed_step_m : float
        Seed spacing and merging grid, metres.

    Returns
    -------
    seeds_xy : ndarray, shape (m, 2)
    membership : scipy.sparse.csr_matrix of bool, shape (n_hypotheses, m)
    """
    lines = rectangle_centrelines(hypotheses)
    n = len(lines)
    if n == 0:
        return np.empty((0, 2)), csr_matrix((0, 0), dtype=bool)
    ends = shapely.get_coordinates(lines).reshape(n, 2, 2)
    length = shapely.length(lines)
    count = np.maximum(1, np.round(length / seed_step_m)).astype(np.int64)
    owner = np.repeat(np.arange(n), count)
    rank = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
    fraction = ((rank + 0.5) / count[owner])[:, None]
    samples = ends[owner, 0] + fraction * (ends[owner, 1] - ends[owner, 0])
    cells = np.floor(samples / seed_step_m).astype(np.int64)
    cells -= cells.min(axis=0)
    cell_key = cells[:, 0] * (cells[:, 1].max() + 1) + cells[:, 1]
    _, first = np.unique(cell_key, return_index=True)
    seeds_xy = samples[np.sort(first)]
    hyp, seed = shapely.STRtree(shapely.points(seeds_xy)).query(
        hypotheses.geometry.values, predicate="intersects")
    membership = csr_matrix((np.ones(len(hyp), dtype=bool), (hyp, seed)),
                            shape=(n, len(seeds_xy)))
    membership.sort_indices()
    return seeds_xy, membership


def seed_likelihood(seeds_xy, likelihood: GeoRaster) -> np.ndarray:
    """Likelihood of every width at every seed: ``L_k(s_j)``, shape ``(K, m)``.

    The value of the pixel containing the seed; NaN (no evidence) outside the raster and on
    nodata pixels. The cost of seed ``j`` in a hypothesis of width index ``k`` is
    ``1 - L[k, j] / l_max``; its dummy-set cost is ``L[:, j].max() / l_max`` (both with
    ``L`` capped at ``l_max``, see the module docstring).

    Parameters
    ----------
    seeds_xy : array_like, shape (m, 2)
    likelihood : GeoRaster
        ``(K, rows, cols)`` maps ``L_k``, band ``k`` for width index ``k``; a 2-D raster is
        one width.
    """
    seeds_xy = np.asarray(seeds_xy, float).reshape(-1, 2)
    data = likelihood.data if likelihood.data.ndim == 3 else likelihood.data[None]
    rows, cols = likelihood.xy_to_rowcol(seeds_xy[:, 0], seeds_xy[:, 1])
    inside = (rows >= 0) & (rows < data.shape[1]) & (cols >= 0) & (cols < data.shape[2])
    values = np.full((data.shape[0], len(seeds_xy)), np.nan)
    values[:, inside] = data[:, rows[inside], cols[inside]]
    if likelihood.nodata is not None:
        values[values == likelihood.nodata] = np.nan
    return values


@dataclass(frozen=True)
class _CoverProblem:
    """The set-cover instance of the module docstring, built once per call."""

    membership: csr_matrix     # (n, m) bool: hypothesis i covers seed j
    seed_cost: csr_matrix      # (n, m) C_i(s_j) on the pattern of membership
    dummy_cost: np.ndarray     # (m,) max_k p_k(s_j)
    hyp_cost: np.ndarray       # (n,) Cost(R_i), Eq. 6
    mean_likelihood: np.ndarray  # (n,) mean L_{k_i} over the hypothesis's seeds


def _cover_problem(hypotheses, likelihood, *, l_max, a, seed_step_m) -> _CoverProblem:
    seeds_xy, membership = cover_seeds(hypotheses, seed_step_m=seed_step_m)
    values = seed_likelihood(seeds_xy, likelihood)
    # seeds off the maps carry no evidence: leaving them out keeps rectangles that reach
    # past a tile's edge from paying for the ground beyond it
    has_data = np.isfinite(values).any(axis=0)
    values, membership = np.nan_to_num(values[:, has_data]), membership[:, has_data]
    if l_max is None:
        l_max = float(np.nanmax(likelihood.data))
    if not l_max > 0:
        raise GisroadsError(f"l_max must be positive, got {l_max}")
    p = np.clip(values / l_max, 0.0, 1.0)
    width_index = hypotheses["width_index"].to_numpy(np.int64)
    if len(width_index) and (width_index.min() < 0 or width_index.max() >= len(p)):
        raise GisroadsError(f"width_index outside the {len(p)} likelihood bands")
    hyp, seed = membership.nonzero()
    cost = 1.0 - p[width_index[hyp], seed]
    seed_cost = csr_matrix((cost, (hyp, seed)), shape=membership.shape)
    seed_cost.sort_indices()
    size = np.asarray(membership.sum(axis=1)).ravel()
    hyp_cost = np.asarray(seed_cost.sum(axis=1)).ravel() + a
    covered_l = np.bincount(hyp, weights=np.minimum(values[width_index[hyp], seed], l_max),
                            minlength=len(size))
    return _CoverProblem(membership, seed_cost, p.max(axis=0) if p.size else np.zeros(0),
                         hyp_cost, covered_l / np.maximum(size, 1))


def _greedy(problem: _CoverProblem, *, a: float, d_max: float, candidates=None,
            progress: Progress = None):
    """Algorithm 2 on a built problem; returns (selected positions, densities)."""
    membership, n_seeds = problem.membership, problem.membership.shape[1]
    by_seed = membership.tocsc()
    cost_by_seed = problem.seed_cost.tocsc()
    uncovered = np.ones(n_seeds, dtype=bool)
    new_count = np.asarray(membership.sum(axis=1), float).ravel()
    new_cost = np.asarray(problem.seed_cost.sum(axis=1)).ravel()
    allowed = np.ones(len(new_count), bool) if candidates is None else candidates
    selected, densities = [], []
    while uncovered.any():
        with np.errstate(divide="ignore", invalid="ignore"):
            density = np.where(allowed & (new_count > 0), (new_cost + a) / new_count, np.inf)
        best = int(np.argmin(density))
        if not (np.isfinite(density[best]) and density[best] <= d_max):
            break
        selected.append(best)
        densities.append(float(density[best]))
        seeds = membership.indices[membership.indptr[best]:membership.indptr[best + 1]]
        newly = seeds[uncovered[seeds]]
        uncovered[newly] = False
        new_count -= np.asarray(by_seed[:, newly].sum(axis=1)).ravel()
        new_cost -= np.asarray(cost_by_seed[:, newly].sum(axis=1)).ravel()
        report(progress, 1.0 - uncovered.mean(), f"minimum cover: {len(selected)} rectangles")
    report(progress, 1.0, f"minimum cover: {len(selected)} rectangles")
    return np.array(selected, dtype=np.int64), np.array(densities)


def _total_cost(problem: _CoverProblem, positions) -> float:
    """Eq. 7 for the hypotheses at ``positions``."""
    positions = np.asarray(positions, dtype=np.int64)
    covered = np.zeros(problem.membership.shape[1], dtype=bool)
    covered[problem.membership[positions].indices] = True
    return float(problem.hyp_cost[positions].sum() + problem.dummy_cost[~covered].sum())


def _selected_frame(hypotheses, problem, positions, densities) -> gpd.GeoDataFrame:
    frame = hypotheses.iloc[positions].copy()
    frame["orientation_deg"] = np.degrees(frame["theta_rad"].to_numpy(float)) % 180.0
    frame["cost"] = problem.hyp_cost[positions]
    frame["density"] = densities
    frame["mean_likelihood"] = problem.mean_likelihood[positions]
    frame["order"] = np.arange(len(positions), dtype=np.int64)
    frame = frame.reset_index(drop=True)
    frame.attrs["cover_cost"] = _total_cost(problem, positions)
    return frame


def greedy_min_cover(hypotheses: gpd.GeoDataFrame, likelihood: GeoRaster, *,
                     l_max: float | None = None, a: float = A, d_max: float = D_MAX,
                     seed_step_m: float = SEED_STEP_M,
                     progress: Progress = None) -> gpd.GeoDataFrame:
    """Select road rectangles by Zhu & Mordohai's greedy minimum cover (Algorithm 2).

    See the module docstring for the seeds, costs and density. Each iteration updates every
    hypothesis's count and cost of new seeds by sparse sums over the columns of the seeds
    just covered.

    Parameters
    ----------
    hypotheses : GeoDataFrame
        Rectangles in a metre CRS with ``hyp_id``, ``theta_rad`` (road direction, radians
        counter-clockwise from east) and ``width_index`` (band of ``likelihood``).
    likelihood : GeoRaster
        ``(K, rows, cols)`` likelihood maps ``L_k`` (Eq. 5) in the hypotheses' CRS.
    l_max : float, optional
        ``L_max`` of Sec. 4.3; default the maps' maximum.
    a : float
        ``A`` of Eq. 6, the fixed cost of a rectangle.
    d_max : float
        ``D_max`` of Algorithm 2, the greatest density accepted.
    seed_step_m : float
        Seed spacing, metres (:func:`cover_seeds`).
    progress : callable, optional
        ``progress(fraction, message)``, fraction of seeds covered.

    Returns
    -------
    GeoDataFrame
        The selected hypotheses in selection order, with all their columns plus
        ``orientation_deg`` (``theta_rad`` in degrees modulo 180), ``cost`` (Eq. 6),
        ``density`` (Eq. 8 when selected), ``mean_likelihood`` (mean ``L_k`` of its own
        width over its seeds) and ``order`` (0, 1, ...). ``attrs["cover_cost"]`` is the
        selection's Eq. 7 cost.
    """
    problem = _cover_problem(hypotheses, likelihood, l_max=l_max, a=a,
                             seed_step_m=seed_step_m)
    positions, densities = _greedy(problem, a=a, d_max=d_max, progress=progress)
    return _selected_frame(hypotheses, problem, positions, densities)


def _identical_columns(membership: csr_matrix):
    """Groups of seeds covered by exactly the same hypotheses, via two random projections
    of the membership columns (equal sets give bit-identical sums)."""
    weights = np.random.default_rng(0).random((membership.shape[0], 2))
    keys = membership.T.tocsr().astype(float) @ weights
    _, first, group = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return first, group.ravel()


def exact_min_cover(hypotheses: gpd.GeoDataFrame, likelihood: GeoRaster, *,
                    l_max: float | None = None, a: float = A,
                    seed_step_m: float = SEED_STEP_M,
                    time_limit_s: float = 60.0) -> gpd.GeoDataFrame:
    """Select road rectangles minimising Eq. 7 exactly, as an integer program.

    Binary ``x_i`` per hypothesis, ``u_j`` per seed (left uncovered): minimise
    ``sum Cost(R_i) x_i + sum max_k p_k(s_j) u_j`` subject to ``sum_{i covers j} x_i + u_j >= 1``
    for every seed. Seeds covered by the same hypotheses share one constraint and one
    ``u`` (their dummy costs summed); ``u`` may be continuous, as it is 0 or 1 at every
    optimum. The greedy selection is passed to CBC as a starting solution.

    Parameters
    ----------
    hypotheses, likelihood, l_max, a, seed_step_m
        As in :func:`greedy_min_cover`.
    time_limit_s : float
        CBC's time limit, seconds; past it the best solution found is returned.

    Returns
    -------
    GeoDataFrame
        As :func:`greedy_min_cover`; ``order`` and ``density`` are those of the greedy
        replayed on the selected rectangles alone (a rectangle adding no seed comes last,
        with density ``inf``). ``attrs["optimal"]`` tells whether CBC proved optimality.
    """
    problem = _cover_problem(hypotheses, likelihood, l_max=l_max, a=a,
                             seed_step_m=seed_step_m)
    membership = problem.membership
    n = membership.shape[0]
    greedy, _ = _greedy(problem, a=a, d_max=D_MAX)
    first, group = _identical_columns(membership)
    by_seed = membership.tocsc()
    dummy = np.bincount(group, weights=problem.dummy_cost, minlength=len(first))
    model = pulp.LpProblem("min_cover", pulp.LpMinimize)
    x = [variable(model, f"x{i}", cat=pulp.LpBinary) for i in range(n)]
    u = [variable(model, f"u{g}", lowBound=0, upBound=1) for g in range(len(first))]
    model += pulp.lpDot(problem.hyp_cost.tolist(), x) + pulp.lpDot(dummy.tolist(), u)
    for g, j in enumerate(first):
        covering = by_seed.indices[by_seed.indptr[j]:by_seed.indptr[j + 1]]
        model += pulp.LpAffineExpression([(x[i], 1) for i in covering] + [(u[g], 1)]) >= 1
    for x_i, start in zip(x, np.isin(np.arange(n), greedy)):
        x_i.setInitialValue(int(start))
    model.solve(solver(time_limit_s=time_limit_s, warm_start=True))
    chosen = np.flatnonzero([(v.varValue or 0) > 0.5 for v in x])
    positions, densities = _greedy(problem, a=a, d_max=np.inf,
                                   candidates=np.isin(np.arange(n), chosen))
    redundant = np.setdiff1d(chosen, positions)   # only in a solution cut short by the limit
    frame = _selected_frame(hypotheses, problem, np.concatenate([positions, redundant]),
                            np.concatenate([densities, np.full(len(redundant), np.inf)]))
    frame.attrs["optimal"] = model.sol_status == pulp.LpSolutionOptimal
    return frame


def cover_cost(selected_ids, hypotheses: gpd.GeoDataFrame, likelihood: GeoRaster, *,
               l_max: float | None = None, a: float = A,
               seed_step_m: float = SEED_STEP_M) -> float:
    """Eq. 7: the cost of covering the seeds with the hypotheses ``selected_ids``.

    Parameters
    ----------
    selected_ids : array_like
        ``hyp_id`` values of the selection.
    hypotheses, likelihood, l_max, a, seed_step_m
        As in :func:`greedy_min_cover`.
    """
    problem = _cover_problem(hypotheses, likelihood, l_max=l_max, a=a,
                             seed_step_m=seed_step_m)
    positions = np.flatnonzero(np.isin(hypotheses["hyp_id"].to_numpy(), selected_ids))
    return _total_cost(problem, positions)
