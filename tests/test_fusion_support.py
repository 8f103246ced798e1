"""The support rule of fused extraction (tracking/support.py, scenario key fusion.support):
the input count against a brute-force loop, the rule's runs of scans by hand, and in a seed-000
twin that it removes reported tracks only (the fused density unchanged)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.fusion_rules import HYBRID_GATE
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.support import SupportRule, input_support


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
    """Seed 000 at Pd 0.9, run 100, 60 scans: with fusion.support = 2 every peer's reported
    fused tracks are a subset of those without (same ids, same states), and some are gone."""
    over = {"sensors.*.detection_probability": 0.9, "scenario.num_scans": 60}
    base = run_twin(load_scenario("seed000", overrides=over), 100)
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
