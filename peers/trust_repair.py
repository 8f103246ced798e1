"""Repair of a neighbour's density instead of its exclusion (issue 24, :attr:`TrustConfig.repair`).

A lie that still carries the liar's measurements loses them when the liar is left out: on
seed 000 the two honest sensors alone fuse to 24 m, the three together to 16 m. Two such lies
keep the liar's real components and add to them: weights scaled up (*inflated*) and targets
nobody else has (*phantoms*). A neighbour whose test fails is offered a repaired density
(:meth:`peers.trust.Trust._repair` decides when): the components that no target of own or
of another trusted neighbour corroborates dropped (:func:`corroborated_part`), and the
weights scaled by a mass factor (:func:`scan_factor`, its median over scans kept by the
trust record): what own weighs the same targets per unit of the neighbour's weight. It is
used only where the repaired density's statistic is smaller. What a repair keeps is what
others already show a target at: a lie can add position information there, but no target
and no mass.

Pure functions (no state).
"""

from __future__ import annotations

import numpy as np
from sensornet.peers.trust_checks import gated, near
from sensornet.tracking.mixture import GaussianMixture


def corroborated(mix: GaussianMixture, others: list[GaussianMixture], pos: list[int],
                 min_weight: float, gate: float, chi2: float | None = None) -> np.ndarray:
    """``(n,)`` bool: the components of ``mix`` with a target component (weight at least
    ``min_weight``, within the gate: ``gate`` metres or the ``chi2`` gate of their
    covariances, :func:`peers.trust_checks.gated`; position entries ``pos`` of the state) in
    ``others[0]`` (own), or in at least two of the other densities of ``others`` (in the one
    other, with only one): two liars telling the same lie do not corroborate each other."""
    if len(mix) == 0:
        return np.zeros(0, bool)
    X, P = mix.means[:, pos], _pos_covs(mix, pos)  # (n, 2), (n, 2, 2)
    hits = np.zeros((len(others), len(mix)), bool)  # (references, n)
    for r, D in enumerate(others):
        sel = D.weights >= min_weight if len(D) else np.zeros(0, bool)
        if sel.any():
            hits[r] = near(X, P, D.means[sel][:, pos], _pos_covs(D, pos)[sel], gate,
                           chi2).any(1)
    need = 1 if len(others) <= 2 else 2
    return hits[0] | (hits[1:].sum(axis=0) >= need)


def mass_factor(mix: GaussianMixture, ref: GaussianMixture, pos: list[int],
                min_weight: float, gate: float, chi2: float | None = None) -> float | None:
    """How much ``ref`` weighs what ``mix`` shows, per unit of ``mix``'s weight: each target
    component of ``ref`` (weight at least ``min_weight``) goes to ``mix``'s nearest
    component if within the gate (``gate`` metres or the ``chi2`` gate,
    :func:`peers.trust_checks.gated`), and the factor is their summed weight over the summed
    weight of the components of ``mix`` they went to (None: nothing matched). An honest
    pair's is about 1; an inflated density's, 1 over its inflation."""
    sel = ref.weights >= min_weight if len(ref) else np.zeros(0, bool)
    if len(mix) == 0 or not sel.any():
        return None
    R = ref.means[sel][:, pos]  # (m, 2)
    diff = R[:, None, :] - mix.means[None, :, pos]  # (m, n, 2)
    j = (diff ** 2).sum(axis=2).argmin(axis=1)
    rows = np.arange(len(R))
    hit = gated(diff[rows, j], _pos_covs(ref, pos)[sel], _pos_covs(mix, pos)[j], gate, chi2)
    if not hit.any():
        return None
    den = float(mix.weights[np.unique(j[hit])].sum())
    f = float(ref.weights[sel][hit].sum()) / den if den > 0.0 else np.inf
    return f if np.isfinite(f) else None  # zero-weight components: nothing to scale


def corroborated_part(mix: GaussianMixture, others: list[GaussianMixture], pos: list[int],
                      min_weight: float, gate: float, chi2: float | None = None
                      ) -> GaussianMixture | None:
    """``mix`` less its components no density of ``others`` corroborates
    (:func:`corroborated`); None if none is left."""
    keep = corroborated(mix, others, pos, min_weight, gate, chi2)
    return mix.select(np.flatnonzero(keep)) if keep.any() else None


def scan_factor(kept: GaussianMixture, others: list[GaussianMixture], pos: list[int],
                min_weight: float, gate: float, chi2: float | None = None) -> float | None:
    """The median :func:`mass_factor` of ``kept`` against each of ``others`` (against
    ``others[0]``, own, alone with fewer than three: a median of two is their mean, which
    one liar among them sets); None if no reference matched it."""
    refs = others if len(others) >= 3 else others[:1]
    factors = [f for D in refs
               if (f := mass_factor(kept, D, pos, min_weight, gate, chi2)) is not None]
    return float(np.median(factors)) if factors else None


def moved_to_own(mix: GaussianMixture, own: GaussianMixture, offset: np.ndarray,
                 pos: list[int]) -> GaussianMixture:
    """``mix`` with ``offset`` (``(2,)``) subtracted from every component's position and each
    covariance replaced by that of own's nearest component (after the move) where that one's
    determinant is larger: a registered neighbour is not taken to be more precise than own
    (a confident lie claims any covariance)."""
    means = mix.means.copy()
    means[:, pos] -= offset
    d2 = ((means[:, None, pos] - own.means[None, :, pos]) ** 2).sum(axis=2)  # (n, m)
    near = own.covs[d2.argmin(axis=1)]  # (n, d, d)
    wider = np.linalg.det(near) > np.linalg.det(mix.covs)
    covs = np.where(wider[:, None, None], near, mix.covs)
    return GaussianMixture(mix.weights.copy(), means, covs)


def _pos_covs(mix: GaussianMixture, pos: list[int]) -> np.ndarray:
    """The position blocks ``(n, 2, 2)`` of ``mix``'s covariances."""
    return mix.covs[:, pos][:, :, pos]
