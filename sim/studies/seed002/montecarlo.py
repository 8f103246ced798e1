"""Seed-002 Monte Carlo: distance vs grid-density + spectral partitioning in the ET-GM-PHD.

``python -m sensornet.sim.studies.seed002.montecarlo --runs 20`` runs the paper's single-sensor
experiment (sensor
``s1`` of
``sim/scenarios/seed002.toml``) at clutter 10 / 15 / 20 / 25 for both partitioners on the same
runs (common random numbers) and prints, per clutter level and partitioner: partition time per
scan, whole ET-GM-PHD step time per scan (predict, partition, update, reduce), mean OSPA
(c = 200, p = 2), mean cardinality error, partitions per scan, the adjusted Rand index of the
best partition against the true measurement origins (clutter points as one-point cells), and
the paper's partition time beside ours. ``--csv`` writes one row per (clutter, partitioner).

Evaluation runs are ``--first-run .. --first-run + runs - 1`` of the scenario's seed; nothing
was tuned on them (the grid's ``cell_factor`` was picked on synthetic scans of another
generator, see :class:`tracking.partition.GridSpectralPartitioner`). Times are CPU time of this
thread per scan (``time.thread_time``: other processes on shared cores do not inflate them),
with BLAS on one thread (set below, before NumPy loads).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small eigenproblems: threads only hurt
os.environ.setdefault("OMP_NUM_THREADS", "1")

import dataclasses  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from sensornet.sim import studies  # noqa: E402
from sensornet.sim.report.report_plots import plt_module
from sensornet.sim.run.pool import map_runs  # noqa: E402
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import Scenario, load_scenario  # noqa: E402
from sensornet.sim.world import generate_truth, labelled_sensor_scans, sensor_rng, truth_rng  # noqa: E402
from sensornet.sim.world.extended import make_et_filter  # noqa: E402
from sensornet.tracking.metrics import cardinality_error, ospa  # noqa: E402
from sensornet.tracking.partition import adjusted_rand_index  # noqa: E402

CLUTTER_LEVELS = (10, 15, 20, 25)
PARTITIONS = ("distance", "grid-spectral")
PAPER_PARTITION_TIME = {  # seconds per scan, seed 002 Table 3
    "distance": {10: 0.0408, 15: 0.0538, 20: 0.0677, 25: 0.0891},
    "grid-spectral": {10: 0.0225, 15: 0.0363, 20: 0.0410, 25: 0.0565},
}


class _Timed:
    """Wraps a partitioner and adds up the time spent in it."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.seconds = 0.0

    def __call__(self, z):
        t = time.thread_time()
        try:
            return self.inner(z)
        finally:
            self.seconds += time.thread_time() - t


@dataclasses.dataclass(frozen=True)
class RunResult:
    """One run of one partitioner at one clutter level (means over the run's scans)."""

    clutter: int
    partition: str
    run: int
    ospa: float
    cardinality_error: float
    partition_ms: float
    step_ms: float
    partitions_per_scan: float
    ari: float


def scenario_at(clutter: float, base: Scenario | None = None) -> Scenario:
    """The seed-002 scenario with every sensor's clutter rate set to ``clutter``."""
    base = base or load_scenario("seed002")
    return dataclasses.replace(base, sensors=tuple(
        dataclasses.replace(s, clutter_rate=float(clutter)) for s in base.sensors))


def truth_labels(origin: np.ndarray) -> np.ndarray:
    """Origins with each clutter point (origin 0) its own label, for the Rand index."""
    lab = origin.astype(int).copy()
    clutter = lab == 0
    lab[clutter] = -1 - np.arange(clutter.sum())
    return lab


def one_run(scn: Scenario, run: int, partition: str, sensor: str = "s1") -> RunResult:
    """One Monte Carlo run of the ET-GM-PHD on ``sensor`` with ``partition``."""
    truth = generate_truth(scn, truth_rng(scn, run))
    scans, origins = labelled_sensor_scans(scn, scn.sensor(sensor), truth,
                                           sensor_rng(scn, run, sensor))
    filt = make_et_filter(scn, sensor, partition)
    timed = _Timed(filt.partitioner)
    filt.partitioner = timed
    c, p = scn.metrics.ospa_cutoff, scn.metrics.ospa_order
    mix = filt.initial()
    errs, card, aris, nparts, step_s = [], [], [], [], 0.0
    for k in range(1, scn.num_scans + 1):
        z = scans[k - 1]
        t = time.thread_time()
        mix = filt.step(mix, z)
        step_s += time.thread_time() - t
        est = filt.extract(mix)[:, [0, 2]]
        X = truth.positions(k)
        errs.append(ospa(X, est, c, p))
        card.append(abs(cardinality_error(X, est)))
        parts = filt.last_partitions
        nparts.append(len(parts))
        if parts:
            lab = truth_labels(origins[k - 1])
            aris.append(max(adjusted_rand_index(q, lab) for q in parts))
    K = scn.num_scans
    return RunResult(int(scn.sensor(sensor).clutter_rate), partition, run, float(np.mean(errs)),
                     float(np.mean(card)), 1e3 * timed.seconds / K, 1e3 * step_s / K,
                     float(np.mean(nparts)), float(np.mean(aris)) if aris else float("nan"))


def run_experiment(runs: int, clutters=CLUTTER_LEVELS, partitions=PARTITIONS,
                   first_run: int = 0, progress: bool = True,
                   base: Scenario | None = None) -> list[RunResult]:
    """Every (clutter, run, partitioner) on the same runs; partitioners alternate per run so
    machine load drifts hit both alike."""
    calls = [(scn, r, part) for scn in (scenario_at(c, base) for c in clutters)
             for r in range(first_run, first_run + runs) for part in partitions]
    # In this process, one run at a time: the partitioners' seconds per scan are the table's.
    return map_runs(one_run, calls, 1, "ET-GM-PHD runs", progress)


def summarise(results: list[RunResult]) -> list[dict]:
    """Per (clutter, partitioner): means over runs, and the paper's partition time."""
    rows = []
    keys = sorted({(r.clutter, r.partition) for r in results},
                  key=lambda k: (k[0], PARTITIONS.index(k[1])))
    for c, part in keys:
        rs = [r for r in results if r.clutter == c and r.partition == part]
        row = {"clutter": c, "partition": part, "runs": len(rs)}
        for f in ("ospa", "cardinality_error", "partition_ms", "step_ms",
                  "partitions_per_scan", "ari"):
            row[f] = float(np.mean([getattr(r, f) for r in rs]))
        row["ospa_sem"] = float(np.std([r.ospa for r in rs], ddof=1) / np.sqrt(len(rs))
                                ) if len(rs) > 1 else float("nan")
        row["paper_partition_ms"] = 1e3 * PAPER_PARTITION_TIME.get(part, {}).get(c, np.nan)
        rows.append(row)
    return rows


def format_table(rows: list[dict]) -> str:
    head = (f"{'clutter':>7} {'partition':<14} {'runs':>4} {'OSPA':>7} {'±sem':>5} "
            f"{'|card|':>6} {'part ms':>7} {'paper ms':>8} {'step ms':>7} {'parts':>5} "
            f"{'ARI':>5}")
    lines = [head]
    for r in rows:
        lines.append(f"{r['clutter']:>7} {r['partition']:<14} {r['runs']:>4} {r['ospa']:>7.2f} "
                     f"{r['ospa_sem']:>5.2f} {r['cardinality_error']:>6.3f} "
                     f"{r['partition_ms']:>7.3f} {r['paper_partition_ms']:>8.1f} "
                     f"{r['step_ms']:>7.3f} {r['partitions_per_scan']:>5.1f} {r['ari']:>5.3f}")
    by = {(r["clutter"], r["partition"]): r for r in rows}
    lines.append("")
    lines.append(f"{'clutter':>7} {'time saved':>10} {'paper':>6} {'OSPA change':>11} "
                 f"{'paper':>6}")
    for c in sorted({r["clutter"] for r in rows}):
        d, g = by.get((c, "distance")), by.get((c, "grid-spectral"))
        if d is None or g is None:
            continue
        saved = 1 - g["partition_ms"] / d["partition_ms"]
        paper = 1 - PAPER_PARTITION_TIME["grid-spectral"][c] / PAPER_PARTITION_TIME["distance"][c]
        lines.append(f"{c:>7} {100 * saved:>9.0f}% {100 * paper:>5.0f}% "
                     f"{100 * (g['ospa'] / d['ospa'] - 1):>+10.1f}% {'~+5%':>6}")
    return "\n".join(lines)


def network_experiment(runs: int, first_run: int = 0, progress: bool = True,
                       base: Scenario | None = None) -> dict[str, dict[str, float]]:
    """The 3-peer network of seed002.toml on the twin (same peers as the processes): mean
    OSPA of each peer's local ET-GM-PHD and of its GCI-fused estimate over ``runs`` runs."""
    scn = base or load_scenario("seed002")
    per: dict[str, dict[str, list[float]]] = {n: {"local": [], "fused": []}
                                              for n in scn.sensor_names}
    for res in map_runs(run_twin, [(scn, r) for r in range(first_run, first_run + runs)], 1,
                        "twin runs (3 ET-GM-PHD peers)", progress):
        for n in scn.sensor_names:
            for kind in ("local", "fused"):
                per[n][kind].append(res.mean_ospa(n, kind))
    return {n: {k: float(np.mean(v)) for k, v in d.items()} | {
        "fused_better_runs": float(np.mean(np.array(d["fused"]) < np.array(d["local"])))}
        for n, d in per.items()}


def write_png(rows: list[dict], path: str) -> None:
    """Fig. 6 and Table 3 side by side: mean OSPA and partition time per clutter level, ours
    (solid) and the paper's times (dashed)."""
    plt = plt_module()

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for part, color in zip(PARTITIONS, ("tab:blue", "tab:orange"), strict=True):
        rs = [r for r in rows if r["partition"] == part]
        c = [r["clutter"] for r in rs]
        ax1.errorbar(c, [r["ospa"] for r in rs], yerr=[r["ospa_sem"] for r in rs], marker="o",
                     color=color, label=part)
        ax2.plot(c, [r["partition_ms"] for r in rs], marker="o", color=color, label=f"{part}")
        ax2.plot(c, [r["paper_partition_ms"] for r in rs], ls="--", marker="x", color=color,
                 label=f"{part} (paper)")
    ax1.set(xlabel="clutter (mean points per scan)", ylabel="mean OSPA (m), c=200, p=2",
            title="ET-GM-PHD accuracy")
    ax2.set(xlabel="clutter (mean points per scan)", ylabel="partition time per scan (ms)",
            yscale="log", title="partition time")
    ax1.legend()
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """``python -m sensornet.sim.studies.seed002.montecarlo``: the study's command line
    (:func:`sim.studies.seed002.study.main`)."""
    return studies.main("seed002", argv)


if __name__ == "__main__":
    raise SystemExit(main())
