"""The seed-003 PDA filter's hot path as it was before the speed work of issue 12 (commit
3fcb50a's ``tracking/pda.py``), kept as the same-run reference of ``bench_pda.py``: the machine
is shared, so the ratio of the two, timed interleaved in one process, is what counts."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.tracking.imm import mixing
from sensornet.tracking.pda import ImmPda, LinearSensor, _quadratic_form


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
    L = (pd / lam) * np.exp(-0.5 * g) / np.sqrt(det2piS)[:, None]
    lik = b + L.sum(axis=1)
    if mu is not None:
        L = L * mu
    denom = b + L.sum(axis=1)
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
    nubar = np.einsum("km,kmi->ki", W, nu)
    x_new = x + np.einsum("kij,kj->ki", K, nubar)
    KSK = K @ S @ K.transpose(0, 2, 1)
    spread = np.einsum("km,kmi,kmj->kij", W, nu, nu) - nubar[:, :, None] * nubar[:, None, :]
    P_new = P - (1.0 - W0)[:, None, None] * KSK + K @ spread @ K.transpose(0, 2, 1)
    return x_new, 0.5 * (P_new + P_new.transpose(0, 2, 1))


class ImmPdaBefore(ImmPda):
    """:class:`tracking.pda.ImmPda` with the predict and update of before (same results up
    to rounding; the update returns the returns, weights and beta0, not a ``SensorUpdate``)."""

    def predict(self, steps: int = 1) -> None:
        """IMM mixing and model-matched prediction, ``steps`` times (eq. 16, 22-23, 45)."""
        for _ in range(int(steps)):
            if len(self.probs) > 1:
                c, mix = mixing(self.probs, self.transition)  # mix (i, j)
                x0 = np.einsum("ij,id->jd", mix, self.x)
                dx = self.x[:, None, :] - x0[None, :, :]  # (i, j, d)
                P0 = np.einsum("ij,ijab->jab", mix,
                               self.P[:, None] + dx[..., :, None] * dx[..., None, :])
                self.x, self.P, self.probs = x0, P0, c
            self.x = np.einsum("kij,kj->ki", self.F, self.x)
            self.P = self.F @ self.P @ self.F.transpose(0, 2, 1) + self.Q
        if self.weighting is not None:
            self.weighting.new_scan()

    def update(self, sensor: LinearSensor, Z: np.ndarray,
               clutter_density: float | None = None):
        """One sensor's PDA update on the latest estimate (eq. 26-33); returns what it did.
        ``clutter_density`` overrides the sensor's for this scan."""
        H, R = sensor.H, sensor.R
        nz = H.shape[0]
        Z = np.asarray(Z, float).reshape(-1, nz)
        zhat = self.x @ H.T  # (M, n_z)
        PHt = self.P @ H.T  # (M, d, n_z)
        S = H @ PHt + R  # (M, n_z, n_z)
        Sinv = np.linalg.inv(S)
        nu = Z[None, :, :] - zhat[:, None, :]  # (M, m, n_z)
        g = _quadratic_form(nu, Sinv)
        inside = (g < sensor.gamma).any(axis=0)  # union of the models' gates
        nu, g, Zg = nu[:, inside], g[:, inside], Z[inside]
        det2piS = np.linalg.det(2.0 * np.pi * S)
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
            total = p.sum()
            self.probs = p / total if total > 0 and np.isfinite(total) else self.probs
        return Zg, self.probs @ W, float(self.probs @ W0)  # what SensorUpdate held
