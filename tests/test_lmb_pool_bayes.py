"""The pooled existence of young fused LMB tracks (tracking.fusion_rules.pool_existence, used by
tracking.support.pooled_weights) against Bayes' rule by brute force: a target that exists with
prior ``r0``, ``n`` sensors whose data are independent given existence (each a finite alphabet
with its own likelihood table); each sensor's posterior ``r_i`` pooled must equal the posterior
given every sensor's datum, computed by enumerating the joint of existence and data."""

from __future__ import annotations

import itertools

import numpy as np
from sensornet.tracking.fusion_rules import pool_existence


def _joint_posterior(r0: float, tables: list[np.ndarray], z: tuple[int, ...]) -> float:
    """P(exists | z_1..z_n) by summing the joint over existence e in {0, 1}:
    ``P(e) prod_i P(z_i | e)``, the tables ``(2, A_i)`` rows e = 0 and e = 1."""
    joint = [(r0 if e else 1.0 - r0) * np.prod([T[e, zi] for T, zi in zip(tables, z,
                                                                          strict=True)])
             for e in (0, 1)]
    return joint[1] / (joint[0] + joint[1])


def test_pool_equals_bayes_by_brute_force():
    """100 random cases of 1-4 sensors with 2-4 symbols each, every data combination: the
    pooled single-sensor posteriors equal the joint posterior to 1e-12 (one batched call per
    case, a group per data combination)."""
    rng = np.random.default_rng(33)
    worst = 0.0
    for _ in range(100):
        n = int(rng.integers(1, 5))
        r0 = float(rng.uniform(0.005, 0.6))
        tables = [rng.dirichlet(np.ones(a), size=2) for a in rng.integers(2, 5, size=n)]
        combos = list(itertools.product(*[range(T.shape[1]) for T in tables]))
        W, group, want = [], [], []
        for g, z in enumerate(combos):
            for T, zi in zip(tables, z, strict=True):  # each sensor's own posterior
                W.append(r0 * T[1, zi] / (r0 * T[1, zi] + (1 - r0) * T[0, zi]))
                group.append(g)
            want.append(_joint_posterior(r0, tables, z))
        got = pool_existence(np.array(W), np.array(group), len(combos), r0)
        worst = max(worst, float(np.max(np.abs(got - np.array(want)))))
    assert worst < 1e-12


def test_pool_of_a_missed_detection_lowers_existence():
    """Detections at two sensors and a miss at a third (Pd 0.9, a plot of likelihood ratio
    ``g / kappa`` = 20): the pooled existence is Bayes' three-sensor posterior, by hand."""
    r0, pd, lr = 0.01, 0.9, 20.0
    hit = r0 * pd * lr / (r0 * pd * lr + 1 - r0)
    miss = r0 * (1 - pd) / (r0 * (1 - pd) + 1 - r0)
    odds = r0 / (1 - r0) * (pd * lr) ** 2 * (1 - pd)
    got = pool_existence(np.array([hit, hit, miss]), np.zeros(3, np.int64), 1, r0)
    np.testing.assert_allclose(got, [odds / (1 + odds)], rtol=1e-12)
    assert got[0] < pool_existence(np.array([hit, hit]), np.zeros(2, np.int64), 1, r0)[0]
