"""Birth scans of shared labels checked where they arrive (issue 33, hostile input;
docs/security.md "Label masks: what a member can claim"): the earliest birth scan wins whatever
the support, so a member could stamp a label earlier than the target's first plots and take
the target's id everywhere. A label is first published at or before its birth scan; a receiver
takes a label older than the estimate only if a stamper it can vouch for published it by then
(itself or a neighbour: first-hand) or a far stamper within the sender's reach claims it
(peers.label_support.LabelSupport.refused); a refused row is re-stamped to the estimate's scan
(it loses to every older label: the same target's copy, not a new track), and counted."""

from __future__ import annotations

import numpy as np
from sensornet.peers.label_support import KEEP_SCANS, LabelSupport, peer_bit, reach_by_name
from sensornet.peers.lmb_estimator import PUBLISHED_BASE as PB
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.label_keys import SHARED_ORIGIN as S

LINE4 = [(0, 1), (1, 2), (2, 3)]


def _line_support() -> LabelSupport:
    """Peer 1 (origin 2) of the line 0 - 1 - 2 - 3, neighbours "a" (0) and "c" (2)."""
    A = np.zeros((4, 4), dtype=int)
    for x, y in LINE4:
        A[x, y] = A[y, x] = 1
    return LabelSupport(peer_bit(2), dict(reach_by_name(list("abcd"), A, [1, 2, 3, 4], 1)))


def test_a_label_older_than_its_first_publication_is_refused_and_counted():
    b1, b2, b3, b4 = (peer_bit(o) for o in (1, 2, 3, 4))
    sup = _line_support()
    lab = np.array([[S, 5, PB + 7]], dtype=np.int64)
    assert sup.vouched("c", lab, np.array([b3]), 5)  # c stamps it at its scan: recorded
    assert sup.vouched("a", lab, np.array([b3]), 7)  # a relays it later: c's stamp vouches
    # a sends the same cell two scans earlier at scan 7, claiming c's stamp or its own: no
    # one was seen to publish that label by scan 3
    early = np.array([[S, 3, PB + 7]], dtype=np.int64)
    assert not sup.vouched("a", early, np.array([b3]), 7)
    assert not sup.vouched("a", early, np.array([b1]), 7)
    # an own label of a's origin it never published by its scan; then one it did
    own = np.array([[1, 4, PB + 1]], dtype=np.int64)
    assert not sup.vouched("a", own, np.array([0]), 7)
    assert sup.backdated == 3
    assert sup.vouched("a", own, np.array([0]), 4) and sup.vouched("a", own, np.array([0]), 9)
    # our own stamp (own()) vouches for it when a neighbour relays it back
    mine = np.array([[S, 6, PB + 2]], dtype=np.int64)
    sup.own(mine, 6)
    assert sup.vouched("a", mine, np.array([b2 | b1]), 8)
    # a far stamper (d, 2 hops from a) cannot be checked here: taken within a's reach
    far = np.array([[S, 2, PB + 9]], dtype=np.int64)
    assert sup.vouched("a", far, np.array([b4]), 7)
    assert not sup.vouched("c", far, np.array([b1]), 7)  # a is our neighbour: first-hand
    # past the kept window, and this scan's or the next's labels, pass as they come
    assert sup.vouched("a", np.array([[S, 1, PB]], dtype=np.int64), np.array([0]),
                       2 + KEEP_SCANS)
    assert sup.vouched("a", np.array([[S, 8, PB], [S, 9, PB]], dtype=np.int64),
                       np.array([0, 0]), 8)
    assert sup.backdated == 4
    # unchecked (no reach): everything taken, nothing counted
    free = LabelSupport(peer_bit(2))
    assert free.vouched("a", early, np.array([b1]), 7) and free.backdated == 0


def _twin(lie: bool, checked: bool, scans: int = 30):
    """seed 000's LMB twin (run 100, ``scans`` scans), s3 honest or sending every shared label
    a scan early; per honest peer its fused track ids by scan, and each peer's label-scan
    count."""
    from sensornet.sim.run.peers import make_peer
    from sensornet.sim.run.twin import run_twin
    from sensornet.sim.studies.labelled.mask_lie import MaskLiarCore

    scn = load_scenario("seed000", overrides={"network.filter": "lmb",
                                              "scenario.num_scans": scans})
    changes = {} if checked else {"label_reach": ()}
    peers = {n: make_peer(scn, n, 100, **changes) for n in scn.sensor_names}
    if lie:
        peers["s3"] = MaskLiarCore(peers["s3"], "backdater")
    run_twin(scn, 100, peers=peers)
    ids = {}
    for n in ("s1", "s2"):
        t = peers[n].scorer.results.table(n)
        ids[n] = [(k, [tuple(i) for i in tid]) for k, e, tid in
                  zip(t["scan"], t["estimate"], t["track_ids"], strict=True) if e == "fused"]
    return ids, {n: c.rejected["label-scan"] for n, c in peers.items()}


def test_on_the_twin_a_backdating_member_takes_ids_only_unchecked_and_is_counted():
    honest, n = _twin(False, True)
    assert set(n.values()) == {0}  # honest labels are never refused
    assert _twin(False, False)[0] == honest
    taken, _ = _twin(True, False)
    assert taken != honest  # unchecked, its earlier scans take the honest peers' ids
    kept, n = _twin(True, True)
    assert kept == honest  # checked, the honest peers' fused ids are the honest run's
    assert n["s1"] > 0 and n["s2"] > 0


def test_fresh_index_is_the_fusions():
    from sensornet.peers.label_support import FRESH_INDEX
    from sensornet.peers.labelling import FRESH_BASE

    assert FRESH_INDEX == FRESH_BASE


def test_a_stamp_moved_a_scan_later_passes_and_only_that():
    b3 = peer_bit(3)
    sup = _line_support()
    assert sup.vouched("c", np.array([[S, 5, PB + 7]], dtype=np.int64), np.array([b3]), 5)
    # c moved its uncorroborated stamp to scan 6 and publishes it when the track is back
    assert sup.vouched("c", np.array([[S, 6, PB + 7]], dtype=np.int64), np.array([0]), 9)
    assert sup.vouched("a", np.array([[S, 6, PB + 7]], dtype=np.int64), np.array([0]), 10)
    # two scans later, or a scan earlier, is no such move
    assert not sup.vouched("c", np.array([[S, 7, PB + 7]], dtype=np.int64), np.array([0]), 9)
    assert not sup.vouched("c", np.array([[S, 4, PB + 7]], dtype=np.int64), np.array([b3]), 9)
    assert sup.backdated == 2


def test_checked_restamps_only_the_refused_rows_and_drops_their_masks():
    b1, b3 = peer_bit(1), peer_bit(3)
    sup = _line_support()
    good = np.array([[S, 5, PB + 7]], dtype=np.int64)
    assert sup.vouched("c", good, np.array([b3]), 5)
    lab = np.array([[S, 5, PB + 7], [S, 3, PB + 7]], dtype=np.int64)
    m = np.array([b3, b1 | b3])
    out, mo = sup.checked("a", lab, m, 7)
    np.testing.assert_array_equal(out, [[S, 5, PB + 7], [S, 7, PB + 7]])
    np.testing.assert_array_equal(mo, [b3, 0])
    np.testing.assert_array_equal(lab[1], [S, 3, PB + 7])  # the input untouched
    assert sup.backdated == 1
    same, sm = sup.checked("a", good, np.array([b3]), 7)  # all vouched: as they came
    assert same is good and sup.backdated == 1


def test_labels_of_far_future_birth_scans_are_forgotten_at_the_next_prune():
    # a neighbour's labels stamped 10^6 scans ahead are recorded as it sends them, and are
    # gone after the next prune: what one sender can leave in the store is bounded in scans
    sup = _line_support()
    far = np.array([[S, 10**6 + i, PB + i] for i in range(50)], dtype=np.int64)
    sup.vouched("c", far, np.full(50, peer_bit(3)), 5)
    sup.heard("c", far, np.full(50, peer_bit(3)), 5)
    assert len(sup._early) == 50 and len(sup.keys) == 50
    near = np.array([[S, 6, PB + 1]], dtype=np.int64)  # a peer a scan ahead: kept
    sup.vouched("c", near, np.array([peer_bit(3)]), 6)
    sup.prune(6)
    assert len(sup._early) == 1 and len(sup.keys) == 0
