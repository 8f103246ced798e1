"""Experiment campaigns: one TOML file, (cell, run) tasks anywhere, resumable results.

A campaign file (see ``sim/campaigns/*.toml``)::

    [campaign]
    name = "policy-sweep"
    scenario = "seed000"        # built-in name, or a scenario file (relative to this file)
    runner = "twin"             # a study with a row hook: "experiment", "twin", "real", ...
    runs = 50                   # Monte Carlo runs per cell (runs first_run .. first_run+runs-1)
    first_run = 0
    metrics = ["*"]             # patterns of the metric columns to keep (fnmatch)

    [set]                       # overrides for every cell (the --set keys)
    "scenario.num_scans" = 60

    [grid]                      # one cell per combination, in file order
    "network.policy" = ["nale", "drop-late", "as-is"]
    "faults.default.loss" = [0.0, 0.2]

    [[cells]]                   # and/or explicit cells (crossed with the grid)
    name = "aa"
    set = { "fusion.rule" = "aa" }

    [[figures]]                 # what `sensornet report` draws (sim/campaign/report.py)
    kind = "sweep"
    x = "faults.default.loss"
    y = "fused_ospa"
    lines = "network.policy"

Results go to ``runs/campaign-<name>/`` (``--out`` elsewhere): ``manifest.json`` (the resolved
cells and every task's key: the plan of the last command that ran it), ``results/``
(:class:`sim.campaign.results.ResultStore`) and, while a process runs it, ``running.json`` (its pid
and
host: ``--status`` says running, stopped or incomplete from it). Running the
same file again skips every task whose key is stored, so an interrupted campaign loses only
the runs that were in flight; adding runs or cells computes only what is new.
"""

from __future__ import annotations

import itertools
import tomllib
from pathlib import Path

from sensornet.sim import studies
from sensornet.sim.campaign.campaign_model import (
    Campaign,
    CampaignError,
    Cell,
    _check,
    _flatten,
    _fmt,
    figure_kinds,
    task_key,
)
from sensornet.sim.campaign.campaign_results import (  # noqa: F401  (re-exported)
    Status,
    canonical_rows,
    format_status,
    read_manifest,
    recorded_runs,
    results_table,
    status,
)
from sensornet.sim.campaign.campaign_run import (  # noqa: F401  (re-exported)
    LOCK,
    CampaignProgress,
    RunSummary,
    _claim,
    lock_alive,
    read_lock,
    run_campaign,
)
from sensornet.sim.campaign.runners import code_version, scenario_source, setup_hash
from sensornet.sim.scenario import MAX_RUNS, ScenarioError, builtin_scenarios, load_scenario
from sensornet.sim.studies import DEFAULT_SCENARIO


def load_campaign(source: str | Path, runs: int | None = None) -> Campaign:
    """Read, check and resolve a campaign file (``runs`` overrides its ``runs``): every cell's
    scenario is loaded and validated here, so a bad override fails before any task runs."""
    path = _campaign_file(source)
    label = path.name
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{label}: invalid TOML: {exc}") from None
    if "study" in data:  # a study expands into its own cells (scenarios, runners, runs)
        kind = data["study"].get("kind") if isinstance(data["study"], dict) else None
        expanders = [n for n in studies.names() if studies.get(n).expand is not None]
        _check(kind in expanders, label, f"study.kind must be one of {', '.join(expanders)}, "
               f"got {kind!r}")
        return studies.get(kind).expand(data, path, runs)
    unknown = set(data) - {"campaign", "set", "grid", "cells", "figures"}
    _check(not unknown, label, f"unknown table(s) {sorted(unknown)} (known: campaign, set, "
           "grid, cells, figures)")
    head = data.get("campaign", {})
    name, runner, n_runs, first, metrics = _head(head, path, label, runs)
    scen_name, scen_text = _scenario_of(head, path, label, runner)
    base = _flatten(data.get("set", {}))
    grid = _flatten(data.get("grid", {}))
    for k, v in grid.items():
        _check(isinstance(v, list) and len(v) > 0, label,
               f"grid key {k!r} must be a non-empty list of values, got {v!r}")
    cells = _cells(data, base, grid, label)
    version = code_version()
    for c in cells:
        c.hash = _cell_hash(c, runner, scen_name, scen_text, label)
        c.keys = [task_key(c.hash, runner, first + r, version) for r in range(n_runs)]
    figures = _figures(data, grid, label)
    return Campaign(name, path, scen_name, scen_text, runner, n_runs, first,
                    tuple(metrics), cells, figures, version)


def _campaign_file(source: str | Path) -> Path:
    """The campaign file ``source`` names: a path, else a shipped campaign by name (with or
    without ``.toml``), so ``sensornet campaign loss-sweep`` works from anywhere."""
    path = Path(source)
    if not path.is_file():
        shipped = Path(__file__).parents[1] / "campaigns" / (
            path.name if path.suffix == ".toml" else f"{path.name}.toml")
        _check(shipped.is_file(), str(source), "no such campaign file (shipped: "
               + ", ".join(sorted(p.stem for p in shipped.parent.glob("*.toml"))) + ")")
        path = shipped
    return path


def _head(head: dict, path: Path, label: str,
          runs: int | None) -> tuple[str, str, int, int, list[str]]:
    """The checked ``[campaign]`` keys: name, runner, runs (``runs`` overrides the file's),
    first run and metric patterns; each mistake a one-line :class:`CampaignError`."""
    unknown = set(head) - {"name", "scenario", "runner", "runs", "first_run", "metrics"}
    _check(not unknown, label, f"unknown key(s) {sorted(unknown)} in [campaign]")
    name = str(head.get("name", path.stem))
    runner = head.get("runner", "twin")
    _check(runner in studies.runners(), label, "campaign.runner must be one of "
           f"{', '.join(studies.runners())}, got {runner!r}")
    n_runs = runs if runs is not None else head.get("runs", 50)
    _check(isinstance(n_runs, int) and 1 <= n_runs <= MAX_RUNS, label,
           f"campaign.runs must be an integer in 1..{MAX_RUNS:,}, got {n_runs!r}")
    first = head.get("first_run", 0)
    _check(isinstance(first, int) and first >= 0, label,
           f"campaign.first_run must be an integer >= 0, got {first!r}")
    metrics = head.get("metrics", ["*"])
    _check(isinstance(metrics, list) and all(isinstance(m, str) for m in metrics) and metrics,
           label, "campaign.metrics must be a list of column patterns, e.g. [\"*\"]")
    return name, runner, n_runs, first, metrics


def _scenario_of(head: dict, path: Path, label: str, runner: str) -> tuple[str, str | None]:
    """``(name, text)`` of the campaign's scenario: the runner's fixed one, a file next to the
    campaign (its text travels with the tasks), or a built-in name (text None)."""
    fixed = studies.get(runner).fixed_scenario
    scen = str(head.get("scenario", fixed or DEFAULT_SCENARIO))
    scen_path = path.parent / scen
    if fixed is not None:
        _check(scen == fixed, label, f"the {runner} runner takes scenario = \"{fixed}\" "
               "(its settings are the study's [set]/[grid] keys)")
        return scen, None
    if scen_path.is_file():
        return scen_path.name, scen_path.read_text(encoding="utf-8")
    key = scen[:-5] if scen.endswith(".toml") else scen
    _check(key in builtin_scenarios(), label, f"campaign.scenario {scen!r}: no such file "
           f"next to the campaign, nor a built-in scenario ({', '.join(builtin_scenarios())})")
    return key, None


def _cells(data: dict, base: dict, grid: dict, label: str) -> list[Cell]:
    """Every cell: each ``[[cells]]`` entry (one empty entry without any) crossed with the
    ``[grid]`` in file order, its overrides ``base`` (``[set]``) < the entry's ``set`` < the
    grid's."""
    listed = data.get("cells", [{}]) or [{}]
    _check(isinstance(listed, list), label, "[[cells]] must be an array of tables")
    cells: list[Cell] = []
    for entry in listed:
        _check(isinstance(entry, dict) and set(entry) <= {"name", "set"}, label,
               f"a [[cells]] entry takes 'name' and 'set', got {entry!r}")
        own = _flatten(entry.get("set", {}))
        for combo in itertools.product(*grid.values()) if grid else [()]:
            values = dict(zip(grid, combo, strict=True))
            over = {**base, **own, **values}
            parts = ([str(entry["name"])] if "name" in entry else
                     [f"{k}={_fmt(v)}" for k, v in own.items()])
            parts += [f"{k}={_fmt(v)}" for k, v in values.items()]
            shown = {**({"cell": entry["name"]} if "name" in entry else own), **values}
            cells.append(Cell(len(cells), ", ".join(parts) or "base", over, shown))
    return cells


def _cell_hash(c: Cell, runner: str, scen_name: str, scen_text: str | None, label: str) -> str:
    """The hash of cell ``c``'s resolved setup (its scenario loaded and validated here, so a
    bad override fails before any task runs)."""
    try:
        make = studies.get(runner).cell_setup
        source = scenario_source(scen_name, scen_text)
        return setup_hash(runner, make(source, c.overrides) if make is not None else
                          load_scenario(source, overrides=c.overrides))
    except (ScenarioError, ValueError) as exc:
        raise CampaignError(f"{label}, cell {c.label!r}: {exc}") from None


def _figures(data: dict, grid: dict, label: str) -> list:
    """The checked ``[[figures]]`` entries (a sweep's ``x`` must be a ``[grid]`` key)."""
    figures = data.get("figures", [])
    _check(isinstance(figures, list), label, "[[figures]] must be an array of tables")
    for f in figures:
        kinds = figure_kinds()
        _check(isinstance(f, dict) and f.get("kind") in kinds, label,
               f"a [[figures]] entry needs kind = one of {', '.join(kinds)}, got {f!r}")
        if f["kind"] == "sweep":
            _check(f.get("x") in grid, label,
                   f"sweep figure: x must be a [grid] key ({', '.join(grid) or 'none'})")
    return figures


def default_folder(c: Campaign) -> Path:
    return Path("runs") / f"campaign-{c.name}"
