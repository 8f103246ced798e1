"""A section's options read from their declarations (:func:`sim.scenario.options.option`:
type, default, choices, bounds, old name), for :mod:`sim.scenario.parse` and the study
sections' readers (:mod:`sim.scenario.parse_study`, :mod:`sim.scenario.seed004`)."""

from __future__ import annotations

import dataclasses
from typing import Any

from sensornet.sim.scenario.options import Meta, key_of, meta, options, required
from sensornet.sim.scenario.tables import REQUIRED, Table


def read(t: Table, cls: type, prefix: str = "") -> dict[str, Any]:
    """``cls``'s options whose key is ``prefix.KEY`` (``KEY`` with no prefix), read from table
    ``t`` as declared (:func:`sim.scenario.options.option`: type, default, choices, bounds,
    old name); the ``custom`` ones are left to their section's code. Field name -> value."""
    out = {}
    for f, m in options(cls):
        k = key_of(f)
        if prefix:
            if not k.startswith(prefix + "."):
                continue
            k = k[len(prefix) + 1:]
        if m.custom is None and "." not in k:
            out[f.name] = _value(t, t.renamed(m.was, k) if m.was else k, f, m)
    return out


def value(t: Table, cls: type, name: str) -> Any:
    """Option ``name`` of ``cls`` read from ``t`` as declared (for a section's own code)."""
    f = next(f for f in dataclasses.fields(cls) if f.name == name)
    return _value(t, key_of(f).rpartition(".")[2], f, meta(f))


def _value(t: Table, k: str, f: dataclasses.Field, m: Meta) -> Any:
    default = REQUIRED if required(f) else f.default
    kind = f.type
    if kind == "float | None":
        if not t.has(k):
            return default
        kind = "float"
    if kind == "bool":
        v = t.flag(k, default)
    elif kind == "int":
        v = t.integer(k, default)
    elif kind == "float":
        v = t.number(k, default)
    elif kind == "str":
        v = t.choice(k, m.values(), default) if m.choices else t.text(k, default)
    elif kind == "tuple[float, float]":
        return t.position(k) if t.has(k) or default is REQUIRED else default
    else:
        raise TypeError(f"option {t.key(k)!r} of type {kind} needs custom= and its own reader")
    if m.check is not None and (problem := m.check.problem(v)) is not None:
        raise t.fail(k, problem)
    return v
