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
    """Greedy merge around the heaviest remaining component (rule ``"vo-ma"`` or ``"weighted"``)."""
    if rule not in MERGE_RULES:
        raise ValueError(f"unknown merge rule {rule!r}; expected one of {MERGE_RULES}")
    n = len(mix)
    if n <= 1:
        return mix
    w, m, P = mix.weights, mix.means, mix.covs
    inv, _ = inv_det_spd(P)
    remaining = np.argsort(-w, kind="stable")
    out_w, out_m, out_P = [], [], []
    while remaining.size:
        j = remaining[0]
        diff = m[remaining] - m[j]
        if rule == "vo-ma":
            d2 = np.einsum("gi,gij,gj->g", diff, inv[remaining], diff)
            close = d2 <= threshold
        else:
            wr = w[remaining]
            d2 = (wr * w[j] / (wr + w[j])) * np.einsum("gi,ij,gj->g", diff, inv[j], diff)
            close = d2 < threshold
        close[0] = True
        group = remaining[close]
        if group.size == 1:
            out_w.append(w[j])
            out_m.append(m[j])
            out_P.append(P[j])
        else:
            gw, gm, gP = moment_match(w[group], m[group], P[group])
            out_w.append(gw)
            out_m.append(gm)
            out_P.append(gP)
        remaining = remaining[~close]
    return GaussianMixture(np.array(out_w), np.array(out_m), np.array(out_P))


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
    res = minimize(
        lambda x: x @ A @ x - 2 * b @ x,
        reduced.weights * (mass / reduced.mass),
        jac=lambda x: 2 * (A @ x - b),
        bounds=[(0.0, None)] * n,
        constraints=[{"type": "eq", "fun": lambda x: x.sum() - mass, "jac": lambda x: np.ones(n)}],
        method="SLSQP",
    )
    if not res.success or not np.all(np.isfinite(res.x)):
        return reduced
    return GaussianMixture(np.clip(res.x, 0.0, None), reduced.means, reduced.covs)


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
