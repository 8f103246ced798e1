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
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from peers.estimators import SingleTargetConfig
from sim.seed001_model import (  # noqa: F401  (re-exported)
    FILTERS,
    GEOMETRIES,
    RULES,
    ExperimentConfig,
    RadarSpec,
    RunResult,
    Seed001Scenario,
    measure,
    run_once,
    run_streams,
    truth,
)
from sim.seed001_tuning import (  # noqa: F401  (re-exported)
    TUNE_FIRST_RUN,
    OmegaTuning,
    format_tuning,
    omega_label,
    parse_omegas,
    tune_omega,
    tune_once,
)
from sim.studies.pool import map_runs
from tracking.particles import ParticleParams, RatioConfig


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
