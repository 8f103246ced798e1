"""Stacked GM-PHD local steps (tracking.gmphd_batch) against one filter step at a time:
the same posteriors on random priors and scans, and a peer's estimator using a prepared step
only when it is the step it would compute."""

from __future__ import annotations

import numpy as np
from sensornet.peers.estimators import GmphdEstimator
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.gmphd_batch import batch_key, step_many
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition, RangeBearing
from sensornet.tracking.reduction import Reducer


def _spd(rng, n: int) -> np.ndarray:
    A = rng.normal(0, 1, (n, 4, 4))
    return A @ A.swapaxes(1, 2) * rng.uniform(5, 60, (n, 1, 1)) + 4 * np.eye(4)


def _mix(rng, centres: np.ndarray, k: int) -> GaussianMixture:
    at = centres[rng.integers(0, len(centres), k)]
    return GaussianMixture(rng.uniform(0.0, 1.2, k), at + rng.normal(0, 4, (k, 4)), _spd(rng, k))


def _filter(rng, centres, motion, reducer, gate=None, radar=False) -> GMPHDFilter:
    model = (RangeBearing(position=(0.0, 0.0)) if radar
             else LinearPosition(float(rng.uniform(5, 30)), (float(rng.uniform(0, 9)), 0.0)))
    sensor = SensorParams(model, float(rng.uniform(0.7, 0.99)), float(rng.uniform(1e-7, 1e-5)))
    birth = _mix(rng, centres, int(rng.integers(0, 4)))
    return GMPHDFilter(motion, [sensor], birth, 0.98, reducer, gate=gate)


def _same(a: GaussianMixture, b: GaussianMixture) -> None:
    assert len(a) == len(b)
    np.testing.assert_allclose(a.weights, b.weights, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(a.means, b.means, rtol=1e-9, atol=1e-8)
    np.testing.assert_allclose(a.covs, b.covs, rtol=1e-9, atol=1e-8)


def test_step_many_equals_each_step_on_random_problems():
    rng = np.random.default_rng(23)
    motion = ConstantVelocity(1.0, 2.0)
    reducer = Reducer(prune_threshold=1e-5, merge_threshold=4.0, max_components=12)
    stacked = 0
    for trial in range(40):
        centres = rng.uniform(-300, 300, (int(rng.integers(1, 5)), 4))
        n = int(rng.integers(1, 9))
        gate = 16.0 if trial % 4 == 3 else None
        filters = [_filter(rng, centres, motion, reducer, gate, radar=(trial % 5 == 4 and p == 0))
                   for p in range(n)]
        mixes = [_mix(rng, centres, int(rng.integers(0, 8))) for _ in range(n)]
        steps = [1 if trial % 3 else int(rng.integers(1, 3)) for _ in range(n)]
        scans = [centres[rng.integers(0, len(centres), int(rng.integers(0, 6)))][:, [0, 2]]
                 + rng.normal(0, 10, (1, 2)) for _ in range(n)]
        got = step_many(filters, mixes, steps, scans)
        keys = [batch_key(f, s) for f, s in zip(filters, steps, strict=True)]
        stacked += sum(1 for k in keys if k is not None and keys.count(k) > 1)
        for f, mix, s, z, g in zip(filters, mixes, steps, scans, got, strict=True):
            _same(g, f.correct(f.predict(mix, s), [z]))
    assert stacked > 100  # most problems went through the stacked path


def test_estimator_uses_a_prepared_step_only_when_it_matches():
    rng = np.random.default_rng(5)
    centres = rng.uniform(-300, 300, (3, 4))
    motion, reducer = ConstantVelocity(1.0, 2.0), Reducer(merge_threshold=4.0)
    ests = [GmphdEstimator(_filter(rng, centres, motion, reducer)) for _ in range(3)]
    plain = [GmphdEstimator(e.filter) for e in ests]
    for k in range(4):
        scans = [centres[:, [0, 2]] + rng.normal(0, 10, (3, 2)) for _ in ests]
        GmphdEstimator.prepare_many(ests, [1, 1, 1], scans)
        # estimator 1 steps 2 scans ahead, estimator 2 sees another scan: both not prepared
        steps = [1, 2, 1]
        seen = [scans[0], scans[1], scans[2][:1]]
        for e, q, s, z in zip(ests, plain, steps, seen, strict=True):
            a, b = e.step(s, z), q.step(s, z)
            _same(a.density, b.density)
            _same(a.published["posterior"], b.published["posterior"])
        assert ests[0].prepared_hits == k + 1
        assert ests[1].prepared_hits == 0 and ests[2].prepared_hits == 0


def test_a_failing_stack_prepares_nothing_and_the_peers_step_on_their_own(monkeypatch):
    """A stacked step that raises must not stop a host: nothing is prepared, and each peer's
    own step runs (its errors counted by its consensus as always)."""
    import sensornet.peers.estimators as estimators
    from sensornet.peers.batching import prepare_local_steps

    rng = np.random.default_rng(9)
    centres = rng.uniform(-300, 300, (2, 4))
    motion, reducer = ConstantVelocity(1.0, 2.0), Reducer(merge_threshold=4.0)
    ests = [GmphdEstimator(_filter(rng, centres, motion, reducer)) for _ in range(2)]
    z = centres[:, [0, 2]]

    class Core:  # what prepare_local_steps reads of a PeerCore
        def __init__(self, est):
            self.consensus = type("C", (), {"estimator": est})()

        def scan_step(self, key, payload):
            return 1, z

    def broken(*args):
        raise FloatingPointError("stack")

    monkeypatch.setattr(estimators, "step_many", broken)
    assert prepare_local_steps([(Core(e), "k", b"") for e in ests]) == []
    for e in ests:  # nothing prepared: its own step
        want = e.filter.correct(e.filter.predict(e.mix, 1), [z])
        _same(e.step(1, z).density, want)
        assert e.prepared_hits == 0
    monkeypatch.undo()
    assert len(prepare_local_steps([(Core(e), "k", b"") for e in ests])) == 2
    for e in ests:
        want = e.filter.correct(e.filter.predict(e.mix, 1), [z])
        _same(e.step(1, z).density, want)
        assert e.prepared_hits == 1
