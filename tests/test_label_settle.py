"""Ids that do not switch while they spread (issue 33): confirmation that waits until a label
is as old as the peer's eccentricity (tracking.labels.Confirmation ``settle``,
peers.labelling.settle_scans), labels stamped when first published and again when they
return after a long gap (tracking.labels.Publication), and a 5-peer chain twin where every
peer's confirmed id of a target is the same from its first confirmed scan."""

from __future__ import annotations

import re

import numpy as np
import pytest
from sensornet.peers.estimators import GmphdEstimator
from sensornet.peers.labelling import SETTLE_MARGIN, settle_scans
from sensornet.sim.run.peers import consensus_options
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.labelled.study import peer_tables, truth_table
from sensornet.sim.world import generate_run
from sensornet.sim.world.graphs import network_scenario
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.labels import (
    PUBLISHED_BASE,
    Confirmation,
    LabelledMixture,
    LabelMatch,
    Publication,
)
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.reduction import Reducer
from sensornet.tracking.track_metrics import (
    TrackTable,
    clear_match,
    first_match_delay,
    label_agreement,
)


def _lm(labels, weights) -> LabelledMixture:
    n = len(weights)
    return LabelledMixture(GaussianMixture(np.asarray(weights, float), np.zeros((n, 4)),
                                           np.tile(np.eye(4), (n, 1, 1))),
                           np.asarray(labels, dtype=np.int64).reshape(n, 3))


# -- confirmation that waits for the label to settle ------------------------------------------
def test_settle_holds_a_young_label_tentative_until_it_is_old_enough():
    """Label born at scan 10, above 0.5 every scan from 10: with settle 5 it is confirmed at
    scan 15 (10 + 5), not at 12 (3 counts); without settle at 12; an unknown label never."""
    lab = [[1, 10, 0]]
    plain, settled = Confirmation(3), Confirmation(3, settle=5)
    got_plain, got_settled = [], []
    for k in range(10, 18):
        plain.observe(_lm(lab, [0.9]), k)
        settled.observe(_lm(lab, [0.9]), k)
        got_plain.append(int(plain.status(np.array(lab))[0]))
        got_settled.append(int(settled.status(np.array(lab))[0]))
    assert got_plain == [0, 0, 1, 1, 1, 1, 1, 1]  # scans 10..17
    assert got_settled == [0, 0, 0, 0, 0, 1, 1, 1]
    # an old label arriving late: settled already, only the 3 counts are waited for
    late = Confirmation(3, settle=5)
    for k in (30, 31, 32):
        late.observe(_lm([[4, 2, 7]], [0.8]), k)
    assert late.status(np.array([[4, 2, 7], [4, 2, 8]])).tolist() == [1, 0]


def test_settle_needs_the_scan_and_a_non_negative_value():
    with pytest.raises(ValueError, match="needs the scan k"):
        Confirmation(3, settle=2).observe(_lm([[0, 1, 0]], [1.0]))
    with pytest.raises(ValueError, match="settle must be at least 0"):
        Confirmation(3, settle=-1)


def _bfs_eccentricity(A: np.ndarray, i: int) -> int:
    """Independent reference: breadth-first search in plain Python."""
    dist = {i: 0}
    frontier = [i]
    while frontier:
        nxt = []
        for u in frontier:
            for v in np.flatnonzero(A[u]):
                if int(v) not in dist:
                    dist[int(v)] = dist[u] + 1
                    nxt.append(int(v))
        frontier = nxt
    return max(dist.values())


def test_settle_scans_is_the_eccentricity_in_hops():
    rng = np.random.default_rng(33)
    chain = np.zeros((5, 5), bool)
    for a in range(4):
        chain[a, a + 1] = chain[a + 1, a] = True
    assert [settle_scans(chain, i, margin=0) for i in range(5)] == [4, 3, 2, 3, 4]
    assert [settle_scans(chain, i, margin=2) for i in range(5)] == [6, 5, 4, 5, 6]
    for _ in range(20):
        n = int(rng.integers(2, 12))
        A = np.triu(rng.random((n, n)) < 0.3, 1)
        A = A | A.T
        for i in range(n):
            assert settle_scans(A, i, margin=0) == _bfs_eccentricity(A, i)
    lone = np.zeros((3, 3), bool)
    lone[0, 1] = lone[1, 0] = True
    assert settle_scans(lone, 2) == 0 and settle_scans(lone, 0) == 1  # no relay: no margin
    full = ~np.eye(4, dtype=bool)
    assert [settle_scans(full, i, margin=5) for i in range(4)] == [1, 1, 1, 1]


# -- labels stamped at (re)publication --------------------------------------------------------
def test_publication_stamps_own_labels_once_and_again_after_a_long_gap():
    pub = Publication(origin=2, gap=2)
    own, theirs = [2, 5, 0], [7, 4, 1]
    # scan 5: own label light (not published), theirs heavy (a network label: never stamped)
    out = pub.stamp(np.array([own, theirs]), np.array([0.3, 0.9]), 0.5, 5)
    assert out.tolist() == [own, theirs]
    # scan 6: own heavy on one of its two components: both take (2, 6, BASE)
    out = pub.stamp(np.array([own, own, theirs]), np.array([0.9, 0.1, 0.9]), 0.5, 6)
    stamped = [2, 6, PUBLISHED_BASE]
    assert out.tolist() == [stamped, stamped, theirs]
    # two missed scans (light), then back: the stamp stays (gap 2)
    for k in (7, 8):
        assert pub.stamp(np.array([stamped]), np.array([0.05]), 0.5, k).tolist() == [stamped]
    assert pub.stamp(np.array([stamped]), np.array([0.9]), 0.5, 9).tolist() == [stamped]
    # three missed scans: stamped anew on return
    for k in (10, 11, 12):
        pub.stamp(np.array([stamped]), np.array([0.05]), 0.5, k)
    assert pub.stamp(np.array([stamped]), np.array([0.9]), 0.5, 13).tolist() == [
        [2, 13, PUBLISHED_BASE]]
    # a network label given by a relabel counts as published: not stamped when heavy
    pub.adopt(np.array([[9, 3, 4]]))
    assert pub.stamp(np.array([[9, 3, 4]]), np.array([0.9]), 0.5, 14).tolist() == [[9, 3, 4]]
    # gap None: never stamped again
    keep = Publication(origin=2, gap=None)
    keep.stamp(np.array([own]), np.array([0.9]), 0.5, 1)
    for k in range(2, 12):
        keep.stamp(np.array([[2, 1, PUBLISHED_BASE]]), np.array([0.01]), 0.5, k)
    assert keep.stamp(np.array([[2, 1, PUBLISHED_BASE]]), np.array([0.9]), 0.5,
                      12).tolist() == [[2, 1, PUBLISHED_BASE]]


def _estimator(pd: float) -> GmphdEstimator:
    birth = GaussianMixture(np.array([0.1]), np.array([[0.0, 0.0, 0.0, 0.0]]),
                            np.diag([100.0, 100.0, 100.0, 100.0])[None])
    f = GMPHDFilter(motion=ConstantVelocity(1.0, 2.0),
                    sensors=[SensorParams(LinearPosition(10.0), pd, 1e-6)], birth=birth,
                    survival_probability=0.99, reducer=Reducer(1e-5, 4.0, 50))
    return GmphdEstimator(f, origin=3)


def test_a_track_that_misses_two_scans_keeps_its_id():
    """A GM-PHD peer's target detected at scans 1-6, missed at 7 and 8 (its weight falls to
    ~0.01, unpublished), detected again from 9: the id it published at its first publication
    is the id it publishes after the misses."""
    est = _estimator(0.9)
    ids = {}
    for k in range(1, 14):
        x = 5.0 * k
        z = np.zeros((0, 2)) if k in (7, 8) else np.array([[x, 0.0]])
        est.begin_scan(k)
        out = est.step(1, z)
        pub = out.labels["posterior"]
        ids[k] = {tuple(r) for r in pub.tolist()}
    first = next(k for k in ids if ids[k])
    assert len(ids[first]) == 1 and next(iter(ids[first]))[2] >= PUBLISHED_BASE
    assert ids[7] == ids[8] == set()  # missed: below the publication threshold
    assert all(ids[k] == ids[first] for k in range(first, 14) if k not in (7, 8))
    # the relabel's winner counts as published: adopted, it is never stamped over
    (label,) = ids[13]
    win = np.array([[0, 1, 5]])
    est.relabel(LabelMatch(np.array([label]), win, np.zeros(1)))
    est.begin_scan(14)
    assert {tuple(r) for r in est.step(1, np.array([[70.0, 0.0]])).labels["posterior"]
            .tolist()} == {(0, 1, 5)}


# -- a 5-peer chain: one confirmed id per target from the first confirmed scan ----------------
@pytest.fixture(scope="module")
def chain_twin(tmp_path_factory):
    text = network_scenario(5, 2, scans=60, detection_probability=0.99, name="chain5")
    chain = ", ".join(f'["p{a:02d}", "p{a + 1:02d}"]' for a in range(4))
    text = re.sub(r"edges = \[.*\]", f"edges = [{chain}]", text)
    path = tmp_path_factory.mktemp("chain") / "chain5.toml"
    path.write_text(text)
    scn = load_scenario(str(path), overrides={"network.filter": "gmphd",
                                              "fusion.rule": "hybrid"})
    return scn, run_twin(scn, 0)


def test_chain_peers_confirm_one_id_per_target_from_the_first_confirmed_scan(chain_twin):
    scn, twin = chain_twin
    names = scn.sensor_names
    ecc = np.array([4, 3, 2, 3, 4])  # hops to the far end of the chain
    assert [consensus_options(scn, p).confirm_settle for p in names] == list(ecc + SETTLE_MARGIN)
    truth, _ = generate_run(scn, 0)
    T = truth_table(truth)
    code: dict = {}
    every = peer_tables(twin, names, "fused", code)
    conf = peer_tables(twin, names, "fused", code, confirmed=True)
    ids_all, ids_conf = {}, {}
    for tabs, ids in ((every, ids_all), (conf, ids_conf)):
        for tab in tabs.values():
            cl = clear_match(T, tab, 200.0)
            for j, tid in enumerate(cl.truth_ids):
                got = cl.match[:, j]
                ids.setdefault(int(tid), []).append(cl.est_ids[got[got >= 0]])
    # the ids do move while they spread over the chain (all fused tracks) ...
    moved = sum(int((np.diff(s) != 0).sum()) for seqs in ids_all.values() for s in seqs)
    assert moved > 0
    # ... but every confirmed target-scan at every peer shows the target's one id
    assert len(ids_conf) == len(np.unique(T.id))
    for tid, seqs in ids_conf.items():
        assert sum(len(s) for s in seqs) > 0, tid
        assert len(set(np.concatenate(seqs).tolist())) == 1, (tid, [np.unique(s) for s in seqs])
    assert label_agreement(conf, T, gate=200.0)["agreement"] == 1.0
    # and a peer confirms no earlier than its settle after the label's first publication
    for p in names:
        t = twin.peers[p].scorer.results.table(p)
        settle = consensus_options(scn, p).confirm_settle
        for k, e, ids, st in zip(t["scan"], t["estimate"], t["track_ids"], t["track_status"],
                                 strict=True):
            if e == "fused":
                assert all(k - i[1] >= settle for i, s in zip(ids, st, strict=True) if s)


def test_first_match_delay_counts_scans_from_birth_to_the_first_match():
    """Hand case: truth 1 from scan 1, first matched at 4 (delay 3); truth 2 from scan 2,
    matched at once (0); truth 3 never matched (left out); an estimate far away never
    matches."""
    truth = TrackTable(np.array([1, 2, 3, 4, 2, 3, 3]), np.array([1, 1, 1, 1, 2, 2, 3]),
                       np.array([[0, 0], [1, 0], [2, 0], [3, 0], [50, 0], [51, 0],
                                 [900, 900]], float))
    est = TrackTable(np.array([4, 2, 3, 1]), np.array([7, 8, 8, 9]),
                     np.array([[3, 1], [50, 1], [51, 1], [-500, -500]], float))
    assert first_match_delay(truth, est, gate=10.0).tolist() == [3.0, 0.0]
    assert first_match_delay(truth, est, gate=10.0, scans=np.arange(1, 6)).tolist() == [3.0,
                                                                                         0.0]
