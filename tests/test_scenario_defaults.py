"""Each scenario option is declared once, in its field (issue 37): a file without a key loads
the field's declared default, the parser, the accepted keys, the command line's choices and
docs/scenario.md all come from the declarations."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import pytest
from sensornet.sim.kinds import names as kind_names
from sensornet.sim.scenario import (
    BirthComponent,
    BirthSpec,
    ClusteringSpec,
    ExtendedSpec,
    FilterSpec,
    FusionSpec,
    MetricsSpec,
    NetworkSpec,
    PdaSpec,
    Scenario,
    ScenarioError,
    SensorSpec,
    TargetSpec,
    load_document,
    load_scenario,
)
from sensornet.sim.scenario.docs import render
from sensornet.sim.scenario.options import meta, options, required

from sensornet.cli.parser import build_parser

ROOT = Path(__file__).resolve().parents[1]
MINIMAL = {"scenario": {"num_scans": 3, "region": [[-100.0, 100.0], [-100.0, 100.0]]},
           "sensors": [{"name": "s1", "kind": "linear", "position": [0.0, 0.0]},
                       {"name": "s2", "kind": "linear", "position": [50.0, 0.0]}]}
"""Only the required keys (two sensors, so "the first sensor" is a choice)."""
SECTIONS = {"birth": BirthSpec, "filter": FilterSpec, "fusion": FusionSpec,
            "metrics": MetricsSpec, "network": NetworkSpec, "extended": ExtendedSpec,
            "clustering": ClusteringSpec, "pda": PdaSpec}
"""Scenario attribute -> the dataclass of its table."""
DERIVED = {("fusion", "fusing_sensor"): "s1"}
"""Defaults that depend on the file (declared ``custom``): what the minimal file loads."""
CLASSES = (Scenario, TargetSpec, SensorSpec, BirthComponent, *SECTIONS.values())


def _load(extra: dict | None = None) -> Scenario:
    doc = copy.deepcopy(MINIMAL)
    doc.update(copy.deepcopy(extra or {}))
    return load_document(doc, "minimal.toml", name="minimal")


def _cases():
    for f, _ in options(Scenario):
        if not required(f) and f.name not in SECTIONS:
            yield pytest.param(None, f.name, f.default, id=f.name)
    for section, cls in SECTIONS.items():
        for f, _ in options(cls):
            yield pytest.param(section, f.name, DERIVED.get((section, f.name), f.default),
                               id=f"{section}.{f.name}")
    for f, _ in options(SensorSpec):
        if not required(f):
            yield pytest.param("sensors[0]", f.name, f.default, id=f"sensors.{f.name}")


@pytest.mark.parametrize("section, name, expected", list(_cases()))
def test_a_file_without_the_key_loads_the_declared_default(section, name, expected):
    # the optional tables present but empty, so their defaults load too
    scn = _load({"extended": {}, "clustering": {}, "pda": {}})
    holder = scn if section is None else (scn.sensors[0] if section == "sensors[0]"
                                          else getattr(scn, section))
    assert getattr(holder, name) == expected


def test_the_python_defaults_are_the_loaded_ones():
    """``FusionSpec()`` (and every section built in Python) is what a file loads: the API gave
    ``rule = "gci"`` while files got ``"hybrid"``."""
    scn = _load()
    assert FusionSpec().rule == scn.fusion.rule == "hybrid"
    assert dataclasses.replace(scn.fusion, fusing_sensor="") == FusionSpec()
    for section in ("birth", "filter", "metrics", "network", "clustering"):
        assert getattr(scn, section) == SECTIONS[section](), section
    assert (scn.extended, scn.pda, scn.faults, scn.security, scn.targets) == (
        None, None, None, None, ())
    assert scn.name == "minimal"  # the file's name (custom: not a declared default)


def test_every_field_is_declared_as_an_option():
    bare = [f"{cls.__name__}.{f.name}" for cls in CLASSES for f in dataclasses.fields(cls)
            if meta(f) is None]
    assert bare == ["Scenario.source"]  # informational, not a key


@pytest.mark.parametrize("path", ["scenario.num_scans", "scenario.region", "sensors[0].name",
                                  "sensors[0].kind", "sensors[0].position"])
def test_a_required_key_missing_is_a_one_line_error_naming_it(path):
    doc = copy.deepcopy(MINIMAL)
    table, _, key = path.partition(".")
    holder = doc["sensors"][0] if table == "sensors[0]" else doc[table]
    del holder[key]
    with pytest.raises(ScenarioError, match=f"missing required key '{path}'".replace(
            "[", r"\[").replace("]", r"\]")) as info:
        load_document(doc, "minimal.toml")
    assert "\n" not in str(info.value)


def test_an_undeclared_key_is_refused_with_the_declared_one_suggested():
    with pytest.raises(ScenarioError, match=r"unknown key 'network\.omgea' \(did you mean "
                                            r"'network\.omega'\?\)"):
        _load({"network": {"omgea": "uniform"}})


def test_the_two_omegas_have_two_names_and_the_old_one_still_loads():
    scn = _load({"fusion": {"fusing_omega": "det"}, "network": {"omega": "uniform"}})
    assert (scn.fusion.fusing_omega, scn.network.omega) == ("det", "uniform")
    with pytest.warns(FutureWarning, match=r"'fusion\.omega' is now 'fusion\.fusing_omega'"):
        old = _load({"fusion": {"omega": "metropolis"}})
    assert old.fusion.fusing_omega == "metropolis" and old.network.omega == "metropolis"
    with pytest.raises(ScenarioError, match=r"'fusion\.omega' is the old name"):
        _load({"fusion": {"omega": "det", "fusing_omega": "det"}})
    with pytest.raises(ScenarioError, match="fusion.omega"):  # checked like the new key
        with pytest.warns(FutureWarning):
            _load({"fusion": {"omega": "median"}})


def test_the_bounds_are_the_declared_ones():
    for key, bad, good in [("network.deadline", 1.5, 1.0), ("network.rounds", 17, 16),
                           ("metrics.ospa_order", 0.5, 1.0), ("filter.gate", 0.0, 9.21),
                           ("sensors[0].detection_probability", 1.01, 1.0)]:
        with pytest.raises(ScenarioError, match=key.replace(".", r"\.").replace(
                "[", r"\[").replace("]", r"\]")):
            load_scenario("seed000", {key: bad})
        load_scenario("seed000", {key: good})


def _choices(command: str) -> dict[str, tuple]:
    sub = build_parser()._subparsers._group_actions[0].choices[command]
    return {a.option_strings[0]: tuple(a.choices) for a in sub._actions
            if a.choices and a.option_strings}


def _declared(cls: type, name: str) -> tuple[str, ...]:
    return next(m for f, m in options(cls) if f.name == name).values()


def test_the_command_line_offers_the_declared_choices():
    peer = _choices("peer")
    assert peer["--filter"] == kind_names() == _declared(NetworkSpec, "filter")
    assert len(peer["--filter"]) >= 6  # every shipped kind, not 3 of them
    assert peer["--fusion"] == _declared(FusionSpec, "rule")
    assert peer["--omega"] == _declared(NetworkSpec, "omega")
    assert peer["--policy"] == _declared(NetworkSpec, "policy")
    assert set(_choices("experiment")["--fusion"]) < set(_declared(FusionSpec, "rule"))
    assert _choices("experiment")["--birth"] == (*_declared(BirthSpec, "model"), "both")


def test_docs_scenario_md_is_generated_from_the_declarations():
    """Regenerate with ``python -m sensornet.sim.scenario.docs > docs/scenario.md``."""
    assert (ROOT / "docs" / "scenario.md").read_text(encoding="utf-8") == render()
    for cls in CLASSES[1:]:
        for f, _ in options(cls):
            if cls is not BirthSpec or "." not in f.name:
                assert f"`{(meta(f).key or f.name)}`" in render(), f"{cls.__name__}.{f.name}"
