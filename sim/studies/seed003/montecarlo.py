"""Seed 003: a manoeuvring target in dense clutter, two position sensors (docs/seed003.md).

The scenario (``sim/scenarios/seed003.toml``), the Monte Carlo comparison of PDAF, IMM-PDAF,
fuzzy PDA and fuzzy IMM with one sensor and with the sequential two-sensor update, and the
filters a peer runs (:func:`make_filter`, the same objects as the table's).

``python -m sensornet.sim.studies.seed003.montecarlo --runs 200 --jobs 2`` evaluates runs 0..199
and prints the table:
track-loss count and rate with a 95 % Wilson interval, position and velocity RMSE over the
kept tracks, detector hit and false-alarm rates. Every run draws its measurements and clutter
from ``default_rng([seed, run])``; all eight filters see the same draws. Filter settings are
fixed in the TOML before any evaluation run (nothing is tuned on runs 0..N-1).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sensornet.sim import studies
from sensornet.sim.kinds.pda_filters import (  # noqa: F401  (re-exported)
    METHODS,
    coordinated_turn,
    imm_models,
    initial_state,
    make_filter,
    run_filter,
)
from sensornet.sim.report.report_plots import plt_module
from sensornet.sim.run.pool import map_runs
from sensornet.sim.world.seed003 import (  # noqa: F401  (re-exported)
    G0,
    H6,
    SCENARIO,
    check_sensor_names,
    cv_steady_state_S,
    gate_clutter,
    load,
    region_clutter,
    sensors,
    target_returns,
    truth,
)
from sensornet.tracking.fuzzy import FuzzySystem, fit, to_config
from sensornet.tracking.imm import POS, VEL

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


def footer(cfg: Mapping, runs: range, seconds: float) -> str:
    """The line under the table: the runs, the time, what lost and RMSE mean."""
    m = cfg["metrics"]
    return (f"({len(runs)} runs from {runs.start}, {seconds:.0f} s; lost: error > "
            f"{m['loss_bound']:g} m for {m['loss_scans']} scans; RMSE over kept tracks; "
            "detector rates per scan)")


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
    plt = plt_module()

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
    """``python -m sensornet.sim.studies.seed003.montecarlo``: the study's command line
    (:func:`sim.studies.seed003.study.main`)."""
    return studies.main("seed003", None if argv is None else list(argv))


if __name__ == "__main__":
    raise SystemExit(main())
