"""Corroborated stamps (issue 33, docs/labelled-tracking.md "Corroborated stamps"): a label
stamped at its first publication that no neighbour's track was paired with in that scan's
fusion moves a scan later, ``(o, k + 1, i)``, at the fused component and at the own
estimator, so a clutter track one scan before a target (at one peer of many) no longer carries
the earliest label of the target. Checked against a loop over the fused rows (random cases),
on the estimators' ``fresh_stamps`` and end to end on one peer pair."""

from __future__ import annotations

import numpy as np
from sensornet.peers.estimators import GmphdEstimator
from sensornet.peers.labelling import FRESH_BASE, label_fused
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.labels import PUBLISHED_BASE as PB
from sensornet.tracking.labels import SHARED_ORIGIN as S
from sensornet.tracking.labels import Publication
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.reduction import Reducer


def _gm(means, w=None) -> GaussianMixture:
    means = np.asarray(means, float).reshape(-1, 4)
    n = len(means)
    return GaussianMixture(np.ones(n) if w is None else np.asarray(w, float), means,
                           np.tile(np.eye(4) * 25.0, (n, 1, 1)))


def test_an_uncorroborated_fresh_stamp_moves_a_scan_later():
    k = 39
    fresh = [S, k, PB + 2]
    fused = _gm([[0, 0, 0, 0], [900, 0, 0, 0]])
    own = (_gm([[1, 0, 1, 0], [901, 0, 0, 0]]), np.array([fresh, [S, 20, PB + 1]]))
    far = (_gm([[-3000, 0, 0, 0]]), np.array([[S, 30, PB + 0]]))
    out = label_fused(fused, [own, far], origin=4, k=k, bump=np.array([fresh]))
    np.testing.assert_array_equal(out.labels[0], [S, k + 1, PB + 2])
    np.testing.assert_array_equal(out.labels[1], [S, 20, PB + 1])  # not stamped now: kept
    assert out.own.own.tolist() == [fresh] and out.own.nbr.tolist() == [[S, k + 1, PB + 2]]
    # without the estimator's stamps (or with a neighbour holding the track) nothing moves
    same = label_fused(fused, [own, far], origin=4, k=k)
    np.testing.assert_array_equal(same.labels[0], fresh)
    held = (_gm([[2, 0, -1, 0]]), np.array([[S, k, PB + 2]]))
    corr = label_fused(fused, [own, held], origin=4, k=k, bump=np.array([fresh]))
    np.testing.assert_array_equal(corr.labels[0], fresh)
    assert len(corr.own) == 0


def reference(fused, inputs, k, bump, gate=26.0):
    """The labels of label_fused's fused rows with the move applied by a loop: a row won by a
    fresh own stamp of scan ``k`` with no neighbour track within the gate of it (the pairs here
    are unambiguous: every track lies within the gate of one fused row at most)."""
    base = label_fused(fused, inputs, 0, k).labels
    out = base.copy()
    fresh = {tuple(b) for b in bump.tolist()}
    for r, lab in enumerate(base.tolist()):
        if tuple(lab) not in fresh or lab[1] != k:
            continue
        held = False
        for mix, labels in inputs[1:]:
            for j in range(len(labels)):
                d = fused.means[r] - mix.means[j]
                q = d @ np.linalg.solve(fused.covs[r] + mix.covs[j], d)
                held |= q <= gate
        if not held and [S, k + 1, lab[2]] not in base.tolist():
            out[r] = [lab[0], k + 1, lab[2]]
    return out


def test_the_move_equals_a_loop_over_the_rows_on_random_cases():
    rng = np.random.default_rng(11)
    moved = 0
    for _ in range(200):
        k = 10
        n = int(rng.integers(1, 6))
        pts = np.column_stack((rng.permutation(20)[:n] * 500.0, np.zeros(n),
                               np.zeros(n), np.zeros(n)))  # rows 500 m apart: one pair each
        fused = _gm(pts)
        own_lab = np.column_stack((np.full(n, S), rng.choice([k, k - 1, k - 5], n),
                                   PB + rng.permutation(n)))
        own = (_gm(pts + rng.normal(0, 2, pts.shape)), own_lab)
        sel = rng.random(n) < 0.5
        nbr_lab = np.column_stack((np.full(sel.sum(), 3), np.full(sel.sum(), k),
                                   PB + np.arange(sel.sum())))
        nbr = (_gm(pts[sel] + rng.normal(0, 2, (sel.sum(), 4))), nbr_lab)
        bump = own_lab[own_lab[:, 1] == k]
        got = label_fused(fused, [own, nbr], 0, k, bump=bump).labels
        np.testing.assert_array_equal(got, reference(fused, [own, nbr], k, bump))
        moved += int((got[:, 1] == k + 1).sum())
    assert moved > 50  # the move was exercised


def test_a_moved_label_never_duplicates_a_fused_one():
    k = 7
    fused = _gm([[0, 0, 0, 0], [900, 0, 0, 0]])
    own = (_gm([[0, 0, 0, 0]]), np.array([[S, k, PB + 2]]))
    nbr = (_gm([[900, 0, 0, 0]]), np.array([[S, k + 1, PB + 2]]))  # held already (a move)
    out = label_fused(fused, [own, nbr], 0, k, bump=own[1])
    np.testing.assert_array_equal(out.labels, [[S, k, PB + 2], [S, k + 1, PB + 2]])
    lone = label_fused(_gm([[0, 0, 0, 0], [5000, 0, 0, 0]]), [own], 2, k, bump=own[1])
    np.testing.assert_array_equal(lone.labels, [[S, k + 1, PB + 2], [2, k, FRESH_BASE]])


def test_publication_reports_what_it_stamped_each_call():
    pub = Publication(2, shared=S)
    labels = np.array([[S, 5, 1], [2, 5, 7], [S, 4, 0], [2, 3, PB]])
    out = pub.stamp(labels, np.array([0.9, 0.8, 0.1, 0.9]), 0.5, 5)
    assert sorted(pub.stamped.tolist()) == sorted([[S, 5, PB + 1], [2, 5, PB]])
    assert all(r in out.tolist() for r in pub.stamped.tolist())
    pub.stamp(out, np.array([0.9, 0.8, 0.1, 0.9]), 0.5, 6)
    assert pub.stamped.shape == (0, 3)  # nothing new: nothing stamped


def _pair_of_gmphd():
    motion = ConstantVelocity(1.0, 2.0)
    reducer = Reducer(prune_threshold=1e-5, merge_threshold=4.0, max_components=20)
    birth = GaussianMixture(np.full(1, 0.1), np.array([[0.0, 0.0, 0.0, 0.0]]),
                            np.diag([100.0, 25, 100, 25])[None])
    return [GmphdEstimator(GMPHDFilter(motion, [SensorParams(LinearPosition(5.0), 0.99, 2.5e-7)],
                                       birth, 0.99, reducer), origin=o, shared_births=True)
            for o in (1, 2)]


def test_a_clutter_track_one_scan_early_takes_the_targets_stamp_not_an_earlier_one():
    """Peer 1 sees a plot at the birth point at scan 3 (clutter), the target appears there at
    scan 4 at both peers. Without the move peer 1's track keeps (S, 3, .), the network's
    earliest label, which then replaces the id peer 2 gave the target; with it both hold
    (S, 4, PB) from scan 4 on."""
    for move in (True, False):
        a, b = _pair_of_gmphd()
        ids = {}
        for k in range(1, 8):
            x = np.array([2.0 * (k - 4), 1.0 * (k - 4)])
            za = [x] if k >= 4 else ([[1.0, -1.0]] if k == 3 else [])
            zb = [x] if k >= 4 else []
            outs = []
            for e, z in ((a, za), (b, zb)):
                e.begin_scan(k)
                outs.append(e.step(1, np.asarray(z, float).reshape(-1, 2)))
            # one round between the two, as the consensus runs it (fused = own + neighbour)
            for j, (e, mine, theirs) in enumerate(((a, outs[0], outs[1]), (b, outs[1], outs[0]))):
                own = (mine.published["posterior"], mine.labels["posterior"])
                nbr = (theirs.published["posterior"], theirs.labels["posterior"])
                fused = own[0] if len(own[0]) else nbr[0]  # the hybrid rule's means here
                lab = label_fused(fused, [own, nbr], e.origin, k,
                                  bump=e.fresh_stamps() if move else None)
                e.relabel(lab.own)
                if k >= 4 and len(fused):  # the target's fused track
                    near = np.argmin(np.hypot(*(fused.means[:, [0, 2]] - x).T))
                    ids.setdefault((move, j), set()).add(tuple(lab.labels[near].tolist()))
        if move:
            assert ids[(True, 0)] == ids[(True, 1)] == {(S, 4, PB)}
        else:
            assert (S, 3, PB) in ids[(False, 1)]  # the clutter's label reached peer 2


def test_lmb_estimator_reports_its_fresh_stamps():
    f = LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(5.0), 0.99, 2.5e-7),
                  origin=1, shared_origin=S)
    e = LmbEstimator(f, origin=1)
    seen = []
    for k in range(1, 6):
        e.begin_scan(k)
        out = e.step(1, np.array([[3.0 * k, 0.0]]))
        seen.append(e.fresh_stamps().tolist())
        pub = out.labels["posterior"]
        assert all(tuple(s) in set(map(tuple, pub.tolist())) for s in seen[-1])
    first = [i for i, s in enumerate(seen) if s]
    assert len(first) == 1 and seen[first[0]][0][1] == first[0] + 1  # once, its scan
    assert seen[first[0]][0][2] >= PB
