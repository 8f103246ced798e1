"""Seed 003's file (``[scenario] study = "seed003"``, ``sim/scenarios/seed003.toml``), read with
the declarations of the ``[pda]`` sections (:mod:`sim.scenario.pda`), whose keys its tables
share: ``[scenario]`` holds the run's keys and the target's (``[pda.target]``), each
``[[sensors]]`` entry a sensor's noise, ``Pd`` and gate probability, ``[clutter]``,
``[filters]``, ``[detector]`` and ``[fuzzy]`` are ``[pda.*]``'s, ``[metrics]`` the loss rule.
A mistake is the scenario's one-line ``ScenarioError`` naming the file's key; the network
scenario is derived from the file by :mod:`sim.studies.seed003.network`."""

from __future__ import annotations

from sensornet.sim.scenario.options import keys
from sensornet.sim.scenario.parse_study import pda_parts
from sensornet.sim.scenario.pda import (
    PdaClutter,
    PdaDetector,
    PdaFilters,
    PdaFuzzy,
    PdaSpec,
    PdaTarget,
)
from sensornet.sim.scenario.reading import value
from sensornet.sim.scenario.tables import Context, Table

TABLES = ("scenario", "sensors", "clutter", "filters", "detector", "fuzzy", "metrics")
"""The file's tables (``[network]``, ``[faults]``, ``[security]``, ``[pda]`` and ``[fusion]``
are the network scenario's own, passed to it)."""
RUN_KEYS = ("name", "study", "seed", "scan_period", "num_scans")
SENSOR_KEYS = ("name", "sigma", "detection_probability", "gate_probability")
TEXT = ("`sim/scenarios/seed003.toml` (`[scenario] study = \"seed003\"`) is read with the "
        "declarations above (`sim.scenario.seed003`): its `[scenario]` has `seed`, "
        "`scan_period` and `num_scans` (required) and the keys of `[pda.target]`; each "
        "`[[sensors]]` entry `name`, `sigma` (m, per axis), `detection_probability` and "
        "`gate_probability`; `[clutter]`, `[filters]`, `[detector]` and `[fuzzy]` are "
        "`[pda.clutter]`, ... ; `[metrics]` has `loss_bound` and `loss_scans`. The network "
        "scenario is derived from it (`sim/studies/seed003/network.py` `network_document`: one "
        "linear sensor and PDA peer per entry, region clutter of the same density, its "
        "`[network]`, `[pda]`, `[faults]`, `[security]` and `[fusion]` taken as they are).")
"""What docs/scenario.md says of the file."""


def read_seed003(doc: dict, label: str) -> PdaSpec:
    """The ``[pda]`` settings of seed-003 document ``doc`` (the network scenario's own tables
    left out by the caller), every key checked as declared; the run's keys are checked too."""
    ctx = Context(label)
    top = Table(doc, "", ctx, TABLES)
    sc = Table(top.raw("scenario"), "scenario", ctx, [*RUN_KEYS, *keys(PdaTarget)])
    sc.integer("seed", minimum=0)
    sc.number("scan_period", positive=True)
    sc.integer("num_scans", minimum=1)
    gates = []
    for i, entry in enumerate(top.tables("sensors")):
        s = Table(entry, f"sensors[{i}]", ctx, SENSOR_KEYS)
        s.text("name")
        s.number("sigma", positive=True)
        s.number("detection_probability", probability=True)
        gates.append(s.number("gate_probability", probability=True))
        if gates[-1] == 0.0:
            raise s.fail("gate_probability", "must be > 0, got 0")
    me = Table(top.raw("metrics", {}), "metrics", ctx, ["loss_bound", "loss_scans"])

    def sub(name: str, cls: type) -> Table:
        return Table(top.raw(name, {}), name, ctx, keys(cls))

    own = {"loss_bound": value(me, PdaSpec, "loss_bound"),
           "loss_scans": value(me, PdaSpec, "loss_scans")}
    return pda_parts(own, tuple(gates), sc, sub("clutter", PdaClutter),
                     sub("filters", PdaFilters), sub("detector", PdaDetector),
                     sub("fuzzy", PdaFuzzy))
