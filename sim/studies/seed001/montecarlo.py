"""Seed 001: a manoeuvring ground target seen by two range-bearing radars (docs/seed001.md).

Scenario (truth, measurements per radar, geometry presets; every draw from a seed) as plain
frozen dataclasses, and the Monte Carlo experiment of the paper's Table 1: x-axis position,
velocity and acceleration RMSE and lost tracks, for the IMM-EKF and the IMM-PF, each radar
alone, GCI fusion and the particle fusion rule (eq. 19-21).

The fusion is centralised in one process: radar 2's filter runs on its own (the "other peer");
the fusing filter runs on radar 1 and at every scan fuses radar 2's published summaries
(posterior, and for the ratio rule also prediction). The fusion calls are the ones a peer
would make with a received message (``tracking.particles``).

``python -m sensornet.sim.studies.seed001.montecarlo --runs 300 --geometry A --jobs 2`` prints the
table (runs 0..299);
``python -m sensornet.sim.studies.seed001.montecarlo --tune-omega 0.2,0.3,0.4,det --tune-runs 40
--jobs 2`` compares
GCI
weights on runs 10000..10039, which the table never evaluates.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.sim import studies
from sensornet.sim.run.pool import map_runs
from sensornet.sim.studies.seed001.model import (  # noqa: F401  (re-exported)
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
from sensornet.sim.studies.seed001.tuning import (  # noqa: F401  (re-exported)
    TUNE_FIRST_RUN,
    OmegaTuning,
    format_tuning,
    omega_label,
    parse_omegas,
    tune_omega,
    tune_once,
)


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
    """``python -m sensornet.sim.studies.seed001.montecarlo``: the study's command line
    (:func:`sim.studies.seed001.study.main`)."""
    return studies.main("seed001", None if argv is None else list(argv))


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
