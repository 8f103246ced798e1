"""The filters' hot paths as they were before issue 15's speed work (commit fea5bab), kept as
the same-run reference of ``bench_immpf.py`` and ``bench_gmphd_stonesoup.py``: each benchmark
times the current code against these in one process (the machine is shared, so ratios from
one run are what count) and checks that both give the same numbers."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.tracking.gaussian import LOG_2PI, inv_det_2x2, symmetrise
from sensornet.tracking.imm import (
    IMMEKF,
    STATE_DIM,
    IMMGaussianState,
    mixing,
    model_posterior,
    radar_jacobian,
)
from sensornet.tracking.models import RangeBearing, wrap_angle
from sensornet.tracking.particles import (
    IMMParticleFilter,
    ParticlePrediction,
    ParticleState,
    counts_to_indices,
)


def systematic_counts(weights: np.ndarray, n: np.ndarray | int, u: np.ndarray) -> np.ndarray:
    """Systematic-sampling counts per row (before: new temporaries at every operation)."""
    R, K = weights.shape
    C = np.empty((R, K + 1))
    C[:, 0] = 0.0
    np.cumsum(weights, axis=1, out=C[:, 1:])
    C[:, 1:] /= C[:, -1:]
    C[:, -1] = 1.0
    n = np.asarray(n, dtype=float).reshape(-1, 1) if np.ndim(n) else float(n)
    f = np.floor(C * n - u[:, None])
    return np.diff(f, axis=1).astype(np.int64)


def residual_counts(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Residual resampling counts per row (before)."""
    w = weights / weights.sum(axis=1, keepdims=True)
    nw = n * w
    base = np.floor(nw)
    rest = nw - base
    left = n - base.sum(axis=1)
    total = rest.sum(axis=1, keepdims=True)
    rest = np.where(total > 0, rest, 1.0)
    extra = systematic_counts(rest, left, rng.random(len(w)))
    return base.astype(np.int64) + extra


def radar_log_likelihood(sensor: RangeBearing, z: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``log N(z; h(x), R)`` (before: stacked ``h``, ``residual`` with a copy, ``%`` wrap)."""
    dx = X[..., 0] - sensor.position[0]
    dy = X[..., 3] - sensor.position[1]
    zhat = np.stack([np.hypot(dx, dy), np.arctan2(dy, dx)], axis=-1)
    nu = np.asarray(z - zhat, dtype=float).copy()
    nu[..., 1] = wrap_angle(nu[..., 1])
    sr, st = sensor.sigma_r, sensor.sigma_theta
    return (-0.5 * ((nu[..., 0] / sr) ** 2 + (nu[..., 1] / st) ** 2)
            - np.log(sr * st) - LOG_2PI)


def weighted_moments(X: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance by ``np.einsum`` (sequential sums over particles)."""
    mean = np.einsum("...n,...nd->...d", w, X)
    D = X - mean[..., None, :]
    cov = np.einsum("...na,...nb->...ab", D * w[..., None], D)
    return mean, symmetrise(cov)


@dataclass(frozen=True)
class IMMParticleFilterBefore(IMMParticleFilter):
    """The IMM-PF step before: particle-major ``(M, N, 6)`` arrays, row gathers, einsum."""

    @cached_property
    def _F_t(self) -> np.ndarray:
        return np.stack([m.F.T for m in self.params.models()])  # (M, 6, 6)

    @cached_property
    def _G_t(self) -> np.ndarray:
        return np.stack([(m.sigma * m.G).T for m in self.params.models()])  # (M, 2, 6)

    def predict(self, state: ParticleState, rng: np.random.Generator) -> ParticlePrediction:
        X = state.particles
        M, N, d = X.shape
        c, mu = mixing(state.probs, self.params.P)
        q = np.repeat(mu.T, N, axis=1)
        idx = counts_to_indices(systematic_counts(q, N, rng.random(M)))
        X0 = X.reshape(M * N, d)[idx]
        Xp = X0 @ self._F_t + rng.standard_normal((M, N, 2)) @ self._G_t
        return ParticlePrediction(Xp, c)

    def update(self, pred: ParticlePrediction, log_lik: np.ndarray,
               rng: np.random.Generator) -> ParticleState:
        X = pred.particles
        M, N, d = X.shape
        top = log_lik.max(axis=1, keepdims=True)
        lik = np.exp(log_lik - top)
        s = lik.sum(axis=1)
        log_Lambda = np.log(s) + top[:, 0] - np.log(N)
        probs = model_posterior(pred.probs, log_Lambda)
        w = lik / s[:, None]
        means, covs = weighted_moments(X, w)
        idx = counts_to_indices(residual_counts(w, N, rng)) + (np.arange(M) * N)[:, None]
        Xr = X.reshape(M * N, d)[idx]
        h = self.particle.jitter
        if h > 0.0:
            L = np.linalg.cholesky(covs + self.particle.cov_floor * np.eye(d))
            E = h * (rng.standard_normal(Xr.shape) @ np.swapaxes(L, 1, 2))
            if self.particle.jitter_kind == "add":
                Xr = Xr + E
            else:
                a = np.sqrt(1.0 - h * h)
                Xr = a * Xr + (1.0 - a) * means[:, None, :] + E
        return ParticleState(Xr, probs, means, covs, log_Lambda)


@dataclass(frozen=True)
class IMMEKFBefore(IMMEKF):
    """The IMM-EKF step before: models rebuilt per call, generic batched products."""

    def predict(self, state: IMMGaussianState) -> IMMGaussianState:
        models = self.params.models()
        c, mu = mixing(state.probs, self.params.P)
        m0 = mu.T @ state.means
        diff = state.means[None, :, :] - m0[:, None, :]
        P0 = np.einsum("ij,iab->jab", mu, state.covs) + np.einsum(
            "ij,jia,jib->jab", mu, diff, diff)
        F = np.stack([m.F for m in models])
        Q = np.stack([m.Q for m in models])
        means = np.einsum("jab,jb->ja", F, m0)
        covs = symmetrise(F @ P0 @ np.swapaxes(F, 1, 2) + Q)
        return IMMGaussianState(c, means, covs)

    def update(self, pred: IMMGaussianState, z: np.ndarray,
               sensor: RangeBearing) -> IMMGaussianState:
        zhat, H = radar_jacobian(sensor, pred.means)
        nu = sensor.residual(z, zhat)
        PHt = pred.covs @ np.swapaxes(H, 1, 2)
        S = H @ PHt + sensor.R
        Sinv, detS = inv_det_2x2(S)
        K = PHt @ Sinv
        means = pred.means + np.einsum("jab,jb->ja", K, nu)
        IKH = np.eye(STATE_DIM) - K @ H
        covs = symmetrise(IKH @ pred.covs @ np.swapaxes(IKH, 1, 2)
                          + K @ sensor.R @ np.swapaxes(K, 1, 2))
        log_lik = -0.5 * (np.einsum("ja,jab,jb->j", nu, Sinv, nu) + np.log(detS) + 2 * LOG_2PI)
        return IMMGaussianState(model_posterior(pred.probs, log_lik), means, covs, log_lik)
