"""``sensornet echo`` and ``sensornet topics`` (issue 26): a running network's messages, live
and decoded, and the Zenoh encoding every put declares. Logic on encoded bytes, then against a
real run (world + 3 peers as processes over Zenoh on 127.0.0.1)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from sensornet.peers.session import endpoint, free_port, open_session
from sensornet.protocol.codec import encode
from sensornet.protocol.encodings import parse
from sensornet.protocol.messages import Scan, Tracks

from sensornet.cli import main
from sensornet.live import describe

ROOT = Path(__file__).resolve().parents[1]


def test_describe_decodes_and_names_what_it_refuses():
    line = describe("sensornet/n/scan/s1", encode(Scan("s1", 7, np.zeros((3, 2)))))
    assert (line.kind, line.sender, line.scan, line.items) == ("scan", "s1", 7, "3 returns")
    line = describe("sensornet/n/tracks/s2", encode(Tracks("s2", 9, np.zeros((2, 4)))),
                    "application/msgpack;sensornet/tracks/v1")
    assert (line.kind, line.items, line.note) == ("tracks", "2 tracks", "")
    bad = describe("sensornet/n/scan/s1", b"\x93\x01\xa1Sxx")
    assert bad.kind == "rejected" and bad.nbytes == 6
    lying = describe("sensornet/n/scan/s1", encode(Scan("s1", 1, np.zeros((1, 2)))),
                     "application/msgpack;sensornet/estimate/v1")
    assert "declared estimate" in lying.note


def test_bad_arguments_are_one_line(capsys):
    assert main(["echo", "a/b"]) == 2
    assert main(["echo", "net", "--count", "0"]) == 2
    assert main(["topics", "net", "--as", "s1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(e.startswith("sensornet: error:") for e in err)


@pytest.mark.network
def test_echo_and_topics_on_a_running_network(tmp_path):
    # the run lasts 300 s, far longer than the tools need: it is stopped in finally
    port = free_port()
    ep = endpoint(port)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RERUN_ANALYTICS": "0"}
    run = subprocess.Popen(
        [sys.executable, "-m", "sensornet", "run", "seed000", "--network", "live1",
         "--listen", ep, "--no-rerun", "--set", "scenario.num_scans=3000",
         "--set", "network.speed=10",
         "--out", str(tmp_path / "run")], cwd=tmp_path, env=env,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    encodings: set[str] = set()
    heard = threading.Event()
    session = None
    try:
        # a plain Zenoh subscriber, as a generic tool: the encodings the puts declare
        session = open_session((), [ep])

        def on(sample):
            encodings.add(str(sample.encoding))
            if {"estimate", "scan", "tracks"} <= {p[0] for p in map(parse, encodings) if p}:
                heard.set()

        sub = session.declare_subscriber("sensornet/live1/**", on)
        tools = (["echo", "live1", "--connect", ep, "--count", "40"],
                 ["echo", "live1", "tracks/*", "--connect", ep, "--count", "5"],
                 ["topics", "live1", "--connect", ep, "--count", "60", "--duration", "170"])
        with ThreadPoolExecutor(max_workers=3) as pool:  # three listeners at once, as users
            echo, only, table = pool.map(lambda argv: subprocess.run(
                [sys.executable, "-m", "sensornet", *argv], cwd=tmp_path, env=env,
                capture_output=True, text=True, timeout=180), tools)
        assert echo.returncode == 0, echo.stderr
        lines = echo.stdout.strip().splitlines()
        assert len(lines) == 40
        kinds = {ln.split()[2] for ln in lines}
        assert {"estimate", "scan"} <= kinds, lines[:5]
        est = next(ln for ln in lines if " estimate " in ln)
        assert "comp, round" in est and " B" in est
        assert only.returncode == 0, only.stderr
        assert all(ln.split()[2] == "tracks" for ln in only.stdout.strip().splitlines())
        assert table.returncode == 0, table.stderr
        assert "| sensornet/live1/estimate/s1 |" in table.stdout, table.stdout
        assert heard.wait(120), encodings
        # GM-PHD peers label their estimates and tracks: protocol 2 of both (scans stay 1)
        assert {"application/msgpack;sensornet/estimate/v2",
                "application/msgpack;sensornet/scan/v1",
                "application/msgpack;sensornet/tracks/v2"} <= encodings
        sub.undeclare()
    finally:
        if session is not None:
            session.close()
        run.terminate()
        try:
            run.wait(timeout=60)
        except subprocess.TimeoutExpired:
            run.kill()
            run.wait()


@pytest.mark.network
def test_echo_in_secure_mode_speaks_as_a_member_and_verifies_signatures(tmp_path):
    """A secure run (mutual TLS, access control, signed messages): echo with s1's keys hears
    what the access control lets s1 hear (no tracks, no other sensor's scans), each message's
    signature checked against the roster."""
    from sensornet.peers.security import make_keys
    from sensornet.sim.run.launcher import start_run
    from sensornet.sim.scenario import load_scenario, parse_overrides

    keys = tmp_path / "keys"
    keys.mkdir()
    make_keys("seclive", ["world", "s1", "s2", "s3"], keys)
    sets = ["scenario.num_scans=3000", "network.speed=10"]
    scn = load_scenario("seed000", overrides=parse_overrides(sets))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RERUN_ANALYTICS": "0"}
    handle = start_run(scn, "seed000", tmp_path / "run", network="seclive", overrides=sets,
                       rerun=False, secure=keys)
    try:
        ep = handle.endpoints["world"]
        assert ep.startswith("tls/")
        echo = subprocess.run(
            [sys.executable, "-m", "sensornet", "echo", "seclive", "--connect", ep,
             "--secure", str(keys), "--as", "s1", "--count", "30"], cwd=tmp_path, env=env,
            capture_output=True, text=True, timeout=180)
        assert echo.returncode == 0, echo.stderr
        lines = echo.stdout.strip().splitlines()
        assert len(lines) == 30
        assert all(ln.endswith("signature ok") for ln in lines), lines[:3]
        kinds = {ln.split()[2] for ln in lines}
        assert "estimate" in kinds and "tracks" not in kinds  # s1 may not hear tracks
        keys_heard = {ln.split()[1] for ln in lines}
        assert not any(k.startswith("sensornet/seclive/scan/") and not k.endswith("/s1")
                       for k in keys_heard), keys_heard
    finally:
        handle.stop_all()
