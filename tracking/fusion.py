"""Fusion of Gaussian-mixture intensities: GCI, AA, Metropolis weights (ALGORITHMS.md §3).

The GCI formula lives here, once. For two mixtures ``D_i = sum_a``, ``D_j = sum_b`` and weight
``omega`` (seed 000 eq. 14-17; Uney, Clark & Julier 2013), with ``C = omega P_a + (1-omega) P_b``:

* ``P_ab = [(1-omega) P_a^-1 + omega P_b^-1]^-1 = P_a C^-1 P_b``
* ``m_ab = P_ab [(1-omega) P_a^-1 m_a + omega P_b^-1 m_b] = m_a + omega P_a C^-1 (m_b - m_a)``
* ``w_ab = w_a^(1-omega) w_b^omega kappa(1-omega, P_a) kappa(omega, P_b)
  N(m_a - m_b; 0, P_a/(1-omega) + P_b/omega)``, and ``P_a/(1-omega) + P_b/omega =
  C / (omega (1-omega))``.

The right-hand forms (identity: ``(1-omega) P_a^-1 + omega P_b^-1 = P_a^-1 C P_b^-1``) need one
inverse per pair instead of three; with the closed-form 4x4 inverse the ``N_i x N_j`` pairs are a
single array computation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import minimize_scalar

from tracking.gaussian import (
    LOG_2PI,
    SYM4_INDEX,
    inv_det_spd,
    sym4_assemble,
    sym4_inverse_entries,
    symmetrise,
)
from tracking.mixture import GaussianMixture

Reduce = Callable[[GaussianMixture], GaussianMixture]


def log_kappa(omega: float, logdet: np.ndarray, d: int) -> np.ndarray:
    """``log kappa(omega, P)``, ``kappa = det(2 pi P / omega)^(1/2) / det(2 pi P)^(omega/2)``."""
    return 0.5 * (1.0 - omega) * (d * LOG_2PI + logdet) - 0.5 * d * np.log(omega)


def gci_pair(Di: GaussianMixture, Dj: GaussianMixture, omega: float) -> GaussianMixture:
    """GCI of two mixtures, ``D_i^(1-omega) D_j^omega``, one component per pair (a, b).

    Computed in information form: ``Y_ab = (1-omega) Y_a + omega Y_b`` (``Y = P^-1``),
    ``P_ab = Y_ab^-1``, ``m_ab = P_ab ((1-omega) Y_a m_a + omega Y_b m_b)``; the weight's
    ``C^-1 = Y_b P_ab Y_a`` and ``det C = det Y_ab det P_a det P_b`` (from ``Y_ab = Y_a C Y_b``).
    """
    if not 0.0 <= omega <= 1.0:
        raise ValueError(f"GCI weight omega must be in [0, 1], got {omega}")
    if omega == 0.0:
        return Di
    if omega == 1.0:
        return Dj
    d = Di.dim
    na, nb = len(Di), len(Dj)
    if na == 0 or nb == 0:
        return GaussianMixture.empty(d)
    Ya, det_a = inv_det_spd(Di.covs)
    Yb, det_b = inv_det_spd(Dj.covs)
    ma, mb = Di.means, Dj.means
    ha = np.einsum("aij,aj->ai", Ya, ma)  # (na, d)
    hb = np.einsum("bij,bj->bi", Yb, mb)  # (nb, d)
    # u = Y_a (m_b - m_a), v = Y_b (m_b - m_a), each (d, na, nb), via two small GEMMs
    u = (Ya.reshape(na * d, d) @ mb.T).reshape(na, d, nb).transpose(1, 0, 2) - ha.T[:, :, None]
    v = hb.T[:, None, :] - (Yb.reshape(nb * d, d) @ ma.T).reshape(nb, d, na).transpose(1, 2, 0)
    info = (1.0 - omega) * ha.T[:, :, None] + omega * hb.T[:, None, :]  # (d, na, nb)
    Ya_t = np.moveaxis(Ya, 0, -1)[..., :, None]  # (d, d, na, 1)
    Yb_t = np.moveaxis(Yb, 0, -1)[..., None, :]  # (d, d, 1, nb)
    if d == 4:
        entries, det_y = sym4_inverse_entries(
            *((1.0 - omega) * Ya_t[i, j] + omega * Yb_t[i, j] for i, j in SYM4_INDEX)
        )
        P = {}
        for (i, j), e in zip(SYM4_INDEX, entries, strict=True):
            P[i, j] = P[j, i] = e
        means_t = np.stack([sum(P[i, j] * info[j] for j in range(4)) for i in range(4)])
        quad = sum(v[i] * sum(P[i, j] * u[j] for j in range(4)) for i in range(4))
        covs = sym4_assemble(entries, (na, nb)).reshape(na * nb, 4, 4)
    else:
        Y = np.moveaxis((1.0 - omega) * Ya_t + omega * Yb_t, (0, 1), (-2, -1))  # (na, nb, d, d)
        Pab, det_y = inv_det_spd(Y)
        means_t = np.einsum("abij,jab->iab", Pab, info)
        quad = np.einsum("iab,abij,jab->ab", v, Pab, u)
        covs = symmetrise(Pab).reshape(na * nb, d, d)
    oo = omega * (1.0 - omega)
    log_det_c = np.log(det_y) + np.log(det_a)[:, None] + np.log(det_b)[None, :]
    log_n = -0.5 * (oo * quad + log_det_c - d * np.log(oo) + d * LOG_2PI)
    with np.errstate(divide="ignore"):
        log_w = (
            (1.0 - omega) * np.log(Di.weights)[:, None]
            + omega * np.log(Dj.weights)[None, :]
            + log_kappa(1.0 - omega, np.log(det_a), d)[:, None]
            + log_kappa(omega, np.log(det_b), d)[None, :]
            + log_n
        )
    means = np.moveaxis(means_t, 0, -1).reshape(na * nb, d)
    return GaussianMixture(np.exp(log_w).reshape(-1), means, covs)


CARDINALITY_RULES = ("emd", "separate")


def gci_combine(Di: GaussianMixture, Dj: GaussianMixture, omega: float,
                cardinality: str = "emd") -> GaussianMixture:
    """GCI of two intensities with a choice of how the fused mass (target number) is formed.

    ``"emd"``: the exponential mixture of two Poisson processes is Poisson with intensity
    ``D_i^(1-omega) D_j^omega`` (Uney, Clark & Julier 2013): exactly :func:`gci_pair`. Its mass
    is at most ``N_i^(1-omega) N_j^omega`` and drops whenever the peers' estimates of a target
    differ, so fused PHDs under-count targets.
    ``"separate"``: location densities and cardinality distributions fused separately, as in
    the consensus CPHD of Battistelli et al. 2013 (seed 000 ref. [13]): the normalised product
    ``p_i^(1-omega) p_j^omega`` scaled to the GCI of the Poisson cardinalities, whose mean is
    ``N_i^(1-omega) N_j^omega`` (our reading for PHD peers).
    """
    if cardinality == "emd":
        return gci_pair(Di, Dj, omega)
    if cardinality != "separate":
        raise ValueError(f"unknown cardinality rule {cardinality!r}; expected {CARDINALITY_RULES}")
    Ni, Nj = Di.mass, Dj.mass
    if Ni <= 0 or Nj <= 0:
        return GaussianMixture.empty(Di.dim)
    fused = gci_pair(Di.scaled(1.0 / Ni), Dj.scaled(1.0 / Nj), omega)
    c = fused.mass
    if not c > 0:
        return GaussianMixture.empty(Di.dim)
    return fused.scaled(Ni ** (1.0 - omega) * Nj**omega / c)


def gci_fuse(
    densities: Sequence[GaussianMixture],
    weights: Sequence[float],
    reduce: Reduce | None = None,
    normalise: bool = False,
    cardinality: str = "emd",
) -> GaussianMixture:
    """n-ary GCI ``prod_i D_i^(omega_i)`` by sequential pairing (§3), reducing after each step.

    Step ``i`` fuses the running result (weight ``s = omega_0 + ... + omega_(i-1)``) with the
    newcomer at ``omega = omega_i / (s + omega_i)``. ``normalise`` gives a unit-mass result
    (single-target densities; with one Gaussian each this is covariance intersection).
    ``cardinality``: see :func:`gci_combine`.
    """
    densities, weights = _check_weights(densities, weights)
    acc, s = None, 0.0
    for D, w in zip(densities, weights, strict=True):
        if w <= 0.0:
            continue
        if acc is None:
            acc, s = D, w
            continue
        acc = gci_combine(acc, D, w / (s + w), cardinality)
        s += w
        if reduce is not None:
            acc = reduce(acc)
    assert acc is not None
    if normalise and acc.mass > 0:
        acc = acc.normalised()
    return acc


def aa_fuse(
    densities: Sequence[GaussianMixture],
    weights: Sequence[float],
    reduce: Reduce | None = None,
) -> GaussianMixture:
    """Arithmetic average ``sum_i omega_i D_i`` (seed 004 baseline): union, scaled, reduced."""
    densities, weights = _check_weights(densities, weights)
    fused = GaussianMixture.concatenate([D.scaled(w) for D, w in zip(densities, weights,
                                                                       strict=True)])
    return reduce(fused) if reduce is not None else fused


def _check_weights(densities, weights):
    densities, weights = list(densities), [float(w) for w in weights]
    if not densities or len(densities) != len(weights):
        raise ValueError(f"need one weight per density ({len(densities)} vs {len(weights)})")
    if any(w < 0 for w in weights) or not np.isclose(sum(weights), 1.0):
        raise ValueError(f"fusion weights must be non-negative and sum to 1, got {weights}")
    return densities, weights


def metropolis_weights(adjacency: np.ndarray) -> np.ndarray:
    """Metropolis weights ``omega_ij = 1/(1 + max(deg_i, deg_j))`` on edges, ``omega_ii = 1 - sum``.

    ``adjacency (n, n)`` symmetric boolean without self-loops; returns a doubly stochastic
    ``(n, n)`` matrix (Battistelli et al. 2013, the consensus of seed 000 ref. [13]).
    """
    A = np.asarray(adjacency, dtype=bool)
    if A.ndim != 2 or A.shape[0] != A.shape[1] or not np.array_equal(A, A.T):
        raise ValueError("adjacency must be a symmetric square matrix")
    A = A & ~np.eye(len(A), dtype=bool)
    deg = A.sum(axis=1)
    W = np.where(A, 1.0 / (1.0 + np.maximum(deg[:, None], deg[None, :])), 0.0)
    W[np.diag_indices_from(W)] = 1.0 - W.sum(axis=1)
    return W


def optimal_omega(Di: GaussianMixture, Dj: GaussianMixture, criterion: str = "det") -> float:
    """The ``omega`` in [0, 1] chosen per fusion (§3, our reading).

    ``"det"``: minimise the determinant of the fused (normalised, moment-matched) covariance.
    ``"chernoff"``: minimise the mass of ``p_i^(1-omega) p_j^omega`` of the normalised inputs
    (the Chernoff point).
    """
    if len(Di) == 0 or len(Dj) == 0:
        return 0.5
    pi, pj = Di.normalised(), Dj.normalised()

    def cost(omega: float) -> float:
        fused = gci_pair(pi, pj, omega)
        if fused.mass <= 0 or not np.isfinite(fused.mass):
            return np.inf
        if criterion == "det":
            _, cov = fused.moments()
            return float(np.linalg.slogdet(cov)[1])
        if criterion == "chernoff":
            return fused.mass
        raise ValueError(f"unknown omega criterion {criterion!r}; expected 'det' or 'chernoff'")

    res = minimize_scalar(cost, bounds=(1e-3, 1 - 1e-3), method="bounded",
                          options={"xatol": 1e-3})
    return float(res.x)


def gci_fuse_optimised(
    densities: Sequence[GaussianMixture],
    criterion: str = "det",
    reduce: Reduce | None = None,
    cardinality: str = "emd",
) -> GaussianMixture:
    """Sequential GCI where each step's ``omega`` is chosen by :func:`optimal_omega`."""
    densities = list(densities)
    if not densities:
        raise ValueError("need at least one density to fuse")
    acc = densities[0]
    for D in densities[1:]:
        acc = gci_combine(acc, D, optimal_omega(acc, D, criterion), cardinality)
        if reduce is not None:
            acc = reduce(acc)
    return acc
