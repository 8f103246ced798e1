"""Scenario files in a study's own format (``[scenario] study = "NAME"``): the adapters that turn
one into the network scenario's document, by study name. Adding a format is one function and
one line in :data:`FORMATS`; the loader (:mod:`sim.scenario`) never names a study."""

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
