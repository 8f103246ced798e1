"""The Study contract: load, run once, summarise, table, figures; and the one driver of it.

A study is a reproduction or a measurement with seeded, independent runs. The ``experiment``
command, campaigns (:mod:`sim.campaign`) and reports (:mod:`sim.campaign.report`) drive every study
through the hooks below and never name one; :func:`run_study` is the one loop that runs them
(over :func:`sim.run.pool.map_runs`, one progress line).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sensornet.sim.run import pool

Setup = Any
"""What a study's ``load`` returns: a resolved scenario or configuration (picklable: it goes to
the worker processes)."""


@dataclass(frozen=True)
class Request:
    """What a caller asks of a study, as Python values (the command line's flags, parsed)."""

    source: str
    """A built-in scenario name or a scenario file."""
    overrides: Mapping[str, Any] = field(default_factory=dict)
    """``--set`` values, parsed (:func:`sim.scenario.parse_overrides`)."""
    runs: int = 1
    jobs: int = 1
    first_run: int = 0
    out: Path | None = None
    """Where the figures and CSVs go (None: none written)."""
    progress: bool = True
    options: Mapping[str, Any] = field(default_factory=dict)
    """Study-specific choices (e.g. ``fusion``, ``birth``); a study ignores what it does not
    take."""


@dataclass
class Outcome:
    """One setup's runs, summarised: what ``table`` and ``figures`` read."""

    setup: Setup
    summary: Any
    runs: range
    seconds: float
    results: list[Any]


@dataclass(frozen=True)
class Cell:
    """What a campaign task gives a study's ``row`` hook (a :class:`sim.campaign.runners.Task` is
    one)."""

    run: int
    scenario: str
    scenario_text: str | None
    overrides: Mapping[str, Any]


@dataclass(frozen=True)
class Study:
    """One study; every hook a plain function of plain values (they run in worker processes)."""

    name: str
    """Registry name; also the campaign ``runner`` when the study has a ``row`` hook."""
    about: str
    """One line for listings and error messages."""
    load: Callable[[Request], Sequence[Setup]] | None = None
    """The setups a request runs, resolved and checked (several when a study compares
    variants, e.g. two birth models); raises :class:`sim.scenario.ScenarioError`. None: the
    study runs as a campaign only (its ``expand`` hook)."""
    run_once: Callable[[Setup, int], Any] | None = None
    """``(setup, run) -> result`` of one seeded run (pure: the same on any worker; a
    module-level function, as it is sent to worker processes)."""
    summarise: Callable[[Setup, list[Any]], Any] | None = None
    """``(setup, results in run order) -> summary``."""
    table: Callable[[Outcome], str] | None = None
    """The printed table (the published digits)."""
    figures: Callable[[Outcome, Path], list[Path]] | None = None
    """Write the CSVs and figures into a folder; returns the paths."""
    claims: Callable[[str, Mapping[str, Any]], bool] = lambda source, overrides: False
    """Whether ``sensornet experiment SOURCE`` is this study (the first claimer runs)."""
    label: Callable[[Setup], str] = lambda setup: "runs"
    """The progress line's label."""
    parallel: bool = True
    """False: runs one at a time in this process (a study that times its methods)."""
    scenario: bool = False
    """Setups are :class:`sim.scenario.Scenario` values (the command line checks its budgets
    and fusion advice on them)."""
    # Campaign hooks (a study without ``row`` is not a campaign runner).
    row: Callable[[Setup, Cell], dict[str, Any]] | None = None
    """``(setup, cell) -> metric columns`` of one campaign task."""
    cell_setup: Callable[[str, Mapping[str, Any]], Setup] | None = None
    """``(scenario source, overrides) -> setup`` of a campaign cell (None: the scenario)."""
    setup_hash: Callable[[Setup], str] | None = None
    """A hash of a cell's resolved setup (None: :func:`sim.campaign.runners.scenario_hash`)."""
    fixed_scenario: str | None = None
    """A runner that reads no scenario file: the ``scenario`` its campaigns must name."""
    modules: tuple[str, ...] = ()
    """Modules a campaign worker imports before its first task."""
    expand: Callable[[dict, Path | None, int | None], Any] | None = None
    """A ``[study]`` campaign file of this ``kind`` -> its :class:`sim.campaign.Campaign`."""
    report: Callable[[dict, dict, Path], tuple[list[str], list[Path]]] | None = None
    """``(cell, cell data, folder) -> (markdown lines, files written)`` for one campaign cell,
    when the campaign file asks for ``[[figures]] kind = report_kind``."""
    report_kind: str | None = None
    """The ``[[figures]]`` kind that asks for ``report`` (default: the study's name)."""
    command: Callable[[Sequence[str] | None], int] | None = None
    """The study's own command line, ``python -m sensornet.sim.<module>`` (argv -> exit code): flags
    made into a :class:`Request` and run through :func:`experiment` like ``sensornet
    experiment`` (:mod:`sim.studies.command`)."""


def run_study(study: Study, setup: Setup, runs: Sequence[int], jobs: int = 1,
              progress: bool = True) -> Outcome:
    """Every run of one setup over the one pool loop, then the study's summary."""
    t0 = time.monotonic()
    results = pool.map_runs(study.run_once, [(setup, r) for r in runs],
                            jobs if study.parallel else 1, study.label(setup), progress)
    summary = study.summarise(setup, results)
    return Outcome(setup, summary, range(runs[0], runs[-1] + 1) if runs else range(0),
                   time.monotonic() - t0, results)


def experiment(study: Study, req: Request, setups: Sequence[Setup] | None = None,
               echo: Callable[[str], None] = print) -> list[Outcome]:
    """Load, run, summarise; print each setup's table and the files written."""
    if req.runs < 1:
        raise ValueError("runs must be at least 1")
    if study.load is None or study.run_once is None or study.table is None:
        raise ValueError(f"study {study.name!r} runs as a campaign only")
    outcomes = []
    runs = range(req.first_run, req.first_run + req.runs)
    for setup in study.load(req) if setups is None else setups:
        outcome = run_study(study, setup, runs, min(req.jobs, req.runs), req.progress)
        echo(study.table(outcome))
        if req.out is not None and study.figures is not None:
            for path in study.figures(outcome, req.out):
                echo(f"wrote {path}")
        outcomes.append(outcome)
    return outcomes
