"""Interacting multiple models on the 6-D kinematic state, and the IMM-EKF.

Formulas and our readings: docs/algorithms.md "IMM models and the particle fusion rule".

State ``x = [px, vx, ax, py, vy, ay]`` (m, m/s, m/s^2). Two models (seed 001 §2):

* CV: per axis ``F = [[1, T, 0], [0, 1, 0], [0, 0, 0]]`` (the acceleration is zeroed),
  ``Q = sigma_a^2 g g^T`` with ``g = [T^2/2, T, 0]``;
* CA: per axis ``F = [[1, T, T^2/2], [0, 1, T], [0, 0, 1]]``, ``Q = sigma^2 g g^T`` with
  ``g = [T^2/2, T, 1]`` (seed 001 eq. 24: the acceleration takes a random step ``w`` per scan,
  sigma in m/s^2, default) or, as an option (``IMMParams.ca_noise_gain="integrated"``),
  ``g = [T^3/6, T^2/2, T]`` (a white jerk held over the scan and integrated, sigma in m/s^3).

Markov switching ``p_ij = P(model j at k | model i at k-1)``. The IMM cycle (Blom &
Bar-Shalom 1988; seed 001 eq. 5-12): mixing probabilities ``mu_(i|j) = p_ij mu_i / c_j``,
``c_j = sum_i p_ij mu_i``; mixed initial conditions; model-matched filtering; model
probabilities ``mu_j ∝ Lambda_j c_j``; output ``x = sum_j mu_j x_j``.

This module also holds the range-bearing measurement on the 6-D state (positions at indices
0 and 3), shared by the IMM-EKF and the IMM particle filter (``tracking.particles``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from sensornet.tracking.gaussian import LOG_2PI, c_einsum, inv_det_2x2
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import RangeBearing

POS = (0, 3)
"""Indices of (px, py) in the 6-D state."""
VEL = (1, 4)
"""Indices of (vx, vy)."""
ACC = (2, 5)
"""Indices of (ax, ay)."""
STATE_DIM = 6


@dataclass(frozen=True)
class KinematicModel:
    """A linear Gaussian motion model ``x_k = F x_(k-1) + G w``, ``w ~ N(0, sigma^2 I_2)``."""

    name: str
    """Model name ("CV", "CA")."""
    F: np.ndarray
    """(6, 6) transition matrix."""
    G: np.ndarray
    """(6, 2) noise gain (one column per axis)."""
    sigma: float
    """Noise standard deviation (m/s^2 for CV and the paper's CA, m/s^3 for the integrated CA)."""

    @property
    def Q(self) -> np.ndarray:
        """(6, 6) process noise covariance ``sigma^2 G G^T``."""
        return self.sigma**2 * self.G @ self.G.T


def _per_axis(F3: np.ndarray, g3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Block-diagonal (x axis, y axis) 6-D ``F`` and ``G`` from one axis' 3-D parts."""
    return np.kron(np.eye(2), F3), np.kron(np.eye(2), g3.reshape(3, 1))


def constant_velocity(T: float = 1.0, sigma_a: float = 0.2) -> KinematicModel:
    """CV on the 6-D state: acceleration zeroed, white acceleration noise ``sigma_a``."""
    F, G = _per_axis(np.array([[1.0, T, 0], [0, 1, 0], [0, 0, 0]]), np.array([T * T / 2, T, 0]))
    return KinematicModel("CV", F, G, sigma_a)


CA_NOISE_GAINS = ("paper", "integrated")
"""CA noise gains: ``"paper"`` ``[T^2/2, T, 1]`` (seed 001 eq. 24), ``"integrated"``
``[T^3/6, T^2/2, T]`` (piecewise-constant white jerk)."""


def ca_noise_gain(T: float, kind: str = "paper") -> np.ndarray:
    """One axis' CA noise gain ``g (3,)`` (``Q = sigma^2 g g^T``).

    ``"paper"``: ``[T^2/2, T, 1]``, seed 001 eq. 24 (``G_2``): the noise ``w`` (m/s^2) is the
    acceleration's change over one scan, propagated to velocity and position as a constant
    acceleration would be (Bar-Shalom's discrete Wiener-process acceleration model).
    ``"integrated"``: ``[T^3/6, T^2/2, T]``: a jerk ``w`` (m/s^3) held constant over the scan and
    integrated into acceleration, velocity and position (the gain used before the paper's).
    """
    if kind == "paper":
        return np.array([T * T / 2, T, 1.0])
    if kind == "integrated":
        return np.array([T**3 / 6, T * T / 2, T])
    raise ValueError(f"unknown CA noise gain {kind!r}; expected one of {CA_NOISE_GAINS}")


def constant_acceleration(T: float = 1.0, sigma_j: float = 0.1,
                          gain: str = "paper") -> KinematicModel:
    """CA (Wiener-process acceleration) with noise ``sigma_j`` per axis through
    :func:`ca_noise_gain` ``gain`` (m/s^2 for ``"paper"``, m/s^3 for ``"integrated"``)."""
    F3 = np.array([[1.0, T, T * T / 2], [0, 1, T], [0, 0, 1]])
    F, G = _per_axis(F3, ca_noise_gain(T, gain))
    return KinematicModel("CA", F, G, sigma_j)


@dataclass(frozen=True)
class IMMParams:
    """The IMM configuration shared by the IMM-EKF and the IMM-PF (seed 001 §4)."""

    T: float = 1.0
    """Scan period in s."""
    sigma_cv: float = 0.2
    """CV white-acceleration noise in m/s^2 (our reading)."""
    sigma_ca: float = 0.1
    """CA noise (our reading): the per-scan acceleration change in m/s^2 with the paper's gain,
    a white jerk in m/s^3 with ``ca_noise_gain="integrated"``."""
    transition: tuple[tuple[float, ...], ...] = ((0.98, 0.02), (0.02, 0.98))
    """Markov matrix ``p_ij`` = P(model j now | model i before)."""
    initial_probs: tuple[float, ...] = (0.5, 0.5)
    """Model probabilities at initialisation (CV, CA)."""
    model_names: tuple[str, ...] = ("CV", "CA")
    """Which models, in order ("CV", "CA"); one entry gives a single-model filter."""
    ca_noise_gain: str = "paper"
    """CA noise gain, one of :data:`CA_NOISE_GAINS`: ``"paper"`` ``[T^2/2, T, 1]`` (seed 001
    eq. 24) or ``"integrated"`` ``[T^3/6, T^2/2, T]``."""

    def __post_init__(self) -> None:
        if self.ca_noise_gain not in CA_NOISE_GAINS:
            raise ValueError(f"IMMParams: unknown ca_noise_gain {self.ca_noise_gain!r}; "
                             f"expected one of {CA_NOISE_GAINS}")
        M = len(self.model_names)
        if self.P.shape != (M, M) or len(self.initial_probs) != M:
            raise ValueError(f"IMMParams: {M} models need an {M}x{M} transition matrix and "
                             f"{M} initial probabilities")

    def models(self) -> tuple[KinematicModel, ...]:
        """The models named in ``model_names``, with this configuration's noises."""
        make = {"CV": lambda: constant_velocity(self.T, self.sigma_cv),
                "CA": lambda: constant_acceleration(self.T, self.sigma_ca, self.ca_noise_gain)}
        return tuple(make[name]() for name in self.model_names)

    @property
    def P(self) -> np.ndarray:
        """(M, M) transition matrix."""
        return np.asarray(self.transition, dtype=float)


def mixing(probs: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """IMM interaction: predicted model probabilities ``c (M,)`` and ``mu_(i|j) (M_i, M_j)``.

    ``c_j = sum_i p_ij mu_i``, ``mu_(i|j) = p_ij mu_i / c_j`` (seed 001 eq. 5-6).
    """
    joint = P * probs[:, None]  # (i, j)
    c = joint.sum(axis=0)
    return c, joint / c[None, :]


def combine(probs: np.ndarray, means: np.ndarray,
            covs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """IMM output combination ``x = sum_j mu_j x_j`` and its covariance (seed 001 eq. 12)."""
    return GaussianMixture(probs, means, covs).moments()


# -- range-bearing radar on the 6-D state -------------------------------------------------------


def radar_h(sensor: RangeBearing, X: np.ndarray) -> np.ndarray:
    """``h(x) = [range, bearing]`` for states ``X (..., 6)``: returns ``(..., 2)`` (§1)."""
    dx = X[..., 0] - sensor.position[0]
    dy = X[..., 3] - sensor.position[1]
    return np.stack([np.hypot(dx, dy), np.arctan2(dy, dx)], axis=-1)


def radar_jacobian(sensor: RangeBearing, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``h(x) (n, 2)`` and its Jacobian ``(n, 2, 6)`` at ``X (n, 6)`` (EKF linearisation)."""
    dx = X[:, 0] - sensor.position[0]
    dy = X[:, 3] - sensor.position[1]
    r2 = np.maximum(dx * dx + dy * dy, 1e-12)
    r = np.sqrt(r2)
    H = np.zeros((len(X), 2, STATE_DIM))
    H[:, 0, 0], H[:, 0, 3] = dx / r, dy / r
    H[:, 1, 0], H[:, 1, 3] = -dy / r2, dx / r2
    return np.stack([r, np.arctan2(dy, dx)], axis=1), H


def radar_log_likelihood(sensor: RangeBearing, z: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``log N(z; h(x), R)`` at states ``X (..., 6)``: returns ``(...)``. Bearing wrapped.

    The arithmetic of ``sensor.residual(z, radar_h(sensor, X))`` and the Gaussian, fused: no
    stacked ``(..., 2)`` temporaries, and the wrap's ``%`` only when a residual leaves
    ``[-pi, pi)`` (inside it ``(a + pi) % 2 pi`` is ``a + pi``: the same numbers).
    """
    X = np.asarray(X)
    if X.ndim < 2:
        return radar_log_likelihood(sensor, z, X[None])[0]
    dx = X[..., 0] - sensor.position[0]
    dy = X[..., 3] - sensor.position[1]
    nr = z[0] - np.hypot(dx, dy)
    nt = np.arctan2(dy, dx, out=dy)
    np.subtract(z[1], nt, out=nt)
    nt += np.pi
    if nt.size and (nt.min() < 0.0 or nt.max() >= _TWO_PI):
        np.remainder(nt, _TWO_PI, out=nt)
    nt -= np.pi
    sr, st = sensor.sigma_r, sensor.sigma_theta
    nr /= sr
    np.square(nr, out=nr)
    nt /= st
    np.square(nt, out=nt)
    nr += nt
    nr *= -0.5
    nr -= np.log(sr * st)
    nr -= LOG_2PI
    return nr


_TWO_PI = 2.0 * np.pi


def polar_to_cartesian(sensor: RangeBearing, z: np.ndarray) -> np.ndarray:
    """Position ``(2,)`` of a measurement ``z = [r, theta]`` (initialisation)."""
    return np.asarray(sensor.position) + z[0] * np.array([np.cos(z[1]), np.sin(z[1])])


# -- IMM-EKF ------------------------------------------------------------------------------------


class ModelConditioned:
    """Shared by IMM states holding ``probs (M,)``, ``means (M, 6)``, ``covs (M, 6, 6)``."""

    probs: np.ndarray
    means: np.ndarray
    covs: np.ndarray

    @property
    def estimate(self) -> np.ndarray:
        """Output combination ``(6,)``: ``sum_j mu_j x_j`` (seed 001 eq. 18)."""
        return self.probs @ self.means

    def summary(self) -> GaussianMixture:
        """The one-component-per-model Gaussian mixture a peer publishes (weights = probs)."""
        return GaussianMixture(self.probs, self.means, self.covs)


@dataclass(frozen=True)
class IMMGaussianState(ModelConditioned):
    """Per-model Gaussians of an IMM-EKF (or of a fused IMM summary)."""

    probs: np.ndarray
    """(M,) model probabilities."""
    means: np.ndarray
    """(M, 6) model-conditioned means."""
    covs: np.ndarray
    """(M, 6, 6) model-conditioned covariances."""
    log_likelihoods: np.ndarray | None = None
    """(M,) ``log Lambda_j`` of the last update (None after a prediction)."""


@dataclass(frozen=True)
class IMMEKF:
    """The IMM extended Kalman filter (baseline of seed 001 Table 1), batched over models."""

    params: IMMParams = field(default_factory=IMMParams)
    """Models, Markov matrix and initial probabilities."""

    def initialise(self, mean: np.ndarray, cov: np.ndarray) -> IMMGaussianState:
        """Every model starts at ``N(mean, cov)`` with the initial model probabilities."""
        M = len(self.params.initial_probs)
        return IMMGaussianState(np.asarray(self.params.initial_probs, float),
                                np.tile(mean, (M, 1)), np.tile(cov, (M, 1, 1)))

    @cached_property
    def _models(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``P (M, M)``, ``F (M, 6, 6)``, ``F^T`` (a view) and ``Q (M, 6, 6)``, built once."""
        models = self.params.models()
        F = np.stack([m.F for m in models])
        return self.params.P, F, np.swapaxes(F, 1, 2), np.stack([m.Q for m in models])

    def predict(self, state: IMMGaussianState) -> IMMGaussianState:
        """Interaction (mixing) and model-matched prediction; ``probs`` become ``c_j``.

        ``m0_j = sum_i mu_(i|j) m_i``, ``P0_j = sum_i mu_(i|j) [P_i + (m_i - m0_j)(.)^T]``,
        then ``m_j = F_j m0_j``, ``P_j = F_j P0_j F_j^T + Q_j``.
        """
        P, F, Ft, Q = self._models
        c, mu = mixing(state.probs, P)
        m0 = mu.T @ state.means  # (j, d)
        diff = state.means[None, :, :] - m0[:, None, :]  # (j, i, d)
        P0 = c_einsum("ij,iab->jab", mu, state.covs) + c_einsum(
            "ij,jia,jib->jab", mu, diff, diff)
        means = c_einsum("jab,jb->ja", F, m0)
        covs = F @ P0 @ Ft
        covs += Q
        return IMMGaussianState(c, means, _symmetrise(covs))

    def update(self, pred: IMMGaussianState, z: np.ndarray,
               sensor: RangeBearing) -> IMMGaussianState:
        """EKF update per model and model-probability update ``mu_j ∝ Lambda_j c_j``.

        ``S = H P H^T + R``, ``K = P H^T S^-1``, ``nu = z - h(m)`` (bearing wrapped),
        Joseph-form covariance, ``Lambda_j = N(nu_j; 0, S_j)`` (seed 001 eq. 9-11).
        """
        zhat, H = radar_jacobian(sensor, pred.means)
        nu = z - zhat  # (M, 2), bearing wrapped below
        nu[:, 1] += np.pi
        nu[:, 1] %= 2.0 * np.pi
        nu[:, 1] -= np.pi
        R = sensor.R
        Ht = np.swapaxes(H, 1, 2)
        PHt = pred.covs @ Ht  # (M, 6, 2)
        S = H @ PHt
        S += R
        Sinv, detS = inv_det_2x2(S)
        K = PHt @ Sinv  # (M, 6, 2)
        means = pred.means + c_einsum("jab,jb->ja", K, nu)
        IKH = _EYE6 - K @ H
        covs = IKH @ pred.covs @ np.swapaxes(IKH, 1, 2)
        covs += K @ R @ np.swapaxes(K, 1, 2)
        log_lik = c_einsum("ja,jab,jb->j", nu, Sinv, nu)
        log_lik += np.log(detS)
        log_lik += 2 * LOG_2PI
        log_lik *= -0.5
        return IMMGaussianState(model_posterior(pred.probs, log_lik), means, _symmetrise(covs),
                                log_lik)

    def step(self, state: IMMGaussianState, z: np.ndarray,
             sensor: RangeBearing) -> IMMGaussianState:
        """One scan: :meth:`predict` then :meth:`update`."""
        return self.update(self.predict(state), z, sensor)


_EYE6 = np.eye(STATE_DIM)


def _symmetrise(P: np.ndarray) -> np.ndarray:
    """``(P + P^T) / 2`` over a stack, as :func:`tracking.gaussian.symmetrise`, in place."""
    Pt = np.swapaxes(P, -1, -2).copy()
    Pt += P
    Pt *= 0.5
    return Pt


def model_posterior(c: np.ndarray, log_lik: np.ndarray) -> np.ndarray:
    """``mu_j = c_j Lambda_j / sum_i c_i Lambda_i`` from ``log Lambda (M,)`` (seed 001 eq. 11)."""
    a = np.log(np.maximum(c, 1e-300)) + log_lik
    a = np.exp(a - a.max())
    return a / a.sum()
