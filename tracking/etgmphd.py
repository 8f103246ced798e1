"""Extended-target GM-PHD filter (Granström, Lundquist & Orguner, IEEE TAES 2012; seed 002).

Each target yields ``Poisson(gamma)`` measurements when detected (probability ``Pd``); clutter
has intensity ``kappa(z) = lambda_c / V``. The corrector (Granström et al. 2012, eq. 5-12) is

    D(x | Z) = L_Z(x) D(x),
    L_Z(x) = 1 - (1 - e^-gamma) Pd
             + e^-gamma Pd sum_{p partition of Z} w_p sum_{W in p} gamma^|W| / d_W
                                                   prod_{z in W} phi_z(x) / kappa(z),
    d_W    = delta_{|W|,1} + sum_j Gamma_W w_j beta_W^j,   Gamma_W = e^-gamma gamma^|W| Pd,
    beta_W^j = N(z_W; H_W m_j, H_W P_j H_W^T + R_W) / prod_{z in W} kappa(z),
    w_p    = prod_{W in p} d_W / sum_{p'} prod_{W' in p'} d_W'.

so the missed-detection components are ``(1 - (1 - e^-gamma) Pd) w_j`` and each (cell, component)
pair gives a component of weight ``w_p Gamma_W beta_W^j w_j / d_W`` updated with the stacked
measurement ``z_W``. A cell shared by several partitions gives the same Gaussian in each, so
its weights are summed over the partitions holding it (``Omega_W = sum_{p ∋ W} w_p``) and
each distinct (cell, component) pair is computed once: one array computation over all pairs.

For the linear position sensor (``H`` picks ``(px, py)``, ``R = sigma^2 I``) the stacked update
is the update with the cell mean ``zbar`` and ``R / n``, and

    N(z_W; H_W m, H_W P H_W^T + R_W) = c_W N(zbar; H m, H P H^T + R / n),
    log c_W = -(n-1) log(2 pi sigma^2) - log n - s_W / 2,  s_W = sum_i |z_i - zbar|^2 / sigma^2

(d = 2), so no ``2n x 2n`` matrix is ever formed. ``tests/test_etgmphd.py`` checks this against
the stacked form summed over every partition of small scans.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.special import logsumexp
from sensornet.tracking.gaussian import inv_det_2x2, quad_form, symmetrise
from sensornet.tracking.gmphd import DEFAULT_EXTRACTION, extract, predict
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity
from sensornet.tracking.partition import ScanTooLarge
from sensornet.tracking.reduction import Reducer

POSITION = (0, 2)
"""State columns the linear sensor measures."""

Partitioner = Callable[[np.ndarray], Sequence[np.ndarray]]
"""``scan (m, 2) -> [labels (m,), ...]`` (:mod:`tracking.partition`)."""


@dataclass(frozen=True)
class ExtendedSensor:
    """A linear position sensor seeing extended targets."""

    sigma: float = 20.0
    """Measurement noise standard deviation per axis, metres (``R = sigma^2 I``)."""
    detection_probability: float = 0.99
    """``Pd``: probability that a target is detected (then it yields ``Poisson(rate)`` points)."""
    clutter_intensity: float = 10.0 / 4e6
    """``kappa = lambda_c / V`` per square metre."""
    rate: float = 10.0
    """``gamma``: Poisson mean of the number of measurements of a detected target."""


def cells_of(partitions: Sequence[np.ndarray], m: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """The distinct cells of a list of partitions: membership ``(c, m)`` bool and, per
    partition, the indices of its cells in that array."""
    rows, owner = [], []
    for p, labels in enumerate(partitions):
        labels = np.asarray(labels).reshape(-1)
        if labels.shape != (m,):
            raise ValueError(f"partition {p} has {labels.shape[0]} labels for {m} measurements")
        u, inv = np.unique(labels, return_inverse=True)
        member = np.zeros((len(u), m), dtype=bool)
        member[inv, np.arange(m)] = True
        rows.append(member)
        owner.append(np.full(len(u), p))
    member = np.concatenate(rows)
    packed = np.packbits(member, axis=1)
    _, first, inv = np.unique(packed, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    owner_all = np.concatenate(owner)
    per_partition = [inv[owner_all == p] for p in range(len(partitions))]
    return member[first], per_partition


def update(mix: GaussianMixture, z: np.ndarray, partitions: Sequence[np.ndarray],
           sensor: ExtendedSensor, min_weight: float = 0.0,
           diagnostics: dict | None = None) -> GaussianMixture:
    """ET-GM-PHD corrector for scan ``z (m, 2)`` over the given ``partitions`` (module doc).

    ``min_weight``: detection components lighter than this are not materialised (the same as
    pruning them afterwards). ``diagnostics``: if given, ``"partition_weights"`` ``(p,)`` is
    stored in it (``w_p``; for display).
    """
    Pd, gamma, kappa = sensor.detection_probability, sensor.rate, sensor.clutter_intensity
    w, mean, P = mix.weights, mix.means, mix.covs
    missed = GaussianMixture(w * (1.0 - (1.0 - np.exp(-gamma)) * Pd), mean, P)
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    m, J = len(z), len(mix)
    if m == 0 or J == 0 or not len(partitions):
        return missed
    member, per_partition = cells_of(partitions, m)  # (c, m)
    M = member.astype(float)
    n = M.sum(axis=1)  # (c,)
    zbar = (M @ z) / n[:, None]  # (c, 2)
    s2 = sensor.sigma**2
    scatter = (M @ (z * z).sum(axis=1) - n * (zbar * zbar).sum(axis=1)) / s2  # (c,)
    log_c = -(n - 1) * np.log(2 * np.pi * s2) - np.log(n) - 0.5 * np.maximum(scatter, 0.0)
    cols = list(POSITION)
    PHt = P[:, :, cols]  # (J, 4, 2)
    HPHt = PHt[:, cols, :]  # (J, 2, 2)
    S = HPHt[None] + (s2 / n)[:, None, None, None] * np.eye(2)  # (c, J, 2, 2)
    S_inv, S_det = inv_det_2x2(S)
    nu = zbar[:, None, :] - mean[None][:, :, cols]  # (c, J, 2)
    log_N = -0.5 * (quad_form(nu, S_inv) + np.log(S_det)) - np.log(2 * np.pi)  # (c, J)
    log_gamma_W = -gamma + n * np.log(gamma) + np.log(Pd)  # (c,)
    with np.errstate(divide="ignore"):
        log_term = (log_gamma_W + log_c - n * np.log(kappa))[:, None] + log_N + np.log(w)[None]
        log_d = np.logaddexp(np.where(n == 1, 0.0, -np.inf), logsumexp(log_term, axis=1))
    log_wp = np.array([log_d[cells].sum() for cells in per_partition])  # (p,)
    if np.all(np.isneginf(log_wp)):
        wp = np.full(len(log_wp), 1.0 / len(log_wp))
    else:
        wp = np.exp(log_wp - logsumexp(log_wp))
    if diagnostics is not None:
        diagnostics["partition_weights"] = wp
    omega = np.zeros(len(member))
    for p, cells in enumerate(per_partition):
        omega[cells] += wp[p]
    with np.errstate(invalid="ignore"):
        weights = omega[:, None] * np.exp(log_term - log_d[:, None])  # (c, J)
    weights = np.nan_to_num(weights, nan=0.0)
    ci, ji = np.nonzero(weights > min_weight) if min_weight > 0 else np.nonzero(weights >= 0)
    K = PHt[ji] @ S_inv[ci, ji]  # (k, 4, 2)
    means = mean[ji] + np.einsum("kij,kj->ki", K, nu[ci, ji])
    covs = symmetrise(P[ji] - K @ np.swapaxes(PHt[ji], 1, 2))
    return GaussianMixture(np.concatenate((missed.weights, weights[ci, ji])),
                           np.concatenate((mean, means)), np.concatenate((P, covs)))


@dataclass
class ETGMPHDFilter:
    """An ET-GM-PHD filter on one sensor: predict (as GM-PHD), partition, update, reduce.

    Same methods as :class:`tracking.gmphd.GMPHDFilter` (``initial``, ``predict``, ``correct``,
    ``step``, ``extract``), so a peer estimator drives either.
    """

    motion: ConstantVelocity
    """Motion model."""
    sensor: ExtendedSensor
    """The sensor (linear position, extended targets)."""
    birth: GaussianMixture
    """Birth intensity added at every prediction."""
    partitioner: Partitioner
    """``scan -> partitions`` (distance or grid-spectral, :mod:`tracking.partition`)."""
    survival_probability: float = 0.99
    """``Ps``."""
    reducer: Reducer = field(default_factory=Reducer)
    """Reduction after each correction."""
    extraction_threshold: float = 0.5
    """Components heavier than this are reported as targets."""
    extraction: str = DEFAULT_EXTRACTION
    """Extraction rule (:func:`tracking.gmphd.extract`)."""
    counts: Counter = field(default_factory=Counter)
    """``scans_too_large``: scans over the partitioner's cap (corrected as all-missed)."""
    last_partitions: list = field(default_factory=list)
    """The partitions of the latest scan (for display)."""
    last_weights: np.ndarray | None = None
    """Their weights ``w_p`` in the latest update (for display)."""

    def initial(self) -> GaussianMixture:
        return GaussianMixture.empty(self.motion.dim)

    def predict(self, mix: GaussianMixture, steps: int = 1) -> GaussianMixture:
        return predict(mix, self.motion, self.survival_probability, self.birth, steps)

    def partition(self, z: np.ndarray) -> list[np.ndarray]:
        """The partitioner's partitions, or ``[]`` (counted) when the scan is over its cap."""
        try:
            parts = list(self.partitioner(z))
        except ScanTooLarge:
            self.counts["scans_too_large"] += 1
            parts = []
        self.last_partitions = parts
        return parts

    def correct(self, mix: GaussianMixture, scans: Sequence[np.ndarray]) -> GaussianMixture:
        if len(scans) != 1:
            raise ValueError(f"an ET-GM-PHD filter corrects with one scan, got {len(scans)}")
        z = np.asarray(scans[0], dtype=float).reshape(-1, 2)
        parts = self.partition(z)
        if not parts:
            z = z[:0]
        diag: dict = {}
        mix = update(mix, z, parts, self.sensor, self.reducer.prune_threshold, diag)
        self.last_weights = diag.get("partition_weights")
        return self.reducer(mix)

    def step(self, mix: GaussianMixture, z: np.ndarray) -> GaussianMixture:
        return self.correct(self.predict(mix), [z])

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        return extract(mix, self.extraction_threshold, self.extraction)


__all__ = ["ETGMPHDFilter", "ExtendedSensor", "cells_of", "update"]
