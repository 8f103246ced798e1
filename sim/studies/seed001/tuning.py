"""Seed 001's GCI weight tuning, on runs Table 1 never evaluates (10000..)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.sim.run.pool import map_runs
from sensornet.sim.studies.seed001.model import (
    ExperimentConfig,
    Seed001Scenario,
    _run_fusers,
    _run_inputs,
    run_streams,
)

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
