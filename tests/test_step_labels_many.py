"""The batched local label step (tracking.labels.step_labels_many, issues 33/38): every
problem's posterior labels are its own tag propagation and duplicate rule's, to the bit, on
random label sequences; and co-hosted GM-PHD peers whose steps were prepared together take
them only when the step is the one prepared (the same labels as peers stepping alone)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.estimators import GmphdEstimator
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.labels import (
    LabelledMixture,
    new_labels,
    split_duplicates,
    step_labels_many,
)
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.reduction import Reducer


def _alone(lab, par, w, nb, bo, o, k, thr):
    pred = np.concatenate((lab, new_labels(bo, k, nb)))
    mix = GaussianMixture(w, np.zeros((len(w), 4)), np.tile(np.eye(4), (len(w), 1, 1)))
    return split_duplicates(LabelledMixture(mix, pred[par]), thr, o, k, nb).labels


def test_step_labels_many_equals_each_problem_on_random_label_sequences():
    rng = np.random.default_rng(31)
    split = 0
    for _ in range(200):
        P = int(rng.integers(1, 7))
        args = []
        for _p in range(P):
            n, nb = int(rng.integers(0, 9)), int(rng.integers(0, 4))
            lab = rng.integers(0, 3, (n, 3)).astype(np.int64)  # few labels: many shared
            m = int(rng.integers(0, 14)) if n + nb else 0
            par = rng.integers(0, max(n + nb, 1), m)
            w = rng.choice([0.2, 0.5, 0.7, 0.9, 1.3], m)  # ties and the threshold itself
            args.append((lab, par, w, nb, int(rng.integers(0, 3)), int(rng.integers(0, 3)),
                         int(rng.integers(1, 50)), float(rng.choice([0.5, 0.8]))))
        got = step_labels_many(*(list(x) for x in zip(*args, strict=True)))
        assert len(got) == P
        for g, a in zip(got, args, strict=True):
            want = _alone(*a)
            assert g.dtype == np.int64 and g.shape == want.shape
            np.testing.assert_array_equal(g, want)
            split += int((want[:, 2] >= a[3]).sum() and (a[2] > a[7]).sum() > 1)
    assert split > 20  # the duplicate rule had work to do
    assert step_labels_many([], [], [], [], [], [], [], []) == []


def _peers(rng, n: int, centres: np.ndarray) -> list[GmphdEstimator]:
    motion, reducer = ConstantVelocity(1.0, 2.0), Reducer(merge_threshold=4.0)
    birth = GaussianMixture(np.full(len(centres), 0.2), centres, np.tile(np.eye(4) * 400.0,
                                                                         (len(centres), 1, 1)))
    sensor = SensorParams(LinearPosition(10.0), 0.95, 1e-6)
    return [GmphdEstimator(GMPHDFilter(motion, [sensor], birth, 0.99, reducer), origin=o,
                           shared_births=bool(o % 2)) for o in range(1, n + 1)]


def test_prepared_labels_are_the_steps_own_and_used_only_for_that_step():
    rng = np.random.default_rng(8)
    centres = np.array([[0.0, 5.0, 0.0, 3.0], [400.0, -4.0, 100.0, 2.0], [10.0, 0, 30.0, 0]])
    ests, plain = _peers(rng, 4, centres), _peers(rng, 4, centres)
    for k in range(1, 12):
        zs = [centres[:, [0, 2]] + k * centres[:, [1, 3]] + rng.normal(0, 8, (3, 2))
              for _ in ests]
        zs[3] = zs[3][rng.random(3) < 0.7]  # misses
        GmphdEstimator.prepare_many(ests, [1] * 4, zs)
        for i, (e, q, z) in enumerate(zip(ests, plain, zs, strict=True)):
            kk = k + 1 if (i == 2 and k == 5) else k  # peer 2 at scan 5: another scan index
            e.begin_scan(kk)
            q.begin_scan(kk)
            a, b = e.step(1, z), q.step(1, z)
            np.testing.assert_array_equal(e.labels, q.labels)
            np.testing.assert_array_equal(a.labels["posterior"], b.labels["posterior"])
            np.testing.assert_array_equal(e.fresh_stamps(), q.fresh_stamps())
        if k == 5:  # peers 2's scan index moved on: keep the plain twin in step
            ests[2].k = plain[2].k = k
    assert [e.prepared_hits for e in ests] == [11] * 4
    assert [e.prepared_label_hits for e in ests] == [11, 11, 10, 11]
    assert len(np.unique(ests[0].labels, axis=0)) > 1


def test_a_failed_prepared_step_rolls_back_labels_and_bookkeeping(monkeypatch):
    """A step that raises after taking the prepared labels leaves the estimator as before
    (peers.step_atomic); the next step, unprepared, gives what a peer that never failed gives."""
    from sensornet.peers.stamp_moves import MovingStamps

    rng = np.random.default_rng(4)
    centres = np.array([[0.0, 5.0, 0.0, 3.0], [400.0, -4.0, 100.0, 2.0]])
    ests, plain = _peers(rng, 2, centres), _peers(rng, 2, centres)
    for k in range(1, 5):
        zs = [centres[:, [0, 2]] + k * centres[:, [1, 3]] for _ in ests]
        GmphdEstimator.prepare_many(ests, [1, 1], zs)
        for e, q, z in zip(ests, plain, zs, strict=True):
            e.step(1, z)
            q.step(1, z)
    zs = [centres[:, [0, 2]] + 5 * centres[:, [1, 3]] for _ in ests]
    GmphdEstimator.prepare_many(ests, [1, 1], zs)
    e = ests[0]
    before = (e.mix, e.labels, e.k, e.publication._keys, e.reid._on, e.reid._last,
              e.publication._last, e.reid._lost, e.prepared_label_hits)

    reached = []

    def broken(self, *args):
        reached.append((e.prepared_stamp_hits, e.prepared_reid_hits))
        raise IndexError("offer")

    with monkeypatch.context() as m:  # the step's last call: after the prepared stages
        m.setattr(MovingStamps, "offer", broken)
        with pytest.raises(IndexError):
            e.step(1, zs[0])
    after = (e.mix, e.labels, e.k, e.publication._keys, e.reid._on, e.reid._last,
             e.publication._last, e.reid._lost, e.prepared_label_hits)
    assert all(x is y for x, y in zip(before[:8], after[:8], strict=True))
    assert after[8] == before[8]
    assert reached == [(3 + 1, 3 + 1)]  # the failed step had taken both prepared memories
    assert (e.prepared_stamp_hits, e.prepared_reid_hits) == (3, 3)  # rolled back too
    e.step(1, zs[0])  # unprepared now (taken by the failed step): its own labels
    plain[0].step(1, zs[0])
    np.testing.assert_array_equal(e.labels, plain[0].labels)


def _pub_twins(rng, P):
    from sensornet.tracking.label_confirmation import Publication
    pubs, twins = [], []
    for p in range(P):
        kw = dict(origin=p % 3, gap=None if p % 5 == 4 else int(rng.integers(0, 3)),
                  revisit=int(rng.integers(1, 3)), shared=0 if p % 2 else None)
        pubs.append(Publication(**kw))
        twins.append(Publication(**kw))
    return pubs, twins


def test_stamp_known_many_equals_each_stamp_where_nothing_is_stamped():
    """On random label sequences of several peers over scans: where the batch prepares a
    stamp, the stamp itself stamps nothing and leaves that memory, to the bit; where the batch
    gives None, the peer's own stamp runs (both peers then equal)."""
    from sensornet.tracking.label_confirmation import stamp_known_many

    rng = np.random.default_rng(12)
    prepared = fell_back = 0
    for _trial in range(30):
        P = int(rng.integers(1, 6))
        pubs, twins = _pub_twins(rng, P)
        pool = [rng.integers(0, 3, (6, 3)).astype(np.int64) for _ in range(P)]
        for k in range(1, 14):
            labels, weights = [], []
            for p in range(P):
                n = int(rng.integers(0, 7))
                lab = pool[p][rng.integers(0, 6, n)]
                if rng.random() < 0.15:  # a label now and then new
                    pool[p][rng.integers(0, 6)] = [p % 3, k, int(rng.integers(0, 4))]
                labels.append(lab)
                weights.append(rng.choice([0.1, 0.5, 0.6, 0.9], n))
            thr = [0.5] * P
            got = stamp_known_many(pubs, labels, weights, thr, [k] * P)
            for pub, twin, lab, w, g in zip(pubs, twins, labels, weights, got, strict=True):
                want = twin.stamp(lab, w, 0.5, k)
                if g is None:
                    fell_back += 1
                    out = pub.stamp(lab, w, 0.5, k)
                    np.testing.assert_array_equal(out, want)
                else:
                    prepared += 1
                    assert not twin.stamped.size
                    np.testing.assert_array_equal(want, lab)  # nothing stamped
                    pub.take_known(g, k)
                assert pub._keys.dtype == twin._keys.dtype
                np.testing.assert_array_equal(pub._keys, twin._keys)
                np.testing.assert_array_equal(pub._last, twin._last)
                assert pub._last.dtype == twin._last.dtype and pub._k == twin._k
                np.testing.assert_array_equal(pub.stamped, twin.stamped)
    assert prepared > 200 and fell_back > 200


def _same(a, b) -> None:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "f":
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)
    else:
        np.testing.assert_array_equal(a, b)


def test_prepared_stamps_are_taken_on_the_usual_scan():
    rng = np.random.default_rng(3)
    centres = np.array([[0.0, 5.0, 0.0, 3.0], [400.0, -4.0, 100.0, 2.0]])
    ests, plain = _peers(rng, 3, centres), _peers(rng, 3, centres)
    for k in range(1, 10):
        zs = [centres[:, [0, 2]] + k * centres[:, [1, 3]] + rng.normal(0, 5, (2, 2))
              for _ in ests]
        GmphdEstimator.prepare_many(ests, [1] * 3, zs)
        if k == 6:  # the memory changed after the preparation: its own stamp
            ests[1].publication.adopt(np.array([[9, 1, 1]]))
            plain[1].publication.adopt(np.array([[9, 1, 1]]))
        for e, q, z in zip(ests, plain, zs, strict=True):
            e.step(1, z)
            q.step(1, z)
            np.testing.assert_array_equal(e.labels, q.labels)
            np.testing.assert_array_equal(e.publication._keys, q.publication._keys)
            np.testing.assert_array_equal(e.publication._last, q.publication._last)
            for a, b in zip(e.reid._on + e.reid._last, q.reid._on + q.reid._last, strict=True):
                _same(a, b)  # (the stacked posterior: equal to round-off, gmphd_batch)
    assert min(e.prepared_reid_hits for e in ests) >= 4
    hits = [e.prepared_stamp_hits for e in ests]
    assert min(hits) >= 5 and hits[1] < hits[0]


def test_same_many_equals_apply_where_it_prepares():
    """On random published label sequences of several peers: where same_many prepares the
    memory, apply would keep the labels and leave that memory (a lost set kept from before,
    none yet, dark labels held); elsewhere apply runs (then both peers are equal again)."""
    from sensornet.tracking.reidentify import Reidentification

    rng = np.random.default_rng(17)
    motion = ConstantVelocity(1.0, 2.0)
    prepared = ran = 0
    cases = {"lost": 0, "dark": 0, "no lost set": 0}  # what same_many keeps as apply would
    for _trial in range(25):
        P = int(rng.integers(1, 5))
        kw = [dict(origin=p % 3, shared=0 if p % 2 else None,
                   jump=None if p % 4 == 3 else 3000.0) for p in range(P)]
        reids = [Reidentification(motion, **a) for a in kw]
        twins = [Reidentification(motion, **a) for a in kw]
        pool = [np.array([[p % 3, 0, 7], [9, 1, 2], [p % 3, 2, 1 << 30]]) for p in range(P)]
        dark = np.zeros(P, dtype=bool)  # a peer's third label on a light row only, for scans
        for k in range(1, 16):
            labels, mixes = [], []
            dark ^= rng.random(P) < 0.2
            for p in range(P):
                if rng.random() < 0.15:  # a label now and then replaced, or stamped new
                    pool[p][rng.integers(0, 3)] = [p % 3, k, (1 << 30) + int(rng.integers(3))]
                n = int(rng.integers(0, 6)) if rng.random() < 0.2 else 4
                lab = pool[p][rng.integers(0, 3, n)] if n != 4 else pool[p][[0, 1, 2, 0]]
                w = (rng.choice([0.2, 0.6, 0.9], n) if n != 4
                     else np.array([0.9, 0.8, 0.1 if dark[p] else 0.7, 0.1]))
                mean = rng.normal(0, 30, (n, 4)) + 100 * lab[:, [2, 1, 2, 1]] % 977
                labels.append(lab)
                mixes.append(GaussianMixture(w, mean, np.tile(np.eye(4) * 50.0, (n, 1, 1))))
            got = Reidentification.same_many(reids, labels, mixes, [0.5] * P, [k] * P)
            for r, t, lab, mx, g in zip(reids, twins, labels, mixes, got, strict=True):
                want = t.apply(lab, mx, 0.5, k)
                if g is None:
                    ran += 1
                    np.testing.assert_array_equal(r.apply(lab, mx, 0.5, k), want)
                else:
                    prepared += 1
                    cases["no lost set"] += r._lost is None
                    cases["lost"] += r._lost is not None and len(r._lost[0]) > 0
                    cases["dark"] += r.jump is not None and len(r._last[0]) > len(r._on[1])
                    np.testing.assert_array_equal(want, lab)
                    r.take_same(g)
                for name in ("_on", "_last", "_lost"):
                    a, b = getattr(r, name), getattr(t, name)
                    assert (a is None) == (b is None)
                    for x, y in zip(a or (), b or (), strict=True):
                        np.testing.assert_array_equal(x, y)
    assert prepared > 100 and ran > 100 and min(cases.values()) > 20, (prepared, ran, cases)
