"""The registry of peer kinds: what a peer runs, found by the name in ``network.filter``.

A *kind* is one module under ``sim/kinds/`` that exposes a :class:`PeerKind`: how a peer of
that kind is built from a scenario (its local estimator and fuser, see
:mod:`peers.contracts`), which fusion rules it takes, how it takes part in the consensus, how
Rerun draws it, and, for scenarios that draw their own runs, how the world does. The loader,
the peer builder (:mod:`sim.run.peers`), the world, the launcher, the twin, recording and replay,
secure mode, faults and campaigns look a kind up here and never name one.

Adding a kind is one module and one line in :data:`KINDS` (or :func:`register` from a
test or a plug-in); ``tests/test_kinds.py`` registers a small one and runs it through
``run``, ``run --sim`` and ``--record`` + ``replay``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sensornet.sim import plugins

Scenario = Any
"""A :class:`sim.scenario.Scenario` (the registry imports nothing of the project, so the loader
can ask it for names without an import cycle)."""
Parts = tuple[Any, Any]
"""``(estimator, fuser)``: a :class:`peers.contracts.LocalEstimator` and a
:class:`peers.contracts.Fuser`."""

KINDS: dict[str, str] = {
    "gmphd": "sensornet.sim.kinds.gmphd:GMPHD",
    "et-gmphd": "sensornet.sim.kinds.extended:ET_GMPHD",
    "imm-pf": "sensornet.sim.kinds.imm:IMM_PF",
    "imm-ekf": "sensornet.sim.kinds.imm:IMM_EKF",
    "flooding": "sensornet.sim.kinds.flooding:FLOODING",
    "pda": "sensornet.sim.kinds.pda:PDA",
    "lmb": "sensornet.sim.kinds.lmb:LMB",
}
"""Kind name (``network.filter``) -> ``"module:attribute"`` of its :class:`PeerKind`. The
module is imported when the kind is first used, so the loader can list the names without
loading every estimator."""


@dataclass(frozen=True)
class View:
    """How Rerun lays out a run of this kind (:class:`peers.rerun_sink.RerunSink`)."""

    single_target: bool = False
    """One target: a panel that follows it."""
    imm: bool = False
    """Model probabilities and a particle/local-estimate legend (IMM kinds)."""

    def layout(self) -> dict[str, bool]:
        return {"single_target": self.single_target, "imm": self.imm}


@dataclass(frozen=True)
class PeerKind:
    """One peer kind: everything generic code needs to know about it."""

    name: str
    """``network.filter`` value."""
    summary: str
    """One line for ``sensornet scenario`` and error messages."""
    build: Callable[[Scenario, str, int], Parts]
    """``(scenario, sensor name, Monte Carlo run) -> (estimator, fuser)``."""
    rules: tuple[str, ...]
    """The ``fusion.rule`` values it takes (checked at load)."""
    same_scan: bool = False
    """Fuses only estimates of the scan at hand (no out-of-sequence prediction: ``max_age``
    0, ``drop-late``, no feedback), as single-target and flooding peers do."""
    round_deadlines: bool = False
    """Each consensus round has its own deadline (flooding: a round forwards scans)."""
    trust: bool = True
    """The neighbour consistency test (:mod:`peers.trust`) applies: the payload is a density."""
    view: View = field(default_factory=View)
    """Its Rerun layout."""
    check: Callable[[Scenario], str | None] | None = None
    """Extra load-time check: ``(scenario) -> "key: message"`` or None when fine."""
    requires: dict[str, Any] = field(default_factory=dict)
    """Notes for the docs: sections of the scenario it reads (informational)."""


_registered: dict[str, PeerKind] = {}


PLUGINS_ENV = "SENSORNET_KINDS"
"""Comma-separated ``"name=module:attribute"`` entries added to :data:`KINDS` (a plug-in's
kinds; inherited by every process a run starts)."""


def _plugins() -> dict[str, str]:
    return plugins.from_env(PLUGINS_ENV)


def _table() -> dict[str, str]:
    return {**KINDS, **_plugins()}


def names() -> tuple[str, ...]:
    """Every kind name, registry order (then plug-ins)."""
    return tuple(dict.fromkeys([*_table(), *_registered]))


def kind(name: str) -> PeerKind:
    """The kind called ``name``; :class:`KeyError` with the known names if there is none."""
    if name in _registered:
        return _registered[name]
    table = _table()
    if name not in table:
        raise KeyError(f"unknown peer kind {name!r}; known: {', '.join(names())}")
    k = plugins.load(table[name])
    if not isinstance(k, PeerKind) or k.name != name:
        raise TypeError(f"{table[name]} is not the PeerKind {name!r}")
    _registered[name] = k
    return k


def kind_of(scn: Scenario) -> PeerKind:
    """The kind of the scenario's peers (``network.filter``)."""
    return kind(scn.network.filter)


def register(k: PeerKind) -> PeerKind:
    """Add (or replace) a kind in this process; returns it. Processes a run starts find a
    plug-in kind through :data:`PLUGINS_ENV` instead."""
    _registered[k.name] = k
    return k


def unregister(name: str) -> None:
    """Remove a kind added with :func:`register` (tests)."""
    _registered.pop(name, None)
