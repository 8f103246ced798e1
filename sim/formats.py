"""Scenario files in a study's own layout (``[scenario] study = "NAME"``): a study file states
the study's parameters and the network scenario is derived from them (seed 003: the sensors'
clutter rates and the region from its clutter settings, its tables as the typed ``[pda]``
sections; seed 004: sensors and a graph from positions and a radius, targets and births from
the start states, its keys declared in :mod:`sim.scenario.seed004`). This is the registry of
those derivations by study name; adding one is a function and a line in :data:`FORMATS`, and
the loader (:mod:`sim.scenario`) never names a study."""

from __future__ import annotations

import importlib

FORMATS: dict[str, str] = {
    "seed003": "sensornet.sim.studies.seed003.network:network_document",
    "seed004": "sensornet.sim.studies.seed004.scenario:network_document",
}
"""``study`` value -> ``"module:function"`` taking ``(document, label)``."""


def adapt_document(study: str, doc: dict, label: str) -> dict:
    """The network-scenario document of a study-format ``doc``; :class:`KeyError` if ``study``
    has no adapter (the loader reports it in one line)."""
    if study not in FORMATS:
        raise KeyError(f"{label}: [scenario] study {study!r} has no network format "
                       f"(known: {', '.join(FORMATS)})")
    module, attr = FORMATS[study].split(":")
    return getattr(importlib.import_module(module), attr)(doc, label)
