"""The sans-I/O peer state machine, driven by the discrete-event twin (no network)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Estimate, Scan
from sensornet.sim.run.peers import consensus_options, make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario, with_birth_model
from sensornet.sim.studies.seed000.montecarlo import run_once
from sensornet.sim.world.build import adjacency
from sensornet.tracking.mixture import GaussianMixture

KEYS = Keys("twin")


@pytest.fixture(scope="module")
def scn():
    s = with_birth_model(load_scenario("seed000"), "truth")
    return dataclasses.replace(s, num_scans=40)


def _per_scan(twin, name, which):
    return twin.ospa[name][which]


def _published(outputs, channel):
    return [o for o in outputs if type(o).__name__ == "Publish" and o.channel == channel]


def test_zero_delay_network_equals_offline_fusion(scn):
    """A zero-delay twin's fused OSPA is the offline experiment's (``fusion.support = 0``,
    pinned: the offline fusion has no ids, so no support rule, issue 33)."""
    # full mesh of 3: Metropolis weights are 1/3 each, the offline experiment's uniform weights
    scn = dataclasses.replace(scn, fusion=dataclasses.replace(scn.fusion, support=0))
    twin = run_twin(scn, run=3)
    offline = run_once(scn, 3)
    fused = _per_scan(twin, "s2", "fused")
    local = _per_scan(twin, "s2", "local")
    ks = sorted(fused)
    assert ks == list(range(1, scn.num_scans + 1))
    offline_fused = offline.ospa[f"fused s2 ({scn.fusion.rule})"]
    np.testing.assert_allclose([fused[k] for k in ks], offline_fused, atol=1e-9)
    np.testing.assert_allclose([local[k] for k in ks], offline.ospa["local s2"], atol=1e-9)
    for name, peer in twin.peers.items():
        assert peer.consensus.stats.fusions == scn.num_scans
        assert peer.consensus.stats.fused_inputs == 2 * scn.num_scans, name
        assert peer.consensus.stats.deadline_fusions == 0


def test_consensus_rounds_publish_one_estimate_per_round(scn):
    s = dataclasses.replace(scn, network=dataclasses.replace(scn.network, rounds=3))
    twin = run_twin(s, run=0)
    for peer in twin.peers.values():
        assert peer.consensus.stats.estimates_out == 3 * s.num_scans
        assert peer.consensus.stats.fusions == 3 * s.num_scans
    # after 3 rounds on a complete graph every peer holds (nearly) the same density
    a, b = twin.tracks["s1"][s.num_scans], twin.tracks["s3"][s.num_scans]
    assert a.shape == b.shape


def test_late_estimates_are_predicted_by_nale(scn):
    interval = scn.scan_period / scn.network.speed

    def delay(sender, receiver, msg):  # s1 -> s2 arrives 1.5 scan intervals late
        return 1.5 * interval if (sender, receiver) == ("s1", "s2") else 0.0

    twin = run_twin(scn, run=1, delay=delay)
    s2 = twin.peers["s2"]
    assert s2.consensus.stats.deadline_fusions >= scn.num_scans - 2
    assert s2.consensus.nale.counts.late >= scn.num_scans - 3
    # every fusion still had both neighbours (s1 through the NALE buffer, one or two scans old)
    assert s2.consensus.stats.fused_inputs >= 2 * scn.num_scans - 3
    assert set(twin.ages["s2"]) <= {0, 1, 2}
    assert s2.rejected == {}  # late estimates are within the window, not rejected


def test_drop_late_policy_fuses_fewer_inputs(scn):
    s = dataclasses.replace(scn, network=dataclasses.replace(scn.network, policy="drop-late"))
    interval = s.scan_period / s.network.speed

    def delay(sender, receiver, msg):
        return 1.5 * interval if (sender, receiver) == ("s1", "s2") else 0.0

    s2 = run_twin(s, run=1, delay=delay).peers["s2"]
    assert s2.consensus.nale.counts.dropped_late >= s.num_scans - 3
    assert s2.consensus.stats.fused_inputs <= s.num_scans + 2


def test_lost_messages_do_not_stall_the_peer(scn):
    twin = run_twin(scn, run=2, delay=lambda s, r, m: None if s == "s3" else 0.0)
    s2 = twin.peers["s2"]
    assert len(twin.tracks["s2"]) == scn.num_scans
    assert s2.consensus.stats.deadline_fusions == scn.num_scans  # always waited for s3, then fused


def test_peer_that_left_is_not_waited_for(scn):
    peer = make_peer(scn, "s2")
    peer.liveliness("s3", False, 0.0)
    out = peer.receive(KEYS.scan("s2"), encode(Scan("s2", 1, np.zeros((0, 2)))), 0.0)
    assert _published(out, "estimate")
    est = Estimate("s1", 1, GaussianMixture.empty(4))
    out = peer.receive(KEYS.estimate("s1"), encode(est), 0.01)
    assert [o.channel for o in _published(out, "tracks")] == ["tracks"]
    assert peer.consensus.stats.deadline_fusions == 0
    assert list(peer.departures) == [("s3", "left", 0)]


def test_stale_scans_and_strangers_are_counted(scn):
    peer = make_peer(scn, "s1")
    scan = lambda k: encode(Scan("s1", k, np.zeros((0, 2))))  # noqa: E731
    peer.receive(KEYS.scan("s1"), scan(2), 0.0)
    assert _published(peer.receive(KEYS.scan("s1"), scan(2), 0.1), "estimate") == []
    assert _published(peer.receive(KEYS.scan("s1"), scan(1), 0.1), "estimate") == []
    assert peer.stale_scans == 2 and peer.rejected["stale"] == 2
    out = peer.receive(KEYS.estimate("mallory"),
                       encode(Estimate("mallory", 2, GaussianMixture.empty(4))), 0.2)
    assert _published(out, "tracks") == []
    assert peer.rejected["not-neighbour"] == 1


def test_topologies(scn):
    for topo, degrees in (("full", [2, 2, 2]), ("line", [1, 2, 1]), ("ring", [2, 2, 2]),
                          ("star", [1, 2, 1])):
        s = dataclasses.replace(scn, network=dataclasses.replace(scn.network, topology=topo))
        names, A = adjacency(s)
        assert list(A.sum(axis=1)) == degrees, topo
        assert np.array_equal(A, A.T)
    s = dataclasses.replace(scn, network=dataclasses.replace(scn.network, topology="line"))
    opts = consensus_options(s, "s1")
    assert opts.neighbours == ("s2",)
    assert dict(opts.degrees) == {"s1": 1, "s2": 2}
