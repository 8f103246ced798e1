"""An LMB peer's step after a gap (peers/lmb_estimator.py ``LmbEstimator.filter_for``): scans
left out while catching up spread the tracks, so loopy clusters get LBP instead of Gibbs
sampling on that step; every other step is the filter's own (Gibbs), bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.labels import new_labels
from sensornet.tracking.lmb import LmbFilter, LmbState
from sensornet.tracking.lmb_sets import LabelledBernoulliSet
from sensornet.tracking.models import ConstantVelocity, LinearPosition


def _filter() -> LmbFilter:
    """Every loopy cluster beyond 1 hypothesis goes to the scalable method (Gibbs)."""
    return LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(10.0), 0.9, 1e-6),
                     exact_limit=1, adaptive_birth=False)


def _crowd(k: int) -> tuple[LmbState, np.ndarray]:
    """Four tracks 15 m apart at scan ``k`` and four measurements among them: one loopy
    cluster."""
    n = 4
    means = np.zeros((n, 4))
    means[:, 0] = 15.0 * np.arange(n)
    tracks = LabelledBernoulliSet(new_labels(0, 1, n), np.full(n, 0.9), np.ones(n), means,
                                  np.tile(np.diag([100.0, 4.0, 100.0, 4.0]), (n, 1, 1)),
                                  np.arange(n))
    z = np.column_stack([15.0 * np.arange(n) + 6.0, np.full(n, 3.0)])
    return LmbState(tracks, np.zeros(n, dtype=np.int64), k, _filter().initial().pending), z


def _same(a: LmbState, b: LmbState) -> bool:
    ta, tb = a.tracks, b.tracks
    return (len(ta) == len(tb) and np.array_equal(ta.labels, tb.labels)
            and np.array_equal(ta.existence, tb.existence)
            and np.array_equal(ta.means, tb.means))


def _stepped(k_from: int, k_to: int) -> LmbState:
    est = LmbEstimator(_filter(), publish_threshold=None)
    est.state, z = _crowd(k_from)
    est.k = k_from
    est.begin_scan(k_to)
    est.step(k_to - k_from, z)
    return est.state


def test_a_step_after_a_gap_uses_lbp_and_a_next_step_gibbs():
    """After a gap of 3 scans the estimator's state is the LBP filter's step of the same state
    and scan, which differs from Gibbs sampling's there (so the check can fail); the step to
    the next scan is the Gibbs filter's, bit for bit."""
    gibbs, lbp = _filter(), dataclasses.replace(_filter(), scalable="lbp")
    state, z = _crowd(2)
    after_gap = _stepped(2, 5)
    assert _same(after_gap, lbp.step(state, z, 5))
    assert not np.allclose(gibbs.step(state, z, 5).tracks.existence, after_gap.tracks.existence)
    next_scan = _stepped(2, 3)
    assert _same(next_scan, _filter().step(state, z, 3))
    assert not np.allclose(lbp.step(state, z, 3).tracks.existence, next_scan.tracks.existence)


def test_the_first_step_and_chosen_methods_are_left_alone():
    """The first step (no previous scan) and a filter that is not ``auto``/Gibbs keep their
    own filter after any gap."""
    est = LmbEstimator(_filter())
    assert est.filter_for(7) is est.filter  # state.k = -1: nothing was skipped
    for f in (dataclasses.replace(_filter(), method="gibbs"),
              dataclasses.replace(_filter(), scalable="lbp")):
        est = LmbEstimator(f)
        est.state = _crowd(2)[0]
        assert est.filter_for(6) is f
    est = LmbEstimator(_filter())
    est.state = _crowd(2)[0]
    gap = est.filter_for(6)
    assert gap.scalable == "lbp" and gap is est.filter_for(9)  # built once
    assert est.filter_for(3) is est.filter
