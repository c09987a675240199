"""Gradient vector flow (Xu & Prince, 1997), the snakes' external force (Boyko & Funkhouser,
2011, Sec. 2.4, Eq. 7).

The GVF field ``(u, v)`` of an edge map ``f`` minimises

    E = integral  mu (u_x^2 + u_y^2 + v_x^2 + v_y^2) + |grad f|^2 |(u, v) - grad f|^2

so it equals ``grad f`` where the edge map changes and varies smoothly elsewhere: the
attraction of an edge reaches far into flat regions, which widens a snake's capture range.
It is found by the explicit iteration of the Euler equations (Xu & Prince, Eq. 12-14):

    u <- u + dt (mu laplacian(u) - |grad f|^2 (u - f_x))

in pixel units, stable for ``dt mu <= 1/4`` and ``dt max|grad f|^2 <= 1``; ``f`` is scaled
to [0, 1] first, as Xu & Prince do.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import GisroadsError

#: Xu & Prince use mu = 0.2 on edge maps scaled to [0, 1] (pixel units); at dt = 1 it keeps
#: dt mu below the 1/4 of the stability bound.
MU = 0.2
#: About 9 pixels of reach (sqrt(4 mu n)): 4-5 m on the 0.5 m attractor grid. A longer reach
#: lets a kerb pull the opposite side of a ribbon across the road where its own kerb has a
#: gap (a drive, a side street), and the ribbon collapses onto one kerb.
MAX_ITERATIONS = 100
TOLERANCE = 1e-4


def gradient_vector_flow(edge_map: np.ndarray, *, mu: float = MU,
                         iterations: int = MAX_ITERATIONS, tolerance: float = TOLERANCE,
                         normalise: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """GVF field of an edge map (Xu & Prince, 1997).

    Parameters
    ----------
    edge_map : ndarray, shape (rows, cols)
        Large on the edges to attract to (here the attractor map ``a``).
    mu : float
        Regularisation weight (pixel units), at most 0.25.
    iterations : int
        Largest number of iterations; the reach of the field grows as the square root of
        the iterations times ``mu`` (pixels).
    tolerance : float
        Stop when no component changes by more than this (edge-map units per pixel) in an
        iteration.
    normalise : bool
        Scale the edge map to [0, 1] first (a constant map gives a zero field).

    Returns
    -------
    u, v : ndarray, shape (rows, cols)
        Components along the array's columns (``u``) and rows (``v``), edge-map units per
        pixel; they point towards the edges.
    """
    f = np.asarray(edge_map, dtype=float)
    if f.ndim != 2:
        raise GisroadsError(f"edge_map must be 2-D, got shape {f.shape}")
    if not np.isfinite(f).all():
        raise GisroadsError("edge_map holds NaN or infinite values")
    if not 0 < mu <= 0.25:
        raise GisroadsError(f"mu must lie in (0, 0.25] for a stable iteration, got {mu}")
    if normalise:
        span = f.max() - f.min()
        f = (f - f.min()) / span if span > 0 else np.zeros_like(f)
    fy, fx = np.gradient(f)
    magnitude = fx ** 2 + fy ** 2
    # dt |grad f|^2 <= 1 keeps the data term from overshooting
    dt = min(1.0, 1.0 / max(float(magnitude.max()), 1e-12))
    u, v = fx.copy(), fy.copy()
    for _ in range(iterations):
        du = dt * (mu * ndimage.laplace(u, mode="nearest") - magnitude * (u - fx))
        dv = dt * (mu * ndimage.laplace(v, mode="nearest") - magnitude * (v - fy))
        u += du
        v += dv
        if max(np.abs(du).max(), np.abs(dv).max()) < tolerance:
            break
    return u, v
