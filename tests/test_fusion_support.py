"""The support rule of fused extraction (tracking/support.py, scenario key fusion.support):
the input count against a brute-force loop, the rule's runs of scans by hand, and in a seed-000
twin that it removes reported tracks only (the fused density unchanged)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.fusion_rules import HYBRID_GATE, pool_existence
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.support import SupportRule, input_mass, input_support, pooled_weights


def _mixture(rng: np.random.Generator, n: int, d: int = 4) -> GaussianMixture:
    A = rng.normal(size=(n, d, d))
    covs = A @ A.swapaxes(1, 2) * 40.0 + 10.0 * np.eye(d)
    return GaussianMixture(rng.uniform(0.1, 1.0, n), rng.normal(0, 30.0, (n, d)), covs)


def test_input_support_equals_brute_force():
    """200 random cases: the count of inputs holding a component within the gate, by loops."""
    rng = np.random.default_rng(33)
    for _ in range(200):
        inputs = [_mixture(rng, int(rng.integers(0, 4))) for _ in range(int(rng.integers(1, 5)))]
        X = rng.normal(0, 30.0, (int(rng.integers(0, 5)), 4))
        want = np.zeros(len(X), dtype=int)
        for a, x in enumerate(X):
            for D in inputs:
                q = [float((x - m) @ np.linalg.solve(P, x - m))
                     for m, P in zip(D.means, D.covs, strict=True)]
                want[a] += any(v <= HYBRID_GATE for v in q)
        np.testing.assert_array_equal(input_support(X, inputs), want)


def test_input_support_bad_input():
    mix = GaussianMixture(np.ones(1), np.zeros((1, 4)), np.eye(4)[None])
    with pytest.raises(ValueError, match="means"):
        input_support(np.zeros(4), [mix])
    with pytest.raises(ValueError, match="dimension"):
        input_support(np.zeros((1, 2)), [mix])
    with pytest.raises(ValueError, match="gate"):
        input_support(np.zeros((1, 4)), [mix], gate=0.0)


def test_rule_by_hand():
    """Label A held by one input: dropped on its first scan, reported from its second in a
    row; label B held by two: reported at once; A's run broken by a scan without it restarts."""
    rule = SupportRule(min_inputs=2, scans=2)
    A, B = [0, 1, 0], [1, 1, 0]
    np.testing.assert_array_equal(rule.keep(np.array([A, B]), np.array([1, 2])), [False, True])
    np.testing.assert_array_equal(rule.keep(np.array([A, B]), np.array([1, 1])), [True, True])
    np.testing.assert_array_equal(rule.keep(np.array([B]), np.array([1])), [True])
    np.testing.assert_array_equal(rule.keep(np.array([A]), np.array([1])), [False])
    with pytest.raises(ValueError, match="support"):
        rule.keep(np.array([A]), np.array([1, 2]))
    with pytest.raises(ValueError, match="min_inputs"):
        SupportRule(min_inputs=0)


def _fused(twin, name):
    t = twin.peers[name].scorer.results.table(name)
    return {k: (np.asarray(tr, float).reshape(-1, 4), [tuple(i) for i in ids])
            for k, e, tr, ids in zip(t["scan"], t["estimate"], t["tracks"], t["track_ids"],
                                     strict=True) if e == "fused"}


def test_twin_support_removes_tracks_only():
    """Seed 000 at Pd 0.9, run 100, 60 scans: with fusion.support = 2 (pinned) every
    peer's reported fused tracks are a subset of those without (``fusion.support = 0``, pinned:
    every extracted track), with the same ids and states, and some are gone."""
    over = {"sensors.*.detection_probability": 0.9, "scenario.num_scans": 60}
    base = run_twin(load_scenario("seed000", overrides={**over, "fusion.support": 0}), 100)
    rule = run_twin(load_scenario("seed000", overrides={**over, "fusion.support": 2}), 100)
    removed = 0
    for name in ("s1", "s2", "s3"):
        a, b = _fused(base, name), _fused(rule, name)
        assert a.keys() == b.keys()
        for k in a:
            (Xa, ia), (Xb, ib) = a[k], b[k]
            assert set(ib) <= set(ia)
            for x, i in zip(Xb, ib, strict=True):
                np.testing.assert_array_equal(x, Xa[ia.index(i)])
            removed += len(ia) - len(ib)
    assert removed > 0


def test_pool_existence_is_bayes_with_independent_likelihoods():
    """Inputs that each updated the common prior ``r0`` with their own likelihood ratio
    ``L_i`` (Bayes: ``r_i = r0 L_i / (r0 L_i + 1 - r0)``) pool to the prior updated with the
    product of the ratios, the centralised answer; 100 random cases, groups of 1-4 inputs."""
    rng = np.random.default_rng(7)
    for _ in range(100):
        r0 = rng.uniform(0.001, 0.5)
        sizes = rng.integers(1, 5, 3)
        L = np.exp(rng.normal(0.0, 2.0, sizes.sum()))
        g = np.repeat(np.arange(3), sizes)
        r = r0 * L / (r0 * L + 1 - r0)
        prod = np.array([L[g == j].prod() for j in range(3)])
        want = r0 * prod / (r0 * prod + 1 - r0)
        np.testing.assert_allclose(pool_existence(r, g, 3, r0), want, rtol=1e-9)
    with pytest.raises(ValueError, match="prior"):
        pool_existence(np.ones(1) / 2, np.zeros(1, int), 1, 1.0)


def test_pooled_weights_by_hand():
    """Scan 10, prior 0.01. A (young, two inputs at 0.2): the pool; B (young, one input):
    kept; C (young, two inputs) beside D (a track at 0.9): kept, it would duplicate D; E
    (label of scan 5, two inputs): kept, not young; D itself: kept."""
    eye = np.eye(4)[None] * 100.0
    means = np.array([[0, 0, 0, 0], [500, 0, 0, 0], [1000, 0, 0, 0], [1005, 0, 0, 0],
                      [0, 0, 800, 0]], float)
    mix = GaussianMixture(np.array([0.1, 0.1, 0.1, 0.9, 0.1]), means, np.repeat(eye, 5, 0))
    labels = np.array([[0, 9, 0], [0, 9, 1], [0, 10, 2], [1, 2, 0], [0, 5, 3]])
    mass = np.array([[0.2, 0.2], [0.2, 0.0], [0.2, 0.2], [0.9, 0.9], [0.2, 0.2]])
    w = pooled_weights(mix, labels, 10, mass, prior=0.01, young=2)
    odds = 0.01 / 0.99 * (0.25 / (0.01 / 0.99)) ** 2
    np.testing.assert_allclose(w, [odds / (1 + odds), 0.1, 0.1, 0.9, 0.1], rtol=1e-12)


def test_input_mass_counts_each_component_once():
    """An input's component goes to its nearest state only (a weak state beside a target
    does not take the target's mass too); ``held`` counts any within the gate."""
    P = np.eye(4)[None] * 400.0
    inp = GaussianMixture(np.array([0.9]), np.zeros((1, 4)), P)
    X = np.array([[0.0, 0, 0, 0], [30.0, 0, 0, 0]])
    np.testing.assert_allclose(input_mass(X, [inp]), [[0.9], [0.0]])
    np.testing.assert_array_equal(input_support(X, [inp]), [1, 1])


def _lmb_filter(origin: int = 2) -> LmbFilter:
    return LmbFilter(ConstantVelocity(1.0, 2.0),
                     SensorParams(LinearPosition(20.0), 0.95, 2.5e-6), origin=origin)


def test_lmb_publishes_young_tentative_tracks():
    """lmb.tentative_threshold: a track is published iff ``r > 0.5``, or ``r`` above the
    tentative threshold and its label at most ``tentative_scans`` scans old; some tracks go
    out below 0.5 (none without the option), each row beside its track's label."""
    truth = np.array([[0.0, 0.0], [300.0, -200.0]])
    v = np.array([[5.0, 2.0], [-3.0, 4.0]])
    for tentative in (None, 0.05):
        rng = np.random.default_rng(6)
        est = LmbEstimator(_lmb_filter(), origin=2, tentative_threshold=tentative,
                           tentative_scans=1)
        below = 0
        for k in range(1, 9):
            z = np.vstack([truth + v * k + rng.normal(0, 10, (2, 2)),
                           rng.uniform(-900, 900, (5, 2))])  # two targets, clutter
            est.begin_scan(k)
            out = est.step(1, z)
            t = est.state.tracks
            want = t.existence > 0.5
            if tentative is not None:
                want |= (t.existence > tentative) & (k - t.labels[:, 1] <= 1)
            np.testing.assert_array_equal(out.labels["posterior"],
                                          t.labels[t.owner][want[t.owner]])
            below += int((want & (t.existence <= 0.5)).sum())
        assert (below > 0) == (tentative is not None)
    with pytest.raises(ValueError, match="tentative_threshold"):
        LmbEstimator(_lmb_filter(), origin=2, tentative_threshold=2.0)
