"""Closed-form divergences between Gaussian mixtures (the consistency test of :mod:`peers.trust`).

Cauchy–Schwarz divergence (Kampa, Hasanbelliu & Principe 2011, "Closed-form Cauchy-Schwarz PDF
divergence for mixture of Gaussians", IJCNN; Hoang, Vo, Vo & Mahler 2015 use it between
multi-target densities):

``D_CS(p, q) = -log int p q + 1/2 log int p^2 + 1/2 log int q^2``,

with ``int N(x; m_a, P_a) N(x; m_b, P_b) dx = N(m_a; m_b, P_a + P_b)``, so every term is a sum
over component pairs. It is zero iff ``p`` and ``q`` are proportional, so for intensities it
compares *where* the targets are; how many is compared apart (the masses).
"""

from __future__ import annotations

import numpy as np
from sensornet.tracking.gaussian import inv_det_spd, log_gaussian
from sensornet.tracking.mixture import GaussianMixture


def log_overlaps(mixtures: list[GaussianMixture]) -> np.ndarray:
    """``L[i, j] = log int D_i D_j`` for every pair of the (unnormalised) mixtures: ``(n, n)``.

    One matrix of component terms ``log a_a + log b_b + log N(m_a; m_b, P_a + P_b)`` over all
    components, log-sum-exp'ed in blocks (far-apart tight components underflow nothing); an
    empty mixture has ``-inf`` rows and columns.
    """
    n = len(mixtures)
    sizes = np.array([len(D) for D in mixtures], dtype=int)
    L = np.full((n, n), -np.inf)
    if sizes.sum() == 0:
        return L
    w = np.concatenate([D.weights for D in mixtures if len(D)])
    m = np.concatenate([D.means for D in mixtures if len(D)])
    P = np.concatenate([D.covs for D in mixtures if len(D)])
    inv, det = inv_det_spd(P[:, None] + P[None, :])
    with np.errstate(divide="ignore"):
        lw = np.log(w)
    G = lw[:, None] + lw[None, :] + log_gaussian(m[:, None] - m[None, :], inv, det)
    present = np.flatnonzero(sizes)
    starts = np.r_[0, np.cumsum(sizes[present])[:-1]]
    blk = np.repeat(np.arange(len(present)), sizes[present])  # block of each component
    top = np.maximum.reduceat(np.maximum.reduceat(G, starts, axis=0), starts, axis=1)
    safe = np.where(np.isfinite(top), top, 0.0)
    S = np.add.reduceat(np.add.reduceat(np.exp(G - safe[blk][:, blk]), starts, axis=0),
                        starts, axis=1)
    with np.errstate(divide="ignore"):
        L[np.ix_(present, present)] = np.where(np.isfinite(top), safe + np.log(S), -np.inf)
    return L


def cs_from_log_overlaps(lpq: np.ndarray, lpp: np.ndarray, lqq: np.ndarray) -> np.ndarray:
    """``D_CS`` from ``log int pq``, ``log int p^2``, ``log int q^2`` (arrays); ``inf`` where
    ``p`` and ``q`` do not overlap at all, ``nan`` where either is empty."""
    empty = ~np.isfinite(lpp) | ~np.isfinite(lqq)
    with np.errstate(invalid="ignore"):
        out = np.maximum(-lpq + 0.5 * lpp + 0.5 * lqq, 0.0)  # >= 0 (Cauchy-Schwarz)
    return np.where(empty, np.nan, out)


def cs_divergence(p: GaussianMixture, q: GaussianMixture) -> float:
    """The Cauchy–Schwarz divergence of two mixtures (``nan`` if either is empty)."""
    L = log_overlaps([p, q])
    return float(cs_from_log_overlaps(L[0, 1], L[0, 0], L[1, 1]))


__all__ = ["cs_divergence", "cs_from_log_overlaps", "log_overlaps"]
