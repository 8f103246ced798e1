"""Seed 003's filters: PDAF, IMM-PDAF and their fuzzy variants built from the scenario, and one
filter run over the scans."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np
from sensornet.sim.world.seed003 import gate_clutter
from sensornet.tracking.fuzzy import weighting_from_config
from sensornet.tracking.imm import constant_acceleration, constant_velocity
from sensornet.tracking.pda import ImmPda, LinearSensor

METHODS = ("PDAF", "IMM-PDAF", "fuzzy PDA", "fuzzy IMM")


def run_filter(cfg: Mapping, flt: ImmPda, sens: Sequence[LinearSensor],
               target: Sequence[Sequence[np.ndarray]],
               region: Sequence[Sequence[np.ndarray]] | None,
               rng: np.random.Generator, on_update=None,
               timing: list[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Run ``flt`` over the scans with the sequential update of ``sens`` in order; clutter from
    ``region`` (per scan, per sensor) or, when None, drawn in the filter's own gate with
    ``rng`` (Poisson with mean ``clutter.in_gate``; the PDA's density is that mean over the
    gate's volume). ``on_update(Z, detected, update)`` sees every sensor update (the target's
    return, when ``detected``, is ``Z[0]``). Returns estimates ``(K, d)`` and detector flags
    ``(K,)``. ``timing``: the seconds spent in the filter's predict and update calls (not in
    drawing the clutter) are appended to it."""
    in_gate = float(cfg["clutter"]["in_gate"])
    est = np.empty((len(target), flt.x.shape[1]))
    fired = np.zeros(len(target), bool)
    clock, spent = time.perf_counter, 0.0
    for k, per in enumerate(target):
        t0 = clock()
        flt.predict()
        spent += clock() - t0
        for i, s in enumerate(sens):
            if region is not None:
                Z = np.vstack([per[i], region[k][i]])
                t0 = clock()
                up = flt.update(s, Z)
            else:
                zhat, S = flt.predicted_measurement(s)
                Z = np.vstack([per[i], gate_clutter(zhat, S, s.gamma, rng.poisson(in_gate),
                                                    rng)])
                density = in_gate / s.gate_volume(S)
                t0 = clock()
                up = flt.update(s, Z, density)
            spent += clock() - t0
            if on_update is not None:
                on_update(Z, len(per[i]) > 0, up, flt)
        est[k] = flt.estimate()[0]
        if flt.weighting is not None:
            fired[k] = flt.weighting.detector.fired
    if timing is not None:
        timing.append(spent)
    return est, fired


# -- filters ----------------------------------------------------------------------------------


def initial_state(cfg: Mapping, x0: np.ndarray,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Initial estimate drawn about the truth with the configured spread, and its covariance."""
    sp, sv, sa = cfg["filters"]["init_sigma"]
    P0 = np.diag(np.array([sp, sv, sa, sp, sv, sa], float) ** 2)
    return x0 + rng.multivariate_normal(np.zeros(6), P0), P0


def coordinated_turn(T: float, omega: float, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Coordinated turn at a known rate ``omega`` (rad/s) on the 6-D state (acceleration
    zeroed), white acceleration noise ``sigma`` (m/s^2) as in the CV model: ``(F, Q)``."""
    c, s = np.cos(omega * T), np.sin(omega * T)
    F = np.zeros((6, 6))
    j = np.ix_((0, 1, 3, 4), (0, 1, 3, 4))  # px, vx, py, vy
    F[j] = [[1, s / omega, 0, -(1 - c) / omega], [0, c, 0, -s],
            [0, (1 - c) / omega, 1, s / omega], [0, s, 0, c]]
    return F, constant_velocity(T, sigma).Q


def imm_models(cfg: Mapping) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray,
                                      np.ndarray]:
    """The IMM's models, Markov matrix and initial probabilities. ``filters.model``:
    ``"ca"``: CV + CA (``transition``, ``initial_probs`` as given); ``"ct"``: CV and
    coordinated turns at +/- ``turn_rate_deg`` (the CV row and column of ``transition`` split
    evenly between the two turns)."""
    f = cfg["filters"]
    T = float(cfg["scenario"]["scan_period"])
    cv = constant_velocity(T, float(f["sigma_cv"]))
    Pi = np.asarray(f["transition"], float)
    p0 = np.asarray(f["initial_probs"], float)
    kind = f.get("model", "ca")
    if kind == "ca":
        ca = constant_acceleration(T, float(f["sigma_ca"]))
        return [(cv.F, cv.Q), (ca.F, ca.Q)], Pi, p0
    if kind == "ct":
        w = np.deg2rad(float(f["turn_rate_deg"]))
        sct = float(f["sigma_ct"])
        stay_cv, stay_ct = Pi[0, 0], Pi[1, 1]
        P3 = np.array([[stay_cv, (1 - stay_cv) / 2, (1 - stay_cv) / 2],
                       [1 - stay_ct, stay_ct, 0.0], [1 - stay_ct, 0.0, stay_ct]])
        return ([(cv.F, cv.Q), coordinated_turn(T, w, sct), coordinated_turn(T, -w, sct)], P3,
                np.array([p0[0], p0[1] / 2, p0[1] / 2]))
    raise ValueError(f"seed003: unknown filters.model {kind!r}; expected 'ca' or 'ct'")


def make_filter(cfg: Mapping, method: str, m0: np.ndarray, P0: np.ndarray) -> ImmPda:
    """One of :data:`METHODS`, with the scenario's models and (fuzzy ones) a fresh weighting."""
    f = cfg["filters"]
    T = float(cfg["scenario"]["scan_period"])
    cv = constant_velocity(T, float(f["sigma_cv"]))
    weighting = (weighting_from_config(cfg["fuzzy"], cfg["detector"])
                 if method.startswith("fuzzy") else None)
    if method in ("PDAF", "fuzzy PDA"):
        return ImmPda([(cv.F, cv.Q)], np.eye(1), m0, P0, weighting=weighting)
    if method in ("IMM-PDAF", "fuzzy IMM"):
        models, Pi, p0 = imm_models(cfg)
        return ImmPda(models, Pi, m0, P0, p0, weighting=weighting)
    raise ValueError(f"seed003: unknown method {method!r}; expected one of {METHODS}")
