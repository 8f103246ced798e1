"""Seed 002's partitioner comparison as a study: the ET-GM-PHD with distance and grid-spectral
partitioning at four clutter levels (:mod:`sim.studies.seed002.montecarlo`). ``sensornet
experiment`` runs it for
any scenario with an ``[extended]`` table; ``python -m sensornet.sim.studies.seed002.montecarlo``
(:func:`main`) is
the same
path with its own flags (clutter levels, a CSV and a PNG file, the twin network instead).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sensornet.sim.scenario import Scenario, ScenarioError, load_scenario, parse_overrides
from sensornet.sim.studies import command
from sensornet.sim.studies.base import Outcome, Request, Study
from sensornet.sim.studies.seed002 import montecarlo as s2

MAX_CLUTTER = 10_000
"""Largest clutter rate (mean points per scan) a request may ask for."""


@dataclass(frozen=True)
class Setup:
    """The scenario (with its ``[extended]`` table) and the clutter levels a run covers."""

    base: Scenario
    clutters: tuple[float, ...] = s2.CLUTTER_LEVELS


def claims(source: str, overrides: Mapping[str, Any]) -> bool:
    """Scenarios of extended targets (an ``[extended]`` table)."""
    try:
        return load_scenario(source, overrides=dict(overrides)).extended is not None
    except ScenarioError:
        return False  # the experiment study reports the error in its one line


def load(req: Request) -> list[Setup]:
    """Option ``clutter``: the clutter levels (default
    :data:`sim.studies.seed002.montecarlo.CLUTTER_LEVELS`)."""
    base = load_scenario(req.source, overrides=dict(req.overrides))
    if base.extended is None:
        raise ScenarioError(f"{base.name}: no [extended] table (extended targets)")
    clutters = tuple(int(c) if float(c).is_integer() else c
                     for c in req.options.get("clutter") or s2.CLUTTER_LEVELS)
    if not clutters or any(not 0 <= c <= MAX_CLUTTER for c in clutters):
        raise ScenarioError(f"clutter levels must be in [0, {MAX_CLUTTER}], got {clutters}")
    return [Setup(base, clutters)]


def run_once(s: Setup, run: int) -> list[s2.RunResult]:
    """Run ``run`` at every clutter level, the partitioners alternating (machine load drifts
    hit both alike)."""
    return [s2.one_run(s2.scenario_at(c, s.base), run, part)
            for c in s.clutters for part in s2.PARTITIONS]


def summarise(s: Setup, results: list[list[s2.RunResult]]) -> list[dict]:
    return s2.summarise([r for run in results for r in run])


def write_table(rows: list[dict], path: Path) -> Path:
    """One CSV row per (clutter, partitioner)."""
    with Path(path).open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return Path(path)


def figures(o: Outcome, folder: Path) -> list[Path]:
    """``seed002_table.csv`` and ``seed002.png`` (OSPA and partition time per clutter)."""
    folder.mkdir(parents=True, exist_ok=True)
    table, png = write_table(o.summary, folder / "seed002_table.csv"), folder / "seed002.png"
    s2.write_png(o.summary, str(png))
    return [table, png]


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sensornet.sim.studies.seed002.montecarlo``: the partitioner table (``--csv
    FILE``, ``--png FILE``),
    or
    ``--network``: the 3-peer GCI network on the twin, fused against local OSPA."""
    ap = command.parser("seed002", s2.__doc__, runs=20, jobs=False,
                        set_help="scenario override, e.g. fusion.rule=aa (repeatable)")
    ap.add_argument("--clutter", type=float, nargs="+", default=list(s2.CLUTTER_LEVELS),
                    help="clutter rates (mean points per scan)")
    ap.add_argument("--csv", help="write the summary table here")
    ap.add_argument("--png", help="plot OSPA and partition time per clutter level here")
    ap.add_argument("--scenario", default="seed002",
                    help="a scenario with an [extended] table (default: seed002)")
    ap.add_argument("--network", action="store_true",
                    help="instead: the 3-peer GCI network on the twin, fused vs local OSPA")
    a = ap.parse_args(argv)
    try:
        req = command.request(a, a.scenario, parse_overrides(a.set), clutter=a.clutter)
        if a.network:
            if a.runs < 1 or a.first_run < 0:
                raise ScenarioError("--runs must be at least 1, --first-run at least 0")
            base = load(req)[0].base
    except ScenarioError as exc:
        return command.fail("seed002", exc)
    if a.network:
        res = s2.network_experiment(a.runs, a.first_run, progress=not a.quiet, base=base)
        print(f"{'peer':<5} {'local OSPA':>10} {'fused OSPA':>10} {'runs fused better':>17}")
        for n, d in res.items():
            print(f"{n:<5} {d['local']:>10.2f} {d['fused']:>10.2f} "
                  f"{100 * d['fused_better_runs']:>16.0f}%")
        return 0

    def files(outcomes: list[Outcome]) -> None:
        if a.csv:
            write_table(outcomes[0].summary, Path(a.csv))
        if a.png:
            s2.write_png(outcomes[0].summary, a.png)

    return command.drive(STUDY, req, files)


STUDY = Study(
    name="seed002",
    about="seed 002: ET-GM-PHD distance vs grid-spectral partitioning over clutter levels",
    load=load, run_once=run_once, summarise=summarise,
    table=lambda o: s2.format_table(o.summary), figures=figures, claims=claims,
    label=lambda s: "ET-GM-PHD runs (every clutter level and partitioner)",
    parallel=False, command=main)
