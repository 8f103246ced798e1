"""Issue 10's attacks against real processes in secure mode (mutual TLS + access control).

World + 3 peers (seed 000, 40 scans at 10 scans/s) started with ``--secure`` keys. The attacker
holds s3's own key and certificate (a member that lies about whose keys it speaks on), or a
certificate of the right CA for a name outside the roster; others have no certificate or one
from another CA. Every forged message is refused by the receivers' transport (Zenoh's access
control at ingress), so the peers' cores never see it (no rejection counted there); each peer
counts what its transport refused (``refused_by_transport``: sender, message, key), the run ends
normally and every peer's fused OSPA equals the clean secure run's.
"""

from __future__ import annotations

import json
import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh
from sensornet.peers.security import Security, make_keys
from sensornet.peers.session import open_session
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.envelope import inner
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Estimate, Scan
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.tracking.mixture import GaussianMixture

from tests.attacks import K0, SETS

pytestmark = pytest.mark.network

NETWORK = "secnet"
PEERS = ("s1", "s2", "s3")


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    d = tmp_path_factory.mktemp("keys")
    make_keys(NETWORK, ["world", *PEERS], d)
    return d


@pytest.fixture(scope="module")
def scn():
    return load_scenario("seed000", overrides=parse_overrides(SETS))


def _run(out: Path, keys: Path, scn, during=None):
    handle = start_run(scn, "seed000", out, network=NETWORK, overrides=SETS, rerun=False,
                       secure=keys)
    try:
        if during is not None:
            during(handle)
        codes = wait_run(handle, timeout=120)
    finally:
        handle.stop_all()
    return codes, read_summaries(out, scn.sensor_names)


@pytest.fixture(scope="module")
def clean(tmp_path_factory, keys, scn):
    out = tmp_path_factory.mktemp("clean")
    return _run(out, keys, scn)


def _check_complete(scn, codes, summaries):
    assert all(c == 0 for c in codes.values()), codes
    assert set(summaries) == set(PEERS)
    for name, s in summaries.items():
        assert s["internal_errors"] == {}, (name, s["internal_errors"])
        assert s["scans"] == scn.num_scans, name
        assert s["stop_reason"] == "end of run", name
        assert s["ospa_misses"] == {"local": 0, "fused": 0}, name


def test_a_secure_run_works_end_to_end(clean, scn):
    codes, summaries = clean
    _check_complete(scn, codes, summaries)
    for name, s in summaries.items():
        assert s["rejected_total"] == 0, (name, s["rejected"])
        assert s["mean_ospa_fused"] < s["mean_ospa_local"], name
        # a mutual-TLS mesh without a router: the links prove each sender (tests/test_envelope)
        assert s["signatures_checked"] is False, name
        assert s["stats"]["last_fused_from"] == {m: scn.num_scans for m in PEERS
                                                 if m != name}, name


def _session_as(folder: Path, member: str, endpoints) -> zenoh.Session:
    return open_session(connect=list(endpoints),
                        security=Security.load(folder, member, NETWORK, PEERS))


def _refused(conf: zenoh.Config, endpoints) -> bool:
    """True if a session with this config cannot connect to any of ``endpoints``."""
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps(list(endpoints)))
    conf.insert_json5("connect/timeout_ms", "1000")
    conf.insert_json5("connect/exit_on_failure", "true")
    try:
        zenoh.open(conf).close()
    except Exception:
        return True
    return False


def test_forgeries_are_refused_and_the_run_matches_the_clean_one(tmp_path, keys, clean, scn):
    """s3's key puts on s2's estimate, every scan key, ctl, truth, alive/ready tokens for
    others; a same-CA stranger (s9) does the same; sessions without a certificate or with
    another CA's cannot even connect."""
    stranger = tmp_path / "stranger"
    stranger.mkdir()
    for f in ("ca.pem", "ca.key"):
        shutil.copy(keys / f, stranger / f)
    make_keys(NETWORK, ["s9"], stranger)
    other_ca = tmp_path / "other"
    make_keys(NETWORK, ["s2"], other_ca)
    report = {}

    def attack(handle):
        handle.wait_listening("world")  # else "cannot connect" could mean "not up yet"
        eps = list(handle.endpoints.values())
        k = Keys(handle.network)
        s3 = _session_as(keys, "s3", eps)  # s3's own key, in another process's hands
        s9 = _session_as(stranger, "s9", eps)
        seen = {"k": 0}
        reached = threading.Event()

        def on_scan(sample) -> None:  # s3 may read its own scans: the run's clock
            seen["k"] = max(seen["k"], decode(inner(sample.payload.to_bytes())).k)
            if seen["k"] >= K0:
                reached.set()

        sub = s3.declare_subscriber(k.scan("s3"), on_scan)
        tokens, sent, rounds, attacked = [], 0, 0, set()

        def refusals() -> None:
            """Who cannot even connect, checked at once beside the attack (each check may wait
            out its 1 s connect timeout; run one after another they once ate the whole run)."""
            no_cert = zenoh.Config()
            no_cert.insert_json5("transport/link/tls/root_ca_certificate",
                                 json.dumps(str(keys / "ca.pem")))
            foreign = zenoh.Config()
            Security.load(other_ca, "s2", NETWORK, PEERS).apply(foreign)
            checks = {"no_cert_refused": (no_cert, eps),
                      "other_ca_refused": (foreign, eps),
                      "plain_tcp_refused": (zenoh.Config(),
                                            [e.replace("tls/", "tcp/") for e in eps])}
            threads = [threading.Thread(target=lambda n=n, c=c: report.__setitem__(
                n, _refused(*c))) for n, c in checks.items()]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            report["all_up"] = all(p.poll() is None for p in handle.procs.values())

        checker = threading.Thread(target=refusals)
        checker.start()
        try:
            assert reached.wait(150), f"the run never reached scan {K0} ({seen})"
            empty = GaussianMixture(np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)))
            phantom = np.array([[0.0, 0.0]])
            for who in (s3, s9):
                tokens += [who.liveliness().declare_token(k.alive("s1")),
                           who.liveliness().declare_token(k.alive("s9")),
                           who.liveliness().declare_token(k.ready("s2"))]
            end_k = min(seen["k"] + 15, scn.num_scans - 2)
            t0 = time.monotonic()
            # every scan: forge what the issue measured, for 15 scans and at least 10 rounds
            # (one clean-clone run got only 7 rounds in during those 15 scans)
            while seen["k"] < end_k or (rounds < 10 and seen["k"] < scn.num_scans - 2):
                kk = seen["k"]
                rounds += 1
                attacked.add(kk)
                for who in (s3, s9):
                    for rnd in range(3):
                        who.put(k.estimate("s2"), encode(Estimate("s2", kk, empty, round=rnd,
                                                                  send_time=time.time())))
                    for sensor in PEERS:
                        who.put(k.scan(sensor), encode(Scan(sensor, kk + 1, phantom,
                                                            seq=kk + 1,
                                                            send_time=time.time())))
                    who.put(k.ctl(), encode(Control("end", "forged", {})))
                    sent += 3 + len(PEERS) + 1
                time.sleep(0.02)  # a few forgeries per scan interval (0.1 s)
            report["attack_s"] = round(time.monotonic() - t0, 2)
        finally:
            checker.join()
            for t in tokens:
                t.undeclare()
            sub.undeclare()
            s9.close()
            s3.close()
        report.update(sent=sent, rounds=rounds, scans_attacked=len(attacked))

    codes, summaries = _run(tmp_path / "run", keys, scn, during=attack)
    assert report["no_cert_refused"] and report["other_ca_refused"]
    assert report["plain_tcp_refused"] and report["all_up"]  # refused by live peers
    assert report["rounds"] >= 5 and report["scans_attacked"] >= 3, report
    assert report["sent"] == report["rounds"] * 2 * (3 + len(PEERS) + 1), report
    _check_complete(scn, codes, summaries)
    _, clean_summaries = clean
    for name, s in clean_summaries.items():
        assert s["refused_by_transport"] == {}, name
    # what the access control refused, counted where it arrived (by sender, message, key);
    # every peer refused the forged liveliness tokens
    every = {n: s["refused_by_transport"] for n, s in summaries.items()}
    assert all(every.values()), every

    # (per-message counts of refused puts come from Zenoh's trace lines, which name the sender
    # by certificate or by Zenoh id depending on the link: not asserted per kind; once, under
    # load, only the token refusals were traced. What the peers saw is asserted below.)
    refused = sum(n for r in every.values() for n in r.values())
    assert refused >= 3, every
    for name, s in summaries.items():
        # refused by the transport: the peers never even saw the forgeries
        assert s["rejected_total"] == 0, (name, s["rejected"])
        assert s["ctl_end_while_world_alive"] <= 1, name  # only the world's own "end"
        assert not [e for e in s["peer_events"] if e[0] in ("s9",)], s["peer_events"]
        # no s1 departure while s1 ran (the forged s1 tokens came and went then); its own
        # exit, after writing its summary, is seen by a peer still finishing the run
        s1_exit = (tmp_path / "run" / "peer-s1.json").stat().st_mtime
        assert not [e for e in s["peer_events"] if e[0] == "s1" and e[1] == "left"
                    and e[2] < s1_exit], (name, s["peer_events"], s1_exit)
        assert abs(s["mean_ospa_fused"] - clean_summaries[name]["mean_ospa_fused"]) < 3.0, (
            name, s["mean_ospa_fused"], clean_summaries[name]["mean_ospa_fused"])
        assert s["stats"]["last_fused_from"] == clean_summaries[name]["stats"][
            "last_fused_from"], name


def test_process_faults_in_secure_mode(tmp_path, keys):
    """The launcher's fault injector follows the scans with the world's key."""
    from sensornet.cli import main

    out = tmp_path / "run"
    code = main(["run", "seed000", "--secure", str(keys), "--no-rerun", "--out", str(out),
                 "--fault", "kill:s3@15", *[a for s in SETS for a in ("--set", s)]])
    assert code == 0
    done = json.loads((out / "process-faults.json").read_text())
    assert [(f["action"], f["peer"]) for f in done] == [("kill", "s3")]
    assert done[0]["at_scan"] >= 15
    summaries = read_summaries(out, ["s1", "s2"])
    for name, s in summaries.items():
        assert s["scans"] == 40 and s["stop_reason"] == "end of run", name
        assert any(p == "s3" and what == "left" for p, what, _, _ in s["peer_events"]), name
