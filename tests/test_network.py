"""Real processes over Zenoh on loopback: the world and 3 peers of the seed-000 scenario."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from protocol.codec import encode
from protocol.keys import Keys
from protocol.messages import Estimate
from sim.launcher import merge_recordings, read_summaries, start_run, wait_run
from sim.scenario import load_scenario
from tracking.mixture import GaussianMixture

SETS = ["birth.model=truth", "network.speed=20"]
SCANS = 100


@pytest.fixture(scope="module")
def network_run(tmp_path_factory):
    """One seed-000 run (world + 3 peer processes); everything is stopped afterwards."""
    out = tmp_path_factory.mktemp("run")
    scn = load_scenario("seed000", overrides={"birth.model": "truth", "network.speed": 20})
    handle = start_run(scn, "seed000", out, overrides=SETS)
    try:
        # publish junk on a peer's estimate key from an outside session while the run goes on
        import zenoh

        from peers.session import open_session

        session = open_session(connect=list(handle.endpoints.values()))
        try:
            keys = Keys(handle.network)
            deadline = time.monotonic() + 30
            alive: set[str] = set()
            while not {"s1", "s2", "s3"} <= alive and time.monotonic() < deadline:
                alive = {Keys.last(str(r.ok.key_expr))
                         for r in session.liveliness().get(keys.alive("*"), timeout=1.0)
                         if r.ok is not None}
                time.sleep(0.1)
            assert {"s1", "s2", "s3"} <= alive, alive
            time.sleep(0.5)
            pub = session.declare_publisher(keys.estimate("s1"),
                                            congestion_control=zenoh.CongestionControl.BLOCK)
            bad = GaussianMixture(np.ones(1), np.zeros((1, 4)), -np.eye(4)[None])
            for payload in (b"not msgpack", b"\x93\x01\x02", encode(Estimate("s1", 1, bad))):
                pub.put(payload)
            time.sleep(0.5)
            pub.undeclare()
        finally:
            session.close()
        codes = wait_run(handle, timeout=SCANS / 20 + 60)
    finally:
        handle.stop_all()
    yield scn, out, codes, read_summaries(out, scn.sensor_names)


def test_every_process_finished_cleanly(network_run):
    scn, out, codes, summaries = network_run
    assert codes == {"world": 0, "s1": 0, "s2": 0, "s3": 0}, codes
    assert set(summaries) == {"s1", "s2", "s3"}
    for s in summaries.values():
        assert s["stop_reason"] == "end of run"
        assert s["scans"] == SCANS


def test_peers_received_and_fused_each_others_estimates(network_run):
    scn, out, codes, summaries = network_run
    for name, s in summaries.items():
        # two neighbours, one estimate per scan each (a few may miss a deadline)
        assert s["received_by_kind"]["estimate"] >= 2 * SCANS - 10, name
        assert s["stats"]["fusions"] == SCANS
        assert s["stats"]["fused_inputs"] >= 2 * SCANS - 10, name
        assert s["messages_sent"] == 2 * SCANS  # an estimate and the tracks per scan


def test_fused_ospa_beats_local_ospa(network_run):
    scn, out, codes, summaries = network_run
    for name, s in summaries.items():
        assert s["mean_ospa_fused"] < s["mean_ospa_local"], (name, s["mean_ospa_fused"],
                                                             s["mean_ospa_local"])


def test_bad_messages_were_rejected_and_counted(network_run):
    scn, out, codes, summaries = network_run
    # the junk went to s1's key: s2 and s3 received it; s1 ignores its own key
    for name in ("s2", "s3"):
        rej = summaries[name]["rejected"]
        assert rej.get("malformed", 0) >= 1 and rej.get("not-psd", 0) >= 1, (name, rej)
        assert sum(rej.values()) == 3


def test_recording_holds_truth_scans_estimates_and_time_series(network_run):
    scn, out, codes, summaries = network_run
    parts = sorted(p.name for p in (out / "rerun").glob("*.rrd"))
    assert parts == ["peer-s1.rrd", "peer-s2.rrd", "peer-s3.rrd", "world.rrd"]
    merged = merge_recordings(out)
    assert merged is not None and merged.stat().st_size > 100_000
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    text = subprocess.run([exe, "rrd", "print", str(merged)], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "RERUN_ANALYTICS": "0"}).stdout
    for entity in ["/world/truth", "/world/scans/s1", "/metrics/ospa/s1/fused"] + [
            f"/peers/{p}/{what}" for p in ("s1", "s2", "s3")
            for what in ("local/means", "local/ellipses", "fused/means", "tracks")] + [
            f"/metrics/{m}/{p}" for p in ("s1", "s2", "s3")
            for m in ("ospa", "components", "latency_ms", "cardinality")] + [
            f"/metrics/out_of_sequence/s1/{c}" for c in ("late", "redundant", "too_old")]:
        assert entity in text, entity
