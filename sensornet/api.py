"""A Python API for notebooks: build a scenario, run the twin, get tracks and metrics as arrays.

    from sensornet.api import scenario, simulate
    scn = scenario("seed000", {"scenario.num_scans": 30})
    run = simulate(scn, run=0)
    run.mean_ospa("s1", "fused")          # the summary's number
    run.columns["ospa"]                   # per-scan results as NumPy arrays (docs/results.md)
    run.tracks("s1")                      # {scan: (n, d) fused states}
    run.tracks_by_id("s1")                # {(origin, birth_scan, index): (scans, states)}
    run.to_pandas()                       # the same table as a DataFrame (needs pandas)
    done = load_run("runs/<time>-run")    # a finished run's folder (processes, twin, hosts)

The run is the discrete-event twin (:func:`sim.run.twin.run_twin`): the peers' own code on a virtual
clock, the same bytes as the processes exchange. docs/notebooks/quickstart.ipynb is an example,
executed by tests/test_api.py.
"""

from __future__ import annotations

import json
import shlex
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sensornet.peers.scan_results import COLUMNS, LIST_COLUMNS, read_part, read_table
from sensornet.sim.run.run_summary import read_summaries
from sensornet.sim.run.twin import TwinResult, run_twin
from sensornet.sim.scenario import Scenario, builtin_scenarios, load_scenario, parse_overrides

__all__ = ["Run", "builtin_scenarios", "load_run", "scenario", "simulate"]


def scenario(source: str | Path, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """A built-in scenario by name (``"seed000"``..``"seed004"``) or a scenario file's path,
    with ``overrides`` as ``{"section.key": value}`` (the ``--set`` keys); raises
    :class:`sim.scenario.ScenarioError` with a one-line message on a bad key or value."""
    return load_scenario(source, overrides=dict(overrides or {}))


@dataclass
class Run:
    """One run: per-peer summaries and the per-scan results table (a twin run of
    :func:`simulate`, or a finished run's folder read by :func:`load_run`)."""

    scenario: Scenario | None
    """The run's scenario (None: a folder whose scenario could not be rebuilt)."""
    twin: TwinResult | None
    """The twin's peers (None: a run read from its folder)."""
    columns: dict[str, np.ndarray | list]
    """The per-scan table (docs/results.md): NumPy arrays, the :data:`LIST_COLUMNS` lists."""
    meta: dict
    """``position_index``, ``cutoff`` and ``order`` of the table (and, in tables written
    since, ``gospa_alpha`` and ``units``)."""
    summaries: dict[str, dict] = field(default_factory=dict)
    """A folder's ``peer-<name>.json`` summaries (a twin run makes them on demand)."""

    @property
    def peers(self) -> list[str]:
        if self.twin is not None:
            return list(self.twin.peers)
        return list(self.summaries) or sorted(set(np.asarray(self.columns["peer"]).tolist()))

    def summary(self, peer: str) -> dict:
        """The peer's summary, as a process writes it (``peer-<name>.json``)."""
        if self.twin is not None:
            return self.twin.summary(peer)
        if peer not in self.summaries:
            raise ValueError(f"peer {peer!r}: no summary in this run (peers: "
                             f"{', '.join(self.summaries) or 'none'})")
        return self.summaries[peer]

    def mean_ospa(self, peer: str, which: str = "fused") -> float:
        """Mean OSPA of ``"local"`` or ``"fused"`` estimates (a missing output at the cut-off)."""
        if self.twin is not None:
            return self.twin.mean_ospa(peer, which)
        value = self.summary(peer).get(f"mean_ospa_{which}")
        return float("nan") if value is None else float(value)

    def select(self, peer: str, which: str = "fused") -> np.ndarray:
        """Row indices of one peer's ``which`` estimates, in scan order."""
        rows = np.flatnonzero((self.columns["peer"] == peer)
                              & (self.columns["estimate"] == which))
        return rows[np.argsort(self.columns["scan"][rows], kind="stable")]

    def metric(self, peer: str, name: str = "ospa", which: str = "fused") -> tuple:
        """``(scans, values)`` of one column for one peer's estimates."""
        rows = self.select(peer, which)
        return self.columns["scan"][rows], self.columns[name][rows]

    def tracks(self, peer: str, which: str = "fused") -> dict[int, np.ndarray]:
        """``{scan: (n, d) states}`` of one peer's estimates (an empty array for a miss)."""
        d = self.scenario_dim
        return {int(self.columns["scan"][i]): np.asarray(self.columns["tracks"][i],
                                                         float).reshape(-1, d)
                for i in self.select(peer, which)}

    def tracks_by_id(self, peer: str, which: str = "fused"
                     ) -> dict[tuple[int, int, int], tuple[np.ndarray, np.ndarray]]:
        """``{id: (scans (T,), states (T, d))}``: one peer's tracks by their id ``(origin,
        birth_scan, index)``, each in scan order (a peer kind without ids gives ``{}``; an id
        twice in one scan keeps its first, heaviest row)."""
        d = self.scenario_dim
        by: dict[tuple[int, int, int], tuple[list, list]] = {}
        for i in self.select(peer, which):
            k = int(self.columns["scan"][i])
            seen = set()
            for x, lab in zip(self.columns["tracks"][i], self.columns["track_ids"][i],
                              strict=False):
                key = tuple(int(v) for v in lab)
                if key in seen:
                    continue
                seen.add(key)
                scans, states = by.setdefault(key, ([], []))
                scans.append(k)
                states.append(x)
        return {key: (np.asarray(s, dtype=np.int64), np.asarray(x, float).reshape(-1, d))
                for key, (s, x) in sorted(by.items())}

    def truth_by_id(self) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """``{true target id: (scans (T,), states (T, d))}`` (the ``truth_ids`` column)."""
        d = self.scenario_dim
        by: dict[int, tuple[list, list]] = {}
        done: set[int] = set()
        for k, t, ids in zip(self.columns["scan"].tolist(), self.columns["truth"],
                             self.columns["truth_ids"], strict=True):
            if k in done or len(ids) != len(t):
                continue
            done.add(k)
            for x, i in zip(t, ids, strict=True):
                scans, states = by.setdefault(int(i), ([], []))
                scans.append(k)
                states.append(x)
        out = {}
        for i, (s, x) in sorted(by.items()):
            order = np.argsort(s, kind="stable")
            out[i] = (np.asarray(s, dtype=np.int64)[order],
                      np.asarray(x, float).reshape(-1, d)[order])
        return out

    def truth(self) -> dict[int, np.ndarray]:
        """``{scan: (m, d) true states}``."""
        d = self.scenario_dim
        out: dict[int, np.ndarray] = {}
        for k, t in zip(self.columns["scan"].tolist(), self.columns["truth"], strict=True):
            if k not in out:
                out[k] = np.asarray(t, float).reshape(-1, d)
        return dict(sorted(out.items()))

    @property
    def scenario_dim(self) -> int:
        """Length of a state row in ``tracks`` and ``truth``."""
        for col in ("truth", "tracks"):
            for rows in self.columns[col]:
                if rows:
                    return len(rows[0])
        return 4

    def to_pandas(self):
        """The per-scan table as a pandas DataFrame (``pip install pandas``)."""
        import pandas as pd  # heavy optional dependency: pandas

        return pd.DataFrame({name: self.columns[name] for name in COLUMNS})


def _arrays(cols: dict[str, list]) -> dict[str, np.ndarray | list]:
    """A table's columns as :class:`Run` holds them: NumPy arrays, the list columns lists."""
    return {c: (list(cols[c]) if c in LIST_COLUMNS else np.asarray(cols[c])) for c in COLUMNS}


def simulate(scn: Scenario, run: int = 0) -> Run:
    """Monte Carlo run ``run`` of ``scn`` on the twin (deterministic: the same ``run`` gives
    the same numbers)."""
    result = run_twin(scn, run)
    cols: dict[str, list] = {name: [] for name in COLUMNS}
    meta: dict = {}
    for name, core in result.peers.items():
        part = core.scorer.results.table(name)
        for c in COLUMNS:
            cols[c].extend(part[c])
        meta = core.scorer.results.meta()
    return Run(scenario=scn, twin=result, columns=_arrays(cols), meta=meta)


def _folder_scenario(folder: Path) -> Scenario | None:
    """The scenario of a process run, from its world's command in ``commands.json``
    (``world SOURCE ... --set K=V``); None if there is none or it does not load."""
    try:
        cmds = json.loads((folder / "commands.json").read_text())
        world = cmds.get("world")
        argv = shlex.split(world) if isinstance(world, str) else list(world)
        source = argv[argv.index("world") + 1]
        sets = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--set"]
        return load_scenario(source, overrides=parse_overrides(sets))
    except Exception:  # a missing or foreign commands.json: the table alone
        return None


def load_run(folder: str | Path) -> Run:
    """A finished run from its folder (``sensornet run``: processes, ``--sim``, hosts): the
    per-scan table of ``results.parquet`` (else the peers' ``*.scans.msgpack`` parts) as the
    same objects :func:`simulate` gives, the ``peer-<name>.json`` summaries, and the scenario
    when the folder's ``commands.json`` names it; a one-line ``ValueError`` if it holds no
    table."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a run folder")
    table = folder / "results.parquet"
    if table.is_file():
        cols, meta = read_table(table)
    else:
        parts = sorted(folder.glob("*.scans.msgpack"))
        if not parts:
            raise ValueError(f"{folder}: no results.parquet nor per-peer *.scans.msgpack "
                             f"parts (is it a sensornet run folder?)")
        cols, meta = {name: [] for name in COLUMNS}, {}
        for p in parts:
            part, meta = read_part(p)
            for c in COLUMNS:
                cols[c].extend(part[c])
    names = sorted(set(cols["peer"]))
    summaries = {n: s for n, s in read_summaries(folder, names).items()}
    return Run(scenario=_folder_scenario(folder), twin=None, columns=_arrays(cols),
               meta=meta, summaries=summaries)
