"""Names are paths and key chunks: one rule (protocol.keys.check_name) for sensor, network and
member names, checked at load with a one-line error (issue 25, item 1)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from sensornet.protocol.keys import NAME_MAX, check_name
from sensornet.sim.scenario import ScenarioError, load_scenario, scenario_text

from sensornet.cli import main

BAD = ["../../evil", "a/b", "*", "**", "", "-x", "a b", "s1.key", "x" * (NAME_MAX + 1), "é"]
RESERVED = ["world", "World", "ca", "router", "router-2"]


def _with_first_sensor(name: str, scenario: str = "seed000") -> str:
    text = scenario_text(scenario)
    new = text.replace('name = "s1"', f'name = "{name}"', 1)
    assert new != text
    return new.replace('"s1"', '"s2"')  # e.g. fusing_sensor: name another sensor


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize("name", ["s1", "a", "A-b_9", "x" * NAME_MAX, "0peer"])
def test_good_names_pass(name):
    assert check_name(name, "sensor name", peer=True) == name


@pytest.mark.parametrize("name", [*BAD, None, 7])
def test_bad_names_are_refused_naming_the_name_and_the_rule(name):
    with pytest.raises(ValueError) as info:
        check_name(name, "sensor name")
    msg = str(info.value)
    assert "\n" not in msg and "invalid sensor name" in msg and f"1-{NAME_MAX} letters" in msg


@pytest.mark.parametrize("name", RESERVED)
def test_reserved_names_are_refused_as_peers_only(name):
    with pytest.raises(ValueError, match="reserved"):
        check_name(name, "sensor name", peer=True)
    if name.lower() != "ca":
        assert check_name(name, "member name") == name  # the world and routers are members


@pytest.mark.parametrize("name", BAD + RESERVED)
def test_run_sim_refuses_a_bad_sensor_name_in_one_line(tmp_path, monkeypatch, capsys, name):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.toml").write_text(_with_first_sensor(name))
    assert main(["run", "bad.toml", "--sim", "--out", "out"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "sensors[0].name" in line and ("reserved" in line or "letters, digits" in line)
    assert _files(tmp_path) == {"bad.toml"}  # no run folder, nothing beside or above it
    assert not (tmp_path.parent / "evil.log").exists()


@pytest.mark.parametrize("name", ["../../evil", "*", "world", "x" * 100])
def test_keys_refuses_a_bad_sensor_name_and_writes_nothing(tmp_path, monkeypatch, capsys, name):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.toml").write_text(_with_first_sensor(name))
    assert main(["keys", "net1", "--out", "keys", "--scenario", "bad.toml"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "sensors[0].name" in line
    assert _files(tmp_path) == {"bad.toml"}


@pytest.mark.parametrize("members", ["s1,../x", "s1,a/b", "*", "s1,ca", "s1,CA",
                                     "s1," + "m" * 33])
def test_keys_refuses_a_bad_member_name(tmp_path, capsys, members):
    assert main(["keys", "net1", "--out", str(tmp_path / "k"), "--members", members]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "member name" in line or "'ca'" in line
    assert not (tmp_path / "k").exists() or not any((tmp_path / "k").iterdir())
    assert _files(tmp_path) <= {"k"}


@pytest.mark.parametrize("argv", [
    ["keys", "../evil", "--out", "k"],
    ["keys", "n" * 33, "--out", "k"],
    ["run", "--sim", "--network", "a/b"],
    ["run", "--sim", "--network", "*"],
    ["run", "--sim", "--run-id", "x/y"],
    ["peer", "s1", "--network", "../x"],
    ["world", "--network=-x"],
    ["router", "--listen", "tcp/127.0.0.1:0", "--name", "../router"],
    ["router", "--listen", "tcp/127.0.0.1:0", "--name", "s1"],
])
def test_cli_refuses_a_bad_network_member_or_run_name(tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    line = _one_line(capsys.readouterr().err)
    assert "invalid" in line and "name" in line or "run id" in line
    assert _files(tmp_path) == set()


def test_the_longest_names_make_keys_and_run(tmp_path, capsys):
    """NAME_MAX fits every place a name goes: a 32-character network in the CA's common name
    (``sensornet <network> CA``, X.509 allows 64), a 32-character member, and a
    32-character sensor whose scans and estimates the twin's peers accept."""
    from sensornet.peers.member_keys import common_name

    net, member = "n" * NAME_MAX, "m" * NAME_MAX
    assert main(["keys", net, "--out", str(tmp_path / "k"), "--members", f"world,{member}"]) == 0
    assert common_name(tmp_path / "k" / f"{member}.pem") == member
    capsys.readouterr()
    long = "s" * NAME_MAX
    (tmp_path / "long.toml").write_text(_with_first_sensor(long))
    assert main(["run", str(tmp_path / "long.toml"), "--sim", "--network", net,
                 "--set", "birth.model=truth", "--set", "scenario.num_scans=5"]) == 0
    out = capsys.readouterr().out
    assert f"| {long} | 5 |" in out  # its 5 scans, none refused


def test_a_longest_name_fits_the_admission_head():
    """A receiver reads a message's first fields from its first 192 bytes (peers.admission):
    a 32-character sender leaves room for all of them."""
    import numpy as np
    from sensornet.peers.admission import peek
    from sensornet.protocol.codec import encode
    from sensornet.protocol.messages import Estimate, Scan
    from sensornet.tracking.mixture import GaussianMixture

    name = "s" * NAME_MAX
    scan = encode(Scan(name, 7, np.zeros((3, 2)), seq=2**40, send_time=1e9))
    assert peek(scan) == ("S", 7, 0, 0)
    mix = GaussianMixture(np.ones(1), np.zeros((1, 4)), np.eye(4)[None])
    est = encode(Estimate(name, 7, mix, round=3, seq=2**40, send_time=1e9))
    assert peek(est)[:3] == ("E", 7, 3)


@pytest.mark.parametrize("second", ["s1", "S1"])
def test_a_repeated_sensor_name_is_refused(second):
    text = scenario_text("seed000").replace('name = "s2"', f'name = "{second}"', 1)
    with pytest.raises(ScenarioError, match="sensors\\[1\\].name") as info:
        load_scenario_text(text)
    assert ("repeats" if second == "s1" else "only in case") in str(info.value)


def load_scenario_text(text: str):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "s.toml"
        path.write_text(text.replace('fusing_sensor = "s2"', 'fusing_sensor = "s1"'))
        return load_scenario(path)


@pytest.mark.parametrize("name", ["../../evil", "world", "*"])
def test_seed003_files_refuse_a_bad_sensor_name(tmp_path, monkeypatch, capsys, name):
    monkeypatch.chdir(tmp_path)
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "seed003.toml").write_text(_with_first_sensor(name, "seed003"))
    assert main(["run", str(folder / "seed003.toml"), "--sim"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "sensors[0].name" in line and name in line
    assert _files(tmp_path) == {"mine", "mine/seed003.toml"}


@pytest.mark.network  # a real `sensornet run` (processes), refused before any starts
def test_real_run_with_a_path_name_writes_nothing_outside(tmp_path):
    (tmp_path / "bad.toml").write_text(_with_first_sensor("../../evil"))
    (tmp_path / "a" / "b").mkdir(parents=True)
    proc = subprocess.run([sys.executable, "-m", "sensornet", "run", str(tmp_path / "bad.toml"),
                           "--out", "run"], cwd=tmp_path / "a" / "b", capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "../../evil" in _one_line(proc.stderr)
    assert _files(tmp_path) == {"bad.toml", "a", "a/b"}
