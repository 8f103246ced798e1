"""Measurement flooding (peers/flooder.py): de-duplication, completion, loss, tuple counts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse.csgraph import shortest_path
from sensornet.peers.flooding import Flooder, flood, flooding_tuples
from sensornet.tracking.idpc import idpc


def _geometric(seed=3, n=20, radius=800.0):
    rng = np.random.default_rng(seed)
    while True:
        p = rng.uniform(-1000, 1000, size=(n, 2))
        A = (np.linalg.norm(p[:, None] - p[None], axis=-1) <= radius) & ~np.eye(n, dtype=bool)
        hops = shortest_path(A, unweighted=True)
        if np.isfinite(hops).all():
            return A, hops


def _scans(rng, n):
    return [rng.normal(size=(int(rng.integers(0, 15)), 2)) for _ in range(n)]


def test_every_peer_holds_exactly_the_scans_within_t_hops():
    A, hops = _geometric()
    rng = np.random.default_rng(1)
    scans = _scans(rng, len(A))
    for t in range(int(hops.max()) + 1):
        out = flood(A, scans, t)
        for i, held in enumerate(out.held):
            assert held == set(np.flatnonzero(hops[i] <= t).tolist())
    full = flood(A, scans, int(hops.max()))
    assert all(h == set(range(len(A))) for h in full.held)


@pytest.mark.parametrize("t", [1, 2, 3, 4, 6])
def test_tuple_count_equals_the_closed_form(t):
    A, hops = _geometric()
    rng = np.random.default_rng(2)
    scans = _scans(rng, len(A))
    sizes = np.array([len(z) for z in scans])
    np.testing.assert_array_equal(flood(A, scans, t).tuples_sent, flooding_tuples(hops, sizes, t))


def test_closed_form_by_hand_on_a_line():
    # 0 - 1 - 2, scans of 1, 2 and 3 points, 2 iterations: peer 0 sends its own (2 tuples) to
    # one neighbour, then peer 1's (4): 6; peer 1 sends its own and both ends' to two: 2*(4+2+6)
    A = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], dtype=bool)
    scans = [np.zeros((1, 2)), np.zeros((2, 2)), np.zeros((3, 2))]
    assert flood(A, scans, 2).tuples_sent.tolist() == [6, 24, 10]


def test_duplicates_are_dropped_and_counted():
    # a triangle: in iteration 2 each peer forwards the two scans it got to both neighbours,
    # and all four copies arrive at peers that hold them already: 4 duplicates per peer
    A = ~np.eye(3, dtype=bool)
    out = flood(A, [np.ones((1, 2)) * i for i in range(3)], 2)
    assert out.duplicates.tolist() == [4, 4, 4]
    assert all(h == {0, 1, 2} for h in out.held)


def test_completion_under_loss_needs_more_iterations_but_holds_true_copies():
    A, hops = _geometric()
    d = int(hops.max())
    rng = np.random.default_rng(4)
    scans = _scans(rng, len(A))
    lossy = flood(A, scans, d, loss=0.3, rng=np.random.default_rng(5))
    complete = np.mean([len(h) == len(A) for h in lossy.held])
    assert complete < 1.0  # 30 % loss: some peer misses some scan after `diameter` iterations
    # flooding needs a first copy only: with more iterations the redundancy fills the gaps
    # (a lost copy is not re-sent, so some scan may stay missing; count, do not assume)
    longer = flood(A, scans, 3 * d, loss=0.3, rng=np.random.default_rng(5))
    assert np.mean([len(h) for h in longer.held]) >= np.mean([len(h) for h in lossy.held])


def test_flooder_keeps_one_copy_counts_late_and_missing():
    f = Flooder(peer=0)
    f.own(7, np.zeros((2, 2)))
    assert f.receive(3, 7, np.ones((1, 2)))
    assert not f.receive(3, 7, np.ones((1, 2)))  # duplicate
    assert f.duplicates == 1
    assert [k for k, _ in f.outgoing()] == [(0, 7), (3, 7)]
    assert f.outgoing() == []  # never forwarded twice
    assert not f.receive(3, 7, np.ones((1, 2))) and f.outgoing() == []
    assert f.close(7, peers=5) == 3  # origins 1, 2, 4 never arrived
    assert not f.receive(4, 7, np.ones((1, 2)))  # after the deadline: late
    assert f.late == 1 and f.pooled(7) == {}


def test_without_scikit_learn_the_ftc_baseline_says_what_to_install(monkeypatch, capsys):
    """scikit-learn is an optional extra ('sensornet[baselines]'): without it an FTC peer,
    the FTC function and the seed-004 study stop with one line naming the extra; IDPC runs."""
    import sys

    from sensornet.peers.flood_parts import FloodEstimator
    from sensornet.tracking.idpc import MissingBaseline, ftc, idpc

    from sensornet.cli import main

    monkeypatch.setitem(sys.modules, "sklearn", None)  # import sklearn -> ImportError
    monkeypatch.setitem(sys.modules, "sklearn.cluster", None)
    with pytest.raises(MissingBaseline, match=r"pip install 'sensornet\[baselines\]'"):
        ftc(np.zeros((3, 2)), 2)
    with pytest.raises(MissingBaseline):
        FloodEstimator("s1", {}, method="ftc")
    assert len(idpc(np.random.default_rng(0).normal(0, 1, (20, 2)), 2).centres) >= 0
    assert main(["experiment", "seed004", "--runs", "1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sensornet[baselines]" in err[0], err


def test_a_host_decodes_a_forward_once_for_its_receivers_read_only():
    """peers.host_parts.SharedDecode: a forwarded scan set handed to several co-hosted
    neighbours (the same bytes object) is decoded once, equal to a decode of its own, and no
    receiver can write into the scans the others hold; a refusal is decoded each time."""
    from sensornet.peers.host_parts import SharedDecode
    from sensornet.protocol.codec import DEFAULT_LIMITS, Rejected, decode, encode
    from sensornet.protocol.messages import Forward, ScanSet

    scans = ScanSet({"s1": np.array([[1.0, 2.0], [3.0, 4.0]]), "s2": np.zeros((0, 2)),
                     "s3": np.array([[-5.0, 6.5]])})
    payload = encode(Forward("s2", 7, scans, round=1, seq=3, send_time=1.5))
    shared, limits = SharedDecode(), DEFAULT_LIMITS
    a, b = shared(payload, limits), shared(payload, limits)
    assert a is b and shared.hits == 1
    own = decode(payload, limits)
    assert (a.sender, a.k, a.round, a.seq) == (own.sender, own.k, own.round, own.seq)
    assert a.scans.scans.keys() == own.scans.scans.keys()
    assert all(np.array_equal(a.scans.scans[o], own.scans.scans[o]) for o in own.scans.scans)
    with pytest.raises(ValueError):
        a.scans.scans["s1"][0, 0] = 0.0
    with pytest.raises(Rejected):
        shared(payload[:-2], limits)
    assert shared.hits == 1


def test_bench_flooding_lists_each_hosts_peers_in_serving_order():
    """benchmarks/bench_flooding.py's per-host rows: the host's own peer order (not by name),
    each peer's median and p99 (sample floor(0.99 n)) and its median transit."""
    from benchmarks.bench_flooding import serving_order

    def summary(host, peers, lat, transit):
        return {"host": {"name": host, "peers": peers}, "latency_ms_samples": lat,
                "latency_breakdown_ms_median": {"transit": transit}}

    h1 = ["s9", "s10", "s2"]
    s = {"s2": summary("h1", h1, [30.0, 10.0, 20.0], 7.0),
         "s9": summary("h1", h1, [1.0, 3.0], 1.0),
         "s10": summary("h1", h1, [5.0], 4.0),
         "s1": {"latency_ms_samples": [2.0]}}  # a peer of its own process
    out = serving_order(s)
    assert [r[0] for r in out["h1"]] == h1
    assert out["h1"][2][1:] == (20.0, 30.0, 7.0) and out["h1"][0][1:] == (2.0, 3.0, 1.0)
    assert out["-"][0][0] == "s1" and math.isnan(out["-"][0][3])


def test_peers_pooling_the_same_points_cluster_them_once(monkeypatch):
    """peers.flood_parts._CLUSTERED: a second peer's extract of an equal pooled set (other
    array objects, the same numbers) reads the first one's centres, the same rows as its own
    clustering gives; a set one ulp apart, or an own scan alone, is clustered afresh."""
    import sensornet.peers.flood_parts as fp
    from sensornet.protocol.messages import ScanSet

    monkeypatch.setattr(fp, "_CLUSTERED", {})
    calls = []

    def counted(points, S, params, rng):
        calls.append(len(points))
        return idpc(points, S, params, rng)

    monkeypatch.setattr(fp, "idpc", counted)
    roster = dict.fromkeys(("a", "b", "c"))
    rng = np.random.default_rng(3)
    target = np.array([[100.0, -200.0], [400.0, 350.0]])
    raw = {o: np.vstack([target + rng.normal(0, 3, (2, 2)), rng.uniform(-900, 900, (4, 2))])
           for o in roster}

    def pooled():
        return ScanSet({o: z.copy() for o, z in raw.items()})

    a, b = (fp.FloodEstimator(n, roster, seed=7) for n in ("a", "b"))
    first, second = a.extract(pooled()), b.extract(pooled())
    assert len(calls) == 1 and np.array_equal(first, second) and len(first) == 2
    monkeypatch.setattr(fp, "_CLUSTERED", {})
    assert np.array_equal(b.extract(pooled()), first) and len(calls) == 2  # its own: equal
    moved = pooled()
    moved.scans["c"][0, 0] = np.nextafter(moved.scans["c"][0, 0], np.inf)
    b.extract(moved)
    assert len(calls) == 3
    a.extract(ScanSet({"a": raw["a"]}))
    b.extract(ScanSet({"a": raw["a"].copy()}))
    assert len(calls) == 5 and len(fp._CLUSTERED) == 2  # own scans: never kept
