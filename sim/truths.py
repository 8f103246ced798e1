"""The registry of truth models: how the world draws a scenario's true targets (``truth``).

A truth model gives the true states per scan (:class:`sim.world.Truth`); one that also draws
its sensors' returns itself (a study whose published numbers come from its own draws) gives
whole runs. The world (:mod:`sim.world`), the peers' scoring (:mod:`sim.run.peers`) and the
single-target kinds' initialisation look a model up here by name and never name one.
Adding a model is one function and one line in :data:`TRUTHS`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

Scenario = Any
"""A :class:`sim.scenario.Scenario` (the registry imports nothing of the project: no cycle)."""
Truth = Any
"""A :class:`sim.world.Truth`."""
Array = Any
"""A NumPy array."""

TRUTHS: dict[str, str] = {
    "straight": "sensornet.sim.world:STRAIGHT",
    "seed001": "sensornet.sim.studies.truth_models:SEED001",
    "seed003": "sensornet.sim.studies.truth_models:SEED003",
    "recorded": "sensornet.sim.traffic.recorded:RECORDED",
}
"""``truth`` value -> ``"module:attribute"`` of its :class:`TruthModel`."""


@dataclass(frozen=True)
class TruthModel:
    name: str
    summary: str
    truth: Callable[[Scenario, Any], Truth]
    """``(scenario, the run's truth stream) -> Truth``."""
    initial: Callable[[Scenario], tuple[Array, Array]] | None = None
    """``scenario -> (x0, P0)``: the known initial state and the spread single-target peers
    start from (one-target models)."""
    run: Callable[[Scenario, int], tuple[Truth, list[list[Array]]]] | None = None
    """``(scenario, run) -> (truth, scans)`` when the model draws the sensors' returns too."""
    ages: Callable[[Scenario, int], list[list[Array]]] | None = None
    """``(scenario, run) -> ages``: ``ages[s][k-1]`` ``(m,)`` how long before scan ``k``'s
    time each row of ``run``'s ``scans[s][k-1]`` was made (s), when the model knows it."""


_loaded: dict[str, TruthModel] = {}


def names() -> tuple[str, ...]:
    return tuple(TRUTHS)


def truth_model(name: str) -> TruthModel:
    """The model called ``name``; :class:`KeyError` naming the known ones if there is none."""
    if name not in _loaded:
        if name not in TRUTHS:
            raise KeyError(f"unknown truth model {name!r}; known: {', '.join(TRUTHS)}")
        module, attr = TRUTHS[name].split(":")
        _loaded[name] = getattr(importlib.import_module(module), attr)
    return _loaded[name]
