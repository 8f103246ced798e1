"""A campaign's plan: its cells (overrides and keys), its tasks, and the checks of its file."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sensornet.sim import studies
from sensornet.sim.campaign.runners import Task
from sensornet.sim.campaign.sweep import _toml
from sensornet.sim.scenario import ScenarioError


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
    campaign's (a study's cells run on several networks: :mod:`sim.studies.fusion.quality`)."""
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
    return v if isinstance(v, str) else _toml(v)


def _check(cond: bool, label: str, problem: str) -> None:
    if not cond:
        raise CampaignError(f"{label}: {problem}")
