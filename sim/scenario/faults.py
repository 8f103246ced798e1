"""The ``[faults]`` table: the link-fault plan, resolved per link."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from sensornet.peers.faultplan import (
    Constant,
    Delay,
    Exponential,
    FaultPlan,
    LinkLayer,
    MultiStep,
    OneStep,
    PlanConflict,
    Scans,
    ShortDelay,
    Uniform,
)
from sensornet.sim.scenario.model import DELAY_KINDS, FAULT_KEYS, ScenarioError
from sensornet.sim.scenario.tables import Context, Table, brief

# --------------------------------------------------------------------------------------------
# [faults]: the link-fault plan
# --------------------------------------------------------------------------------------------


def parse_faults(table: Mapping[str, Any], interval: float, peers: Iterable[str],
                 label: str = "[faults]") -> FaultPlan:
    """The fault plan of a ``[faults]`` table, checked like a scenario file's (for code that
    builds plans without a file). ``interval`` is the scan interval (s) delays in scans are
    multiples of; ``peers`` the peer names. Errors are :class:`ScenarioError` naming the key
    (``faults.links[0].loss``), prefixed by ``label``.
    """
    if not (isinstance(interval, int | float) and math.isfinite(interval) and interval > 0):
        raise ScenarioError(f"{label}: scan interval must be > 0 s, got {interval!r}")
    ctx = Context(label)
    return _faults(Table(dict(table), "faults", ctx, ["default", "peers", "links"]),
                   list(peers), float(interval))


def _faults(f: Table, names: list[str], interval: float) -> FaultPlan:
    """``faults.default``, ``faults.peers.<name>``, ``faults.links[i]`` -> the resolved plan."""
    ctx = f.ctx
    default = _fault_layer(Table(f.raw("default", {}), "faults.default", ctx, FAULT_KEYS),
                           interval)
    peers: dict[str, LinkLayer] = {}
    raw = f.raw("peers", {})
    for name in raw if isinstance(raw, dict) else ():
        if name not in names:
            raise ctx.fail(f"faults.peers.{name}", f"key 'faults.peers.{name}' names no peer "
                                                   f"(peers: {', '.join(names)})")
    raw_peers = Table(raw, "faults.peers", ctx, names)
    for name in raw_peers.data:
        peers[name] = _fault_layer(
            Table(raw_peers.raw(name), raw_peers.key(name), ctx, FAULT_KEYS), interval)
    links: dict[tuple[str, str], LinkLayer] = {}
    first: dict[tuple[str, str], str] = {}
    for i, entry in enumerate(f.tables("links", [])):
        t = Table(entry, f"faults.links[{i}]", ctx, ["from", "to", *FAULT_KEYS])
        pair = (t.choice("from", names), t.choice("to", names))
        if pair[0] == pair[1]:
            raise t.fail("to", f"is {pair[1]!r} like 'from': a link joins two different peers")
        if pair in links:
            raise ctx.fail(t.path, f"key '{t.path}' repeats the link {pair[0]} -> {pair[1]} "
                                   f"of '{first[pair]}'")
        links[pair], first[pair] = _fault_layer(t, interval), t.path
    try:
        return FaultPlan.layered(names, interval, default, peers, links)
    except PlanConflict as exc:
        raise ctx.fail(exc.key, str(exc)) from None


def _fault_layer(t: Table, interval: float) -> LinkLayer:
    """One ``default`` / ``peers.<name>`` / ``links[i]`` table: the keys it sets."""
    kw: dict[str, Any] = {}
    for name in ("loss", "duplicate", "reorder"):
        if t.has(name):
            kw[name] = t.number(name, probability=True)
    for name in ("delay", "reorder_delay"):
        if t.has(name):
            kw[name] = _delay(t, name, interval)
    if t.has("partitions"):
        kw["partitions"] = _partitions(t, "partitions")
    return LinkLayer(**kw, where=t.path)


def _delay(t: Table, name: str, interval: float) -> Delay:
    """Seconds (a number), a parameterless kind (``"short"``, ``"one-step"``) or a table
    ``{kind = ..., <its parameters>}`` (:data:`DELAY_KINDS`)."""
    v = t.raw(name)
    if isinstance(v, bool) or not isinstance(v, int | float | str | dict):
        raise t.fail(name, f"must be seconds, a delay kind or a table with 'kind', "
                           f"got {brief(v)}")
    if isinstance(v, int | float):
        if not (math.isfinite(v) and v >= 0):
            raise t.fail(name, f"must be a delay >= 0 s, got {brief(v)}")
        return Constant(float(v))
    path = t.key(name)
    if isinstance(v, str):
        kind = t.choice(name, DELAY_KINDS)
        if DELAY_KINDS[kind]:
            raise t.fail(name, f"is {kind!r}, which needs a table: {{kind = \"{kind}\", "
                               + ", ".join(f"{p} = ..." for p in DELAY_KINDS[kind]) + "}")
        d = Table({"kind": kind}, path, t.ctx, ["kind"])
    else:
        kind = v.get("kind")
        params = DELAY_KINDS[kind] if isinstance(kind, str) and kind in DELAY_KINDS else sorted(
            {p for ps in DELAY_KINDS.values() for p in ps})
        d = Table(v, path, t.ctx, ["kind", *params])
        kind = d.choice("kind", DELAY_KINDS)
    if kind == "constant":
        return Constant(d.number("value", minimum=0.0))
    if kind == "uniform":
        low, high = d.number("low", minimum=0.0), d.number("high", minimum=0.0)
        if high < low:
            raise d.fail("high", f"must be >= low ({low:g}), got {high:g}")
        return Uniform(low, high)
    if kind == "exponential":
        return Exponential(d.number("mean", positive=True))
    if kind == "scans":
        low, high = d.integer("low", minimum=0), d.integer("high", minimum=0)
        if high < low:
            raise d.fail("high", f"must be >= low ({low}), got {high}")
        return Scans(low, high, interval)
    if kind == "short":
        return ShortDelay(interval)
    if kind == "one-step":
        return OneStep(interval)
    return MultiStep(d.integer("max_steps", minimum=1), interval)


def _partitions(t: Table, name: str) -> tuple[tuple[float, float], ...]:
    """``[[start, end], ...]``: run-clock seconds, ``0 <= start < end``."""
    raw = t.raw(name)
    if not isinstance(raw, list):
        raise t.fail(name, f"must be a list of [start, end] pairs (s), got {brief(raw)}")
    out = []
    for i, part in enumerate(raw):
        where = f"{t.key(name)}[{i}]"
        ok = isinstance(part, list) and len(part) == 2 and all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
            for x in part)
        if not ok:
            raise t.ctx.fail(where, f"key '{where}' must be [start, end] (s), got {brief(part)}")
        start, end = float(part[0]), float(part[1])
        if start < 0:
            raise t.ctx.fail(where, f"key '{where}' starts before 0 s: {brief(part)}")
        if not end > start:
            raise t.ctx.fail(where, f"key '{where}' must end after it starts, got {brief(part)}")
        out.append((start, end))
    return tuple(out)
