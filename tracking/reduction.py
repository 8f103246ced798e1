"""Mixture reduction: pruning, merging, capping, ISE weight re-fit (ALGORITHMS.md §4).

Two merge rules share one sweep (take the heaviest remaining component, merge its neighbours
into it by moment matching, repeat):

* ``"vo-ma"``: Vo & Ma 2006, Table II: merge ``i`` into the heaviest ``j`` when
  ``(m_i - m_j)^T P_i^-1 (m_i - m_j) <= U``.
* ``"weighted"``: seed 000 §3.3 level 1: merge when
  ``d^2 = (w_i w_j / (w_i + w_j)) (m_i - m_j)^T P_j^-1 (m_i - m_j) < eta``, ``P_j`` the
  heaviest component's covariance (our reading).

Each sweep step is one array computation over all remaining components; the Python loop runs
once per *output* component.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from tracking.gaussian import inv_det_spd, log_gaussian, symmetrise
from tracking.mixture import GaussianMixture

MERGE_RULES = ("vo-ma", "weighted")


def prune(mix: GaussianMixture, threshold: float) -> GaussianMixture:
    """Drop components with weight below ``threshold``."""
    if len(mix) == 0:
        return mix
    return mix.select(mix.weights >= threshold)


def keep_above(mix: GaussianMixture, threshold: float = 0.5) -> GaussianMixture:
    """Level-2 pruning before publishing (seed 000 §3.3): keep ``w > threshold`` only."""
    if len(mix) == 0:
        return mix
    return mix.select(mix.weights > threshold)


def cap(mix: GaussianMixture, max_components: int) -> GaussianMixture:
    """Keep the ``max_components`` heaviest components."""
    if len(mix) <= max_components:
        return mix
    order = np.argsort(-mix.weights, kind="stable")[:max_components]
    return mix.select(np.sort(order))


def moment_match(weights: np.ndarray, means: np.ndarray, covs: np.ndarray):
    """One Gaussian with the mass, mean and covariance of a group ``(g,), (g,d), (g,d,d)``."""
    w = weights.sum()
    m = weights @ means / w
    diff = means - m
    P = (np.einsum("g,gij->ij", weights, covs) + np.einsum("g,gi,gj->ij", weights, diff, diff)) / w
    return w, m, 0.5 * (P + P.T)


def merge(mix: GaussianMixture, threshold: float, rule: str = "vo-ma") -> GaussianMixture:
    """Greedy merge around the heaviest remaining component (rule ``"vo-ma"`` or ``"weighted"``).

    Output order: the merged components in the order their centres were taken (decreasing
    weight). A cheap exact bound finds the pairs that *can* merge, so the sweep only visits
    components with a possible partner; every other component is its own group (see
    :func:`_merge_candidates`). Groups and results are those of the plain sweep.
    """
    if rule not in MERGE_RULES:
        raise ValueError(f"unknown merge rule {rule!r}; expected one of {MERGE_RULES}")
    n = len(mix)
    if n <= 1:
        return mix
    order = np.argsort(-mix.weights, kind="stable")
    w, m, P = mix.weights[order], mix.means[order], mix.covs[order]  # heaviest first
    cand = _merge_candidates(w, m, P, threshold, rule)  # (n, n): i may merge into centre j
    active = np.flatnonzero(cand.any(axis=0) | cand.any(axis=1))
    if active.size == 0:
        return GaussianMixture(w, m, P)
    inv_active, _ = inv_det_spd(P[active])
    inv = np.empty_like(P)
    inv[active] = inv_active
    out_w, out_m, out_P = w.copy(), m.copy(), P.copy()
    keep = np.ones(n, dtype=bool)
    remaining = active  # sweep positions, heaviest first
    while remaining.size:
        j = remaining[0]
        rest = remaining[1:]
        others = rest[cand[rest, j]]
        if others.size:
            diff = m[others] - m[j]
            if rule == "vo-ma":
                d2 = np.einsum("gi,gij,gj->g", diff, inv[others], diff)
                others = others[d2 <= threshold]
            else:
                wr = w[others]
                d2 = (wr * w[j] / (wr + w[j])) * np.einsum("gi,ij,gj->g", diff, inv[j], diff)
                others = others[d2 < threshold]
        if others.size:
            group = np.concatenate(([j], others))
            out_w[j], out_m[j], out_P[j] = moment_match(w[group], m[group], P[group])
            keep[others] = False
            remaining = np.setdiff1d(rest, others, assume_unique=True)
        else:
            remaining = rest
    return GaussianMixture(out_w[keep], out_m[keep], out_P[keep])


def _merge_candidates(w: np.ndarray, m: np.ndarray, P: np.ndarray, threshold: float,
                      rule: str) -> np.ndarray:
    """``(n, n)`` mask, ``True`` where component ``i`` may be merged into centre ``j``.

    A superset of the pairs within the merge distance, from ``x^T P^-1 x >= |x|^2 / tr P`` (the
    largest eigenvalue of an SPD ``P`` is at most its trace): vo-ma needs
    ``|m_i - m_j|^2 <= U tr P_i``; the weighted rule ``|m_i - m_j|^2 (w_i w_j / (w_i + w_j))
    <= eta tr P_j``. Squared distances come from one Gram product; the bound is widened by a
    margin far above its round-off, so no mergeable pair is missed. The diagonal is False.
    """
    mc = m - m.mean(axis=0)
    sq = np.einsum("ij,ij->i", mc, mc)
    scale = sq[:, None] + sq[None, :]
    dist2 = scale - 2.0 * (mc @ mc.T)
    tr = np.einsum("nii->n", P)
    if rule == "vo-ma":
        bound = threshold * tr[:, None]
    else:
        bound = threshold * tr[None, :] * (w[:, None] + w[None, :]) / (w[:, None] * w[None, :])
    cand = dist2 <= bound * (1.0 + 1e-9) + 1e-9 * scale + 1e-300
    np.fill_diagonal(cand, False)
    return cand


def ise_refit(original: GaussianMixture, reduced: GaussianMixture) -> GaussianMixture:
    """Re-fit the reduced weights to minimise the integral squared error to ``original``.

    ``ISE(w) = w^T A w - 2 b^T w + const`` with ``A_ij = N(m_i; m_j, P_i + P_j)`` over the
    reduced components and ``b_j = sum_a a_a N(m_a; m_j, P_a + P_j)`` (closed form of
    ``int N N``), minimised over ``w >= 0`` with the total mass kept (seed 000 §3.3).
    """
    n = len(reduced)
    if n <= 1 or len(original) == 0:
        return reduced
    A = _cross_overlap(reduced, reduced)
    b = _cross_overlap(reduced, original) @ original.weights
    mass = original.mass
    if mass <= 0:
        return GaussianMixture(np.zeros(n), reduced.means, reduced.covs)
    # Solve for the fractions y = w / mass with the objective scaled to O(1):
    # w^T A w - 2 b^T w = mass^2 s (y^T A' y - 2 b'^T y), A' = A / s, b' = b / (s mass).
    # SLSQP's stopping test on the objective is absolute (ftol), and the raw ISE of 4-D mixtures
    # with covariances of hundreds of m^2 is ~1e-6: unscaled, it stopped at the starting point.
    scale = float(np.max(np.diag(A)))
    As, bs = A / scale, b / (scale * mass)
    y0 = reduced.weights / reduced.mass if reduced.mass > 0 else np.full(n, 1.0 / n)
    res = minimize(
        lambda y: y @ As @ y - 2 * bs @ y,
        y0,
        jac=lambda y: 2 * (As @ y - bs),
        bounds=[(0.0, None)] * n,
        constraints=[{"type": "eq", "fun": lambda y: y.sum() - 1.0, "jac": lambda y: np.ones(n)}],
        method="SLSQP",
        options={"ftol": 1e-12, "maxiter": 200},
    )
    if not res.success or not np.all(np.isfinite(res.x)):
        return reduced
    return GaussianMixture(np.clip(res.x, 0.0, None) * mass, reduced.means, reduced.covs)


def _cross_overlap(g: GaussianMixture, h: GaussianMixture) -> np.ndarray:
    """``int N(x; m_i, P_i) N(x; n_j, Q_j) dx = N(m_i; n_j, P_i + Q_j)``: ``(len g, len h)``."""
    S = g.covs[:, None] + h.covs[None, :]
    inv, det = inv_det_spd(S)
    diff = g.means[:, None] - h.means[None, :]
    return np.exp(log_gaussian(diff, inv, det))


@dataclass(frozen=True)
class Reducer:
    """Level-1 reduction inside a filter: prune, merge, cap, optional ISE re-fit (§4)."""

    prune_threshold: float = 1e-5
    """Components lighter than this are dropped."""
    merge_threshold: float = 5.0
    """Merge distance threshold (``U`` for Vo–Ma, ``eta`` for the weighted rule)."""
    max_components: int = 100
    """Cap on the number of components kept (``Jmax``)."""
    merge_rule: str = "vo-ma"
    """``"vo-ma"`` (plain Mahalanobis) or ``"weighted"`` (seed 000 weighted distance)."""
    refit: bool = False
    """Re-fit the kept weights by minimising the integral squared error."""

    def __post_init__(self) -> None:
        if self.merge_rule not in MERGE_RULES:
            raise ValueError(f"unknown merge rule {self.merge_rule!r}; expected {MERGE_RULES}")

    def __call__(self, mix: GaussianMixture) -> GaussianMixture:
        pruned = prune(mix, self.prune_threshold)
        reduced = cap(merge(pruned, self.merge_threshold, self.merge_rule), self.max_components)
        if self.refit:
            reduced = ise_refit(pruned, reduced)
        return GaussianMixture(reduced.weights, reduced.means, symmetrise(reduced.covs))


__all__ = [
    "MERGE_RULES",
    "Reducer",
    "cap",
    "ise_refit",
    "keep_above",
    "merge",
    "moment_match",
    "prune",
]
