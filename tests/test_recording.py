"""Record a run's core inputs and replay them offline: the same fused tracks, bit for bit."""

from __future__ import annotations

import subprocess
import sys

import pytest
from sensornet.peers.recording import read
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.replay import replay
from sensornet.sim.scenario import load_scenario, parse_overrides

pytestmark = pytest.mark.network

SETS = ["scenario.num_scans=30", "network.deadline=0.9"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec")
    scn = load_scenario("seed000", overrides=parse_overrides(SETS))
    handle = start_run(scn, "seed000", out, overrides=SETS, rerun=False,
                       peer_args={n: ["--record"] for n in scn.sensor_names})
    try:
        codes = wait_run(handle, timeout=120)
    finally:
        handle.stop_all()
    assert all(c == 0 for c in codes.values()), codes
    return out, scn, read_summaries(out, scn.sensor_names)


def test_replay_reproduces_every_peers_fused_tracks_bit_for_bit(recorded):
    out, scn, summaries = recorded
    for name in scn.sensor_names:
        path = out / "record" / f"peer-{name}.mcap"
        meta, records = read(path)
        assert meta["peer"] == name and path.stat().st_size < 20e6
        r = replay(path)
        assert len(r.recorded) == scn.num_scans and r.identical, name
        assert r.snapshot["mean_ospa_fused"] == pytest.approx(
            summaries[name]["mean_ospa_fused"], abs=1e-12)


def test_what_if_replay_changes_the_result(recorded):
    out, scn, _ = recorded
    r = replay(out / "record" / "peer-s1.mcap", ["fusion.rule=gci"])
    assert not r.identical and len(r.replayed) == scn.num_scans


def test_replay_command(recorded):
    out, _, _ = recorded
    p = subprocess.run([sys.executable, "-m", "sensornet", "replay", str(out)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.count("| yes |") == 3
    bad = subprocess.run([sys.executable, "-m", "sensornet", "replay", str(out / "nope")],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "no recording" in bad.stderr


def test_replay_refuses_other_rounds(recorded):
    """The recording holds the neighbours' estimates of the rounds the run had: a replay with
    another ``network.rounds`` cannot make the others (it came out identical and said
    "expected to differ"); refused in one line, exit code 2, no table."""
    out, scn, _ = recorded
    with pytest.raises(ValueError, match="network.rounds=3: the recording holds only the 1"):
        replay(out / "record" / "peer-s2.mcap", ["network.rounds=3"])
    p = subprocess.run([sys.executable, "-m", "sensornet", "replay", str(out), "--peer", "s2",
                        "--set", "network.rounds=3"], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 2 and p.stdout == "", (p.stdout, p.stderr)
    assert len(p.stderr.strip().splitlines()) == 1 and "network.rounds" in p.stderr
    same = subprocess.run([sys.executable, "-m", "sensornet", "replay", str(out), "--peer",
                           "s2", "--set", f"network.rounds={scn.network.rounds}"],
                          capture_output=True, text=True, timeout=120)
    assert same.returncode == 0 and "| yes |" in same.stdout
    assert "changed none of the tracks" in same.stdout and "expected to differ" not in same.stdout


def test_readme_what_if_example_differs(recorded):
    """README's what-if example (its --set) changes the replayed tracks."""
    import re
    from pathlib import Path

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    line = next(ln for ln in readme.splitlines() if ln.startswith("sensornet replay ")
                and "--set" in ln)
    sets = re.findall(r"--set (\S+)", line)
    assert sets and not any(s.startswith("network.rounds") for s in sets)
    out, _, _ = recorded
    assert not replay(out / "record" / "peer-s2.mcap", sets).identical


def test_a_cut_recording_is_a_one_line_error(recorded, tmp_path):
    """A peer killed mid-run never closes its MCAP file: reading it is one ValueError line
    saying so, not a traceback from the MCAP reader (the run's other recordings replay)."""
    out, _, _ = recorded
    whole = (out / "record" / "peer-s2.mcap").read_bytes()
    cut = tmp_path / "peer-s2.mcap"
    cut.write_bytes(whole[: len(whole) // 2])
    with pytest.raises(ValueError, match="not a complete recording") as e:
        replay(cut)
    assert "\n" not in str(e.value) and "killed" in str(e.value)


def test_standard_tools_decode_every_message_without_our_code(recorded):
    """The mcap reader and a JSON Schema validator (jsonschema) alone: every channel has a
    jsonschema schema and json messages, and every message validates against its schema."""
    import base64
    import json

    import jsonschema
    from mcap.reader import make_reader

    out, scn, _ = recorded
    files = sorted((out / "record").glob("*.mcap"))
    assert len(files) == len(scn.sensor_names)
    validators: dict[bytes, jsonschema.protocols.Validator] = {}

    def validator(data: bytes) -> jsonschema.protocols.Validator:
        """What jsonschema.validate does (check the schema, pick its draft's validator), once
        per schema, not once per message (most of this test's time)."""
        if data not in validators:
            schema = json.loads(data)
            cls = jsonschema.validators.validator_for(schema)
            cls.check_schema(schema)
            validators[data] = cls(schema)
        return validators[data]

    for path in files:
        seen = set()
        with path.open("rb") as fh:
            for schema, channel, message in make_reader(fh).iter_messages():
                assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
                body = json.loads(message.data)
                validator(schema.data).validate(body)
                if "payload" in body:
                    assert base64.b64decode(body["payload"], validate=True)
                seen.add(channel.topic)
        assert {"receive", "tick", "tracks", "finish"} <= seen, seen
