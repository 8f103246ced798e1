"""A Python API for notebooks: build a scenario, run the twin, get tracks and metrics as arrays.

    from sensornet.api import scenario, simulate
    scn = scenario("seed000", {"scenario.num_scans": 30})
    run = simulate(scn, run=0)
    run.mean_ospa("s1", "fused")          # the summary's number
    run.columns["ospa"]                   # per-scan results as NumPy arrays (docs/results.md)
    run.tracks("s1")                      # {scan: (n, d) fused states}
    run.tracks_by_id("s1")                # {(origin, birth_scan, index): (scans, states)}
    run.to_pandas()                       # the same table as a DataFrame (needs pandas)

The run is the discrete-event twin (:func:`sim.run.twin.run_twin`): the peers' own code on a virtual
clock, the same bytes as the processes exchange. docs/notebooks/quickstart.ipynb is an example,
executed by tests/test_api.py.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sensornet.peers.scan_results import COLUMNS, LIST_COLUMNS
from sensornet.sim.run.twin import TwinResult, run_twin
from sensornet.sim.scenario import Scenario, builtin_scenarios, load_scenario

__all__ = ["Run", "builtin_scenarios", "scenario", "simulate"]


def scenario(source: str | Path, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """A built-in scenario by name (``"seed000"``..``"seed004"``) or a scenario file's path,
    with ``overrides`` as ``{"section.key": value}`` (the ``--set`` keys); raises
    :class:`sim.scenario.ScenarioError` with a one-line message on a bad key or value."""
    return load_scenario(source, overrides=dict(overrides or {}))


@dataclass
class Run:
    """One twin run: per-peer summaries and the per-scan results table."""

    scenario: Scenario
    twin: TwinResult
    columns: dict[str, np.ndarray | list]
    """The per-scan table (docs/results.md): NumPy arrays, the :data:`LIST_COLUMNS` lists."""
    meta: dict
    """``position_index``, ``cutoff`` and ``order`` of the table."""

    @property
    def peers(self) -> list[str]:
        return list(self.twin.peers)

    def summary(self, peer: str) -> dict:
        """The peer's summary, as a process writes it (``peer-<name>.json``)."""
        return self.twin.summary(peer)

    def mean_ospa(self, peer: str, which: str = "fused") -> float:
        """Mean OSPA of ``"local"`` or ``"fused"`` estimates (a missing output at the cut-off)."""
        return self.twin.mean_ospa(peer, which)

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
    arrays: dict[str, np.ndarray | list] = {
        c: (cols[c] if c in LIST_COLUMNS else np.asarray(cols[c])) for c in COLUMNS}
    return Run(scenario=scn, twin=result, columns=arrays, meta=meta)
