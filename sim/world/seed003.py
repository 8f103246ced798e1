"""Seed 003's scenario and world: the file's tables, the manoeuvring target, the position
sensors, target returns and clutter (in a region or in the gate)."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from scipy.linalg import solve_discrete_are
from sensornet.protocol.keys import check_name
from sensornet.sim.bounds import MAX_SENSORS
from sensornet.tracking.imm import POS, VEL, constant_velocity
from sensornet.tracking.pda import LinearSensor

SCENARIO = Path(__file__).parents[1] / "scenarios" / "seed003.toml"
H6 = np.zeros((2, 6))
H6[0, POS[0]] = H6[1, POS[1]] = 1.0
"""Position sensor on the 6-D state ``[px, vx, ax, py, vy, ay]``."""
G0 = 9.80665


def load(path: str | Path = SCENARIO, overrides: Mapping | None = None) -> dict:
    """The scenario as nested dicts; ``overrides`` maps ``"table.key"`` to a value."""
    cfg = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    for dotted, value in (overrides or {}).items():
        table, key = dotted.split(".", 1)
        if table not in cfg or key not in cfg[table]:
            raise ValueError(f"seed003: unknown setting {dotted!r}")
        cfg[table][key] = value
    check_sensor_names(cfg.get("sensors"), f"seed003 ({Path(path).name})")
    return cfg


def check_sensor_names(sensors, label: str) -> None:
    """The ``[[sensors]]`` of a seed-003 file: a list of tables, at most
    :data:`sim.scenario.MAX_SENSORS`, each ``name`` following the name rule
    (:func:`protocol.keys.check_name`) and not repeated. :class:`ValueError` (one line)."""
    if not isinstance(sensors, list) or not sensors:
        raise ValueError(f"{label}: 'sensors' must list at least one sensor ([[sensors]])")
    if len(sensors) > MAX_SENSORS:
        raise ValueError(f"{label}: {len(sensors):,} sensors, over the limit of {MAX_SENSORS}")
    seen: set[str] = set()
    for i, s in enumerate(sensors):
        name = s.get("name") if isinstance(s, dict) else None
        try:
            check_name(name, "sensor name", peer=True)
        except ValueError as exc:
            raise ValueError(f"{label}: sensors[{i}].name: {exc}") from None
        if name.lower() in seen:
            raise ValueError(f"{label}: sensors[{i}].name repeats the sensor name {name!r}")
        seen.add(name.lower())


# -- truth and measurements -------------------------------------------------------------------


def truth(cfg: Mapping) -> np.ndarray:
    """True 6-D states ``(K + 1, 6)`` at scans 0..K (noise-free, as in the paper)."""
    s = cfg["scenario"]
    T, K = float(s["scan_period"]), int(s["num_scans"])
    first, last = s["turn_scans"]
    n_turn = last - first + 1
    x = np.zeros((K + 1, 6))
    x[0, POS[0]], x[0, POS[1]] = s["start"]
    x[0, VEL[0]] = s["speed"]
    omega = (np.pi / 2) / (n_turn * T)  # coordinated: 90 deg over the turn
    for k in range(1, K + 1):
        px, vx, _, py, vy, _ = x[k - 1]
        turning = first <= k <= last
        if turning and s["manoeuvre"] == "coordinated":
            c, sn = np.cos(omega * T), np.sin(omega * T)
            nvx, nvy = c * vx - sn * vy, sn * vx + c * vy
            npx = px + (sn * vx - (1 - c) * vy) / omega
            npy = py + ((1 - c) * vx + sn * vy) / omega
            ax, ay = -omega * nvy, omega * nvx
        elif turning and s["manoeuvre"] == "literal":
            ax, ay = 0.0, 5 * G0
            nvx, nvy = vx, vy + ay * T
            npx, npy = px + vx * T, py + vy * T + 0.5 * ay * T * T
        elif s["manoeuvre"] in ("coordinated", "literal"):
            ax = ay = 0.0
            nvx, nvy, npx, npy = vx, vy, px + vx * T, py + vy * T
        else:
            raise ValueError(f"seed003: unknown manoeuvre {s['manoeuvre']!r}")
        x[k] = (npx, nvx, ax, npy, nvy, ay)
    return x


def cv_steady_state_S(cfg: Mapping, sigma: float) -> np.ndarray:
    """Innovation covariance ``(2, 2)`` of the steady-state CV Kalman filter for one sensor."""
    T = float(cfg["scenario"]["scan_period"])
    m = constant_velocity(T, float(cfg["filters"]["sigma_cv"]))
    idx = [0, 1, 3, 4]  # the CV model's acceleration is zeroed: the 4-D part is the filter
    F, Q, H = m.F[np.ix_(idx, idx)], m.Q[np.ix_(idx, idx)], H6[:, idx]
    R = sigma**2 * np.eye(2)
    P = solve_discrete_are(F.T, H.T, Q, R)  # prior covariance at steady state
    return H @ P @ H.T + R


def sensors(cfg: Mapping) -> tuple[LinearSensor, ...]:
    """The scenario's sensors, each with the clutter density of ``clutter.in_gate`` returns in
    its steady-state CV gate."""
    out = []
    for s in cfg["sensors"]:
        sigma = float(s["sigma"])
        base = LinearSensor(H6, sigma**2 * np.eye(2), 1.0, float(s["detection_probability"]),
                            float(s["gate_probability"]))
        lam = float(cfg["clutter"]["in_gate"]) / base.gate_volume(cv_steady_state_S(cfg, sigma))
        out.append(LinearSensor(H6, base.R, lam, base.detection_probability,
                                base.gate_probability))
    return tuple(out)


def target_returns(X: np.ndarray, sens: Sequence[LinearSensor],
                   rng: np.random.Generator) -> list[list[np.ndarray]]:
    """Per scan 1..K, per sensor: the target's return ``(1, 2)`` if detected, else ``(0, 2)``."""
    out = []
    for k in range(1, len(X)):
        pos = X[k, list(POS)]
        out.append([(pos + rng.multivariate_normal(np.zeros(2), s.R))[None]
                    if rng.random() < s.detection_probability else np.empty((0, 2))
                    for s in sens])
    return out


def region_clutter(cfg: Mapping, X: np.ndarray, sens: Sequence[LinearSensor],
                   rng: np.random.Generator) -> list[list[np.ndarray]]:
    """``clutter.mode = "region"``: per scan, per sensor, Poisson clutter uniform in the square
    of half-width ``clutter.halfwidth`` about the truth, of the sensor's density."""
    hw = float(cfg["clutter"]["halfwidth"])
    area = (2 * hw) ** 2
    return [[X[k, list(POS)] + rng.uniform(-hw, hw, size=(rng.poisson(s.clutter_density * area),
                                                           2))
             for s in sens] for k in range(1, len(X))]


def gate_clutter(zhat: np.ndarray, S: np.ndarray, gamma: float, n: int,
                 rng: np.random.Generator) -> np.ndarray:
    """``n`` returns uniform in the gate ``{z: (z - zhat)^T S^-1 (z - zhat) < gamma}``
    (``clutter.mode = "gate"``, the paper's eq. 3: clutter about the predicted measurement)."""
    r = np.sqrt(rng.random(n))
    t = rng.uniform(0.0, 2 * np.pi, n)
    u = np.stack([r * np.cos(t), r * np.sin(t)], axis=1)
    return zhat + np.sqrt(gamma) * u @ np.linalg.cholesky(S).T
