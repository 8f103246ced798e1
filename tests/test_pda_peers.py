"""Seed 003 peer parts (peers/pda_parts.py) and the offline peer-mode comparison."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.contracts import Fuser, FusionInput, LocalEstimator
from sensornet.peers.pda_parts import CiFuser, PdaEstimator, ci_det_weight, covariance_intersection
from sensornet.sim.studies.seed003 import montecarlo as seed003
from sensornet.sim.studies.seed003 import peers as seed003_peers
from sensornet.tracking.mixture import GaussianMixture


def test_covariance_intersection_closed_form():
    m = np.array([[0.0, 0.0], [2.0, 4.0]])
    P = np.array([np.diag([1.0, 10.0]), np.diag([10.0, 1.0])])
    x, C = covariance_intersection(m, P, np.array([0.5, 0.5]))
    info = 0.5 * np.diag([1.0, 0.1]) + 0.5 * np.diag([0.1, 1.0])
    np.testing.assert_allclose(C, np.linalg.inv(info))
    np.testing.assert_allclose(x, np.linalg.inv(info) @ (0.5 * np.diag([0.1, 1.0]) @ m[1]))
    assert ci_det_weight(m, P) == pytest.approx(0.5, abs=1e-3)  # symmetric: half each
    # a uniformly better input takes all the weight
    assert ci_det_weight(m, np.array([np.eye(2), 4 * np.eye(2)])) == pytest.approx(1.0, abs=1e-3)


def test_ci_is_consistent_for_any_correlation():
    """CI's covariance bounds the true error covariance of the fused mean for fully
    correlated inputs too (here: the same estimate twice)."""
    P = np.diag([4.0, 9.0])
    x, C = covariance_intersection(np.zeros((2, 2)), np.array([P, P]), np.array([0.3, 0.7]))
    np.testing.assert_allclose(C, P)


def test_parts_meet_the_contracts_and_fuse():
    cfg = seed003.load()
    X = seed003.truth(cfg)
    sens = seed003.sensors(cfg)
    m0, P0 = X[0], np.diag([50.0, 10, 1, 50, 10, 1]) ** 2
    est = PdaEstimator(seed003.make_filter(cfg, "IMM-PDAF", m0, P0), sens[0], (0, 3))
    assert isinstance(est, LocalEstimator) and isinstance(CiFuser(), Fuser)
    out = est.step(1, X[1, [0, 3]][None])
    own = out.published["posterior"]
    other = GaussianMixture(np.ones(1), own.means + 10.0, own.covs * 2)
    fused = CiFuser().fuse(FusionInput(1, 0, own, {"s2": {"posterior": other}}, [0.5, 0.5],
                                       np.empty((0, 2))))
    assert len(fused) == 1
    assert np.linalg.det(fused.covs[0]) <= np.linalg.det(own.covs[0]) * (1 + 1e-3)
    est.adopt(fused)
    np.testing.assert_allclose(est.filter.estimate()[0], fused.means[0])


def test_peer_modes_one_run():
    cfg = seed003.load(overrides={"clutter.mode": "region", "clutter.in_gate": 0.5})
    r = seed003_peers.run_once(cfg, 10000)
    assert set(r) == {"local s1", "local s2", "CI s1", "CI s2", "CI+feedback s1",
                      "CI+feedback s2", "sequential s1+s2"}
    rows = seed003_peers.summarise(cfg, [r])
    assert "sequential" in seed003_peers.format_table(rows)
    # straight leg, light clutter: every mode tracks within a few sigma
    for key, e in r.items():
        assert np.median(e[0][10:50]) < 150.0, key
