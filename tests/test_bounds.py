"""Sizes nothing bounded before issue 25 (item 3): rounds, region, runs, sensors. Each is
checked when the scenario or the command line is read, with a one-line error."""

from __future__ import annotations

from pathlib import Path

import pytest
from sensornet.sim.scenario import (
    MAX_COORDINATE,
    MAX_ROUNDS,
    MAX_RUNS,
    MAX_SENSORS,
    ScenarioError,
    load_scenario,
    parse,
    scenario_text,
)

from sensornet.cli import main


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.mark.parametrize("sets, needle", [
    (["network.rounds=17"], f"must be <= {MAX_ROUNDS}"),
    (["network.rounds=1000000000"], f"must be <= {MAX_ROUNDS}"),
    (["scenario.region=[[-1e308, 1e308], [-1e308, 1e308]]"], "beyond +-1e+07 m"),
    (["scenario.region=[[0.0, 0.0], [0.0, 10.0]]"], "an empty area"),
    (["scenario.region=[[0.0, 1e7], [-1.5e7, 0.0]]"], "y = -1.5e+07 m"),
    (["sensors.s1.position=[0.0, 1e300]"], "sensors[0].position"),
    (["targets[0].start=[-1e9, 0.0]"], "targets[0].start"),
])
def test_run_sim_refuses_an_unbounded_size_in_one_line(tmp_path, monkeypatch, capsys, sets,
                                                      needle):
    monkeypatch.chdir(tmp_path)
    argv = ["run", "--sim", "--out", "out"]
    for s in sets:
        argv += ["--set", s]
    assert main(argv) == 2
    assert needle in _one_line(capsys.readouterr().err)
    assert _files(tmp_path) == set()


def test_the_bounds_themselves_are_accepted():
    scn = load_scenario("seed000", overrides={
        "network.rounds": MAX_ROUNDS,
        "scenario.region": [[-MAX_COORDINATE, MAX_COORDINATE], [0.0, 1.0]],
        "sensors[0].position": [MAX_COORDINATE, -MAX_COORDINATE]})
    assert scn.network.rounds == MAX_ROUNDS
    assert scn.region[0] == (-MAX_COORDINATE, MAX_COORDINATE)


@pytest.mark.parametrize("argv", [
    ["sweep", "--param", "faults.default.loss", "--values", "0.1", "--runs", "1000000000"],
    ["sweep", "--param", "faults.default.loss", "--values", "0.1", "--runs", str(MAX_RUNS + 1)],
    ["sweep", "--param", "faults.default.loss", "--values", "0.1", "--runs", "1e9"],
    ["experiment", "--runs", str(MAX_RUNS + 1)],
    ["campaign", "seed000-twin", "--runs", str(MAX_RUNS + 1)],
    ["peer", "s1", "--network", "x", "--rounds", str(MAX_ROUNDS + 1)],
])
def test_cli_refuses_too_many_runs_or_rounds(tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    line = _one_line(capsys.readouterr().err)
    assert f"<= {MAX_RUNS:,}" in line or f"<= {MAX_ROUNDS}" in line
    assert _files(tmp_path) == set()


def test_a_campaign_file_over_the_runs_bound_is_refused(tmp_path):
    from sensornet.sim.campaign import load_campaign

    path = tmp_path / "c.toml"
    path.write_text(f'[campaign]\nname = "c"\nscenario = "seed000"\nrunner = "twin"\n'
                    f"runs = {MAX_RUNS + 1}\n")
    with pytest.raises(ScenarioError, match="campaign.runs"):
        load_campaign(path)


def _sensors(n: int, repeat_last: bool = False) -> str:
    text = scenario_text("seed000")
    head = text[:text.index("[[sensors]]")]
    tail = text[text.index("[birth]"):]
    names = [f"x{i}" for i in range(n)]
    if repeat_last:
        names[-1] = names[0]
    body = "".join(f'[[sensors]]\nname = "{m}"\nkind = "linear"\nposition = [0.0, {i}.0]\n\n'
                   for i, m in enumerate(names))
    return head + body + tail.replace('fusing_sensor = "s2"', 'fusing_sensor = "x0"')


def test_a_100000_sensor_file_is_refused_at_load(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "big.toml").write_text(_sensors(100_000))
    checked: list[str] = []  # the count is refused before any sensor's own checks (no timing)
    monkeypatch.setattr(parse, "check_name", lambda name, *a, **k: checked.append(name))
    assert main(["run", "big.toml", "--sim"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "100,000 sensors" in line and f"limit of {MAX_SENSORS}" in line
    assert checked == []
    assert _files(tmp_path) == {"big.toml"}


def test_the_most_sensors_load_and_a_repeat_among_them_is_found(tmp_path):
    path = tmp_path / "many.toml"
    path.write_text(_sensors(MAX_SENSORS))
    assert len(load_scenario(path).sensors) == MAX_SENSORS
    path.write_text(_sensors(MAX_SENSORS, repeat_last=True))
    with pytest.raises(ScenarioError, match=rf"sensors\[{MAX_SENSORS - 1}\].name' repeats"):
        load_scenario(path)
    path.write_text(_sensors(MAX_SENSORS + 1))
    with pytest.raises(ScenarioError, match="over the limit"):
        load_scenario(path)


@pytest.mark.parametrize("overrides, needle", [
    ({"flooding.iterations": MAX_ROUNDS + 1}, "flooding.iterations"),
    ({"consensus.rounds": [1, 10**9]}, "consensus.rounds"),
    ({"network.rounds": MAX_ROUNDS + 1}, "network.rounds"),
    ({"scenario.region": [[-1e308, 1e308], [-1.0, 1.0]]}, "scenario.region"),
    ({"scenario.region": [[1.0, 1.0], [-1.0, 1.0]]}, "non-empty"),
    ({"sensors.positions": [[float(i), 0.0] for i in range(MAX_SENSORS + 1)]}, "over the limit"),
])
def test_seed004_sizes_are_bounded(overrides, needle):
    with pytest.raises(ScenarioError, match=needle.replace(".", r"\.")) as info:
        load_scenario("seed004", overrides=overrides)
    assert "\n" not in str(info.value)


def test_seed004_offline_sizes_are_bounded():
    from sensornet.sim.studies.seed004 import montecarlo as seed004

    with pytest.raises(seed004.ScenarioError, match="flooding.iterations"):
        seed004.load(overrides=[f"flooding.iterations={MAX_ROUNDS + 1}"])
    assert seed004.load(overrides=[f"flooding.iterations={MAX_ROUNDS}"]).iterations == MAX_ROUNDS


def test_seed003_sensor_count_is_bounded():
    from sensornet.sim.studies.seed003.montecarlo import check_sensor_names

    check_sensor_names([{"name": f"p{i}"} for i in range(MAX_SENSORS)], "seed003")
    with pytest.raises(ValueError, match="over the limit"):
        check_sensor_names([{"name": f"p{i}"} for i in range(MAX_SENSORS + 1)], "seed003")
