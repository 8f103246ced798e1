"""Operations on weighted particle sets: resampling counts and indices, weighted moments.

Used by the IMM particle filter (:mod:`tracking.particles`, seed 001) and by its Gaussian-mixture
summaries (:mod:`tracking.particle_fusion`). Array code: no Python loop over particles.
"""

from __future__ import annotations

import numpy as np
from sensornet.tracking.gaussian import symmetrise


def systematic_counts(weights: np.ndarray, n: np.ndarray | int, u: np.ndarray) -> np.ndarray:
    """Systematic-sampling counts per row: ``weights (R, K)`` normalised rows, ``n`` draws per
    row (scalar or ``(R,)``), offsets ``u (R,)`` in [0, 1). Returns integer ``(R, K)``.

    Points ``(k + u) / n``, ``k < n``; the count in ``(C_(i-1), C_i]`` is
    ``floor(n C_i - u) - floor(n C_(i-1) - u)`` with ``C`` the cumulative weights.
    """
    R, K = weights.shape
    C = np.empty((R, K + 1))
    C[:, 0] = 0.0
    np.cumsum(weights, axis=1, out=C[:, 1:])
    C[:, 1:] /= C[:, -1:]
    C[:, -1] = 1.0
    C *= np.asarray(n, dtype=float).reshape(-1, 1) if np.ndim(n) else float(n)
    C -= u[:, None]
    np.floor(C, out=C)  # floor(n C - u), in place
    f = C[:, 1:] - C[:, :-1]
    return f.astype(np.int64)


def residual_counts(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Residual resampling counts (Liu & Chen 1998) per row of ``weights (R, K)``: ``(R, K)``.

    Deterministic part ``floor(n w_i)`` exactly; the ``n - sum floor(n w)`` remaining draws are
    systematic over the residual weights ``n w_i - floor(n w_i)``.
    """
    nw = weights / weights.sum(axis=1, keepdims=True)
    nw *= n  # n w
    base = np.floor(nw)
    rest = nw
    rest -= base  # n w - floor(n w)
    left = n - base.sum(axis=1)  # (R,) integer-valued
    total = rest.sum(axis=1, keepdims=True)
    if not np.all(total > 0):
        rest = np.where(total > 0, rest, 1.0)
    counts = base.astype(np.int64)
    counts += systematic_counts(rest, left, rng.random(len(weights)))
    return counts


def interaction_indices(mu: np.ndarray, n: int, u: np.ndarray) -> np.ndarray:
    """The IMM-PF interaction draws: for each model ``j``, ``n`` systematic draws (offset
    ``u_j``) from the ``M*n`` particles, model ``i``'s ``n`` particles each weighted
    ``mu_(i|j) / n``. Returns indices ``(M*n,)`` into the particles (model-major), row ``j``
    sorted: the same as ``counts_to_indices(systematic_counts(np.repeat(mu.T, n, axis=1), n,
    u))``, computed from the ``M`` block boundaries instead of a cumulative sum over ``M*n``.

    Draw ``t_k = (k + u_j) / n`` lands in block ``i`` with ``B_(i-1) < t <= B_i`` (``B`` the
    cumulative ``mu_(.|j)``, normalised) and on particle ``l`` of it with
    ``B_(i-1) + l v < t <= B_(i-1) + (l + 1) v``, ``v = mu_(i|j) / n``: ``l = ceil((t -
    B_(i-1)) / v) - 1``. (Empty blocks are skipped: their two boundaries are equal.)
    """
    M = mu.shape[0]
    t = np.arange(n) + u[:, None]
    t /= n  # (j, k) the draws
    if M == 2:  # the same arithmetic on Python floats (IEEE doubles, as NumPy's)
        b0 = [mu[0, j] / (mu[0, j] + mu[1, j]) for j in (0, 1)]  # end of block 0
        hi = t > np.array(b0)[:, None]
        t -= np.where(hi, np.array(b0)[:, None], 0.0)
        t /= np.where(hi, np.array([(1.0 - b) / n for b in b0])[:, None],
                      np.array([b / n for b in b0])[:, None])
        block = np.where(hi, n, 0)
    else:
        B = np.cumsum(mu.T, axis=1)  # (j, i) block ends
        B /= B[:, -1:]
        B[:, -1] = 1.0
        start = np.zeros_like(B)
        start[:, 1:] = B[:, :-1]
        v = (B - start) / n  # (j, i) the mass of one particle of block i
        b = (t[:, :, None] > B[:, None, :-1]).sum(axis=2)
        t -= np.take_along_axis(start, b, axis=1)
        t /= np.take_along_axis(v, b, axis=1)
        block = b * n
    np.ceil(t, out=t)
    t -= 1.0
    np.maximum(t, 0.0, out=t)
    np.minimum(t, n - 1, out=t)
    g = t.astype(np.intp)
    g += block
    return g.reshape(-1)


def counts_to_indices(counts: np.ndarray) -> np.ndarray:
    """Column indices ``(R, n)`` from per-row counts ``(R, K)`` that each sum to ``n``."""
    R, K = counts.shape
    return np.repeat(np.tile(np.arange(K), R), counts.reshape(-1)).reshape(R, -1)


# -- the filter -------------------------------------------------------------------------------


def weighted_moments(X: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(..., d)`` and covariance ``(..., d, d)`` of particles ``X (..., N, d)`` with
    normalised weights ``w (..., N)``.

    Two matrix products per stack entry (BLAS, any memory layout of ``X``, including the
    filter's dimension-major particles): ``mean = w^T X``, ``cov = (D w)^T D``, ``D = X - mean``.
    """
    mean = np.matmul(w[..., None, :], X)[..., 0, :]
    D = X - mean[..., None, :]
    cov = np.matmul(np.swapaxes(D * w[..., None], -1, -2), D)
    return mean, symmetrise(cov)
