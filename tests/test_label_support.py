"""Same-scan ties of shared labels broken by support (issue 33, docs/labelled-tracking.md,
"Same-scan ties broken by support"): a target's first plots fall in two neighbouring 200 m
birth cells at different LMB peers, so two shared stamps of one scan name it; the network rule
picked the lower cell, even when one peer held it and the others the other cell. With
``network.label_support`` each label carries the mask of the peers that stamped it (OR-ed over
the neighbours'), and the better-supported label wins at every peer."""

from __future__ import annotations

import numpy as np
from sensornet.peers.label_support import SUPPORT_SHIFT, LabelSupport, decode, peer_bit
from sensornet.peers.labelling import label_fused
from sensornet.peers.lmb_estimator import PUBLISHED_BASE as PB
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import SHARED_ORIGIN as S
from sensornet.tracking.label_keys import cell_index
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition

LOW = int(cell_index(np.array([[199.0, 100.0]]), 200.0)[0])  # cell [0, 200)
HIGH = int(cell_index(np.array([[222.0, 100.0]]), 200.0)[0])  # cell [200, 400)


def _peer(origin: int) -> LmbEstimator:
    f = LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(5.0), 0.99, 2.5e-7),
                  origin=origin, shared_origin=S)
    return LmbEstimator(f, origin=origin, tentative_threshold=0.15)


def _run(bias: list[float], links: list[tuple[int, int]], support: bool,
         scans: int = 7) -> list[list[tuple]]:
    """Peers of origins 1.. see one target at ``x = 210 + k`` with a bias each (a plot below
    200 m falls in the lower cell), linked by ``links``; one fusion round a scan as
    ``peers.consensus.Consensus`` runs it (own labels published with the own bit, masks on the
    wire in the origin column, decoded and OR-ed by the receivers). Returns, per peer, the label
    of its published track at each scan from its first publication."""
    n = len(bias)
    peers = [_peer(i + 1) for i in range(n)]
    sup = [LabelSupport(peer_bit(i + 1)) if support else None for i in range(n)]
    nbrs = [sorted({b for a, b in links if a == i} | {a for a, b in links if b == i})
            for i in range(n)]
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
            if sup[i] is not None:
                sup[i].own(lab, k)
                lab, extra = sup[i].encode(lab)
                assert extra is None  # up to 39 peers: the origin column alone
            wire.append((out.published["posterior"], lab))
        for i, e in enumerate(peers):
            own = (outs[i].published["posterior"], outs[i].labels["posterior"])
            inputs = [own]
            for j in nbrs[i]:
                mix, lab = wire[j]
                if sup[i] is not None:
                    lab, masks = decode(lab)
                    sup[i].add(lab, masks)
                inputs.append((mix, lab))
            fused = next((m for m, _ in inputs if len(m)), None)
            if fused is not None:
                e.relabel(label_fused(fused, inputs, e.origin, k, bump=e.fresh_stamps(),
                                      support=sup[i]).own)
    return seen


def test_the_better_supported_stamp_wins_at_every_peer():
    # peer 1's plot falls 1 m across the edge (the lower cell), peers 2 and 3 3-5 m inside
    assert LOW < HIGH
    for support, want in ((False, LOW), (True, HIGH)):
        seen = _run([-12.0, -8.0, -6.0], [(0, 1), (0, 2), (1, 2)], support)
        ends = {s[-1] for s in seen}
        assert ends == {(S, 2, PB + want)}, (support, seen)
    # with support the two peers that stamped the higher cell never change their id
    seen = _run([-12.0, -8.0, -6.0], [(0, 1), (0, 2), (1, 2)], True)
    assert set(seen[1]) == set(seen[2]) == {(S, 2, PB + HIGH)}


def test_support_travels_with_the_label_over_a_line():
    # 1 - 2 - 3: peer 1 (lower cell) hears peer 2 only; 3's stamp of the higher cell reaches
    # 1 through 2's mask a scan later, and every peer ends on the higher cell
    seen = _run([-12.0, -8.0, -6.0], [(0, 1), (1, 2)], True)
    assert {s[-1] for s in seen} == {(S, 2, PB + HIGH)}, seen
    seen = _run([-12.0, -8.0, -6.0], [(0, 1), (1, 2)], False)
    assert {s[-1] for s in seen} == {(S, 2, PB + LOW)}, seen


def test_a_tie_in_support_keeps_the_lowest_cell():
    # two peers, one stamp each: equal support, the order's index decides at both
    seen = _run([-12.0, -8.0], [(0, 1)], True)
    assert {s[-1] for s in seen} == {(S, 2, PB + LOW)}, seen


def test_masks_on_the_wire_and_back():
    sup = LabelSupport(peer_bit(3))
    lab = np.array([[S, 4, PB + HIGH], [5, 4, PB + 1], [S, 4, PB + LOW]], dtype=np.int64)
    sup.own(lab, 4)
    sup.add(lab[:1], np.int64(0b1011))
    wire, extra = sup.encode(lab)
    assert extra is None
    assert wire.min() >= 0 and wire[1, 0] == 5  # own labels travel as they are
    back, masks = decode(wire)
    np.testing.assert_array_equal(back, lab)
    np.testing.assert_array_equal(masks, [[0b1111], [0], [0b100]])
    np.testing.assert_array_equal(sup.counts(lab), [4, 0, 1])
    assert wire[0, 0] == 0b1111 << SUPPORT_SHIFT
    sup.prune(4 + 100)
    assert not sup.counts(lab).any()


def test_a_mixture_without_rows_and_unlabelled_masks():
    sup = LabelSupport(peer_bit(1))
    none = np.zeros((0, 3), dtype=np.int64)
    sup.add(none, np.zeros(0, dtype=np.int64))
    assert sup.encode(none)[0].shape == (0, 3)
    assert len(label_fused(GaussianMixture.empty(4), [], 1, 1, support=sup).labels) == 0
