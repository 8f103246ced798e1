"""Scenario files: the built-in loads, overrides apply, every bad input is a one-line error."""

from __future__ import annotations

import dataclasses
import tomllib

import numpy as np
import pytest
from sensornet.sim.scenario import (
    Scenario,
    ScenarioError,
    builtin_scenarios,
    load_scenario,
    parse_overrides,
    scenario_text,
    with_birth_model,
)
from sensornet.sim.world.build import birth_mixture, clutter_intensity, make_filter, sensor_params


@pytest.fixture(scope="module")
def seed000() -> Scenario:
    return load_scenario("seed000")


def test_builtin_loads(seed000: Scenario) -> None:
    assert "seed000" in builtin_scenarios()
    assert seed000.name == "seed000"
    assert seed000.num_scans == 100
    assert seed000.region == ((-1000.0, 1000.0), (-1000.0, 1000.0))
    assert [(t.birth_scan, t.death_scan) for t in seed000.targets] == [
        (1, 100), (20, 60), (40, 80), (40, 80)]
    assert seed000.targets[2].start == (450.0, -209.0)
    assert seed000.sensor_names == ["s1", "s2", "s3"]
    assert seed000.sensor("s1").position == (-800.0, -1000.0)
    assert seed000.fusion.fusing_sensor == "s2"
    assert seed000.filter.gate is None
    assert seed000.birth.model == "truth"  # births at the true birth points (README: results)
    assert len(seed000.birth.paper) == 2
    hash(seed000)  # immutable all the way down


def test_builtin_by_path_and_text_agree(seed000: Scenario, tmp_path) -> None:
    text = scenario_text("seed000")
    assert tomllib.loads(text)["scenario"]["name"] == "seed000"
    copy = tmp_path / "mine.toml"
    copy.write_text(text)
    assert dataclasses.replace(load_scenario(copy), source="") == dataclasses.replace(
        seed000, source="")


def test_overrides(seed000: Scenario) -> None:
    scn = load_scenario("seed000", {
        "filter.gate": 9.21,
        "fusion": {"rule": "aa"},
        "sensors.*.clutter_rate": 20,
        "sensors.s2.sigma_r": 5.0,
        "sensors[0].detection_probability": 0.9,
        "birth.model": "truth",
    })
    assert scn.filter.gate == 9.21
    assert scn.fusion.rule == "aa"
    assert [s.clutter_rate for s in scn.sensors] == [20.0] * 3
    assert scn.sensor("s2").sigma_r == 5.0
    assert scn.sensor("s1").detection_probability == 0.9
    assert scn.birth.model == "truth"
    assert seed000.filter.gate is None  # the built-in is untouched


def test_parse_overrides() -> None:
    assert parse_overrides(["filter.gate=9.21", "fusion.rule=aa", "fusion.level2_pruning=false",
                            'fusion.fusing_sensor="s1"']) == {
        "filter.gate": 9.21, "fusion.rule": "aa", "fusion.level2_pruning": False,
        "fusion.fusing_sensor": "s1"}
    with pytest.raises(ScenarioError, match="KEY=VALUE"):
        parse_overrides(["filter.gate"])


def test_bad_override_is_reported_as_override() -> None:
    with pytest.raises(ScenarioError) as err:
        load_scenario("seed000", {"filter.merge_treshold": 4.0})
    msg = str(err.value)
    assert "overrides" in msg and "'filter.merge_treshold'" in msg
    assert "'filter.merge_threshold'" in msg  # the suggestion
    with pytest.raises(ScenarioError, match="sensors"):
        load_scenario("seed000", {"sensors[7].sigma_r": 1.0})


def test_with_birth_model(seed000: Scenario) -> None:
    paper = with_birth_model(seed000, "paper")
    assert paper.birth.model == "paper" and seed000.birth.model == "truth"
    assert len(birth_mixture(seed000)) == 4
    np.testing.assert_array_equal(birth_mixture(seed000).means[:, [0, 2]],
                                  [t.start for t in seed000.targets])
    assert len(birth_mixture(paper)) == 2
    with pytest.raises(ScenarioError):
        with_birth_model(seed000, "adaptiv")


def test_build(seed000: Scenario) -> None:
    assert clutter_intensity(seed000, "s1") == pytest.approx(10 / 4e6)
    assert sensor_params(seed000, "s2").detection_probability == 0.99
    assert len(make_filter(seed000, ["s1"]).sensors) == 1
    assert len(make_filter(seed000, seed000.sensor_names).sensors) == 3
    with pytest.raises(ScenarioError, match="s9"):
        sensor_params(seed000, "s9")


def test_unknown_source() -> None:
    with pytest.raises(ScenarioError, match="seed999"):
        load_scenario("seed999")


# --- bad files ----------------------------------------------------------------------------

GOOD = scenario_text("seed000")


def _edit(old: str, new: str, count: int = 1) -> str:
    assert old in GOOD, old
    return GOOD.replace(old, new, count)


BAD = {
    "typo": (_edit("merge_threshold = 5.0", "merge_treshold = 5.0"),
             ["'filter.merge_treshold'", "did you mean 'filter.merge_threshold'"]),
    "unknown section": (GOOD + "\n[filtre]\ngate = 3.0\n", ["'filtre'"]),
    "negative sigma_r": (_edit("sigma_r = 20.0", "sigma_r = -20.0"), ["'sensors[0].sigma_r'"]),
    "probability 1.5": (_edit("detection_probability = 0.99", "detection_probability = 1.5"),
                        ["'sensors[0].detection_probability'", "[0, 1]"]),
    "survival 1.5": (_edit("survival_probability = 0.99", "survival_probability = 1.5"),
                     ["'motion.survival_probability'"]),
    "non-PSD cov_diag": (_edit("cov_diag = [100.0, 25.0, 100.0, 25.0]",
                               "cov_diag = [100.0, -25.0, 100.0, 25.0]"),
                         ["'birth.paper[0].cov_diag'", "positive definite"]),
    "short cov_diag": (_edit("cov_diag = [100.0, 25.0, 100.0, 25.0]",
                             "cov_diag = [100.0, 25.0, 100.0]"), ["'birth.paper[0].cov_diag'"]),
    "non-PSD cov": (_edit("cov_diag = [100.0, 2500.0, 100.0, 2500.0]",
                          "cov = [[1.0, 2.0, 0, 0], [2.0, 1.0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"),
                    ["'birth.truth.cov'", "positive definite"]),
    "asymmetric cov": (_edit("cov_diag = [100.0, 2500.0, 100.0, 2500.0]",
                             "cov = [[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"),
                       ["'birth.truth.cov'", "symmetric"]),
    "death before birth": (_edit("birth_scan = 20\ndeath_scan = 60",
                                 "birth_scan = 20\ndeath_scan = 10"),
                           ["'targets[1].death_scan'", "before"]),
    "unknown kind": (_edit('"s1"\nkind = "linear"', '"s1"\nkind = "lidar"'),
                     ["'sensors[0].kind'", "lidar"]),
    "unknown merge rule": (_edit('merge_rule = "vo-ma"', 'merge_rule = "vo_ma"'),
                           ["'filter.merge_rule'", "did you mean 'vo-ma'"]),
    "wrong type": (_edit("num_scans = 100", 'num_scans = "100"'), ["'scenario.num_scans'"]),
    "bool is not int": (_edit("max_components = 100", "max_components = true"),
                        ["'filter.max_components'"]),
    "missing key": (_edit("start = [100.0, 450.0]\n", ""), ["'targets[0].start'", "missing"]),
    "range-bearing without sigma_theta": (
        _edit('"s1"\nkind = "linear"', '"s1"\nkind = "range-bearing"'),
        ["'sensors[0].sigma_theta_deg'", "needs it"]),
    "sigma_theta on linear": (_edit("sigma_r = 20.0", "sigma_r = 20.0\nsigma_theta_deg = 1.0"),
                              ["'sensors[0].sigma_theta_deg'"]),
    "unknown fusing sensor": (_edit('fusing_sensor = "s2"', 'fusing_sensor = "s4"'),
                              ["'fusion.fusing_sensor'"]),
    "duplicate sensor": (_edit('name = "s3"', 'name = "s1"'), ["'sensors[2].name'"]),
    "bad region": (_edit("region = [[-1000.0, 1000.0], [-1000.0, 1000.0]]",
                         "region = [[1000.0, -1000.0], [-1000.0, 1000.0]]"), ["'scenario.region'"]),
    "negative clutter": (_edit("clutter_rate = 10", "clutter_rate = -1"),
                         ["'sensors[0].clutter_rate'"]),
    "invalid toml": (GOOD + "\n[filter\n", ["invalid TOML"]),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_file_gives_one_line_error_naming_the_key(case: str, tmp_path) -> None:
    text, expected = BAD[case]
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(str(path)), msg
    for fragment in expected:
        assert fragment in msg, msg
    assert isinstance(err.value, ValueError)


def test_defaults_for_optional_sections(tmp_path) -> None:
    path = tmp_path / "tiny.toml"
    path.write_text(
        "[scenario]\nnum_scans = 5\nregion = [[0, 10], [0, 10]]\n"
        '[[sensors]]\nname = "a"\nkind = "range-bearing"\nposition = [0, 0]\n'
        "sigma_theta_deg = 1.0\n"
    )
    scn = load_scenario(path)
    assert scn.name == "tiny" and scn.seed == 0 and scn.targets == ()
    assert scn.fusion.fusing_sensor == "a"
    assert scn.filter.max_components == 100 and scn.birth.model == "paper"
    assert scn.sensor("a").sigma_theta == pytest.approx(np.deg2rad(1.0))
    # range-bearing clutter box: [0, r_max] x [-pi, pi), r_max to the corner (10, 10)
    assert clutter_intensity(scn, "a") == pytest.approx(10 / (np.hypot(10, 10) * 2 * np.pi))


# --- [faults]: the typed link-fault plan ------------------------------------------------------

FAULTS = GOOD + """
[faults.default]
delay = { kind = "scans", low = 0, high = 2 }
loss = 0.1

[faults.peers.s3]
partitions = [[3.0, 4.5]]

[[faults.links]]
from = "s1"
to = "s2"
loss = 0.3
"""


def test_faults_table_becomes_a_typed_plan(seed000: Scenario, tmp_path) -> None:
    from sensornet.peers.faultplan import FaultPlan, Scans

    assert seed000.faults is None
    path = tmp_path / "faulty.toml"
    path.write_text(FAULTS)
    scn = load_scenario(path)
    interval = scn.scan_period / scn.network.speed
    assert isinstance(scn.faults, FaultPlan) and scn.faults.interval == interval
    assert scn.faults.default.delay == Scans(0, 2, interval)
    assert scn.faults.for_link("s1", "s2").loss == 0.3
    assert scn.faults.for_link("s2", "s1").loss == 0.1
    assert scn.faults.for_link("s1", "s3").partitions == ((3.0, 4.5),)
    hash(scn)  # still immutable all the way down
    assert load_scenario(path) == scn

    # overrides reach the plan: existing keys, new tables, list entries, another delay kind
    # (an override table merges into the file's table, so a kind spelled as a string)
    changed = load_scenario(path, parse_overrides([
        "faults.default.loss=0.2", "faults.links[0].duplicate=0.5", "faults.peers.s2.loss=0.4",
        'faults.default.delay="one-step"']))
    assert changed.faults.default.loss == 0.2
    assert changed.faults.for_link("s1", "s2").duplicate == 0.5
    assert changed.faults.for_link("s3", "s2").loss == 0.4  # into s2
    assert changed.faults.default.delay.mean == interval
    assert load_scenario("seed000", {"faults": {}}).faults is None


@pytest.mark.parametrize("where, text, expected", [
    ("file", FAULTS.replace("loss = 0.3", "loss = 1.3"), ["'faults.links[0].loss'", "[0, 1]"]),
    ("file", FAULTS.replace("loss = 0.1", "los = 0.1"),
     ["'faults.default.los'", "did you mean 'faults.default.loss'"]),
    ("file", FAULTS.replace('to = "s2"', 'to = "s7"'), ["'faults.links[0].to'", "'s7'"]),
    ("file", FAULTS.replace("[faults.peers.s3]", "[faults.peers.s9]"),
     ["'faults.peers.s9'", "s1, s2, s3"]),
    ("file", FAULTS.replace("high = 2", "high = -2"), ["'faults.default.delay.high'"]),
    ("file", FAULTS.replace("[[3.0, 4.5]]", "[[4.5, 3.0]]"), ["'faults.peers.s3.partitions[0]'"]),
    ("overrides", "faults.default.reorder=0.5\nfaults.default.reorder_delay=0",
     ["(overrides)", "'faults.default.reorder_delay'"]),
    ("overrides", 'faults.links[0].delay="multi-step"',
     ["(overrides)", "'faults.links[0].delay'", "max_steps"]),
    ("overrides", "faults=3", ["(overrides)", "'faults'", "table"]),
])
def test_bad_faults_give_one_line_errors_naming_the_key(where, text, expected,
                                                        tmp_path) -> None:
    path = tmp_path / "faulty.toml"
    path.write_text(text if where == "file" else FAULTS)
    overrides = parse_overrides(text.splitlines()) if where == "overrides" else None
    with pytest.raises(ScenarioError) as err:
        load_scenario(path, overrides)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    for fragment in expected:
        assert fragment in msg, msg
