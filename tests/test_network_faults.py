"""The hostile network with real processes: twin equality, process faults, fuzzing, loss, SIGTERM.

Every run's processes are stopped in ``finally`` blocks (``RunHandle.stop_all``).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest
import zenoh

from peers.session import open_session
from protocol.codec import VERSION, encode, pack_mixture
from protocol.keys import Keys
from protocol.messages import Estimate, Scan
from sim.launcher import (
    ProcessFault,
    inject_process_faults,
    read_summaries,
    start_run,
    wait_run,
)
from sim.scenario import load_scenario, parse_overrides, scenario_text
from sim.twin import run_twin
from tracking.mixture import GaussianMixture

FOUR = scenario_text("seed000") + """
[[sensors]]
name = "s4"
kind = "linear"
position = [0.0, 1000.0]
sigma_r = 20.0
detection_probability = 0.99
clutter_rate = 10
"""


def _run(source: str, out: Path, sets: list[str], faults: list[str] = (), timeout=90,
         during=None, **kw):
    scn = load_scenario(source, overrides=parse_overrides(sets))
    handle = start_run(scn, source, out, overrides=sets, **kw)
    stop = threading.Event()
    thread = None
    try:
        if faults:
            thread = threading.Thread(target=inject_process_faults, daemon=True, args=(
                handle, [ProcessFault.parse(f) for f in faults], scn.sensor_names[0], stop))
            thread.start()
        if during is not None:
            during(handle)
        codes = wait_run(handle, timeout=timeout)
    finally:
        stop.set()
        handle.stop_all()
        if thread is not None:
            thread.join(timeout=5)
    return scn, codes, read_summaries(out, scn.sensor_names)


def test_real_processes_equal_the_twin(tmp_path):
    sets = ["birth.model=truth", "scenario.num_scans=40", "network.deadline=1.0",
            "network.speed=10"]
    scn, codes, summaries = _run("seed000", tmp_path, sets, rerun=False,
                                 peer_args={n: ["--save-tracks"] for n in ("s1", "s2", "s3")})
    assert all(c == 0 for c in codes.values()), codes
    twin = run_twin(scn, 0)
    for name in scn.sensor_names:
        assert summaries[name]["stats"]["deadline_fusions"] == 0  # every input arrived
        saved = np.load(tmp_path / f"tracks-{name}.npz")
        assert len(saved.files) == scn.num_scans
        for k in range(1, scn.num_scans + 1):
            real, virtual = saved[f"k{k}"], twin.tracks[name][k]
            assert real.shape == virtual.shape, (name, k)
            np.testing.assert_allclose(real, virtual, rtol=0, atol=1e-9)


def test_kill_restart_and_freeze(tmp_path):
    source = tmp_path / "four.toml"
    source.write_text(FOUR)
    sets = ["birth.model=truth", "scenario.num_scans=90"]
    faults = ["kill:s4@15", "restart:s4@30", "stop:s3@50", "cont:s3@65"]
    # the default Zenoh lease (peers.session.DEFAULT_LEASE_MS): no --lease-ms
    scn, codes, summaries = _run(str(source), tmp_path / "run", sets, faults, rerun=False)
    done = json.loads((tmp_path / "run" / "process-faults.json").read_text())
    assert [d["action"] for d in done] == ["kill", "restart", "stop", "cont"]
    assert codes["world"] == 0 and codes["s1"] == 0 and codes["s2"] == 0, codes
    kill, restart, stop = done[0]["wall"], done[1]["wall"], done[2]["wall"]
    for name in ("s1", "s2"):
        events = summaries[name]["peer_events"]
        left = [w for p, what, w, _ in events if p == "s4" and what == "left" and w >= kill]
        assert left and left[0] - kill < 2.0, (name, events)  # kill -9 seen within 2 s
        back = [w for p, what, w, _ in events if p == "s4" and what == "joined" and w > restart]
        assert back, (name, events)  # the restarted peer rejoined
        assert summaries[name]["stats"]["last_fused_from"]["s4"] > 30  # and is fused again
        froze = [w for p, what, w, _ in events if p == "s3" and what == "left" and w >= stop]
        assert froze and froze[0] - stop < 2.5, (name, events)  # 1.5 s default lease
        assert summaries[name]["scans"] == scn.num_scans  # kept fusing, finished the run


def _fuzz_payloads(rng: np.random.Generator, replays: list[bytes], n: int) -> list[bytes]:
    good = GaussianMixture(np.ones(2), rng.normal(size=(2, 4)), np.tile(np.eye(4), (2, 1, 1)))
    out = []
    for i in range(n):
        kind = i % 7
        if kind == 0:
            out.append(rng.bytes(int(rng.integers(0, 300))))
        elif kind == 1:  # wrong types in an otherwise well-formed message
            out.append(msgpack.packb([VERSION, "E", 17, "k", 0, 1, 1.0, 1, 0, 4,
                                      pack_mixture(good)], use_bin_type=True))
        elif kind == 2:  # NaN
            bad = good.copy()
            bad.means[0, 0] = np.nan
            out.append(encode(Estimate("s1", 5, bad)))
        elif kind == 3:  # non-PSD
            bad = good.copy()
            bad.covs[1] = -np.eye(4)
            out.append(encode(Estimate("s1", 5, bad)))
        elif kind == 4:  # huge counts
            out.append(msgpack.packb([VERSION, "E", "s1", 5, 0, 1, 1.0, 1, 0, 4,
                                      b"\0" * (8 * 15 * 5000)], use_bin_type=True))
        elif kind == 5:  # an old scan replayed on the estimate key
            out.append(encode(Scan("s1", 1, rng.normal(size=(5, 2)))))
        else:  # a genuine old estimate replayed
            out.append(replays[i % len(replays)] if replays else rng.bytes(10))
    return out


def test_ten_thousand_fuzzed_messages(tmp_path):
    sets = ["birth.model=truth", "scenario.num_scans=100", "network.deadline=0.9"]
    sent = {"n": 0}

    def fuzz(handle):
        session = open_session(connect=list(handle.endpoints.values()))
        keys = Keys(handle.network)
        replays: list[bytes] = []
        sub = session.declare_subscriber(keys.estimate("s1"),
                                         lambda s: replays.append(s.payload.to_bytes()))
        try:
            deadline = time.monotonic() + 30
            while len(replays) < 10 and time.monotonic() < deadline:
                time.sleep(0.05)
            assert replays, "no genuine estimate seen"
            pub = session.declare_publisher(keys.estimate("s1"),
                                            congestion_control=zenoh.CongestionControl.BLOCK)
            rng = np.random.default_rng(11)
            for payload in _fuzz_payloads(rng, list(replays[:10]), 10_000):
                pub.put(payload)
                sent["n"] += 1
            time.sleep(0.5)
            pub.undeclare()
        finally:
            sub.undeclare()
            session.close()

    scn, codes, summaries = _run("seed000", tmp_path, sets, during=fuzz, rerun=False)
    assert sent["n"] == 10_000
    assert all(c == 0 for c in codes.values()), codes
    twin = run_twin(scn, 0)
    for name in ("s2", "s3"):  # they subscribe to s1's estimate key
        s = summaries[name]
        assert s["internal_errors"] == {}
        got = s["received_by_kind"]["estimate"]
        early = s["rejected_before_decoding"]
        # every fuzzed message arrived: most were refused from their first bytes (stale scan
        # index, a slot already filled, over the rate), the rest decoded and rejected or redundant
        assert got + early >= 10_000, s["rejected"]
        assert early >= 10_000 // 2, s["rejected"]
        decoded_ok = s["nale"]["redundant"] + s["nale"]["accepted"]
        assert s["rejected_total"] - early + decoded_ok >= got - 5, s
        # s1's genuine estimates still got through: fused as in the clean twin run
        assert s["nale"]["accepted"] >= scn.num_scans - 2
        assert abs(s["mean_ospa_fused"] - twin.peers[name].mean_ospa("fused")) < 5.0


def test_loss_duplication_and_reordering(tmp_path):
    sets = ["birth.model=truth", "scenario.num_scans=60", "faults.default.loss=0.3",
            "faults.default.duplicate=0.2", "faults.default.reorder=1.0",
            'faults.default.delay={kind="scans", low=0, high=2}']
    scn, codes, summaries = _run("seed000", tmp_path, sets, rerun=False)
    assert all(c == 0 for c in codes.values()), codes
    total = {}
    for s in summaries.values():
        assert s["scans"] == scn.num_scans and s["internal_errors"] == {}
        for action, n in s["injected_faults"].items():
            total[action] = total.get(action, 0) + n
        assert (tmp_path / f"faults-into-{s['peer']}.csv").is_file()
    decided = sum(total.values())
    assert decided == 3 * 2 * scn.num_scans  # one decision per estimate per receiving link
    assert 0.2 < total["drop-loss"] / decided < 0.4
    assert total["duplicate"] > 0


def test_sigterm_leaves_summary_and_recording(tmp_path):
    sets = ["birth.model=truth", "scenario.num_scans=60"]
    scn, codes, summaries = _run("seed000", tmp_path, sets, ["term:s2@20"])
    assert codes["s2"] == 0  # a clean exit on SIGTERM
    s2 = summaries["s2"]
    assert s2["stop_reason"] == "SIGTERM" and 15 <= s2["scans"] < scn.num_scans
    rrd = tmp_path / "rerun" / "peer-s2.rrd"
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    verify = subprocess.run([exe, "rrd", "verify", str(rrd)], capture_output=True, text=True,
                            timeout=120, env={**os.environ, "RERUN_ANALYTICS": "0"})
    assert verify.returncode == 0, verify.stderr[-2000:]
    text = subprocess.run([exe, "rrd", "print", str(rrd)], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "RERUN_ANALYTICS": "0"}).stdout
    assert "/metrics/ospa/s2/fused" in text and "/peers/s2/fused/means" in text


@pytest.mark.parametrize("text", ["kill:s2", "boom:s2@3", "kill:s2@0", "kill@3"])
def test_bad_process_fault_specs(text):
    with pytest.raises(ValueError):
        ProcessFault.parse(text)


def test_sparse_links_along_a_ring(tmp_path):
    """Gossip off, each peer linked to the world and its ring neighbours only: still fuses."""
    source = tmp_path / "four.toml"
    source.write_text(FOUR)
    sets = ["birth.model=truth", "scenario.num_scans=40", "network.topology=ring",
            "network.deadline=0.9"]
    scn, codes, summaries = _run(str(source), tmp_path / "run", sets, rerun=False, sparse=True)
    assert all(c == 0 for c in codes.values()), codes
    twin = run_twin(scn, 0)
    for name, s in summaries.items():
        assert s["stats"]["fused_inputs"] == 2 * scn.num_scans, (name, s["stats"])
        seen = {p for p, what, _, _ in s["peer_events"] if what == "joined"}
        assert seen == set(twin.peers[name].consensus.o.neighbours)  # only the linked neighbours
        assert abs(s["mean_ospa_fused"] - twin.peers[name].mean_ospa("fused")) < 1e-9
