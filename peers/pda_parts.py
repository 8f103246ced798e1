"""Single-target PDA peers (seed 003): a :class:`peers.contracts.LocalEstimator` running a
(fuzzy) IMM-PDAF on this peer's sensor, and a :class:`peers.contracts.Fuser` that fuses the
neighbours' posteriors by covariance intersection (estimate sharing).

Covariance intersection (Julier & Uhlmann 1997) of Gaussians ``(x_i, P_i)``:
``P^-1 = sum_i w_i P_i^-1``, ``x = P sum_i w_i P_i^-1 x_i``, ``sum w_i = 1``; consistent
whatever the (unknown) correlation between the inputs, which feedback of the fused estimate
into every peer's filter creates. With two inputs ``w`` minimises ``log det P`` (the usual
choice, ``omega="det"``); otherwise the consensus weights are used.

Measurement sharing (each peer applies every peer's returns in a fixed sensor order, the
paper's sequential scheme) is what :func:`sim.seed003.run_filter` does with two sensors; it is
not a peer mode yet (its messages would carry returns, not densities).
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from scipy.optimize import minimize_scalar

from peers.contracts import FusionInput, LocalOutput
from tracking.mixture import GaussianMixture
from tracking.pda import ImmPda, LinearSensor


def covariance_intersection(means: np.ndarray, covs: np.ndarray,
                            weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CI of ``means (n, d)``, ``covs (n, d, d)`` with ``weights (n,)``: ``(x (d,), P (d, d))``."""
    info = np.linalg.inv(covs)
    Y = np.einsum("n,nij->ij", weights, info)
    P = np.linalg.inv(Y)
    x = P @ np.einsum("n,nij,nj->i", weights, info, means)
    return x, 0.5 * (P + P.T)


def ci_det_weight(means: np.ndarray, covs: np.ndarray) -> float:
    """The weight ``w`` of input 0 (``1 - w`` of input 1) minimising ``log det`` of the CI."""
    info = np.linalg.inv(covs)

    def cost(w: float) -> float:
        return -float(np.linalg.slogdet(w * info[0] + (1 - w) * info[1])[1])

    return float(minimize_scalar(cost, bounds=(0.0, 1.0), method="bounded",
                                 options={"xatol": 1e-4}).x)


def _single(x: np.ndarray, P: np.ndarray) -> GaussianMixture:
    return GaussianMixture(np.ones(1), x[None], P[None])


class PdaEstimator:
    """A (fuzzy) IMM-PDAF on one sensor; publishes its moment-matched posterior (one
    Gaussian). With ``feedback`` the fused density becomes the next scan's prior."""

    kinds = ("posterior",)

    def __init__(self, filt: ImmPda, sensor: LinearSensor, position_index: tuple[int, int],
                 feedback: bool = True) -> None:
        self.filter = filt
        self.sensor = sensor
        self.dim = filt.x.shape[1]
        self.position_index = position_index
        self.feedback = feedback

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        self.filter.predict(steps)
        up = self.filter.update(self.sensor, np.asarray(z, float).reshape(-1, 2))
        x, P = self.filter.estimate()
        mix = _single(x, P)
        return LocalOutput(mix, {"posterior": mix},
                           {"gated": float(len(up.returns)), "beta0": up.beta0})

    def predict(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        return mix  # single-target peers fuse only estimates of the same scan

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        return (mix.weights @ mix.means)[None, :] / max(float(mix.weights.sum()), 1e-300)

    def adopt(self, fused: GaussianMixture) -> None:
        if self.feedback and len(fused) == 1:
            self.filter.adopt(fused.means[0], fused.covs[0])


class CiFuser:
    """Covariance intersection of this peer's posterior with its neighbours' (one round)."""

    kinds = ("posterior",)
    max_rounds = 1

    def __init__(self, omega: str = "det") -> None:
        if omega not in ("det", "consensus"):
            raise ValueError(f"CI weight {omega!r}: expected 'det' or 'consensus'")
        self.omega = omega
        self.counts: Counter = Counter()

    def fuse(self, inp: FusionInput) -> GaussianMixture:
        mixes = [inp.own] + [inp.neighbours[s]["posterior"] for s in sorted(inp.neighbours)]
        if len(mixes) == 1:
            return inp.own
        means = np.stack([m.means[0] for m in mixes])
        covs = np.stack([m.covs[0] for m in mixes])
        if self.omega == "det" and len(mixes) == 2:
            w0 = ci_det_weight(means, covs)
            w = np.array([w0, 1.0 - w0])
        else:
            w = np.asarray(inp.weights, float)
        x, P = covariance_intersection(means, covs, w)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            self.counts["fusion_fallbacks"] += 1
            return inp.own
        return _single(x, P)
