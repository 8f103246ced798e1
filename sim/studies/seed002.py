"""Seed 002's partitioner comparison as a study: the ET-GM-PHD with distance and grid-spectral
partitioning at four clutter levels (:mod:`sim.seed002`). ``sensornet experiment`` runs it for
any scenario with an ``[extended]`` table.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sim import seed002 as s2
from sim.scenario import Scenario, ScenarioError, load_scenario
from sim.studies.base import Outcome, Request, Study


def claims(source: str, overrides: Mapping[str, Any]) -> bool:
    """Scenarios of extended targets (an ``[extended]`` table)."""
    try:
        return load_scenario(source, overrides=dict(overrides)).extended is not None
    except ScenarioError:
        return False  # the experiment study reports the error in its one line


def load(req: Request) -> list[Scenario]:
    base = load_scenario(req.source, overrides=dict(req.overrides))
    if base.extended is None:
        raise ScenarioError(f"{base.name}: no [extended] table (extended targets)")
    return [base]


def run_once(base: Scenario, run: int) -> list[s2.RunResult]:
    """Run ``run`` at every clutter level, the partitioners alternating (machine load drifts
    hit both alike)."""
    return [s2.one_run(s2.scenario_at(c, base), run, part)
            for c in s2.CLUTTER_LEVELS for part in s2.PARTITIONS]


def summarise(base: Scenario, results: list[list[s2.RunResult]]) -> list[dict]:
    return s2.summarise([r for run in results for r in run])


def figures(o: Outcome, folder: Path) -> list[Path]:
    """``seed002_table.csv`` and ``seed002.png`` (OSPA and partition time per clutter)."""
    folder.mkdir(parents=True, exist_ok=True)
    table, png = folder / "seed002_table.csv", folder / "seed002.png"
    with table.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(o.summary[0]))
        w.writeheader()
        w.writerows(o.summary)
    s2.write_png(o.summary, str(png))
    return [table, png]


STUDY = Study(
    name="seed002",
    about="seed 002: ET-GM-PHD distance vs grid-spectral partitioning over clutter levels",
    load=load, run_once=run_once, summarise=summarise,
    table=lambda o: s2.format_table(o.summary), figures=figures, claims=claims,
    label=lambda base: "ET-GM-PHD runs (every clutter level and partitioner)",
    parallel=False)
