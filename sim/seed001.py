"""Seed 001: a manoeuvring ground target seen by two range-bearing radars (docs/seed001.md).

Scenario (truth, measurements per radar, geometry presets; every draw from a seed) as plain
frozen dataclasses, and the Monte Carlo experiment of the paper's Table 1: x-axis position,
velocity and acceleration RMSE and lost tracks, for the IMM-EKF and the IMM-PF, each radar
alone, GCI fusion and the particle fusion rule (eq. 19-21).

The fusion is centralised in one process: radar 2's filter runs on its own (the "other peer");
the fusing filter runs on radar 1 and at every scan fuses radar 2's published summaries
(posterior, and for the ratio rule also prediction). The fusion calls are the ones a peer
would make with a received message (``tracking.particles``).

``python -m sim.seed001 --runs 300 --geometry A --jobs 2`` prints the table (runs 0..299);
``python -m sim.seed001 --tune-omega 0.2,0.3,0.4,det --tune-runs 40 --jobs 2`` compares GCI
weights on runs 10000..10039, which the table never evaluates.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from peers.contracts import FusionInput
from peers.estimators import ImmEstimator, SingleTargetConfig
from peers.fusers import ImmFuser
from sim.studies.pool import map_runs
from tracking.models import RangeBearing
from tracking.particles import ParticleParams, RatioConfig

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


@dataclass(frozen=True)
class Seed001Scenario:
    """The seed-001 ground target and radars (docs/seed001.md)."""

    start: tuple[float, float] = (6000.0, 8400.0)
    """Initial position in m."""
    speed: float = 23.0
    """Speed in m/s."""
    heading_deg: float = -29.36
    """Initial heading in degrees counter-clockwise from east (29.36 deg south of east)."""
    segments: tuple[tuple[float, float], ...] = (
        (180.0, 0.0), (80.0, 1.15), (110.0, 0.0), (140.0, -0.43), (140.0, 0.0))
    """(duration s, turn rate deg/s; positive = left) per segment; 650 s in total."""
    T: float = 1.0
    """Scan period in s."""
    geometry: str = "A"
    """Key of :data:`GEOMETRIES` (used when ``radars`` is empty)."""
    radars: tuple[RadarSpec, ...] = ()
    """Explicit radars (override ``geometry``)."""
    init_sigma: tuple[float, float, float] = (20.0, 2.0, 0.05)
    """Initial estimate spread per axis: position m, velocity m/s, acceleration m/s^2."""
    seed: int = 1
    """Base seed; run ``r`` draws from ``SeedSequence([seed, r])``."""

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


@dataclass(frozen=True)
class ExperimentResult:
    """All runs of :func:`run_experiment`."""

    scenario: Seed001Scenario
    config: ExperimentConfig
    runs: list[RunResult]

    def lost(self, method: tuple[str, str]) -> np.ndarray:
        """(runs,) whether the track was lost (position error > threshold after scan N)."""
        c = self.config
        return np.array([r.pos_error[method][c.loss_after:].max() > c.loss_threshold
                         for r in self.runs])

    def rows(self) -> list[dict]:
        """Per method: x RMSE (pos, vel, acc) over the runs not lost, and lost-track count."""
        out = []
        for method in self.runs[0].errors:
            lost = self.lost(method)
            kept = [r.errors[method] for r, bad in zip(self.runs, lost, strict=True) if not bad]
            if kept:
                rmse = np.sqrt(np.mean(np.square(np.stack(kept)), axis=(0, 1)))
            else:
                rmse = np.full(3, np.nan)
            every = np.stack([r.errors[method][:, 0] for r in self.runs])
            out.append({"filter": method[0], "rule": method[1], "rmse": rmse,
                        "rmse_all": float(np.sqrt(np.mean(np.square(every)))),
                        "lost": int(lost.sum()), "runs": len(self.runs),
                        "seconds": float(np.mean([r.seconds[method[0]] for r in self.runs]))})
        return out


def run_experiment(scn: Seed001Scenario, cfg: ExperimentConfig, runs: int, jobs: int = 1,
                   progress: bool = True, first_run: int = 0) -> ExperimentResult:
    """``runs`` Monte Carlo runs over ``jobs`` worker processes, with a progress bar."""
    results = map_runs(run_once, [(scn, cfg, first_run + i) for i in range(runs)], jobs,
                       f"runs (seed001, geometry {scn.geometry})", progress)
    return ExperimentResult(scn, cfg, results)


PAPER_TABLE1 = {
    ("IMM-EKF", "fusion"): (38.27, 1.222, 9.237),
    ("IMM-PF", "fusion"): (12.29, 0.892, 8.965),
}
"""Seed 001 Table 1, x-axis RMSE (m, m/s, m/s^2), 300 runs, radar positions not given."""


def format_table(result: ExperimentResult) -> str:
    """The Table-1 layout (Markdown): one row per (filter, rule), paper rows for reference."""
    scn = result.scenario
    radars = ", ".join(f"({s.position[0]:g}, {s.position[1]:g}) sr={s.sigma_r:g} m "
                       f"st={np.rad2deg(s.sigma_theta):g} deg" for s in scn.sensors())
    lines = [f"seed001 geometry {scn.geometry}: radars {radars}; {len(result.runs)} runs x "
             f"{scn.num_scans} scans; RMSE over runs not lost (lost: position error > "
             f"{result.config.loss_threshold:g} m after scan {result.config.loss_after})", "",
             "| filter | estimate | x pos RMSE (m) | x vel RMSE (m/s) | x acc RMSE (m/s^2) "
             "| lost tracks | x pos RMSE, all runs (m) | s / run |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in result.rows():
        p, v, a = r["rmse"]
        lines.append(f"| {r['filter']} | {r['rule']} | {p:.3f} | {v:.4f} | {a:.4f} | "
                     f"{r['lost']}/{r['runs']} | {r['rmse_all']:.3f} | {r['seconds']:.2f} |")
    for (f, rule), (p, v, a) in PAPER_TABLE1.items():
        lines.append(f"| {f} (paper) | {rule} | {p} | {v} | {a} | - | - | - |")
    return "\n".join(lines)


# -- GCI weight tuning (on runs that Table 1 never evaluates) ---------------------------------


TUNE_FIRST_RUN = 10000
"""First run of the omega tuning; Table 1 evaluates runs ``0..N-1`` with ``N`` <= 10000, so the
weight is never chosen on a run it is evaluated on."""


def omega_label(omega: float | str | None) -> str:
    """``0.3`` -> ``"0.3"``, ``"det"`` -> ``"det"``, None -> ``"0.5"`` (uniform weights)."""
    if omega is None:
        return "0.5"
    return omega if isinstance(omega, str) else f"{omega:g}"


def parse_omegas(text: str) -> tuple[float | str, ...]:
    """``"0.2,0.3,det"`` -> ``(0.2, 0.3, "det")``; ValueError on anything else."""
    out: list[float | str] = []
    for item in (t.strip() for t in text.split(",")):
        if not item:
            continue
        if item in ("det", "chernoff"):
            out.append(item)
            continue
        w = float(item)
        if not 0.0 <= w <= 1.0:
            raise ValueError(f"omega {w} outside [0, 1]")
        out.append(w)
    if not out:
        raise ValueError("no omega candidates")
    if len({omega_label(w) for w in out}) != len(out):
        raise ValueError("repeated omega candidate")
    return tuple(out)


def tune_once(scn: Seed001Scenario, cfg: ExperimentConfig, run: int,
              omegas: Sequence[float | str]) -> dict[tuple[str, str], np.ndarray]:
    """GCI-fused errors of run ``run`` for every candidate weight: ``{(filter, label): (2, K)}``
    (x-position error, position error norm). One pair of local filters per filter kind feeds
    one GCI fuser per candidate; each fuser gets the run's GCI stream afresh, so candidate
    ``w`` reproduces :func:`run_once`'s "GCI fusion" row with ``gci_omega = w`` exactly (and
    the candidates differ by the weight only: common random numbers)."""
    X, sensors, Z, m0, g_f = _run_inputs(scn, run)
    out = {}
    for kind in cfg.filters:
        fusers = [("gci", w, run_streams(scn, run, 2 + 4)[2 + 2] if kind == "IMM-PF" else None)
                  for w in omegas]
        ests = _run_fusers(kind, scn, cfg, sensors, Z, m0, g_f[:2], fusers)[2:]
        e = ests - X[1:]
        for w, ek in zip(omegas, e, strict=True):
            out[(kind, omega_label(w))] = np.stack([ek[:, 0], np.hypot(ek[:, 0], ek[:, 3])])
    return out


@dataclass(frozen=True)
class OmegaTuning:
    """GCI-fused errors of every candidate weight on the tuning runs."""

    scenario: Seed001Scenario
    config: ExperimentConfig
    omegas: tuple[float | str, ...]
    runs: tuple[int, ...]
    """The run indices used (all >= :data:`TUNE_FIRST_RUN`)."""
    x_error: dict[tuple[str, str], np.ndarray]
    """(runs, K) x-position error per (filter, candidate label)."""
    pos_error: dict[tuple[str, str], np.ndarray]
    """(runs, K) position error norm."""

    def lost(self, key: tuple[str, str]) -> np.ndarray:
        """(runs,) lost tracks, the rule of :meth:`ExperimentResult.lost`."""
        c = self.config
        return self.pos_error[key][:, c.loss_after:].max(axis=1) > c.loss_threshold

    def rows(self) -> list[dict]:
        """Per candidate and filter: x-position RMSE over the runs not lost (as Table 1), lost
        count, and the RMSE difference to the best candidate of that filter with its paired
        standard error (per-run mean squared errors over the runs neither lost)."""
        out = []
        for w in self.omegas:
            row: dict = {"omega": omega_label(w), "value": w}
            for kind in self.config.filters:
                key = (kind, row["omega"])
                kept = ~self.lost(key)
                mse = np.mean(np.square(self.x_error[key]), axis=1)
                row[kind] = {"rmse": float(np.sqrt(mse[kept].mean())) if kept.any() else np.nan,
                             "lost": int((~kept).sum()), "mse": mse, "kept": kept}
            out.append(row)
        for kind in self.config.filters:
            best = min(out, key=lambda r, k=kind: (r[k]["lost"], _nan_last(r[k]["rmse"])))
            for r in out:
                both = r[kind]["kept"] & best[kind]["kept"]
                d = r[kind]["mse"][both] - best[kind]["mse"][both]
                rmse = best[kind]["rmse"]
                n = int(both.sum())
                r[kind]["delta"] = float(r[kind]["rmse"] - rmse)
                # delta RMSE ~ delta MSE / (2 RMSE); standard error of the paired mean
                r[kind]["delta_se"] = (float(d.std(ddof=1) / np.sqrt(n) / (2 * rmse))
                                       if n > 1 else np.nan)
        return out

    def best(self, kind: str | None = None) -> str:
        """Label of the best candidate: fewest lost tracks, then the smallest x-position RMSE
        (``kind`` None: the mean over the filters run)."""
        kinds = [kind] if kind else list(self.config.filters)
        rows = self.rows()
        return min(rows, key=lambda r: (sum(r[k]["lost"] for k in kinds),
                                        _nan_last(float(np.mean([r[k]["rmse"]
                                                                 for k in kinds])))))["omega"]


def _nan_last(x: float) -> float:
    return np.inf if np.isnan(x) else x


def tune_omega(scn: Seed001Scenario, cfg: ExperimentConfig, omegas: Sequence[float | str],
               runs: int, jobs: int = 1, progress: bool = True,
               first_run: int = TUNE_FIRST_RUN) -> OmegaTuning:
    """The GCI weight candidates on runs ``first_run .. first_run + runs - 1`` (never below
    :data:`TUNE_FIRST_RUN`), over ``jobs`` worker processes, with a progress bar."""
    if first_run < TUNE_FIRST_RUN:
        raise ValueError(f"tuning runs start at {TUNE_FIRST_RUN} (runs below are evaluated)")
    omegas = tuple(omegas)
    idx = tuple(range(first_run, first_run + runs))
    label = f"tuning runs (seed001 omega, geometry {scn.geometry}, {len(omegas)} candidates)"
    done = map_runs(tune_once, [(scn, cfg, r, omegas) for r in idx], jobs, label, progress)
    keys = list(done[0])
    return OmegaTuning(scn, cfg, omegas, idx,
                       {k: np.stack([r[k][0] for r in done]) for k in keys},
                       {k: np.stack([r[k][1] for r in done]) for k in keys})


def format_tuning(t: OmegaTuning) -> str:
    """The tuning table (Markdown): one row per candidate, then the best candidate."""
    kinds = list(t.config.filters)
    head = "| omega | " + " | ".join(
        f"{k} x pos RMSE (m) | {k} vs best (m) | {k} lost" for k in kinds) + " |"
    lines = [f"seed001 GCI weight tuning, geometry {t.scenario.geometry}: runs {t.runs[0]}.."
             f"{t.runs[-1]} ({len(t.runs)} runs x {t.scenario.num_scans} scans; Table 1 "
             f"evaluates runs below {TUNE_FIRST_RUN}); x-position RMSE of the GCI-fused filter "
             f"over the runs not lost; 'vs best': paired difference to that filter's best "
             f"candidate +- standard error", "", head,
             "|---|" + "---:|---:|---:|" * len(kinds)]
    for r in t.rows():
        cells = []
        for k in kinds:
            c = r[k]
            cells += [f"{c['rmse']:.3f}", f"{c['delta']:+.3f} +- {c['delta_se']:.3f}"
                      if c["delta"] != 0 else "best", f"{c['lost']}/{len(t.runs)}"]
        lines.append(f"| {r['omega']} | " + " | ".join(cells) + " |")
    per = ", ".join(f"{k}: {t.best(k)}" for k in kinds)
    lines += ["", f"best omega: {t.best()} (fewest lost tracks, then the smallest x-position "
              f"RMSE{' averaged over ' + ' and '.join(kinds) if len(kinds) > 1 else ''}); "
              f"best per filter: {per}"]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sim.seed001 --runs N --geometry A|G|close|near [--jobs J]`` prints Table 1;
    ``--tune-omega 0.2,0.3,det --tune-runs N`` compares GCI weights on runs 10000.. instead."""
    ap = argparse.ArgumentParser(prog="python -m sim.seed001", description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--geometry", choices=sorted(GEOMETRIES), default="A")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--particles", type=int, default=800, help="particles per model")
    ap.add_argument("--jitter", type=float, default=0.3)
    ap.add_argument("--jitter-kind", choices=("add", "shrink"), default="add")
    ap.add_argument("--ratio-space", choices=("position", "full"), default="position")
    ap.add_argument("--no-clip", action="store_true", help="keep negative information")
    default_omega = omega_label(SingleTargetConfig.gci_omega)
    ap.add_argument("--omega", default=default_omega,
                    help="GCI weight of the other peer: a number in [0, 1], 'det' or 'chernoff' "
                         f"(default {default_omega})")
    ap.add_argument("--filters", default="IMM-EKF,IMM-PF")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--first-run", type=int, default=0)
    ap.add_argument("--tune-omega", metavar="W1,W2,...",
                    help="instead of Table 1: the GCI-fused x-position RMSE for each candidate "
                         "weight (numbers, 'det', 'chernoff') on runs "
                         f"{TUNE_FIRST_RUN}.. only (never evaluated runs), and the best")
    ap.add_argument("--tune-runs", type=int, default=40,
                    help=f"tuning runs {TUNE_FIRST_RUN}..{TUNE_FIRST_RUN}+N-1 (default 40)")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args(argv)
    if a.runs < 1:
        ap.error("--runs must be at least 1")
    omega: float | str = a.omega
    if a.omega not in ("det", "chernoff"):
        try:
            omega = float(a.omega)
        except ValueError:
            ap.error(f"--omega: expected a number, 'det' or 'chernoff', got {a.omega!r}")
    filters = tuple(f.strip() for f in a.filters.split(",") if f.strip())
    if any(f not in FILTERS for f in filters):
        ap.error(f"--filters: expected a comma list of {FILTERS}")
    scn = Seed001Scenario(geometry=a.geometry, seed=a.seed)
    cfg = ExperimentConfig(
        particle=ParticleParams(n_particles=a.particles, jitter=a.jitter,
                                jitter_kind=a.jitter_kind),
        ratio=RatioConfig(space=a.ratio_space, clip=not a.no_clip),
        gci_omega=omega, filters=filters)
    if a.tune_omega is not None:
        if a.first_run != 0:
            ap.error(f"--first-run does not apply to --tune-omega (tuning runs start at "
                     f"{TUNE_FIRST_RUN})")
        if a.tune_runs < 2:
            ap.error("--tune-runs must be at least 2")
        try:
            omegas = parse_omegas(a.tune_omega)
        except ValueError as exc:
            ap.error(f"--tune-omega: {exc}")
        t = tune_omega(scn, cfg, omegas, a.tune_runs, jobs=a.jobs, progress=not a.quiet)
        print(format_tuning(t))
        return 0
    if a.first_run + a.runs > TUNE_FIRST_RUN:
        print(f"note: runs >= {TUNE_FIRST_RUN} are the GCI weight's tuning runs",
              file=sys.stderr)
    res = run_experiment(scn, cfg, a.runs, jobs=a.jobs, progress=not a.quiet,
                         first_run=a.first_run)
    print(format_table(res))
    return 0


__all__ = [
    "GEOMETRIES",
    "ExperimentConfig",
    "ExperimentResult",
    "OmegaTuning",
    "RadarSpec",
    "Seed001Scenario",
    "TUNE_FIRST_RUN",
    "format_table",
    "format_tuning",
    "measure",
    "run_experiment",
    "run_once",
    "tune_omega",
    "tune_once",
    "truth",
]

if __name__ == "__main__":
    sys.exit(main())
