"""Holder masks checked where they arrive (issue 33, hostile input; docs/security.md "Label
masks", docs/labelled-tracking.md "Same-scan ties broken by support"): a member that lies
could set every bit of its shared labels' masks and win every same-scan tie. A receiver takes
from a neighbour's mask only what that neighbour can vouch for (peers.label_support.reach_masks)
and counts what it drops; honest masks are never cut, so honest ties end as before."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.label_support import (
    KEEP_SCANS,
    ORIGIN_MASK,
    SUPPORT_BITS,
    SUPPORT_SHIFT,
    LabelSupport,
    decode,
    mask_ints,
    peer_bit,
    reach_by_name,
    reach_masks,
)
from sensornet.peers.labelling import label_fused
from sensornet.peers.lmb_estimator import PUBLISHED_BASE as PB
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.sim.run.peers import consensus_options
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import SHARED_ORIGIN as S
from sensornet.tracking.label_keys import cell_index
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.models import ConstantVelocity, LinearPosition

LOW = int(cell_index(np.array([[199.0, 100.0]]), 200.0)[0])  # cell [0, 200)
HIGH = int(cell_index(np.array([[222.0, 100.0]]), 200.0)[0])  # cell [200, 400)
ALL = (1 << SUPPORT_BITS) - 1


def _peer(origin: int) -> LmbEstimator:
    f = LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(5.0), 0.99, 2.5e-7),
                  origin=origin, shared_origin=S)
    return LmbEstimator(f, origin=origin, tentative_threshold=0.15)


def _adjacency(n: int, links: list[tuple[int, int]]) -> np.ndarray:
    A = np.zeros((n, n), dtype=int)
    for a, b in links:
        A[a, b] = A[b, a] = 1
    return A


def _run(bias: list[float], links: list[tuple[int, int]], checked: bool,
         liar: int | None = None, scans: int = 7):
    """As tests/test_label_support.py's harness (peers of origins 1.. see one target at ``x =
    210 + k`` with a bias each; one fusion round a scan as peers.consensus.Consensus runs it,
    masks on the wire), with the masks checked by each receiver (``checked``) and peer
    ``liar`` setting every bit of its shared labels' masks on the wire (its own fusion
    honest). Returns, per peer, the label of its published track at each scan, and each
    peer's LabelSupport."""
    n = len(bias)
    A = _adjacency(n, links)
    names = [str(i) for i in range(n)]
    peers = [_peer(i + 1) for i in range(n)]
    sup = [LabelSupport(peer_bit(i + 1), dict(reach_by_name(names, A, range(1, n + 1), i))
                        if checked else None) for i in range(n)]
    nbrs = [list(np.flatnonzero(A[i])) for i in range(n)]
    seen: list[list[tuple]] = [[] for _ in range(n)]
    for k in range(1, scans + 1):
        outs = []
        for i, e in enumerate(peers):
            e.begin_scan(k)
            outs.append(e.step(1, np.array([[210.0 + k + bias[i], 100.0]])))
        wire = []
        for i, out in enumerate(outs):
            lab = out.labels["posterior"]
            if len(lab):
                seen[i].append(tuple(lab[0].tolist()))
            sup[i].own(lab, k)
            lab, _ = sup[i].encode(lab)
            if i == liar:
                lab = lab.copy()
                lab[(lab[:, 0] & ORIGIN_MASK) == S, 0] |= ALL << SUPPORT_SHIFT
            wire.append((out.published["posterior"], lab))
        for i, e in enumerate(peers):
            inputs = [(outs[i].published["posterior"], outs[i].labels["posterior"])]
            for j in nbrs[i]:
                mix, lab = wire[j]
                lab, masks = decode(lab)
                sup[i].heard(names[j], lab, masks, k, 0)
                inputs.append((mix, lab))
            fused = next((m for m, _ in inputs if len(m)), None)
            if fused is not None:
                e.relabel(label_fused(fused, inputs, e.origin, k, bump=e.fresh_stamps(),
                                      support=sup[i]).own)
    return seen, sup


MESH3 = [(0, 1), (0, 2), (1, 2)]
LINE4 = [(0, 1), (1, 2), (2, 3)]


@pytest.mark.parametrize("links, bias", [
    (MESH3, [-12.0, -8.0, -6.0]),  # peer 0 alone in the lower cell, 1 and 2 in the higher
    (LINE4, [-12.0, -8.0, -6.0, -7.0]),  # 0 - 1 - 2 - 3, peer 0 at the end alone below
])
def test_a_member_setting_every_bit_no_longer_wins_a_tie_it_should_lose(links, bias):
    n = len(bias)
    honest, _ = _run(bias, links, checked=True)
    assert {s[-1] for s in honest} == {(S, 2, PB + HIGH)}, honest
    # unchecked, the liar's mask (every bit) takes the target's id at every honest peer
    lied, _ = _run(bias, links, checked=False, liar=0)
    assert {s[-1] for s in lied[1:]} == {(S, 2, PB + LOW)}, lied
    # checked, the honest peers keep the better-supported stamp, and count what they dropped
    kept, sup = _run(bias, links, checked=True, liar=0)
    assert {s[-1] for s in kept[1:]} == {(S, 2, PB + HIGH)}, kept
    assert all(sup[j].clipped > 0 for j in range(1, n) if (0, j) in links), \
        [s.clipped for s in sup]
    # what the liar's label holds at its neighbour 1: the liar's own bit, and in the line the
    # far peer 3 once the hops allow it (it cannot be checked from peer 1)
    got = mask_ints(sup[1].mask_of(np.array([[S, 2, PB + LOW]])))[0]
    assert got & (peer_bit(2) | peer_bit(3)) == 0 and got & peer_bit(1)
    assert got & ~(peer_bit(1) | peer_bit(4)) == 0, bin(got)


@pytest.mark.parametrize("links, bias", [
    (MESH3, [-12.0, -8.0, -6.0]),
    ([(0, 1), (1, 2)], [-12.0, -8.0, -6.0]),
    ([(0, 1)], [-12.0, -8.0]),
    (LINE4, [-6.0, -12.0, -8.0, -13.0]),
    ([(0, 1), (1, 2), (2, 3), (3, 4), (4, 0), (0, 2)], [-12.0, -6.0, -13.0, -7.0, -8.0]),
])
def test_honest_masks_are_never_cut(links, bias):
    plain, a = _run(bias, links, checked=False)
    checked, b = _run(bias, links, checked=True)
    assert plain == checked
    assert [s.clipped for s in b] == [0] * len(bias)
    for x, y in zip(a, b, strict=True):  # the same masks at every peer, bit for bit
        np.testing.assert_array_equal(x.keys, y.keys)
        np.testing.assert_array_equal(x.masks, y.masks)


def test_reach_masks_on_a_line():
    # 0 - 1 - 2 - 3 (origins 1-4), seen from peer 1: it hears 0 and 2 itself, 3 is far
    A = _adjacency(4, LINE4)
    r = reach_masks(A, [1, 2, 3, 4], 1)
    assert sorted(r) == [0, 2]
    b = [peer_bit(o) for o in (1, 2, 3, 4)]
    assert mask_ints(r[0]) == [b[0], b[0], b[0], b[0] | b[3]]  # 3 hops from 0
    assert mask_ints(r[2]) == [b[2], b[2] | b[3], b[2] | b[3], b[2] | b[3]]
    # more peers than a word's bits: each peer its own bit (two words), none shared
    n = SUPPORT_BITS + 3
    ring = _adjacency(n, [(i, (i + 1) % n) for i in range(n)])
    r = reach_masks(ring, list(range(1, n + 1)), 0)
    assert r[1].shape == (n // 2 + 1, 2)
    # neighbour 1 (origin 2) vouches at last for itself and every peer 0 does not hear
    assert mask_ints(r[1][-1]) == sum(peer_bit(o) for o in range(2, n))


def test_heard_drops_what_the_sender_cannot_vouch_for_and_counts_it():
    A = _adjacency(4, LINE4)
    sup = LabelSupport(peer_bit(2), dict(reach_by_name(list("abcd"), A, [1, 2, 3, 4], 1)))
    lab = np.array([[S, 5, PB + HIGH], [S, 5, PB + LOW], [7, 5, PB + 1]], dtype=np.int64)
    b1, b2, b3, b4 = (peer_bit(o) for o in (1, 2, 3, 4))
    sup.own(lab[:1], 5)  # we stamped the first
    # "a" sends at scan 5: its own bit passes; ours, c's (our neighbour) and d's (3 hops from
    # a: not before scan 7) do not; the own label's mask is nonsense
    lost = sup.heard("a", lab, np.array([b1 | b2, b1 | b3 | b4, ALL]), 5)
    assert mask_ints(sup.mask_of(lab)) == [b1 | b2, b1, 0]
    assert lost == 2 and sup.clipped == 2  # our own bit was known: not counted
    # c vouches for itself, d one hop from it; at scan 7 a may vouch for d
    assert sup.heard("c", lab[1:2], np.array([b3 | b4]), 5) == 0
    assert sup.heard("a", lab[1:2], np.array([b1 | b4]), 7) == 0
    np.testing.assert_array_equal(sup.counts(lab), [2, 3, 0])
    # a stranger vouches for nothing; labels past the kept window pass as they come
    assert sup.heard("x", lab[:1], np.array([b4]), 5) == 1
    old = np.array([[S, 1, PB + 3]], dtype=np.int64)
    assert sup.heard("a", old, np.array([ALL]), 2 + KEEP_SCANS) == 0
    assert mask_ints(sup.mask_of(old))[0] == ALL
    # unchecked (no reach): as before, every bit taken
    free = LabelSupport(peer_bit(2))
    assert free.heard("a", lab[1:2], np.array([ALL]), 5) == 0 and free.counts(lab[1:2])[0] == 39


def test_consensus_options_carry_each_neighbours_reach():
    scn = load_scenario("seed000", overrides={"network.filter": "lmb"})
    names = scn.sensor_names
    o = consensus_options(scn, names[0])
    assert o.label_support and {n for n, _ in o.label_reach} == set(o.neighbours)
    for n, table in o.label_reach:  # a full mesh of 3: a neighbour vouches for itself only
        assert set(table) == {peer_bit(sorted(names).index(n) + 1)}
    off = consensus_options(load_scenario("seed000", overrides={"network.filter": "gmphd"}),
                            names[0])
    assert off.label_reach == ()


def _twin_ids(forge: bool | None, checked: bool, scans: int = 30):
    """seed 000's LMB twin (run 100, ``scans`` scans) with s3 honest (``forge`` None) or
    forging (every holder bit, its stamps moved to the next cell index; ``False``: every bit
    only); per honest peer its fused track ids by scan, and each peer's label-mask count."""
    from sensornet.sim.run.peers import make_peer
    from sensornet.sim.run.twin import run_twin
    from sensornet.sim.studies.labelled.mask_lie import MaskLiarCore

    scn = load_scenario("seed000", overrides={"network.filter": "lmb",
                                              "scenario.num_scans": scans})
    changes = {} if checked else {"label_reach": ()}
    peers = {n: make_peer(scn, n, 100, **changes) for n in scn.sensor_names}
    if forge is not None:
        peers["s3"] = MaskLiarCore(peers["s3"], "forger" if forge else "liar")
    run_twin(scn, 100, peers=peers)
    ids = {}
    for n in ("s1", "s2"):
        t = peers[n].scorer.results.table(n)
        ids[n] = [(k, [tuple(i) for i in tid]) for k, e, tid in
                  zip(t["scan"], t["estimate"], t["track_ids"], strict=True) if e == "fused"]
    return ids, {n: c.rejected["label-mask"] for n, c in peers.items()}


def test_on_the_twin_a_forging_member_takes_ids_only_unchecked_and_is_counted():
    honest, cut = _twin_ids(None, True)
    assert set(cut.values()) == {0}
    forged, _ = _twin_ids(True, False)
    assert forged != honest  # unchecked, its mask moves the honest peers' ids
    kept, cut = _twin_ids(True, True)
    assert kept == honest  # checked, the honest peers' fused ids are the honest run's
    assert cut["s1"] > 0 and cut["s2"] > 0  # (s3 counts its own forged labels coming back)
