"""Seed 001's Table 1 as a study: two radars, IMM-EKF and IMM-PF peers, each radar alone, GCI
fusion and the particle fusion rule (:mod:`sim.studies.seed001.montecarlo`). A campaign cell of its
runner sets
:data:`KEYS` (``geometry = "A"``, ``particles = 800``, ``omega = 0.15``, ...), not scenario-file
keys; ``[[figures]] kind = "seed001"`` draws Table 1 per cell beside the paper's numbers.

``sensornet experiment seed001`` is the one-model experiment (:mod:`sim.studies.seed000.study`);
this study is ``python -m sensornet.sim.studies.seed001.montecarlo`` (:func:`main`, with the GCI
weight's tuning
beside it)
and the ``seed001`` campaign runner.
"""

from __future__ import annotations

import hashlib
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from sensornet.peers.estimators import SingleTargetConfig
from sensornet.sim.report.report_plots import methods as methods_of
from sensornet.sim.report.report_plots import plt_module
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.sim.studies import command
from sensornet.sim.studies.base import Cell, Outcome, Request, Study
from sensornet.sim.studies.seed001 import montecarlo as s1
from sensornet.sim.studies.seed001.montecarlo import PAPER_TABLE1

KEYS = ("geometry", "seed", "particles", "jitter", "jitter_kind", "ratio_space", "clip", "omega",
        "filters", "loss_threshold", "loss_after")
"""What a ``seed001`` cell (or request) may set."""

Setup = tuple  # (Seed001Scenario, ExperimentConfig)


def setup(source: str, overrides: Mapping[str, Any]) -> Setup:
    """``(Seed001Scenario, ExperimentConfig)`` from :data:`KEYS` (the target: seed001.toml's
    ``[manoeuvre]``); ``ValueError`` naming the key for anything else."""
    unknown = sorted(set(overrides) - set(KEYS))
    if unknown:
        raise ValueError(f"seed001 runner: unknown key(s) {unknown} (known: {', '.join(KEYS)})")
    o = dict(overrides)
    geometry = o.get("geometry", "A")
    if geometry not in s1.GEOMETRIES:
        raise ValueError(f"seed001 runner: geometry must be one of {sorted(s1.GEOMETRIES)}, "
                         f"got {geometry!r}")
    # the target of the shipped scenario's [manoeuvre] (the peers' too), the cell's radars
    scn = replace(s1.Seed001Scenario.of(load_scenario("seed001")), geometry=geometry,
                  seed=int(o.get("seed", 1)))
    cfg = s1.ExperimentConfig()
    if "particles" in o or "jitter" in o or "jitter_kind" in o:
        cfg = replace(cfg, particle=replace(
            cfg.particle, n_particles=int(o.get("particles", cfg.particle.n_particles)),
            jitter=float(o.get("jitter", cfg.particle.jitter)),
            jitter_kind=str(o.get("jitter_kind", cfg.particle.jitter_kind))))
    if "ratio_space" in o or "clip" in o:
        cfg = replace(cfg, ratio=replace(
            cfg.ratio, space=str(o.get("ratio_space", cfg.ratio.space)),
            clip=bool(o.get("clip", cfg.ratio.clip))))
    if "omega" in o:
        cfg = replace(cfg, gci_omega=o["omega"])
    if "filters" in o:
        filters = tuple(o["filters"]) if isinstance(o["filters"], list) else (o["filters"],)
        if not filters or any(f not in s1.FILTERS for f in filters):
            raise ValueError(f"seed001 runner: filters must be a list of {s1.FILTERS}, "
                             f"got {o['filters']!r}")
        cfg = replace(cfg, filters=filters)
    for k in ("loss_threshold", "loss_after"):
        if k in o:
            cfg = replace(cfg, **{k: type(getattr(cfg, k))(o[k])})
    return scn, cfg


def setup_hash(s: Setup) -> str:
    return hashlib.sha256(repr(s).encode()).hexdigest()[:16]


def load(req: Request) -> list[Setup]:
    try:
        return [setup(req.source, req.overrides)]
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None


def run_once(s: Setup, run: int) -> s1.RunResult:
    return s1.run_once(s[0], s[1], run)


def summarise(s: Setup, results: list) -> s1.ExperimentResult:
    return s1.ExperimentResult(s[0], s[1], results)


def table(o: Outcome) -> str:
    return s1.format_table(o.summary)


def method(filt: str, rule: str) -> str:
    """``("IMM-EKF", "GCI fusion")`` -> ``IMM-EKF.GCI_fusion``."""
    return f"{filt}.{rule.replace(' ', '_')}"


def row(s: Setup, cell: Cell) -> dict[str, Any]:
    """A campaign task's columns: mean squared x errors, lost flag, mean position error."""
    scn, cfg = s
    res = s1.run_once(scn, cfg, cell.run)
    out: dict[str, Any] = {}
    for (filt, rule), e in res.errors.items():
        m = method(filt, rule)
        sq = np.mean(np.square(e), axis=0)  # x position, velocity, acceleration
        out[f"msx_pos.{m}"], out[f"msx_vel.{m}"], out[f"msx_acc.{m}"] = (float(x) for x in sq)
        pe = res.pos_error[(filt, rule)]
        out[f"lost.{m}"] = float(pe[cfg.loss_after:].max() > cfg.loss_threshold)
        out[f"mean_pos_error.{m}"] = float(pe.mean())
    for filt, sec in res.seconds.items():
        out[f"ms_per_scan.{filt}"] = sec / scn.num_scans * 1e3
    return out


def cell_table(cell: dict, data: dict[str, Any], out: Path) -> tuple[list[str], Path | None]:
    """Seed 001's Table 1 for one cell of a ``seed001`` campaign: x-axis RMSE over the runs
    whose track was not lost, beside the paper's numbers; and a bar chart of the x position
    RMSE with the paper's values marked."""
    methods = methods_of(data, "msx_pos.")
    if not methods:
        return [], None
    lines = ["| filter | estimate | x pos RMSE (m) | x vel RMSE (m/s) | x acc RMSE (m/s²) | "
             "lost tracks |", "|---|---|---:|---:|---:|---:|"]
    pos: dict[str, float] = {}
    for m in methods:
        lost = np.array(data[f"lost.{m}"], dtype=float) > 0.5
        kept = ~lost
        rmse = [math.sqrt(float(np.mean(np.array(data[f"msx_{q}.{m}"], dtype=float)[kept])))
                if kept.any() else math.nan for q in ("pos", "vel", "acc")]
        filt, rule = m.split(".", 1)
        pos[m] = rmse[0]
        lines.append(f"| {filt} | {rule.replace('_', ' ')} | {rmse[0]:.3f} | {rmse[1]:.4f} | "
                     f"{rmse[2]:.4f} | {int(lost.sum())}/{len(lost)} |")
    for (filt, rule), (p, v, a) in PAPER_TABLE1.items():
        lines.append(f"| {filt} (paper, 300 runs) | {rule} | {p} | {v} | {a} | – |")
    plt = plt_module()
    fig, ax = plt.subplots(figsize=(8, 4))
    x = np.arange(len(methods))
    ax.bar(x, [0.0 if math.isnan(pos[m]) else pos[m] for m in methods], color="tab:blue",
           label="measured")
    for i, m in enumerate(methods):
        if math.isnan(pos[m]):
            ax.text(i, 0.5, "every track lost", ha="center", va="bottom", fontsize=8)
    labelled = False
    for i, m in enumerate(methods):
        filt, rule = m.split(".", 1)
        paper = PAPER_TABLE1.get((filt, "fusion")) if "fusion" in rule.lower() else None
        if paper is not None:
            ax.plot([i - 0.4, i + 0.4], [paper[0]] * 2, "r-", lw=2,
                    label=None if labelled else "paper (its fusion row)")
            labelled = True
    ax.set_xticks(x, [m.replace(".", "\n").replace("_", " ") for m in methods], fontsize=7)
    ax.set_ylabel("x position RMSE (m)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    ax.set_title(f"seed 001 Table 1, {cell['label']} ({len(data['key'])} runs)", fontsize=10)
    fig.tight_layout()
    path = out / f"cell{cell['index']}-table1.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return lines, path




def report(cell: dict, data: dict[str, Any], out: Path) -> tuple[list[str], list[Path]]:
    table1, png = cell_table(cell, data, out)
    lines: list[str] = []
    if table1:
        lines += ["Table 1 (x axis; RMSE over the runs not lost):", "", *table1, ""]
    if png is None:
        return lines, []
    caption = "x position RMSE per filter and estimate; red: the paper's"
    return lines + [f"![{caption}]({png.name})", "", f"*{caption}*", ""], [png]


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sensornet.sim.studies.seed001.montecarlo --runs N --geometry A|G|close|near
    [--jobs J]`` prints
    Table 1;
    ``--tune-omega 0.2,0.3,det --tune-runs N`` compares GCI weights on runs 10000.. instead."""
    ap = command.parser("seed001", s1.__doc__, runs=10, set_help=None)
    ap.add_argument("--geometry", choices=sorted(s1.GEOMETRIES), default="A")
    ap.add_argument("--particles", type=int, default=800, help="particles per model")
    ap.add_argument("--jitter", type=float, default=0.3)
    ap.add_argument("--jitter-kind", choices=("add", "shrink"), default="add")
    ap.add_argument("--ratio-space", choices=("position", "full"), default="position")
    ap.add_argument("--no-clip", action="store_true", help="keep negative information")
    default_omega = s1.omega_label(SingleTargetConfig.gci_omega)
    ap.add_argument("--omega", default=default_omega,
                    help="GCI weight of the other peer: a number in [0, 1], 'det' or 'chernoff' "
                         f"(default {default_omega})")
    ap.add_argument("--filters", default="IMM-EKF,IMM-PF")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--tune-omega", metavar="W1,W2,...",
                    help="instead of Table 1: the GCI-fused x-position RMSE for each candidate "
                         "weight (numbers, 'det', 'chernoff') on runs "
                         f"{s1.TUNE_FIRST_RUN}.. only (never evaluated runs), and the best")
    ap.add_argument("--tune-runs", type=int, default=40,
                    help=f"tuning runs {s1.TUNE_FIRST_RUN}..{s1.TUNE_FIRST_RUN}+N-1 (default 40)")
    a = ap.parse_args(argv)
    if a.runs < 1:
        ap.error("--runs must be at least 1")
    omega: float | str = a.omega
    if a.omega not in ("det", "chernoff"):
        try:
            omega = float(a.omega)
        except ValueError:
            ap.error(f"--omega: expected a number, 'det' or 'chernoff', got {a.omega!r}")
    filters = [f.strip() for f in a.filters.split(",") if f.strip()]
    if any(f not in s1.FILTERS for f in filters):
        ap.error(f"--filters: expected a comma list of {s1.FILTERS}")
    keys = {"geometry": a.geometry, "seed": a.seed, "particles": a.particles,
            "jitter": a.jitter, "jitter_kind": a.jitter_kind, "ratio_space": a.ratio_space,
            "clip": not a.no_clip, "omega": omega, "filters": filters}
    req = command.request(a, "seed001", keys)
    if a.tune_omega is not None:
        if a.first_run != 0:
            ap.error(f"--first-run does not apply to --tune-omega (tuning runs start at "
                     f"{s1.TUNE_FIRST_RUN})")
        if a.tune_runs < 2:
            ap.error("--tune-runs must be at least 2")
        try:
            omegas = s1.parse_omegas(a.tune_omega)
        except ValueError as exc:
            ap.error(f"--tune-omega: {exc}")
        scn, cfg = load(req)[0]
        print(s1.format_tuning(s1.tune_omega(scn, cfg, omegas, a.tune_runs, jobs=a.jobs,
                                             progress=not a.quiet)))
        return 0
    if a.first_run + a.runs > s1.TUNE_FIRST_RUN:
        print(f"note: runs >= {s1.TUNE_FIRST_RUN} are the GCI weight's tuning runs",
              file=sys.stderr)
    return command.drive(STUDY, req)


STUDY = Study(
    name="seed001",
    about="seed 001 Table 1: IMM-EKF / IMM-PF, each radar alone, GCI and particle fusion",
    load=load, run_once=run_once, summarise=summarise, table=table,
    label=lambda s: f"runs (seed001, geometry {s[0].geometry})",
    row=row, cell_setup=setup, setup_hash=setup_hash, fixed_scenario="seed001",
    modules=("sensornet.sim.studies.seed001.montecarlo",), report=report, command=main)
