"""Probabilistic data association: PDAF and IMM-PDAF with a sequential multi-sensor update
(docs/seed003.md; seed 003 eq. 22-36; Bar-Shalom & Tse 1975, Houles & Bar-Shalom 1989).

One target, linear Gaussian models on any state (seed 003 uses the 6-D kinematic state
``[px, vx, ax, py, vy, ay]`` of :mod:`tracking.imm` so that CV and CA share it), linear
sensors ``z = H x + v``, ``v ~ N(0, R)``, Poisson clutter of spatial density ``lam`` (per unit
measurement volume), detection probability ``PD`` and gate probability ``PG``.

Per sensor, on the latest estimate (the sequential scheme, seed 003 steps (1)-(5)):

* predicted measurement ``zhat = H x``, ``S = H P H^T + R`` (eq. 24-25, 29-30);
* gate ``g_j = nu_j^T S^-1 nu_j < gamma`` with ``gamma = chi2.ppf(PG, n_z)`` (eq. 26, 31);
* likelihood ratio of return ``j`` against clutter ``L_j = PD N(nu_j; 0, S) / lam`` and
  ``b = 1 - PD PG``; association probabilities ``beta_j = L_j / (b + sum L)``,
  ``beta_0 = b / (b + sum L)`` (eq. 35-36 with ``e_j = exp(-g_j / 2)``: the paper's extracted
  text drops the 1/2 and, with its PD = PG = 1, has ``b = 0``; we keep the standard form and
  take PD, PG from the scenario);
* optional per-return degrees ``mu_j`` (the fuzzy association degree, :mod:`tracking.fuzzy`):
  weights ``W_j = mu_j beta_j / c``, ``W_0 = beta_0 / c``, ``c = beta_0 + sum mu_j beta_j``
  (eq. 12, 34: the normaliser ``P(A)`` keeps the weights a distribution);
* ``nubar = sum W_j nu_j``, ``K = P H^T S^-1``, ``x+ = x + K nubar`` (eq. 14, 27),
  ``P+ = W_0 P + (1 - W_0)(P - K S K^T) + K (sum W_j nu_j nu_j^T - nubar nubar^T) K^T``
  (eq. 15, 28).

The IMM-PDAF (Houles & Bar-Shalom 1989; seed 003 eq. 45-46): one mixing per scan
(:func:`tracking.imm.mixing`), each model predicts, and each sensor's returns are validated
by the union of the models' gates so that every model weighs the same returns; model ``j``'s
likelihood is ``Lambda_j ∝ b + sum_i L_ij`` (the factor common to all models, which depends on
the number of returns only, cancels). A single model is the PDAF: :class:`ImmPda` with one
model is the PDAF and its mixing is the identity.

Vectorised over the gated returns and the models; nothing here draws random numbers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import numpy as np
from sensornet.tracking.chi2 import chi2_ppf
from sensornet.tracking.imm import mixing


@dataclass(frozen=True)
class LinearSensor:
    """A linear sensor ``z = H x + v``, ``v ~ N(0, R)``, with Poisson clutter."""

    H: np.ndarray
    """(n_z, d) measurement matrix."""
    R: np.ndarray
    """(n_z, n_z) measurement noise covariance."""
    clutter_density: float
    """Clutter returns per unit measurement volume (per m^2 for a position sensor), > 0."""
    detection_probability: float = 1.0
    """PD: probability that the target gives a return."""
    gate_probability: float = 0.99
    """PG: probability that a target return falls in the gate; sets ``gamma``."""

    @property
    def gamma(self) -> float:
        """Gate threshold on ``nu^T S^-1 nu``: the ``PG`` quantile of chi2 with n_z dof."""
        return _chi2_ppf(self.gate_probability, self.H.shape[0])

    def gate_volume(self, S: np.ndarray) -> float:
        """Volume of the ellipsoidal gate ``{nu: nu^T S^-1 nu < gamma}`` (n_z = 1, 2 or 3)."""
        nz = self.H.shape[0]
        c = {1: 2.0, 2: np.pi, 3: 4.0 * np.pi / 3.0}[nz]
        return float(c * self.gamma ** (nz / 2) * np.sqrt(np.linalg.det(S)))


@lru_cache(maxsize=256)
def _chi2_ppf(p: float, dof: int) -> float:
    return chi2_ppf(p, dof)


_SIGN2 = np.array([[1.0, -1.0], [-1.0, 1.0]])


def _inv_det(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``S^-1`` and ``|S|`` of a stack ``S (M, n, n)`` (closed form for n = 2: NumPy's
    batched ``inv`` and ``det`` cost more in call overhead than the arithmetic)."""
    if S.shape[-1] == 2:
        det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
        return np.swapaxes(S[:, ::-1, ::-1], 1, 2) * _SIGN2 / det[:, None, None], det
    return np.linalg.inv(S), np.linalg.det(S)


def _quadratic_form(nu: np.ndarray, Sinv: np.ndarray) -> np.ndarray:
    """``nu^T S^-1 nu`` for ``nu (M, m, n_z)``, ``Sinv (M, n_z, n_z)``; ``(M, m)`` (closed
    form for n_z = 2, the common case, else einsum)."""
    if nu.shape[-1] == 2:
        a, b, d = Sinv[:, 0, 0, None], Sinv[:, 0, 1, None], Sinv[:, 1, 1, None]
        u, v = nu[..., 0], nu[..., 1]
        return a * u * u + 2.0 * b * u * v + d * v * v
    return np.einsum("kmi,kij,kmj->km", nu, Sinv, nu)


class ReturnWeighting(Protocol):
    """Per-return association degrees ``mu_j`` (the fuzzy part), consulted once per sensor."""

    def new_scan(self) -> None:
        """A new scan begins (the detector's window moves on)."""
        ...

    def observe(self, nis: float, dof: int) -> None:
        """The no-manoeuvre model's PDA-combined normalised innovation of one sensor update."""
        ...

    def degrees(self, g: np.ndarray) -> np.ndarray | None:
        """Degrees ``mu (M, m)`` for the returns' NIS ``g (M, m)``; None: plain PDA weights."""
        ...


@dataclass
class SensorUpdate:
    """What one sensor's update did (for display, the detector and the tests)."""

    returns: np.ndarray
    """(m, n_z) the validated returns."""
    model_weights: np.ndarray
    """(M, m) ``W_ij`` per model and return."""
    model_beta0: np.ndarray
    """(M,) ``W_0`` per model."""
    probs: np.ndarray
    """(M,) model probabilities after the update."""
    nis: np.ndarray
    """(M, m) ``g_ij`` per model and return."""
    S: np.ndarray
    """(n_z, n_z) innovation covariance of model 0 (the gate drawn in the view)."""
    zhat: np.ndarray
    """(n_z,) predicted measurement of model 0."""

    @property
    def weights(self) -> np.ndarray:
        """(m,) the returns' weights in the output (model-probability-weighted ``W_j``;
        computed when asked: the filter's step does not need them)."""
        return self.probs @ self.model_weights

    @property
    def beta0(self) -> float:
        """Weight of "no return is the target's" (model-probability-weighted)."""
        return float(self.probs @ self.model_beta0)


def pda_weights(g: np.ndarray, det2piS: np.ndarray, sensor: LinearSensor,
                mu: np.ndarray | None = None, clutter_density: float | None = None,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Association weights over a stack of models.

    ``g (M, m)`` NIS of each return under each model, ``det2piS (M,)`` ``|2 pi S_j|``.
    Returns ``W0 (M,)``, ``W (M, m)`` (``beta`` when ``mu`` is None, else ``mu beta / c``) and
    ``Lambda (M,)`` the model likelihood ``b + sum_i L_ij`` (up to a factor common to all
    models). With no return and ``b = 0`` (PD = PG = 1), ``W0 = 1``: nothing to update with.
    ``clutter_density`` overrides the sensor's (clutter simulated in the gate).
    """
    pd, pg = sensor.detection_probability, sensor.gate_probability
    lam = sensor.clutter_density if clutter_density is None else clutter_density
    b = 1.0 - pd * pg
    L = np.exp(-0.5 * g) * ((pd / lam) / np.sqrt(det2piS))[:, None]
    lik = b + L.sum(axis=1)
    if mu is not None:
        L = L * mu
        denom = b + L.sum(axis=1)
    else:
        denom = lik
    if (denom > 0).all():
        return b / denom, L / denom[:, None], lik
    safe = denom > 0
    W0 = np.where(safe, b / np.where(safe, denom, 1.0), 1.0)
    W = np.where(safe[:, None], L / np.where(safe, denom, 1.0)[:, None], 0.0)
    return W0, W, lik


def pda_moments(x: np.ndarray, P: np.ndarray, K: np.ndarray, S: np.ndarray, nu: np.ndarray,
                W0: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """PDA state and covariance update over a stack of models (eq. 14-15).

    ``x (M, d)``, ``P (M, d, d)``, ``K (M, d, n_z)``, ``S (M, n_z, n_z)``, ``nu (M, m, n_z)``,
    ``W0 (M,)``, ``W (M, m)``.
    """
    nubar = (W[:, None, :] @ nu)[:, 0]  # (M, n_z)
    x_new = x + (K @ nubar[:, :, None])[:, :, 0]
    # P - (1 - W0) K S K^T + K spread K^T = P + K (spread - (1 - W0) S) K^T
    spread = (nu.transpose(0, 2, 1) * W[:, None, :]) @ nu - nubar[:, :, None] * nubar[:, None, :]
    P_new = P + K @ (spread - (1.0 - W0)[:, None, None] * S) @ K.transpose(0, 2, 1)
    return x_new, 0.5 * (P_new + P_new.transpose(0, 2, 1))


class ImmPda:
    """IMM-PDAF over ``models`` with a sequential multi-sensor update; one model is the PDAF.

    ``models``: ``(F (d, d), Q (d, d))`` pairs; ``transition (M, M)`` the Markov matrix
    ``p_ij``; ``weighting``: optional :class:`ReturnWeighting` (fuzzy PDA / fuzzy IMM).
    """

    def __init__(self, models: Sequence[tuple[np.ndarray, np.ndarray]], transition: np.ndarray,
                 x0: np.ndarray, P0: np.ndarray, probs0: np.ndarray | None = None,
                 weighting: ReturnWeighting | None = None) -> None:
        self.F = np.stack([np.asarray(F, float) for F, _ in models])  # (M, d, d)
        self.Q = np.stack([np.asarray(Q, float) for _, Q in models])
        M = len(models)
        self.transition = np.asarray(transition, float).reshape(M, M)
        self.x = np.repeat(np.asarray(x0, float)[None], M, axis=0)  # (M, d)
        self.P = np.repeat(np.asarray(P0, float)[None], M, axis=0)  # (M, d, d)
        self.probs = (np.full(M, 1.0 / M) if probs0 is None
                      else np.asarray(probs0, float).copy())
        self.weighting = weighting
        self._FT = self.F.transpose(0, 2, 1).copy()

    # -- output -----------------------------------------------------------------------------

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """Combined mean ``(d,)`` and covariance ``(d, d)`` (moment match over the models)."""
        x = self.probs @ self.x
        dx = self.x - x
        M, d = self.x.shape
        P = self.probs @ (self.P + dx[:, :, None] * dx[:, None, :]).reshape(M, d * d)
        return x, P.reshape(d, d)

    def predicted_measurement(self, sensor: LinearSensor) -> tuple[np.ndarray, np.ndarray]:
        """``zhat (n_z,)`` and ``S (n_z, n_z)`` of the combined estimate: the gate drawn in the
        view and the one clutter is simulated in (seed 003 eq. 3)."""
        x, P = self.estimate()
        return sensor.H @ x, sensor.H @ P @ sensor.H.T + sensor.R

    def adopt(self, x: np.ndarray, P: np.ndarray) -> None:
        """Replace every model's state by ``(x, P)`` (a fused estimate fed back)."""
        self.x[:] = x
        self.P[:] = P

    # -- cycle ------------------------------------------------------------------------------

    def predict(self, steps: int = 1) -> None:
        """IMM mixing and model-matched prediction, ``steps`` times (eq. 16, 22-23, 45)."""
        M, d = self.x.shape
        for _ in range(int(steps)):
            if M > 1:
                c, mix = mixing(self.probs, self.transition)  # mix (i, j)
                x0 = mix.T @ self.x
                dx = self.x[:, None, :] - x0[None, :, :]  # (i, j, d)
                # sum_i mix_ij (P_i + dx_ij dx_ij^T), as two matrix products
                P0 = (mix.T @ self.P.reshape(M, d * d)).reshape(M, d, d) + \
                    (dx * mix[:, :, None]).transpose(1, 2, 0) @ dx.transpose(1, 0, 2)
                self.x, self.P, self.probs = x0, P0, c
            self.x = (self.F @ self.x[:, :, None])[:, :, 0]
            self.P = self.F @ self.P @ self._FT + self.Q
        if self.weighting is not None:
            self.weighting.new_scan()

    def update(self, sensor: LinearSensor, Z: np.ndarray,
               clutter_density: float | None = None) -> SensorUpdate:
        """One sensor's PDA update on the latest estimate (eq. 26-33); returns what it did.
        ``clutter_density`` overrides the sensor's for this scan."""
        H, R = sensor.H, sensor.R
        nz = H.shape[0]
        Z = np.asarray(Z, float).reshape(-1, nz)
        Ht = H.T
        zhat = self.x @ Ht  # (M, n_z)
        PHt = self.P @ Ht  # (M, d, n_z)
        S = H @ PHt + R  # (M, n_z, n_z)
        Sinv, detS = _inv_det(S)
        nu = Z[None, :, :] - zhat[:, None, :]  # (M, m, n_z)
        g = _quadratic_form(nu, Sinv)  # (M, m) NIS, element by element: the same bits
        # whatever other returns the scan holds (a peer's pre-gated share of it included)
        inside = (g < sensor.gamma).any(axis=0)  # union of the models' gates
        if inside.all():
            Zg = Z
        else:
            nu, g, Zg = nu[:, inside], g[:, inside], Z[inside]
        det2piS = (2.0 * np.pi) ** nz * detS
        K = PHt @ Sinv
        W0, W, lik = pda_weights(g, det2piS, sensor, None, clutter_density)
        if self.weighting is not None:
            # the detector sees model 0's (no-manoeuvre) PDA-combined innovation
            nubar0 = W[0] @ nu[0]
            self.weighting.observe(float(nubar0 @ Sinv[0] @ nubar0), nz)
            mu = self.weighting.degrees(g)
            if mu is not None:
                W0, W, _ = pda_weights(g, det2piS, sensor, mu, clutter_density)
        self.x, self.P = pda_moments(self.x, self.P, K, S, nu, W0, W)
        if len(self.probs) > 1:
            p = self.probs * lik
            total = float(p.sum())
            self.probs = p / total if total > 0 and math.isfinite(total) else self.probs
        return SensorUpdate(Zg, W, W0, self.probs, g, S[0], zhat[0])

    def step(self, sensors: Sequence[LinearSensor], scans: Sequence[np.ndarray | None],
             steps: int = 1) -> list[SensorUpdate | None]:
        """Predict ``steps`` scans, then update with each sensor's returns in order (None: the
        sensor's scan is missing, skipped)."""
        self.predict(steps)
        return [None if Z is None else self.update(s, Z)
                for s, Z in zip(sensors, scans, strict=True)]
