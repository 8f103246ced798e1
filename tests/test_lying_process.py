"""A member lying with its own valid key, as real processes in secure mode (issue 24).

World + 3 peers (seed 000, 40 scans at 10 scans/s) over Zenoh on loopback with ``--secure``
keys; s2 is started with the test hook ``fusion.lie = "s2:shifted"``
(:mod:`sim.studies.lying.study`: every
estimate it publishes, signed with its own key, has every component 110 m off and a tight
covariance), the honest peers run the neighbour defence (``fusion.trust``, with its default
registration and repair). Secure mode lets every lie through (it is s2's own key and s2's
own name); the defence must take the lie out: both honest peers fuse s2 repaired (moved
back, with their own covariances) from scan 3 at the latest, and their fused OSPA is the
twin's for the same run. Also: a biased member registered, a phantoms member repaired
(plain mode).
"""

from __future__ import annotations

import pytest
from sensornet.peers.security import make_keys
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides

from tests.attacks import SETS

pytestmark = pytest.mark.network

NETWORK = "lienet"
PEERS = ("s1", "s2", "s3")
LYING = [*SETS, "fusion.trust=true", "fusion.lie=s2:shifted"]


def _run(tmp_path, sets: list[str], **kw):
    """Seed 000 with ``sets`` as processes and on the twin (run 0): the scenario, the twin's
    result and the summaries; every process ended cleanly and both honest peers ran to the
    end without an internal error."""
    scn = load_scenario("seed000", overrides=parse_overrides(sets))
    twin = run_twin(scn, 0)
    out = tmp_path / "run"
    handle = start_run(scn, "seed000", out, overrides=sets, rerun=False, **kw)
    try:
        codes = wait_run(handle, timeout=120)
    finally:
        handle.stop_all()
    summaries = read_summaries(out, scn.sensor_names)
    assert all(c == 0 for c in codes.values()), codes
    for name in ("s1", "s3"):
        s = summaries[name]
        assert s["internal_errors"] == {}, (name, s["internal_errors"])
        assert s["scans"] == scn.num_scans and s["stop_reason"] == "end of run", name
    return scn, twin, summaries


def test_a_member_lying_with_its_own_key_is_repaired_as_in_the_twin(tmp_path):
    keys = tmp_path / "keys"
    make_keys(NETWORK, ["world", *PEERS], keys)
    scn, twin, summaries = _run(tmp_path, LYING, network=NETWORK, secure=keys)
    for name in ("s1", "s3"):
        s = summaries[name]
        assert s["rejected_total"] == 0, (name, s["rejected"])  # secure mode passes the lies
        trust = s["trust"]["neighbours"]
        got = trust["s2"]
        assert got["repaired_scan"] is not None and got["repaired_scan"] <= 3, (name, got)
        assert got["repairs"] >= 0.7 * got["rounds"], (name, got)
        assert trust["s3" if name == "s1" else "s1"]["state"] == "trusted", (name, trust)
        assert abs(s["mean_ospa_fused"] - twin.mean_ospa(name)) < 3.0, (
            name, s["mean_ospa_fused"], twin.mean_ospa(name))
    # the liar's estimates really were lies: s2 told one in every estimate it published
    assert summaries["s2"]["stats"]["estimates_out"] >= scn.num_scans


def test_a_biased_member_is_repaired_not_excluded_as_in_the_twin(tmp_path):
    """Registration alone (``fusion.trust_register``; repair off): s2's every estimate 30 m off
    along x (``s2:biased``; plain mode); once the offset test fires, each honest peer subtracts
    s2's estimated offset and keeps fusing it: at the end s2 is trusted with an offset of about
    30 m along x in both honest peers' summaries, as on the twin, and their fused OSPA is the
    twin's."""
    sets = [*SETS, "scenario.num_scans=60", "fusion.trust=true", "fusion.lie=s2:biased",
            "fusion.trust_register=true", "fusion.trust_repair=false"]
    scn, twin, summaries = _run(tmp_path, sets)
    for name in ("s1", "s3"):
        s = summaries[name]
        got = s["trust"]["neighbours"]["s2"]
        want = twin.peers[name].consensus.trust.n["s2"].registered
        assert got["state"] == "trusted" and got["registered"] is not None, (name, got)
        dx, dy = got["registered"]
        # the lie: +30 m along x; across, the drift fit's (TrustConfig.register_drift) rate
        # of the honest filters' own relative drift: 16.6 m at scan 60 on run 0 (8.2 with the
        # window's mean before issue 36), the twin's too (below)
        assert 15.0 < dx < 45.0 and abs(dy) < 20.0, (name, got)
        assert want is not None and abs(dx - want[0]) < 5.0 and abs(dy - want[1]) < 5.0, (
            name, got["registered"], want)
        assert abs(s["mean_ospa_fused"] - twin.mean_ospa(name)) < 3.0, (
            name, s["mean_ospa_fused"], twin.mean_ospa(name))


def test_a_member_telling_phantoms_is_repaired_not_excluded_as_in_the_twin(tmp_path):
    """Repair (``fusion.trust_repair``, on by default): s2 adds three confident phantom targets
    to every estimate (``s2:phantoms``; plain mode); each honest peer drops what nobody
    else corroborates and keeps fusing s2's real targets: s2 ends trusted, fused repaired in
    most rounds in both honest peers, as on the twin, and their fused OSPA is the twin's and
    better than with s2 left out. At 4 scans/s (the twin's numbers are the same at any
    speed): a round fused at its deadline without a neighbour's estimate is not the twin's,
    and at 10 scans/s the 90 ms deadline was missed on a machine at load 5-10 (18.07 against
    11.34); a round closes when every neighbour's estimate is in, the deadline is a backstop."""
    sets = [*SETS, "fusion.trust=true", "fusion.lie=s2:phantoms", "network.speed=4"]
    scn, twin, summaries = _run(tmp_path, sets)
    excluded = run_twin(load_scenario("seed000", overrides=parse_overrides(
        [*sets, "fusion.trust_repair=false"])), 0)
    for name in ("s1", "s3"):
        s = summaries[name]
        got = s["trust"]["neighbours"]["s2"]
        want = twin.peers[name].consensus.trust.n["s2"]
        assert got["state"] == "trusted" and got["repaired_scan"] is not None, (name, got)
        assert got["repairs"] >= 0.7 * got["rounds"], (name, got)
        assert want.repairs >= 0.7 * want.rounds, (name, want.repairs, want.rounds)
        assert abs(s["mean_ospa_fused"] - twin.mean_ospa(name)) < 3.0, (
            name, s["mean_ospa_fused"], twin.mean_ospa(name), s["stats"]["deadline_fusions"],
            s["scans_skipped_behind"], s["latency_ms_p99"])
        assert twin.mean_ospa(name) < excluded.mean_ospa(name), name
