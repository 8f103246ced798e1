"""The registry of studies: each seed's reproduction and each measurement, found by name.

A *study* is a package under ``sim/studies/`` whose ``study`` module exposes a
:class:`sim.studies.base.Study`
(load, run once, summarise, table, figures; campaign and report hooks). ``sensornet
experiment``, campaigns and reports look a study up here and never name one. Adding a study is
one module and one line in :data:`STUDIES` (or :func:`register` from a test or a plug-in,
:data:`PLUGINS_ENV` for the processes a campaign starts); ``tests/test_studies.py`` registers
a small one and runs it through ``experiment`` and a campaign.
"""

from __future__ import annotations

from typing import Any

from sensornet.sim import plugins

STUDIES: dict[str, str] = {
    "seed004": "sensornet.sim.studies.seed004.study:STUDY",
    "seed003": "sensornet.sim.studies.seed003.study:STUDY",
    "seed003-peers": "sensornet.sim.studies.seed003.peers_study:STUDY",
    "seed002": "sensornet.sim.studies.seed002.study:STUDY",
    "seed001": "sensornet.sim.studies.seed001.study:STUDY",
    "twin": "sensornet.sim.studies.network.study:TWIN",
    "real": "sensornet.sim.studies.network.study:REAL",
    "fusion-quality": "sensornet.sim.studies.fusion.study:STUDY",
    "lying": "sensornet.sim.studies.lying.study:STUDY",
    "experiment": "sensornet.sim.studies.seed000.study:STUDY",
}
"""Study name -> ``"module:attribute"``, in the order ``experiment`` asks them whether they
read a scenario (the last, ``experiment``, reads any). Modules are imported on first use."""

DEFAULT_SCENARIO = "seed000"
"""The built-in scenario a command or campaign plays when it names none."""

PLUGINS_ENV = "SENSORNET_STUDIES"
"""Comma-separated ``"name=module:attribute"`` entries added to :data:`STUDIES` (a plug-in's
studies, asked first; inherited by campaign workers)."""

_registered: dict[str, Any] = {}
"""Studies added with :func:`register` (asked first)."""
_loaded: dict[str, Any] = {}
"""Built-in and plug-in studies imported so far."""


def _plugins() -> dict[str, str]:
    return plugins.from_env(PLUGINS_ENV)


def names() -> tuple[str, ...]:
    """Every study name: registered and plug-ins first (they may claim a scenario before a
    built-in does), then the built-ins in :data:`STUDIES` order."""
    return tuple(dict.fromkeys([*_registered, *_plugins(), *STUDIES]))


def get(name: str):
    """The study called ``name``; :class:`KeyError` with the known names if there is none."""
    if name in _registered:
        return _registered[name]
    if name in _loaded:
        return _loaded[name]
    table = {**STUDIES, **_plugins()}
    if name not in table:
        raise KeyError(f"unknown study {name!r}; known: {', '.join(names())}")
    study = plugins.load(table[name])
    if getattr(study, "name", None) != name:
        raise TypeError(f"{table[name]} is not the study {name!r}")
    _loaded[name] = study
    return study


def for_source(source: str, overrides: dict | None = None):
    """The study ``sensornet experiment SOURCE`` runs: the first that claims it."""
    for name in names():
        study = get(name)
        if study.claims(source, overrides or {}):
            return study
    raise KeyError(f"no study reads {source!r}")


def runners() -> tuple[str, ...]:
    """The studies a campaign can run (those with a ``row`` hook)."""
    return tuple(n for n in names() if get(n).row is not None)


def for_report(kind: str):
    """The study whose ``report`` hook draws ``[[figures]] kind = KIND``."""
    for name in names():
        study = get(name)
        if study.report is not None and (study.report_kind or study.name) == kind:
            return study
    raise KeyError(f"no study draws figures of kind {kind!r}")


def report_kinds() -> tuple[str, ...]:
    """Every ``[[figures]]`` kind a study draws."""
    return tuple(s.report_kind or s.name for s in map(get, names()) if s.report is not None)


def main(name: str, argv: list[str] | None = None) -> int:
    """``python -m sensornet.sim.<module>`` of study ``name``: its ``command`` hook (the module's
    ``__main__`` block calls this, so the study module, which imports the computation, is
    loaded by name and the computation never imports its study)."""
    study = get(name)
    if study.command is None:
        raise KeyError(f"study {name!r} has no command line; use: sensornet experiment")
    return study.command(argv)


def register(study):
    """Add (or replace) a study in this process; returns it."""
    _registered[study.name] = study
    return study


def unregister(name: str) -> None:
    """Forget a study added with :func:`register` or loaded from a plug-in (tests)."""
    _registered.pop(name, None)
    _loaded.pop(name, None)
