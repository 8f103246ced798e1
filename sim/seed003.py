"""Seed 003: a manoeuvring target in dense clutter, two position sensors (docs/seed003.md).

The scenario (``sim/scenarios/seed003.toml``), the Monte Carlo comparison of PDAF, IMM-PDAF,
fuzzy PDA and fuzzy IMM with one sensor and with the sequential two-sensor update, and the
filters a peer runs (:func:`make_filter`, the same objects as the table's).

``python -m sim.seed003 --runs 200 --jobs 2`` evaluates runs 0..199 and prints the table:
track-loss count and rate with a 95 % Wilson interval, position and velocity RMSE over the
kept tracks, detector hit and false-alarm rates. Every run draws its measurements and clutter
from ``default_rng([seed, run])``; all eight filters see the same draws. Filter settings are
fixed in the TOML before any evaluation run (nothing is tuned on runs 0..N-1).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.linalg import solve_discrete_are

from sim.studies.pool import map_runs
from tracking.fuzzy import weighting_from_config
from tracking.imm import POS, VEL, constant_acceleration, constant_velocity
from tracking.pda import ImmPda, LinearSensor

SCENARIO = Path(__file__).with_name("scenarios") / "seed003.toml"
H6 = np.zeros((2, 6))
H6[0, POS[0]] = H6[1, POS[1]] = 1.0
"""Position sensor on the 6-D state ``[px, vx, ax, py, vy, ay]``."""
G0 = 9.80665
METHODS = ("PDAF", "IMM-PDAF", "fuzzy PDA", "fuzzy IMM")


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
    from protocol.keys import check_name
    from sim.scenario import MAX_SENSORS

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


# -- Monte Carlo ------------------------------------------------------------------------------


@dataclass
class RunResult:
    """One run: per (method, sensors) position and velocity errors per scan and detector
    flags (fuzzy methods)."""

    run: int
    pos_err: dict[tuple[str, int], np.ndarray] = field(default_factory=dict)
    vel_err: dict[tuple[str, int], np.ndarray] = field(default_factory=dict)
    fired: dict[tuple[str, int], np.ndarray] = field(default_factory=dict)
    step_seconds: dict[tuple[str, int], float] = field(default_factory=dict)


def run_once(cfg: Mapping, run: int, methods: Sequence[str] = METHODS,
             sensor_counts: Sequence[int] = (1, 2)) -> RunResult:
    """All filters on run ``run``'s draws (the same measurements and initial estimate)."""
    seed = int(cfg["scenario"]["seed"])
    rng = np.random.default_rng([seed, int(run)])
    X = truth(cfg)
    sens = sensors(cfg)
    target = target_returns(X, sens, rng)
    m0, P0 = initial_state(cfg, X[0], rng)
    mode = cfg["clutter"]["mode"]
    if mode not in ("gate", "region"):
        raise ValueError(f"seed003: unknown clutter.mode {mode!r}; expected 'gate' or 'region'")
    region = region_clutter(cfg, X, sens, rng) if mode == "region" else None
    res = RunResult(run)
    for method in methods:
        for n in sensor_counts:
            flt = make_filter(cfg, method, m0, P0)
            spent: list[float] = []
            # gate clutter: every filter draws from the same stream (seed, run, sensors), so
            # the unit-disc draws are shared and scaled by each filter's own gate (paired)
            est, fired = run_filter(cfg, flt, sens[:n], [p[:n] for p in target], region,
                                    np.random.default_rng([seed, int(run), 1000 + n]),
                                    timing=spent)
            res.step_seconds[(method, n)] = spent[0] / len(target)  # filter calls only
            d = est - X[1:]
            res.pos_err[(method, n)] = np.hypot(d[:, POS[0]], d[:, POS[1]])
            res.vel_err[(method, n)] = np.hypot(d[:, VEL[0]], d[:, VEL[1]])
            if flt.weighting is not None:
                res.fired[(method, n)] = fired
    return res


def training_samples(cfg: Mapping, run: int, n_sensors: int = 2
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Features and labels of every gated return of the fuzzy IMM on run ``run``: NIS under
    each model, ``D_L / (L n_z)``, and 1 for the target's return (training runs only)."""
    seed = int(cfg["scenario"]["seed"])
    rng = np.random.default_rng([seed, int(run)])
    X = truth(cfg)
    sens = sensors(cfg)[:n_sensors]
    target = target_returns(X, sens, rng)
    m0, P0 = initial_state(cfg, X[0], rng)
    flt = make_filter(cfg, "fuzzy IMM", m0, P0)
    rows: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def record(Z, detected, up, f) -> None:
        if len(up.returns) == 0:
            return
        is_target = (np.all(up.returns == Z[0], axis=1) if detected
                     else np.zeros(len(up.returns), bool))
        d = f.weighting.normalised_statistic()
        for gm in up.nis:
            rows.append((gm, np.full(len(gm), d), is_target))

    run_filter(cfg, flt, sens, target, None,
               np.random.default_rng([seed, int(run), 1000 + n_sensors]), record)
    if not rows:
        return np.empty(0), np.empty(0), np.empty(0)
    return tuple(np.concatenate(c) for c in zip(*rows, strict=True))


def train_fuzzy(cfg: Mapping, runs: int, first_run: int = 10000, what: str = "all") -> dict:
    """Fit the fuzzy system on training runs ``first_run..`` (never the evaluation runs) and
    return the fitted ``[fuzzy]`` table."""
    from tracking.fuzzy import FuzzySystem, fit, to_config

    parts = [training_samples(cfg, r) for r in range(first_run, first_run + runs)]
    g, d, t = (np.concatenate(c) for c in zip(*parts, strict=True))
    fis = fit(FuzzySystem.from_config(cfg["fuzzy"]), g, d, t, what)
    return to_config(fis, cfg["fuzzy"].get("mode", "switched"))


def lost(pos_err: np.ndarray, bound: float, scans_: int) -> bool:
    """True when the error exceeds ``bound`` for ``scans_`` consecutive scans."""
    run = 0
    for e in pos_err > bound:
        run = run + 1 if e else 0
        if run >= scans_:
            return True
    return False


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial proportion ``k / n``."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def summarise(cfg: Mapping, results: Sequence[RunResult]) -> list[dict]:
    """One row per (method, sensors): loss count/rate/interval, RMSE over kept tracks, detector
    rates (hit: turn scans after the first ``L``; false alarm: straight scans once the window
    is full, and from ``L`` scans after the turn)."""
    bound, nscan = float(cfg["metrics"]["loss_bound"]), int(cfg["metrics"]["loss_scans"])
    first, last = cfg["scenario"]["turn_scans"]
    L = int(cfg["detector"]["window"])
    k = np.arange(1, int(cfg["scenario"]["num_scans"]) + 1)
    hit_scans = (k >= first + L - 1) & (k <= last)
    quiet_scans = ((k >= L) & (k < first)) | (k > last + L)
    rows = []
    for key in results[0].pos_err:
        flags = np.array([lost(r.pos_err[key], bound, nscan) for r in results])
        kept = [r for r, f in zip(results, flags, strict=True) if not f]
        n, nl = len(results), int(flags.sum())
        lo, hi = wilson(nl, n)
        row = {"method": key[0], "sensors": key[1], "runs": n, "lost": nl, "loss_rate": nl / n,
               "loss_lo": lo, "loss_hi": hi,
               "rmse_pos": (float(np.sqrt(np.mean([r.pos_err[key] ** 2 for r in kept])))
                            if kept else float("nan")),
               "rmse_vel": (float(np.sqrt(np.mean([r.vel_err[key] ** 2 for r in kept])))
                            if kept else float("nan")),
               "step_ms": 1e3 * float(np.median([r.step_seconds[key] for r in results]))}
        if key in results[0].fired:
            F = np.array([r.fired[key] for r in results])
            row["det_hit"] = float(F[:, hit_scans].mean())
            row["det_fa"] = float(F[:, quiet_scans].mean())
        rows.append(row)
    return rows


def rmse_over_time(results: Sequence[RunResult]) -> dict[tuple[str, int], np.ndarray]:
    """Position RMSE per scan over all runs, per (method, sensors)."""
    return {key: np.sqrt(np.mean([r.pos_err[key] ** 2 for r in results], axis=0))
            for key in results[0].pos_err}


def run_experiment(cfg: Mapping, runs: int, jobs: int = 1, first_run: int = 0,
                   progress: bool = True, methods: Sequence[str] = METHODS) -> list[RunResult]:
    """Runs ``first_run .. first_run + runs - 1``, in ``jobs`` processes, in run order."""
    ids = range(first_run, first_run + runs)
    return map_runs(run_once, [(cfg, r, methods) for r in ids], jobs, "runs", progress)


def format_table(rows: Sequence[dict]) -> str:
    head = (f"{'method':<10} {'sens':>4} {'lost':>9} {'loss rate [95% CI]':>22} "
            f"{'RMSE pos m':>10} {'RMSE vel':>9} {'det hit':>7} {'det FA':>7} {'step ms':>7}")
    lines = [head, "-" * len(head)]
    for r in rows:
        det = (f"{r['det_hit']:>7.2f} {r['det_fa']:>7.3f}" if "det_hit" in r
               else f"{'-':>7} {'-':>7}")
        lines.append(
            f"{r['method']:<10} {r['sensors']:>4} {r['lost']:>4}/{r['runs']:<4} "
            f"{r['loss_rate']:>6.1%} [{r['loss_lo']:5.1%},{r['loss_hi']:6.1%}] "
            f"{r['rmse_pos']:>10.1f} {r['rmse_vel']:>9.1f} {det} {r['step_ms']:>7.3f}")
    return "\n".join(lines)


def write_csv(rows: Sequence[dict], over_time: Mapping, folder: Path) -> list[Path]:
    """``seed003_table.csv`` (the rows) and ``seed003_rmse.csv`` (position RMSE per scan)."""
    folder.mkdir(parents=True, exist_ok=True)
    t = folder / "seed003_table.csv"
    cols = ["method", "sensors", "runs", "lost", "loss_rate", "loss_lo", "loss_hi",
            "rmse_pos", "rmse_vel", "det_hit", "det_fa", "step_ms"]
    t.write_text(",".join(cols) + "\n" + "".join(
        ",".join(str(r.get(c, "")) for c in cols) + "\n" for r in rows))
    o = folder / "seed003_rmse.csv"
    names = [f"{m} x{n}" for m, n in over_time]
    K = len(next(iter(over_time.values())))
    o.write_text("scan," + ",".join(names) + "\n" + "".join(
        f"{k + 1}," + ",".join(f"{v[k]:.3f}" for v in over_time.values()) + "\n"
        for k in range(K)))
    return [t, o]


def plot_rmse(over_time: Mapping, cfg: Mapping, path: Path) -> Path:
    """Position RMSE per scan (all runs, lost tracks included, log scale) as a PNG, the turn
    shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    first, last = cfg["scenario"]["turn_scans"]
    ax.axvspan(first, last, color="0.9", label="turn")
    for (method, n), v in over_time.items():
        ax.semilogy(np.arange(1, len(v) + 1), v, "-" if n == 2 else "--",
                    label=f"{method}, {n} sensor{'s' if n > 1 else ''}")
    ax.set_xlabel("scan")
    ax.set_ylabel("position RMSE over all runs (m)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sim.seed003", description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=200, help="Monte Carlo runs (0..N-1)")
    p.add_argument("--first-run", type=int, default=0, help="first run index")
    p.add_argument("--jobs", type=int, default=1, help="worker processes")
    p.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE",
                   help="override a scenario setting (TOML value), e.g. clutter.in_gate=1")
    p.add_argument("--methods", default=",".join(METHODS),
                   help=f"comma-separated subset of {', '.join(METHODS)}")
    p.add_argument("--csv", type=Path,
                   help="write the table and RMSE-over-time CSVs and the RMSE PNG here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--scenario", type=Path, default=SCENARIO,
                   help="scenario file (default sim/scenarios/seed003.toml)")
    p.add_argument("--train-fuzzy", type=int, metavar="N", default=0,
                   help="fit the fuzzy system on training runs 10000..10000+N-1, print the "
                        "fitted [fuzzy] table as JSON and exit")
    p.add_argument("--fuzzy", type=Path, metavar="JSON",
                   help="use this [fuzzy] table (e.g. a --train-fuzzy result) instead of the "
                        "scenario's")
    a = p.parse_args(argv)
    overrides = {}
    for item in a.set:
        if "=" not in item:
            p.error(f"--set {item!r}: expected TABLE.KEY=VALUE")
        k, v = item.split("=", 1)
        try:
            overrides[k] = tomllib.loads(f"v = {v}")["v"]
        except tomllib.TOMLDecodeError:
            overrides[k] = v  # a bare word is a string
    try:
        cfg = load(a.scenario, overrides)
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if a.fuzzy:
        mode = cfg["fuzzy"].get("mode")
        cfg["fuzzy"] = json.loads(a.fuzzy.read_text(encoding="utf-8"))
        cfg["fuzzy"]["mode"] = overrides.get("fuzzy.mode", mode)
    if a.train_fuzzy:
        print(json.dumps(train_fuzzy(cfg, a.train_fuzzy), indent=1))
        return 0
    methods = tuple(m.strip() for m in a.methods.split(","))
    if unknown := [m for m in methods if m not in METHODS]:
        p.error(f"--methods: unknown {unknown}; expected some of {', '.join(METHODS)}")
    t0 = time.monotonic()
    results = run_experiment(cfg, a.runs, a.jobs, a.first_run, not a.quiet, methods)
    rows = summarise(cfg, results)
    print(format_table(rows))
    print(f"({a.runs} runs from {a.first_run}, {time.monotonic() - t0:.0f} s; lost: error > "
          f"{cfg['metrics']['loss_bound']:g} m for {cfg['metrics']['loss_scans']} scans; RMSE "
          f"over kept tracks; detector rates per scan)")
    if a.csv:
        over_time = rmse_over_time(results)
        for path in [*write_csv(rows, over_time, a.csv),
                     plot_rmse(over_time, cfg, a.csv / "seed003_rmse.png")]:
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
