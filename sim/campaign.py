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

    [[figures]]                 # what `sensornet report` draws (sim/report.py)
    kind = "sweep"
    x = "faults.default.loss"
    y = "fused_ospa"
    lines = "network.policy"

Results go to ``runs/campaign-<name>/`` (``--out`` elsewhere): ``manifest.json`` (the resolved
cells and every task's key: the plan of the last command that ran it), ``results/``
(:class:`sim.results.ResultStore`) and, while a process runs it, ``running.json`` (its pid and
host: ``--status`` says running, stopped or incomplete from it). Running the
same file again skips every task whose key is stored, so an interrupted campaign loses only
the runs that were in flight; adding runs or cells computes only what is new.
"""

from __future__ import annotations

import itertools
import json
import math
import time
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from sim import studies
from sim.progress import Progress
from sim.runners import Task, code_version, setup_hash
from sim.scenario import MAX_RUNS, ScenarioError, builtin_scenarios, load_scenario

DEFAULT_SCENARIO = "seed000"
"""The scenario of a campaign file that names none (the project's default, as the commands')."""


def figure_kinds() -> tuple[str, ...]:
    """``[[figures]]`` kinds: the campaign-wide ones and each study's per-cell report."""
    return ("sweep", "ospa-time", *studies.report_kinds())


class CampaignError(ScenarioError):
    """A campaign file that cannot be run (reported in one line)."""


@dataclass
class Cell:
    index: int
    label: str
    overrides: dict[str, Any]
    values: dict[str, Any]
    """The grid/list values that make this cell (for tables and sweep plots)."""
    hash: str = ""
    keys: list[str] = field(default_factory=list)
    scenario: str | None = None
    """This cell's own scenario (name or file name of ``scenario_text``); None: the
    campaign's (a study's cells run on several networks: :mod:`sim.fusion_study`)."""
    scenario_text: str | None = None
    runner: str | None = None
    """This cell's own runner; None: the campaign's."""


@dataclass
class Campaign:
    name: str
    path: Path | None
    scenario: str
    scenario_text: str | None
    runner: str
    runs: int
    first_run: int
    metrics: tuple[str, ...]
    cells: list[Cell]
    figures: list[dict[str, Any]]
    code_version: str

    def tasks(self) -> list[Task]:
        out = []
        for c in self.cells:
            own = c.scenario is not None
            for i, key in enumerate(c.keys):
                out.append(Task(key=key, cell=c.index, cell_label=c.label,
                                run=self.first_run + i, runner=c.runner or self.runner,
                                scenario=c.scenario if own else self.scenario,
                                scenario_text=c.scenario_text if own else self.scenario_text,
                                overrides=c.overrides, scenario_hash=c.hash,
                                code_version=self.code_version, metrics=self.metrics))
        return out

    def manifest(self) -> dict[str, Any]:
        return {"name": self.name, "file": str(self.path) if self.path else None,
                "scenario": self.scenario, "runner": self.runner, "runs": self.runs,
                "first_run": self.first_run, "code_version": self.code_version,
                "metrics": list(self.metrics), "figures": self.figures,
                "cells": [{"index": c.index, "label": c.label, "set": c.overrides,
                           "values": c.values, "hash": c.hash, "keys": c.keys,
                           **({"scenario": c.scenario} if c.scenario is not None else {}),
                           **({"runner": c.runner} if c.runner is not None else {})}
                          for c in self.cells]}


def task_key(cell_hash: str, runner: str, run: int, version: str) -> str:
    import hashlib

    return hashlib.sha256(f"{cell_hash}/{runner}/{run}/{version}".encode()).hexdigest()[:24]


def _flatten(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested TOML tables -> dotted keys (``{"birth": {"model": x}}`` -> ``birth.model``)."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        path = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, dict) and "kind" not in v:  # a delay table {kind = ...} is a value
            out.update(_flatten(v, path))
        else:
            out[path] = v
    return out


def _fmt(v: Any) -> str:
    """A value as in a ``--set`` (strings bare, tables inline)."""
    from sim.sweep import _toml

    return v if isinstance(v, str) else _toml(v)


def _check(cond: bool, label: str, problem: str) -> None:
    if not cond:
        raise CampaignError(f"{label}: {problem}")


def load_campaign(source: str | Path, runs: int | None = None) -> Campaign:
    """Read, check and resolve a campaign file (``runs`` overrides its ``runs``): every cell's
    scenario is loaded and validated here, so a bad override fails before any task runs."""
    path = Path(source)
    if not path.is_file():
        shipped = Path(__file__).parent / "campaigns" / (
            path.name if path.suffix == ".toml" else f"{path.name}.toml")
        _check(shipped.is_file(), str(source), "no such campaign file (shipped: "
               + ", ".join(sorted(p.stem for p in shipped.parent.glob("*.toml"))) + ")")
        path = shipped
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
    unknown = set(head) - {"name", "scenario", "runner", "runs", "first_run", "metrics"}
    _check(not unknown, label, f"unknown key(s) {sorted(unknown)} in [campaign]")
    name = str(head.get("name", path.stem))
    runner = head.get("runner", "twin")
    _check(runner in studies.runners(), label, "campaign.runner must be one of "
           f"{', '.join(studies.runners())}, got {runner!r}")
    fixed = studies.get(runner).fixed_scenario
    n_runs = runs if runs is not None else head.get("runs", 50)
    _check(isinstance(n_runs, int) and 1 <= n_runs <= MAX_RUNS, label,
           f"campaign.runs must be an integer in 1..{MAX_RUNS:,}, got {n_runs!r}")
    first = head.get("first_run", 0)
    _check(isinstance(first, int) and first >= 0, label,
           f"campaign.first_run must be an integer >= 0, got {first!r}")
    metrics = head.get("metrics", ["*"])
    _check(isinstance(metrics, list) and all(isinstance(m, str) for m in metrics) and metrics,
           label, "campaign.metrics must be a list of column patterns, e.g. [\"*\"]")
    scen = str(head.get("scenario", fixed or DEFAULT_SCENARIO))
    scen_path = path.parent / scen
    if fixed is not None:
        _check(scen == fixed, label, f"the {runner} runner takes scenario = \"{fixed}\" "
               "(its settings are the study's [set]/[grid] keys)")
        scen_name, scen_text = scen, None
    elif scen_path.is_file():
        scen_name, scen_text = scen_path.name, scen_path.read_text(encoding="utf-8")
    else:
        key = scen[:-5] if scen.endswith(".toml") else scen
        _check(key in builtin_scenarios(), label, f"campaign.scenario {scen!r}: no such file "
               f"next to the campaign, nor a built-in scenario ({', '.join(builtin_scenarios())})")
        scen_name, scen_text = key, None
    base = _flatten(data.get("set", {}))
    grid = _flatten(data.get("grid", {}))
    for k, v in grid.items():
        _check(isinstance(v, list) and len(v) > 0, label,
               f"grid key {k!r} must be a non-empty list of values, got {v!r}")
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
    from sim.runners import scenario_source

    version = code_version()
    for c in cells:
        try:
            make = studies.get(runner).cell_setup
            source = scenario_source(scen_name, scen_text)
            c.hash = setup_hash(runner, make(source, c.overrides) if make is not None else
                                load_scenario(source, overrides=c.overrides))
        except (ScenarioError, ValueError) as exc:
            raise CampaignError(f"{label}, cell {c.label!r}: {exc}") from None
        c.keys = [task_key(c.hash, runner, first + r, version) for r in range(n_runs)]
    figures = data.get("figures", [])
    _check(isinstance(figures, list), label, "[[figures]] must be an array of tables")
    for f in figures:
        kinds = figure_kinds()
        _check(isinstance(f, dict) and f.get("kind") in kinds, label,
               f"a [[figures]] entry needs kind = one of {', '.join(kinds)}, got {f!r}")
        if f["kind"] == "sweep":
            _check(f.get("x") in grid, label,
                   f"sweep figure: x must be a [grid] key ({', '.join(grid) or 'none'})")
    return Campaign(name, path, scen_name, scen_text, runner, n_runs, first,
                    tuple(metrics), cells, figures, version)


def default_folder(c: Campaign) -> Path:
    return Path("runs") / f"campaign-{c.name}"


# --------------------------------------------------------------------------------------------
# Status and progress
# --------------------------------------------------------------------------------------------


@dataclass
class Status:
    done: int
    total: int
    per_cell: list[tuple[Cell, int]]
    stale: int
    """Stored rows that belong to no task of this campaign (other code, other cells)."""
    running: dict[str, Any] | None = None
    """The lock of the process running the campaign now (pid, host), if one does."""
    died: dict[str, Any] | None = None
    """The lock a process left when it died without finishing (``kill -9``, a crash)."""

    @property
    def cells_done(self) -> int:
        return sum(1 for c, n in self.per_cell if n == len(c.keys))


def status(c: Campaign, folder: Path) -> Status:
    from sim.results import ResultStore

    stored = ResultStore(folder / "results").done_keys()
    per = [(cell, sum(1 for k in cell.keys if k in stored)) for cell in c.cells]
    wanted = {k for cell in c.cells for k in cell.keys}
    lock = read_lock(folder)
    alive = lock is not None and lock_alive(lock)
    return Status(sum(n for _, n in per), len(wanted), per, len(stored - wanted),
                  running=lock if alive else None,
                  died=lock if lock is not None and not alive else None)


def recorded_runs(folder: Path) -> int | None:
    """Runs per cell of the plan the folder records (its ``manifest.json``), if any."""
    try:
        runs = json.loads((Path(folder) / "manifest.json").read_text()).get("runs")
    except (OSError, ValueError):
        return None
    return runs if isinstance(runs, int) and runs >= 1 else None


def format_status(c: Campaign, folder: Path, st: Status) -> str:
    lines = [f"campaign {c.name}: runner {c.runner}, {len(c.cells)} cells x {c.runs} runs, "
             f"code {c.code_version}",
             f"{st.done}/{st.total} runs done, {st.cells_done}/{len(c.cells)} cells complete"
             f" ({folder})"]
    left = st.total - st.done
    if st.running is not None:
        lines.append(f"running: pid {st.running.get('pid')} on {st.running.get('host')}")
    elif left and st.died is not None:
        lines.append(f"stopped: the process that ran it (pid {st.died.get('pid')} on "
                     f"{st.died.get('host')}) is gone, {left} runs to go; run the campaign "
                     "again to finish")
    elif left and st.done:
        lines.append(f"incomplete: no process is running it, {left} runs to go; run the "
                     "campaign again to finish")
    elif left:
        lines.append("not started")
    width = max(len(cell.label) for cell in c.cells)
    partial = "running" if st.running is not None else "incomplete"
    for cell, n in st.per_cell:
        mark = "done" if n == len(cell.keys) else (partial if n else "")
        lines.append(f"  cell {cell.index:>3}  {cell.label:<{width}}  {n:>5}/{len(cell.keys)}"
                     f"  {mark}".rstrip())
    if st.stale:
        lines.append(f"{st.stale} stored runs belong to other code versions or cells "
                     "(kept, not used)")
    return "\n".join(lines)


class CampaignProgress(Progress):
    """``[####   ] 37/100 runs, cells 1/2, 3.1 runs/s, eta 20s``."""

    def __init__(self, total: int, cell_sizes: dict[int, int], cell_done: dict[int, int],
                 stream: TextIO | None = None, enabled: bool = True) -> None:
        self.cell_sizes, self.cell_done = cell_sizes, dict(cell_done)
        super().__init__(total, "runs", stream=stream, enabled=enabled)

    def finished(self, cell: int) -> None:
        self.cell_done[cell] = self.cell_done.get(cell, 0) + 1
        self.advance()

    def _line(self) -> str:
        frac = self.done / self.total
        elapsed = time.monotonic() - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else math.nan
        cells = sum(1 for c, n in self.cell_sizes.items() if self.cell_done.get(c, 0) >= n)
        return (f"[{'#' * int(30 * frac):<30}] {self.done}/{self.total} runs, cells "
                f"{cells}/{len(self.cell_sizes)}, {rate:.2f} runs/s, eta "
                f"{'?' if math.isnan(eta) else f'{eta:.0f}s'}, "
                f"{elapsed:.0f}s elapsed")


# --------------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------------


LOCK = "running.json"
"""In a campaign folder while a process runs it: ``{"pid", "host", "start"}``."""


def _start_stamp(pid: int) -> str | None:
    """When process ``pid`` started (Linux ``/proc``: a pid reused by another process has
    another stamp), or None where that cannot be read."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def read_lock(folder: Path) -> dict[str, Any] | None:
    try:
        lock = json.loads((Path(folder) / LOCK).read_text())
    except (OSError, ValueError):
        return None
    return lock if isinstance(lock, dict) else None


def lock_alive(lock: dict[str, Any]) -> bool:
    """Whether the process that wrote ``lock`` still runs (one on another host: assumed)."""
    import os
    import socket

    if lock.get("host") != socket.gethostname():
        return True  # cannot be checked from here
    pid = lock.get("pid")
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    stamp = _start_stamp(pid)
    return stamp is None or lock.get("start") in (None, stamp)


def _claim(folder: Path) -> Path:
    """Write the folder's lock (refused while another live process holds it)."""
    import os
    import socket

    held = read_lock(folder)
    if held is not None and held.get("pid") != os.getpid() and lock_alive(held):
        raise CampaignError(f"{folder}: the campaign is running already (pid {held.get('pid')} "
                            f"on {held.get('host')}); wait for it, or stop it first")
    path = folder / LOCK
    path.write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                                "start": _start_stamp(os.getpid())}) + "\n")
    return path


@dataclass
class RunSummary:
    ran: int
    skipped: int
    stopped: bool
    seconds: float
    cpu_seconds: float = 0.0
    """CPU time the finished tasks used (all workers): ``cpu_seconds / seconds`` is how many
    cores the campaign actually had."""


def run_campaign(c: Campaign, folder: Path, jobs: int = 1, dask: str | None = None,
                 progress: bool = True, stop_after: int | None = None,
                 on_row: Callable[[dict], None] | None = None,
                 stream: TextIO | None = None) -> RunSummary:
    """Run every task of ``c`` whose key is not stored in ``folder``.

    ``dask``: ``None`` (a local process pool of ``jobs``), ``"local"`` (a Dask
    ``LocalCluster`` of ``jobs`` workers) or a scheduler address. ``stop_after``: stop (as an
    interrupt would) once that many tasks have finished in this call.
    """
    from sim.results import need_pyarrow

    need_pyarrow()
    folder.mkdir(parents=True, exist_ok=True)
    lock = _claim(folder)
    try:
        return _run(c, folder, jobs, dask, progress, stop_after, on_row, stream)
    finally:
        lock.unlink(missing_ok=True)


def _run(c: Campaign, folder: Path, jobs: int, dask: str | None, progress: bool,
         stop_after: int | None, on_row: Callable[[dict], None] | None,
         stream: TextIO | None) -> RunSummary:
    from sim.results import ResultStore

    (folder / "manifest.json").write_text(json.dumps(c.manifest(), indent=1) + "\n")
    store = ResultStore(folder / "results")
    stored = store.done_keys()
    tasks = [t for t in c.tasks() if t.key not in stored]
    skipped = len(c.tasks()) - len(tasks)
    sizes = {cell.index: len(cell.keys) for cell in c.cells}
    done0 = {cell.index: sum(1 for k in cell.keys if k in stored) for cell in c.cells}
    t0 = time.monotonic()
    ran, cpu = 0, 0.0
    stopped = False
    rows: Iterator[dict]
    if not tasks:
        rows = iter(())
    elif dask is None:
        from sim.runners import run_pool

        rows = run_pool(tasks, jobs)
    else:
        from sim.runners import run_dask

        rows = run_dask(tasks, scheduler=None if dask == "local" else dask, jobs=jobs)
    try:
        with CampaignProgress(len(tasks), sizes, done0, stream=stream,
                              enabled=progress and bool(tasks)) as bar:
            for row in rows:
                store.write(row)
                ran += 1
                cpu += float(row.get("cpu_seconds", 0.0))
                bar.finished(row["cell"])
                if on_row is not None:
                    on_row(row)
                if stop_after is not None and ran >= stop_after and ran < len(tasks):
                    stopped = True
                    break
    finally:
        close = getattr(rows, "close", None)
        if close is not None:
            close()
        store.compact()
    return RunSummary(ran, skipped, stopped, time.monotonic() - t0, cpu)


# --------------------------------------------------------------------------------------------
# Reading results
# --------------------------------------------------------------------------------------------


def read_manifest(folder: Path) -> dict[str, Any]:
    path = Path(folder) / "manifest.json"
    if not Path(folder).exists():
        raise CampaignError(f"{folder}: no such folder (a campaign folder is what 'sensornet "
                            "campaign FILE' writes, runs/campaign-<name> by default)")
    if not Path(folder).is_dir():
        raise CampaignError(f"{folder}: not a folder (give the campaign's folder, e.g. "
                            "runs/campaign-<name>)")
    if not path.is_file():
        raise CampaignError(f"{folder}: no manifest.json (not a campaign folder; run "
                            "'sensornet campaign FILE' first)")
    return json.loads(path.read_text())


def results_table(folder: Path, manifest: dict[str, Any] | None = None,
                  complete_only: bool = False):
    """The campaign's rows in (cell, run) order, from the manifest's keys (rows not yet
    computed are absent). Columns ``cell``/``cell_label`` are the manifest's."""
    import pyarrow as pa

    from sim.results import ResultStore

    manifest = manifest or read_manifest(folder)
    order = [(cell["index"], cell["label"], k) for cell in manifest["cells"]
             for k in cell["keys"]]
    table = ResultStore(Path(folder) / "results").read({k for _, _, k in order})
    where = {k: i for i, k in enumerate(table.column("key").to_pylist())}
    picked = [(ci, lab, where[k]) for ci, lab, k in order if k in where]
    if complete_only and len(picked) < len(order):
        raise CampaignError(f"{folder}: {len(order) - len(picked)} of {len(order)} runs "
                            "not computed yet")
    table = table.take(pa.array([i for _, _, i in picked], pa.int64()))
    if table.num_rows:
        for name, values, typ in (("cell", [ci for ci, _, _ in picked], pa.int64()),
                                  ("cell_label", [lab for _, lab, _ in picked], pa.string())):
            table = table.set_column(table.schema.get_field_index(name), name,
                                     pa.array(values, typ))
    return table


def canonical_rows(table) -> list[tuple]:
    """The table's computed values as exact text (``repr`` of every float), without timing
    columns, keys and code versions: equal lists mean bit-identical results."""
    from sim.results import is_timing

    cols = sorted(c for c in table.column_names
                  if not is_timing(c) and c not in ("key", "code_version"))
    data = {c: table.column(c).to_pylist() for c in cols}
    return [tuple((c, repr(data[c][i])) for c in cols) for i in range(table.num_rows)]
