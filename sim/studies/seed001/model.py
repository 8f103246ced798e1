"""Seed 001's model and one Monte Carlo run: two radars, one manoeuvring target, IMM-EKF and
IMM-PF peers, each radar alone, GCI fusion and the particle fusion rule, on the same draws."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.peers.contracts import FusionInput
from sensornet.peers.estimators import ImmEstimator, SingleTargetConfig
from sensornet.peers.fusers import ImmFuser
from sensornet.sim.scenario import ManoeuvreSpec, Scenario
from sensornet.tracking.models import RangeBearing

# -- scenario ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class RadarSpec:
    """One range-bearing radar."""

    position: tuple[float, float]
    """(sx, sy) in m."""
    sigma_r: float
    """Range noise standard deviation in m."""
    sigma_theta_deg: float
    """Bearing noise standard deviation in degrees."""

    def sensor(self) -> RangeBearing:
        """The ``tracking.models.RangeBearing`` for this radar."""
        return RangeBearing(self.sigma_r, float(np.deg2rad(self.sigma_theta_deg)),
                            (float(self.position[0]), float(self.position[1])))


GEOMETRIES: dict[str, tuple[RadarSpec, RadarSpec]] = {
    # docs/seed001.md "geometry A" (default): the radars 12 km apart, target ~5-15 km away
    "A": (RadarSpec((0.0, 0.0), 3.0, 0.08), RadarSpec((12000.0, 0.0), 2.0, 0.1)),
    # "geometry G": ~100 km away, nearly the same viewing direction
    "G": (RadarSpec((0.0, -100000.0), 3.0, 0.08), RadarSpec((2000.0, -100000.0), 2.0, 0.1)),
    # "close" (ours): radars a few hundred metres off the track, bearing noise 3 deg: strongly
    # nonlinear (banana-shaped) likelihoods where the particle filter should beat the EKF
    "close": (RadarSpec((8000.0, 7500.0), 3.0, 3.0), RadarSpec((12000.0, 8000.0), 2.0, 3.0)),
    # "near" (ours): radars about 250 m off the first leg, 10 deg bearing noise, 2 m range
    # noise: each measurement is a thin arc; here the particle filter clearly beats the EKF
    "near": (RadarSpec((7000.0, 7600.0), 2.0, 10.0), RadarSpec((9000.0, 7000.0), 2.0, 10.0)),
}
"""Radar presets (radar 1 sigma_r = 3 m, 0.08 deg; radar 2 sigma_r = 2 m, 0.1 deg; seed 001)."""


_TARGET = ManoeuvreSpec()


@dataclass(frozen=True)
class Seed001Scenario:
    """The seed-001 ground target and radars (docs/seed001.md). The target's defaults are the
    scenario's ``[manoeuvre]`` section's (:class:`sim.scenario.ManoeuvreSpec`, declared
    once); :meth:`of` takes them, the scan period and the seed from a loaded scenario."""

    start: tuple[float, float] = _TARGET.start
    """Initial position in m."""
    speed: float = _TARGET.speed
    """Speed in m/s."""
    heading_deg: float = _TARGET.heading_deg
    """Initial heading in degrees counter-clockwise from east (29.36 deg south of east)."""
    segments: tuple[tuple[float, float], ...] = _TARGET.segments
    """(duration s, turn rate deg/s; positive = left) per segment; 650 s in total."""
    T: float = 1.0
    """Scan period in s."""
    geometry: str = "A"
    """Key of :data:`GEOMETRIES` (used when ``radars`` is empty)."""
    radars: tuple[RadarSpec, ...] = ()
    """Explicit radars (override ``geometry``)."""
    init_sigma: tuple[float, ...] = _TARGET.init_sigma
    """Initial estimate spread per axis: position m, velocity m/s, acceleration m/s^2."""
    seed: int = 1
    """Base seed; run ``r`` draws from ``SeedSequence([seed, r])``."""

    @classmethod
    def of(cls, scn: Scenario) -> Seed001Scenario:
        """The target of ``scn``'s ``[manoeuvre]`` (its defaults when absent), its scan period
        and seed (the radars: geometry A; the network's are ``scn.sensors``)."""
        m = scn.manoeuvre or _TARGET
        return cls(m.start, m.speed, m.heading_deg, m.segments, T=scn.scan_period,
                   init_sigma=m.init_sigma, seed=scn.seed)

    def sensors(self) -> tuple[RangeBearing, ...]:
        """The radars as ``RangeBearing`` objects."""
        specs = self.radars or GEOMETRIES[self.geometry]
        return tuple(s.sensor() for s in specs)

    @property
    def num_scans(self) -> int:
        """Number of scans ``K`` (truth has ``K + 1`` states, scans at k = 1..K)."""
        return int(round(sum(d for d, _ in self.segments) / self.T))

    @property
    def init_cov(self) -> np.ndarray:
        """(6, 6) initial covariance ``diag(sp^2, sv^2, sa^2)`` per axis."""
        return np.diag(np.tile(np.square(self.init_sigma), 2))


def truth(scn: Seed001Scenario) -> np.ndarray:
    """True states ``(K + 1, 6)`` ``[px, vx, ax, py, vy, ay]``: exact constant-turn motion.

    A turn at rate ``w`` rotates the velocity by ``w T`` per scan; the position moves by
    ``(sin wT / w) v + ((1 - cos wT) / w) J v`` (``J`` = rotation by 90 deg); the acceleration
    is ``w J v``.
    """
    h = np.deg2rad(scn.heading_deg)
    p = np.array(scn.start, float)
    v = scn.speed * np.array([np.cos(h), np.sin(h)])
    rates = np.concatenate([np.full(int(round(d / scn.T)), np.deg2rad(r)) for d, r in scn.segments])
    out = np.empty((len(rates) + 1, 6))
    J = np.array([[0.0, -1.0], [1.0, 0.0]])
    T = scn.T
    for k, w in enumerate(rates):
        out[k, [0, 3]], out[k, [1, 4]], out[k, [2, 5]] = p, v, w * (J @ v)
        if abs(w) > 1e-12:
            s, c = np.sin(w * T) / w, (1.0 - np.cos(w * T)) / w
        else:
            s, c = T, 0.0
        p = p + s * v + c * (J @ v)
        v = np.array([[np.cos(w * T), -np.sin(w * T)], [np.sin(w * T), np.cos(w * T)]]) @ v
    out[-1, [0, 3]], out[-1, [1, 4]], out[-1, [2, 5]] = p, v, rates[-1] * (J @ v)
    return out


def measure(sensors: Sequence[RangeBearing], states: np.ndarray,
            rng: np.random.Generator) -> np.ndarray:
    """Measurements ``(n_radars, K + 1, 2)`` ``[range, bearing]`` of ``states (K + 1, 6)``."""
    xy4 = states[:, [0, 1, 3, 4]]  # RangeBearing works on [px, vx, py, vy]
    return np.stack([s.measure(xy4, rng) for s in sensors])


def run_streams(scn: Seed001Scenario, run: int, n: int) -> list[np.random.Generator]:
    """``n`` independent generators for run ``run`` (measurements, initial estimate, filters)."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence([scn.seed, run]).spawn(n)]


# -- experiment ---------------------------------------------------------------------------------


FILTERS = ("IMM-EKF", "IMM-PF")
RULES = ("radar 1", "radar 2", "GCI fusion", "particle fusion rule")


@dataclass(frozen=True)
class ExperimentConfig(SingleTargetConfig):
    """The peers' filter and fusion settings plus the experiment's own (losses, filters)."""

    loss_threshold: float = 100.0
    """A track is lost when the position error exceeds this (m) ..."""
    loss_after: int = 20
    """... at any scan after this one."""
    filters: tuple[str, ...] = FILTERS
    """Which filters to run."""


@dataclass(frozen=True)
class RunResult:
    """Errors of one Monte Carlo run, per method ``(filter, rule)``."""

    errors: dict[tuple[str, str], np.ndarray]
    """(K, 3) x-position, x-velocity, x-acceleration errors at scans 1..K."""
    pos_error: dict[tuple[str, str], np.ndarray]
    """(K,) position error norm in m."""
    seconds: dict[str, float]
    """Wall time per filter kind (all four rules)."""


def _errors(est: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, float]:
    return est[[0, 1, 2]] - x[[0, 1, 2]], float(np.hypot(est[0] - x[0], est[3] - x[3]))


def _run_inputs(scn: Seed001Scenario, run: int):
    """Run ``run``'s truth ``(K + 1, 6)``, sensors, measurements, initial estimate and the four
    filter streams (own radar, other radar, GCI fuser, ratio fuser)."""
    g_meas, g_init, *g_f = run_streams(scn, run, 2 + 4)
    X = truth(scn)
    sensors = scn.sensors()
    Z = measure(sensors, X, g_meas)
    m0 = X[0] + g_init.standard_normal(6) @ np.linalg.cholesky(scn.init_cov).T
    return X, sensors, Z, m0, g_f


def run_once(scn: Seed001Scenario, cfg: ExperimentConfig, run: int) -> RunResult:
    """One Monte Carlo run: both filter kinds, four rules each, on the same measurements."""
    X, sensors, Z, m0, g_f = _run_inputs(scn, run)
    K = scn.num_scans
    errors, pos_error, seconds = {}, {}, {}
    for kind in cfg.filters:
        t0 = time.perf_counter()
        ests = _run_filters(kind, scn, cfg, sensors, Z, m0, g_f)  # (4, K, 6)
        seconds[kind] = time.perf_counter() - t0
        for r, rule in enumerate(RULES):
            e = ests[r] - X[1:]
            errors[(kind, rule)] = e[:, [0, 1, 2]]
            pos_error[(kind, rule)] = np.hypot(e[:, 0], e[:, 3])
    assert all(v.shape[0] == K for v in pos_error.values())
    return RunResult(errors, pos_error, seconds)


def _run_filters(kind: str, scn, cfg, sensors, Z, m0, rngs) -> np.ndarray:
    """Estimates ``(4, K, 6)``: radar 1, radar 2, GCI, particle fusion rule.

    The same objects the peers run (:class:`peers.estimators.ImmEstimator`,
    :class:`peers.fusers.ImmFuser`): radar 1's peer fuses radar 2's published estimate, so this
    table and a two-peer network compute the same thing (tests/test_seed001.py ties them).
    """
    rngs = list(rngs) if kind == "IMM-PF" else [None] * 4
    return _run_fusers(kind, scn, cfg, sensors, Z, m0, rngs[:2],
                       [("gci", cfg.gci_omega, rngs[2]), ("ratio", cfg.gci_omega, rngs[3])])


def _run_fusers(kind: str, scn, cfg, sensors, Z, m0, filter_rngs, fusers) -> np.ndarray:
    """Estimates ``(2 + F, K, 6)``: radar 1, radar 2, then one row per fuser ``(rule, omega,
    rng)``. Every fuser runs on radar 1 and fuses radar 2's published estimate; the fusers never
    touch each other or the local filters, so a fuser's estimates do not depend on which other
    fusers run beside it (the omega tuning runs several GCI fusers on one pair of filters)."""
    kind = "imm-pf" if kind == "IMM-PF" else "imm-ekf"
    r_own, r_other = filter_rngs if kind == "imm-pf" else (None, None)
    own = ImmEstimator(kind, cfg.imm, cfg.particle, sensors[0], m0, scn.init_cov, r_own,
                       cfg.cov_floor)
    other = ImmEstimator(kind, cfg.imm, cfg.particle, sensors[1], m0, scn.init_cov, r_other,
                         cfg.cov_floor, with_prediction=True)
    fused = [ImmFuser(rule, own, m0, scn.init_cov, rng if kind == "imm-pf" else None, omega,
                      cfg.ratio) for rule, omega, rng in fusers]
    K = scn.num_scans
    out = np.empty((2 + len(fused), K, 6))
    for k in range(1, K + 1):
        z1, z2 = Z[0, k], Z[1, k]
        own.step(1, z1)
        sent = {"r2": other.step(1, z2).published}
        for fuser in fused:
            fuser.fuse(FusionInput(k, 0, own.state.summary(), sent, (0.5, 0.5), z1))
        for r, state in enumerate([own.state, other.state] + [f.state for f in fused]):
            out[r, k - 1] = state.estimate
    return out
