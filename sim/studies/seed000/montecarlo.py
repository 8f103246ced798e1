"""Offline Monte Carlo experiment for a scenario (seed 000 §4): local vs fused vs centralized.

For every run and scan, in one process and without a network:

* (a) each sensor's local GM-PHD alone;
* (b) the fusing sensor's fusion (GCI by default) of all local estimates at every scan, as
  sensor 2 in the paper (level-2 pruning before fusion when the scenario says so);
* (c) a centralized multi-sensor GM-PHD (iterated corrector over all scans), the upper
  reference.

Runs are independent (every draw comes from ``(scenario.seed, run)``), so they are spread
over worker processes and the result does not depend on the number of workers.
"""

from __future__ import annotations

import csv
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sensornet.sim.report.report_plots import plt_module
from sensornet.sim.run.pool import map_runs
from sensornet.sim.scenario import Scenario
from sensornet.sim.world import generate_run
from sensornet.sim.world.build import make_filter, make_reducer
from sensornet.tracking.fusion import gci_fuse
from sensornet.tracking.fusion_rules import (
    aa_fuse,
    gci_fuse_optimised,
    hybrid_fuse,
    metropolis_weights,
)
from sensornet.tracking.metrics import cardinality_error, ospa
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import keep_above


def fusion_weights(scn: Scenario, order: list[str]) -> list[float]:
    """Fixed fusion weights for the fusing sensor (first in ``order``) and the others.

    ``uniform``: ``1/n`` each. ``metropolis``: the fusing sensor's row of the Metropolis matrix
    of the star graph it forms with the others (seed 000: sensors 1 and 3 send to sensor 2).
    """
    n = len(order)
    if scn.fusion.fusing_omega == "metropolis":
        A = np.zeros((n, n), dtype=bool)
        A[0, 1:] = A[1:, 0] = True
        return list(metropolis_weights(A)[0])
    return [1.0 / n] * n


def fuse_estimates(scn: Scenario, densities: list[GaussianMixture]) -> GaussianMixture:
    """Fuse local estimates per the scenario's fusion section (first density: the fuser's own)."""
    reduce = make_reducer(scn)
    if scn.fusion.level2_pruning:
        densities = [keep_above(D, scn.fusion.level2_threshold) for D in densities]
    if scn.fusion.rule == "aa":
        return aa_fuse(densities, fusion_weights(scn, [""] * len(densities)), reduce)
    if scn.fusion.rule == "hybrid":
        return hybrid_fuse(densities, fusion_weights(scn, [""] * len(densities)), reduce)
    if scn.fusion.fusing_omega in ("det", "chernoff"):
        return gci_fuse_optimised(densities, scn.fusion.fusing_omega, reduce,
                                  scn.fusion.cardinality)
    return gci_fuse(densities, fusion_weights(scn, [""] * len(densities)), reduce,
                    cardinality=scn.fusion.cardinality)


@dataclass
class RunResult:
    """Per-scan figures of one Monte Carlo run, per method (``(K,)`` arrays)."""

    ospa: dict[str, np.ndarray] = field(default_factory=dict)
    card_error: dict[str, np.ndarray] = field(default_factory=dict)
    n_estimates: dict[str, np.ndarray] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    """Total compute seconds per method over the run."""
    components: dict[str, np.ndarray] = field(default_factory=dict)
    """Component counts: local filter output and after level-2 pruning, per scan."""
    n_true: np.ndarray | None = None


def method_names(scn: Scenario) -> list[str]:
    names = [f"local {s.name}" for s in scn.sensors]
    if scn.fusion.rule != "none":
        names.append(f"fused {scn.fusion.fusing_sensor} ({scn.fusion.rule})")
    names.append("centralized")
    return names


def run_once(scn: Scenario, run: int) -> RunResult:
    """One Monte Carlo run: every method over every scan."""
    truth, scans = generate_run(scn, run)
    names = [s.name for s in scn.sensors]
    K = scn.num_scans
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    local = {s: make_filter(scn, [s]) for s in names}
    central = make_filter(scn, names)
    mix = {s: f.initial() for s, f in local.items()}
    mix_c = central.initial()
    fuser = scn.fusion.fusing_sensor
    order = [fuser] + [s for s in names if s != fuser]
    methods = method_names(scn)
    res = RunResult(
        ospa={m: np.zeros(K) for m in methods},
        card_error={m: np.zeros(K) for m in methods},
        n_estimates={m: np.zeros(K) for m in methods},
        seconds={m: 0.0 for m in methods},
        components={"local": np.zeros(K), "level2": np.zeros(K), "fused": np.zeros(K)},
        n_true=np.array([len(x) for x in truth.states]),
    )

    def score(method: str, k: int, est: np.ndarray) -> None:
        X = truth.states[k][:, [0, 2]]
        Y = est[:, [0, 2]]
        res.ospa[method][k] = ospa(Y, X, c, p)
        res.card_error[method][k] = cardinality_error(Y, X)
        res.n_estimates[method][k] = len(Y)

    for k in range(K):
        for s, f in local.items():
            t0 = time.perf_counter()
            mix[s] = f.step(mix[s], scans[names.index(s)][k])
            res.seconds[f"local {s}"] += time.perf_counter() - t0
            score(f"local {s}", k, f.extract(mix[s]))
        res.components["local"][k] = len(mix[fuser])
        res.components["level2"][k] = len(keep_above(mix[fuser], scn.fusion.level2_threshold))
        if scn.fusion.rule != "none":
            m = methods[len(names)]
            t0 = time.perf_counter()
            fused = fuse_estimates(scn, [mix[s] for s in order])
            res.seconds[m] += time.perf_counter() - t0
            res.components["fused"][k] = len(fused)
            score(m, k, local[fuser].extract(fused))
        t0 = time.perf_counter()
        mix_c = central.step(mix_c, *[scans[i][k] for i in range(len(names))])
        res.seconds["centralized"] += time.perf_counter() - t0
        score("centralized", k, central.extract(mix_c))
    return res


@dataclass
class ExperimentResult:
    """All runs of an experiment, stacked: ``ospa[method]`` is ``(runs, K)``."""

    scenario: Scenario
    methods: list[str]
    ospa: dict[str, np.ndarray]
    card_error: dict[str, np.ndarray]
    n_estimates: dict[str, np.ndarray]
    seconds: dict[str, np.ndarray]
    components: dict[str, np.ndarray]
    n_true: np.ndarray

    def summary_rows(self) -> list[dict[str, object]]:
        K = self.scenario.num_scans
        rows = []
        for m in self.methods:
            o = self.ospa[m]
            rows.append({
                "method": m,
                "mean_ospa": float(o.mean()),
                "ospa_sem": float(o.mean(axis=1).std(ddof=1) / np.sqrt(len(o))) if len(o) > 1
                else float("nan"),
                "mean_card_error": float(self.card_error[m].mean()),
                "ms_per_scan": float(self.seconds[m].mean() / K * 1e3),
            })
        return rows


def run_experiment(scn: Scenario, runs: int, jobs: int = 1, progress: bool = True,
                   first_run: int = 0) -> ExperimentResult:
    """``runs`` Monte Carlo runs of :func:`run_once`, over ``jobs`` worker processes."""
    if runs < 1:
        raise ValueError("runs must be at least 1")
    done = map_runs(run_once, [(scn, first_run + i) for i in range(runs)], jobs,
                    f"runs ({scn.name}, births: {scn.birth.model})", progress)
    return collect(scn, done)


def collect(scn: Scenario, done: list[RunResult]) -> ExperimentResult:
    """The runs' results stacked (``done`` in run order)."""
    methods = method_names(scn)
    return ExperimentResult(
        scenario=scn,
        methods=methods,
        ospa={m: np.stack([r.ospa[m] for r in done]) for m in methods},
        card_error={m: np.stack([r.card_error[m] for r in done]) for m in methods},
        n_estimates={m: np.stack([r.n_estimates[m] for r in done]) for m in methods},
        seconds={m: np.array([r.seconds[m] for r in done]) for m in methods},
        components={k: np.stack([r.components[k] for r in done]) for k in done[0].components},
        n_true=np.stack([r.n_true for r in done]),
    )


def format_table(result: ExperimentResult) -> str:
    """The summary as an aligned text table (also valid Markdown)."""
    rows = result.summary_rows()
    runs = len(next(iter(result.ospa.values())))
    head = ("| method | mean OSPA (m) | ± s.e. | mean card. error | ms / scan |\n"
            "|---|---:|---:|---:|---:|")
    lines = [f"scenario {result.scenario.name}, births '{result.scenario.birth.model}', "
             f"{runs} runs x {result.scenario.num_scans} scans, OSPA c="
             f"{result.scenario.metrics.ospa_cutoff:g} p={result.scenario.metrics.ospa_order:g}",
             "", head]
    for r in rows:
        lines.append(f"| {r['method']} | {r['mean_ospa']:.1f} | {r['ospa_sem']:.1f} | "
                     f"{r['mean_card_error']:.3f} | {r['ms_per_scan']:.3f} |")
    return "\n".join(lines)


def write_outputs(result: ExperimentResult, folder: Path) -> list[Path]:
    """Write ``summary.csv``, ``per_scan.csv`` and a PNG of OSPA, cardinality and components."""
    folder.mkdir(parents=True, exist_ok=True)
    tag = result.scenario.birth.model
    written = []
    path = folder / f"summary-{tag}.csv"
    rows = result.summary_rows()
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    written.append(path)
    path = folder / f"per_scan-{tag}.csv"
    K = result.scenario.num_scans
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["scan", "n_true"] + [f"ospa {m}" for m in result.methods]
                   + [f"n_est {m}" for m in result.methods]
                   + ["components local", "components level2", "components fused"])
        for k in range(K):
            w.writerow([k + 1, result.n_true[:, k].mean()]
                       + [result.ospa[m][:, k].mean() for m in result.methods]
                       + [result.n_estimates[m][:, k].mean() for m in result.methods]
                       + [result.components[c][:, k].mean()
                          for c in ("local", "level2", "fused")])
    written.append(path)
    written.append(_plot(result, folder / f"experiment-{tag}.png"))
    return written


def _plot(result: ExperimentResult, path: Path) -> Path:
    plt = plt_module()

    K = result.scenario.num_scans
    k = np.arange(1, K + 1)
    fig, ax = plt.subplots(3, 1, figsize=(8, 10), sharex=True)
    for m in result.methods:
        ax[0].plot(k, result.ospa[m].mean(axis=0), label=m)
        ax[1].plot(k, result.n_estimates[m].mean(axis=0), label=m)
    ax[1].plot(k, result.n_true.mean(axis=0), "k--", label="truth")
    for c in ("local", "level2", "fused"):
        ax[2].plot(k, result.components[c].mean(axis=0), label=f"{c}")
    ax[0].set_ylabel("mean OSPA (m)")
    ax[1].set_ylabel("mean number of estimates")
    ax[2].set_ylabel(f"components at {result.scenario.fusion.fusing_sensor}")
    ax[2].set_xlabel("scan")
    for a in ax:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    runs = len(next(iter(result.ospa.values())))
    ax[0].set_title(f"{result.scenario.name}: births '{result.scenario.birth.model}', "
                    f"{runs} Monte Carlo runs")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
