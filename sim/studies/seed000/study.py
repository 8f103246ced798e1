"""Seed 000's reproduction as a study: each sensor's local GM-PHD, the fused estimate and the
centralized filter, offline Monte Carlo (:mod:`sim.studies.seed000.montecarlo`); the ``experiment``
runner of
campaigns, whose ``[[figures]] kind = "seed000"`` draws the paper's Figs. 4-8 per cell.

It reads any scenario of the one model, so ``sensornet experiment`` asks it last.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from sensornet.sim.report.report_plots import band, plt_module, series
from sensornet.sim.report.report_plots import methods as methods_of
from sensornet.sim.scenario import Scenario, load_scenario, with_birth_model
from sensornet.sim.studies.base import Cell, Outcome, Request, Study
from sensornet.sim.studies.seed000 import montecarlo as ex


def load(req: Request) -> list[Scenario]:
    """The scenario with ``--set`` (and ``fusion``: a fusion rule); one setup per birth model
    (``birth``: ``paper``, ``truth`` or ``both``; default the scenario's)."""
    scn = load_scenario(req.source, overrides=dict(req.overrides))
    if req.options.get("fusion"):
        scn = replace(scn, fusion=replace(scn.fusion, rule=req.options["fusion"]))
    birth = req.options.get("birth")
    models = ["paper", "truth"] if birth == "both" else [birth or scn.birth.model]
    return [with_birth_model(scn, m) for m in models]


def label(scn: Scenario) -> str:
    return f"runs ({scn.name}, births: {scn.birth.model})"


def table(o: Outcome) -> str:
    return ex.format_table(o.summary) + "\n"


def figures(o: Outcome, folder: Path) -> list[Path]:
    return ex.write_outputs(o.summary, folder)


def row(scn: Scenario, cell: Cell) -> dict[str, Any]:
    """A campaign task's columns: per-method means and per-scan series."""
    res = ex.run_once(scn, cell.run)
    K = scn.num_scans
    out: dict[str, Any] = {}
    for m in ex.method_names(scn):
        k = method_key(m)
        out[f"mean_ospa.{k}"] = float(res.ospa[m].mean())
        out[f"mean_card_error.{k}"] = float(res.card_error[m].mean())
        out[f"ms_per_scan.{k}"] = res.seconds[m] / K * 1e3
    for m in ex.method_names(scn):
        k = method_key(m)
        out[f"ospa_k.{k}"] = res.ospa[m]
        out[f"n_est_k.{k}"] = res.n_estimates[m]
    out["n_true_k"] = res.n_true
    for c, v in res.components.items():
        out[f"comp_k.{c}"] = v
    return out


def method_key(method: str) -> str:
    """``"local s1"`` -> ``local_s1``, ``"fused s2 (gci)"`` -> ``fused``, ``centralized``."""
    if method.startswith("fused"):
        return "fused"
    return method.replace(" ", "_")


def cell_figures(cell: dict, data: dict[str, Any], out: Path) -> list[tuple[str, Path]]:
    """Figs. 4-8 of seed 000 for one cell of an ``experiment`` campaign."""
    plt = plt_module()
    if "n_true_k" not in data or not data["n_true_k"]:
        return []
    n_true = series(data["n_true_k"])
    runs, K = n_true.shape
    k = np.arange(1, K + 1)
    methods = methods_of(data, "ospa_k.")
    tag = f"cell{cell['index']}"
    title = f"{cell['label']} ({runs} runs)"
    figs: list[tuple[str, Path]] = []

    def save(fig, ax, name: str, ylabel: str, caption: str) -> None:
        ax.set_xlabel("scan")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(title, fontsize=10)
        fig.tight_layout()
        path = out / f"{tag}-{name}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        figs.append((caption, path))

    fig, ax = plt.subplots(figsize=(8, 4))
    for m in methods:
        ax.plot(k, series(data[f"n_est_k.{m}"]).mean(axis=0), label=m)
    ax.plot(k, n_true.mean(axis=0), "k--", label="truth")
    save(fig, ax, "cardinality", "mean number of targets",
         "Cardinality: mean number of estimated targets against the truth (Fig. 4)")
    fig, ax = plt.subplots(figsize=(8, 4))
    for m in methods:
        err = series(data[f"n_est_k.{m}"]) - n_true
        ax.plot(k, np.sqrt((err ** 2).mean(axis=0)), label=m)
    save(fig, ax, "cardinality-rmse", "cardinality RMSE (targets)",
         "Cardinality RMSE over the runs per scan (Fig. 5)")
    fig, ax = plt.subplots(figsize=(8, 4))
    for m in methods:
        band(ax, k, series(data[f"ospa_k.{m}"]), m,
              lw=2 if m in ("fused", "centralized") else 1)
    save(fig, ax, "ospa", "OSPA (m)",
         "OSPA over time: each sensor alone, GCI-fused, centralized; 95 % bands (Figs. 6-7)")
    comp = [(c, f"comp_k.{c}") for c in ("local", "level2", "fused") if f"comp_k.{c}" in data]
    if comp:
        fig, ax = plt.subplots(figsize=(8, 4))
        names = {"local": "local filter output (after level-1 pruning)",
                 "level2": "after level-2 pruning (published)", "fused": "after fusion"}
        for c, col in comp:
            ax.plot(k, series(data[col]).mean(axis=0), label=names[c])
        save(fig, ax, "components", "mean number of components",
             "Components at the fusing sensor before and after each pruning level (Fig. 8)")
    return figs




def report(cell: dict, data: dict[str, Any], out: Path) -> tuple[list[str], list[Path]]:
    lines: list[str] = []
    files: list[Path] = []
    for caption, path in cell_figures(cell, data, out):
        lines += [f"![{caption}]({path.name})", "", f"*{caption}*", ""]
        files.append(path)
    return lines, files


STUDY = Study(
    name="experiment",
    about="local vs fused vs centralized GM-PHD, offline Monte Carlo (seed 000 §4)",
    load=load, run_once=ex.run_once, summarise=ex.collect, table=table, figures=figures,
    claims=lambda source, overrides: True, label=label, scenario=True,
    row=row, modules=("sensornet.sim.studies.seed000.montecarlo",), report=report,
    report_kind="seed000")
