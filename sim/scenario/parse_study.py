"""Reading the seeds' own sections of a scenario: ``[manoeuvre]`` (seed 001's target,
:mod:`sim.scenario.manoeuvre`) and ``[pda]`` with its sub-tables (seed 003,
:mod:`sim.scenario.pda`; also seed 003's own file, :mod:`sim.scenario.seed003`). Their
declared options are read by :func:`sim.scenario.reading.read`; the lists and tables here
have their own checks, each a one-line error naming the key."""

from __future__ import annotations

from typing import Any

from sensornet.sim.scenario.manoeuvre import ManoeuvreSpec
from sensornet.sim.scenario.options import keys
from sensornet.sim.scenario.pda import (
    PdaClutter,
    PdaDetector,
    PdaFilters,
    PdaFuzzy,
    PdaSpec,
    PdaTarget,
)
from sensornet.sim.scenario.reading import read
from sensornet.sim.scenario.tables import Table, brief
from sensornet.tracking.fuzzy import FuzzySystem


def read_manoeuvre(t: Table) -> ManoeuvreSpec:
    """``[manoeuvre]``: legs as ``[[duration, turn rate], ...]`` (durations > 0)."""
    d = ManoeuvreSpec()
    segments = d.segments
    if t.has("segments"):
        raw = t.raw("segments")
        if not isinstance(raw, list) or not raw or not all(
                isinstance(g, list) and len(g) == 2 for g in raw):
            raise t.fail("segments", f"must be a list of [duration, turn rate] pairs, got "
                                     f"{brief(raw)}")
        segments = tuple((t._number("segments", g[0]), t._number("segments", g[1]))
                         for g in raw)
        if min(g[0] for g in segments) <= 0:
            raise t.fail("segments", f"must have durations > 0, got {brief(raw)}")
    return ManoeuvreSpec(**read(t, ManoeuvreSpec), segments=segments,
                         init_sigma=_nonnegative(t, "init_sigma", 3, d.init_sigma))


def read_pda(t: Table, n_sensors: int) -> PdaSpec:
    """``[pda]`` and its sub-tables (:mod:`sim.scenario.pda`); ``gate_probability`` lists one
    probability per sensor."""
    def sub(name: str, cls: type) -> Table:
        return Table(t.raw(name, {}), t.key(name), t.ctx, keys(cls))

    gates = ()
    if t.has("gate_probability"):
        gates = t.vector("gate_probability", n_sensors)
        if not all(0.0 < g <= 1.0 for g in gates):
            raise t.fail("gate_probability", f"must be probabilities in (0, 1], got "
                                             f"{brief(list(gates))}")
    return pda_parts(read(t, PdaSpec), gates, sub("target", PdaTarget),
                     sub("clutter", PdaClutter), sub("filters", PdaFilters),
                     sub("detector", PdaDetector), sub("fuzzy", PdaFuzzy))


def pda_parts(values: dict[str, Any], gates: tuple[float, ...], target: Table, clutter: Table,
              filters: Table, detector: Table, fuzzy: Table) -> PdaSpec:
    """A :class:`PdaSpec` of ``values`` (its own options), the sensors' gate probabilities and
    the tables of its sections, each read as declared (also seed 003's file, whose tables
    have the sections' keys: :mod:`sim.scenario.seed003`)."""
    fi = filters
    return PdaSpec(**values, gate_probability=gates,
                   target=PdaTarget(**read(target, PdaTarget), turn_scans=_turn_scans(target)),
                   clutter=PdaClutter(**read(clutter, PdaClutter)),
                   filters=PdaFilters(**read(fi, PdaFilters), transition=_stochastic(fi),
                                      initial_probs=_probabilities(fi, "initial_probs",
                                                                   (0.9, 0.1)),
                                      init_sigma=_nonnegative(fi, "init_sigma", 3,
                                                              (100.0, 50.0, 5.0))),
                   detector=PdaDetector(**read(detector, PdaDetector)), fuzzy=_fuzzy(fuzzy))


def _turn_scans(t: Table) -> tuple[int, int]:
    if not t.has("turn_scans"):
        return PdaTarget().turn_scans
    v = t.raw("turn_scans")
    if (not isinstance(v, list) or len(v) != 2 or not all(
            isinstance(x, int) and not isinstance(x, bool) for x in v) or not 1 <= v[0] <= v[1]):
        raise t.fail("turn_scans", f"must be [first, last] scans with 1 <= first <= last, got "
                                   f"{brief(v)}")
    return v[0], v[1]


def _probabilities(t: Table, name: str, default: tuple[float, ...]) -> tuple[float, ...]:
    """``len(default)`` probabilities summing to 1."""
    if not t.has(name):
        return default
    p = t.vector(name, len(default))
    if min(p) < 0 or abs(sum(p) - 1.0) > 1e-9:
        raise t.fail(name, f"must be {len(default)} probabilities summing to 1, got "
                           f"{brief(list(p))}")
    return p


def _nonnegative(t: Table, name: str, n: int, default: tuple[float, ...]) -> tuple[float, ...]:
    v = t.vector(name, n) if t.has(name) else default
    if min(v) < 0:
        raise t.fail(name, f"must be {n} numbers >= 0, got {brief(list(v))}")
    return v


def _stochastic(t: Table) -> tuple[tuple[float, ...], ...]:
    """``transition``: a 2 x 2 Markov matrix (rows of probabilities summing to 1)."""
    rows = t.raw("transition", None)
    if rows is None:
        return PdaFilters().transition
    if not isinstance(rows, list) or len(rows) != 2:
        raise t.fail("transition", f"must be a 2 x 2 list of lists, got {brief(rows)}")
    out = []
    for row in rows:
        r = tuple(t._number("transition", x, "a matrix of numbers")
                  for x in (row if isinstance(row, list) and len(row) == 2 else [None]))
        if len(r) != 2 or min(r) < 0 or abs(sum(r) - 1.0) > 1e-9:
            raise t.fail("transition", f"must have rows of 2 probabilities summing to 1, got "
                                       f"{brief(rows)}")
        out.append(r)
    return tuple(out)


def _fuzzy(t: Table) -> PdaFuzzy:
    """``[pda.fuzzy]``: terms as ``NAME = [centre, width]`` (inputs) or ``NAME = centre``
    (outputs), rules naming them; checked by building the fuzzy system."""
    d = PdaFuzzy()
    inputs = Table(t.raw("inputs", {}), t.key("inputs"), t.ctx, ["nis", "dl"])

    def terms(table: Table, name: str, default):
        raw = table.raw(name, None)
        if raw is None:
            return default
        sub = Table(raw, table.key(name), t.ctx, list(raw) if isinstance(raw, dict) else [])
        return tuple((k, *sub.vector(k, 2)) for k in raw)

    rules = d.rules
    if t.has("rules"):
        raw = t.raw("rules")
        if not isinstance(raw, list) or not raw or not all(
                isinstance(r, list) and len(r) == 3 and all(isinstance(x, str) for x in r)
                for r in raw):
            raise t.fail("rules", f"must be a list of [nis term, D term, output term], got "
                                  f"{brief(raw)}")
        rules = tuple((r[0], r[1], r[2]) for r in raw)
    outputs = d.outputs
    if t.has("outputs"):
        o = Table(t.raw("outputs"), t.key("outputs"), t.ctx, list(t.raw("outputs"))
                  if isinstance(t.raw("outputs"), dict) else [])
        outputs = tuple((k, o.number(k)) for k in o.data)
    spec = PdaFuzzy(**read(t, PdaFuzzy), rules=rules, nis=terms(inputs, "nis", d.nis),
                    dl=terms(inputs, "dl", d.dl), outputs=outputs)
    try:
        FuzzySystem.from_config(spec.config())
    except ValueError as exc:
        raise t.ctx.fail(t.path, f"'{t.path}': {exc}") from None
    return spec
