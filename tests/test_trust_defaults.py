"""What keeps honest neighbours trusted (issue 36 item 5): the covariance gate of the
matching tests, single-target summaries compared where the target is, and the settings a
scenario gives the test (per-scan detection probability, warm-up); each against an
independent reference (a loop over pairs, the closed-form Mahalanobis distance)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.trust import Trust, TrustConfig, _collapsed
from sensornet.peers.trust_checks import gated, near, unmatched_weights
from sensornet.peers.trust_repair import corroborated
from sensornet.sim.run.peers import SINGLE_TARGET_WARMUP, consensus_options
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.mixture import GaussianMixture

CHI2 = 13.82


def _loop_near(Xa, Pa, Xb, Pb, gate, chi2):
    out = np.zeros((len(Xa), len(Xb)), bool)
    for i in range(len(Xa)):
        for j in range(len(Xb)):
            d = Xa[i] - Xb[j]
            P = Pa[i] if np.linalg.det(Pa[i]) <= np.linalg.det(Pb[j]) else Pb[j]
            out[i, j] = (np.hypot(*d) <= gate
                         or float(d @ np.linalg.solve(2.0 * P, d)) <= chi2)
    return out


def _covs(rng, n, scale):
    A = rng.normal(size=(n, 2, 2)) * scale
    return A @ np.swapaxes(A, 1, 2) + scale ** 2 * np.eye(2)


def test_gate_is_metres_or_the_chi_square_of_the_smaller_covariance():
    rng = np.random.default_rng(3)
    Xa, Xb = rng.uniform(0, 2000, (7, 2)), rng.uniform(0, 2000, (9, 2))
    Pa, Pb = _covs(rng, 7, 150.0), _covs(rng, 9, 40.0)
    got = near(Xa, Pa, Xb, Pb, 60.0, CHI2)
    assert np.array_equal(got, _loop_near(Xa, Pa, Xb, Pb, 60.0, CHI2))
    assert got.any() and not got.all()
    assert np.array_equal(near(Xa, Pa, Xb, Pb, 60.0), _loop_near(Xa, Pa, Xb, Pb, 60.0, -1.0))


def test_a_wide_covariance_does_not_widen_the_gate():
    d = np.array([[300.0, 0.0]])
    honest = np.diag([200.0 ** 2, 200.0 ** 2])[None]  # 300 m at 200 m sd: one target
    tight = np.eye(2)[None]
    huge = 1e12 * np.eye(2)[None]
    assert gated(d, honest, honest, 60.0, CHI2).all()
    assert not gated(d, tight, huge, 60.0, CHI2).any()  # the smaller one decides
    assert not gated(d, honest, honest, 60.0, None).any()  # metres only: 300 > 60


def _mix(points, sd):
    n = len(points)
    means = np.zeros((n, 4))
    means[:, [0, 2]] = points
    return GaussianMixture(np.ones(n), means, np.tile(np.diag([sd ** 2, 100.0, sd ** 2, 100.0]),
                                                      (n, 1, 1)))


def test_uncertain_estimates_hundreds_of_metres_apart_are_matched_not_unmatched():
    own = _mix([[0.0, 0.0], [10_000.0, 0.0]], 200.0)
    nb = _mix([[250.0, -150.0], [10_300.0, 100.0], [30_000.0, 0.0]], 220.0)  # + a real extra
    U, _ = unmatched_weights([own, nb], [0, 2], 0.5, 60.0)
    assert U[0, 1] == 2.0 and U[1, 0] == 3.0  # metres alone: nothing matches
    U, _ = unmatched_weights([own, nb], [0, 2], 0.5, 60.0, CHI2)
    assert U[0, 1] == 0.0 and U[1, 0] == 1.0  # only the target own does not show
    assert corroborated(nb, [own], [0, 2], 0.5, 60.0, CHI2).tolist() == [True, True, False]
    assert corroborated(nb, [own], [0, 2], 0.5, 60.0).tolist() == [False, False, False]


def _imm(pos, cov, probs=(0.8, 0.2), lag=(0.0, 0.0)):
    """A two-model single-target summary (6-D state, positions at 0 and 3)."""
    means = np.zeros((2, 6))
    means[:, [0, 3]] = pos
    means[1, [0, 3]] += lag
    covs = np.tile(np.eye(6), (2, 1, 1))
    covs[:, :1, :1] = covs[:, 3:4, 3:4] = 1.0
    covs[:, np.ix_([0, 3], [0, 3])[0], np.ix_([0, 3], [0, 3])[1]] = cov
    return GaussianMixture(np.array(probs), means, covs)


def test_single_target_summaries_are_compared_where_the_target_is():
    cfg = TrustConfig(single_target=True, location_only=True, bias=False, register=False,
                      repair=False)
    t = Trust(cfg, ("b",), position_index=(0, 3))
    # two radars that see the target from different sides: covariances crossed
    Pa = np.array([[200.0, 0.0], [0.0, 10.0]])
    Pb = np.array([[10.0, 0.0], [0.0, 200.0]])
    own = _imm([1000.0, 2000.0], Pa)
    same = _imm([1000.0, 2000.0], Pb, probs=(0.6, 0.4))
    stats = t.statistics(*_collapsed_pair(t, own, same), {"": 0.5, "b": 0.5})
    assert stats["b"] == pytest.approx(0.0, abs=1e-9)  # shapes differ, nothing else
    off = np.array([12.0, -9.0])
    moved = _imm(np.array([1000.0, 2000.0]) + off, Pb)
    stats = t.statistics(*_collapsed_pair(t, own, moved), {"": 0.5, "b": 0.5})
    mean_a, cov_a = own.moments()
    mean_b, cov_b = moved.moments()
    p = [0, 3]
    d = (mean_b - mean_a)[p]
    S = cov_a[np.ix_(p, p)] + cov_b[np.ix_(p, p)]
    assert stats["b"] == pytest.approx(0.5 * d @ np.linalg.solve(S, d), rel=1e-9)


def _collapsed_pair(t, own, nb):
    """What :meth:`Trust.weigh` tests for single-target summaries."""
    p = t.state_pos
    return _collapsed(own, p), {"b": _collapsed(nb, p)}


def test_a_lagging_model_is_within_the_summary_not_a_disagreement():
    cfg = TrustConfig(single_target=True, location_only=True, bias=False, register=False,
                      repair=False)
    P = np.diag([25.0, 25.0])
    own = _imm([0.0, 0.0], P, probs=(0.5, 0.5), lag=(30.0, 0.0))  # the models 30 m apart
    nb = _imm([30.0, 0.0], P, probs=(0.5, 0.5), lag=(-30.0, 0.0))  # the same two, swapped
    t = Trust(cfg, ("b",), position_index=(0, 3))
    w = [0.5, 0.5]
    t.weigh(1, 0, own, {"b": nb}, w)
    assert t.n["b"].last_statistic == pytest.approx(0.0, abs=1e-9)


def test_scenarios_give_the_test_per_scan_detection_and_a_warm_up():
    off = load_scenario("paris", overrides={"fusion.trust": False})
    assert consensus_options(off, "cdg").trust is None  # off when asked
    paris = load_scenario("paris")
    cfg = consensus_options(paris, "cdg").trust  # on by default (issue 36 item 5)
    assert cfg is not None and cfg.enabled
    # the en-route radars sweep 2 s of their 12 s turn per scan: Pd 0.95 x 1/6
    assert cfg.detection_probability == pytest.approx(0.95 * 2.0 / 12.0)
    assert cfg.warmup == 12  # two turns of the slowest radar, in 2 s scans
    assert cfg.gate_chi2 is not None and not cfg.single_target
    s1 = load_scenario("seed001", overrides={"fusion.trust": True})
    cfg = consensus_options(s1, "r1").trust
    assert cfg.single_target and cfg.location_only and not cfg.bias
    assert not cfg.register and not cfg.repair
    assert cfg.detection_probability is None  # Pd 1: no miss explains anything
    assert cfg.warmup == int(SINGLE_TARGET_WARMUP / s1.scan_period)
    s0 = load_scenario("seed000", overrides={"fusion.trust": True})
    cfg = consensus_options(s0, "s1").trust
    assert cfg.warmup == 0 and not cfg.single_target and not cfg.location_only
    assert cfg.detection_probability == min(s.detection_probability for s in s0.sensors)


def test_single_target_settings_refuse_registration_and_repair():
    for bad in ({"register": True, "repair": False}, {"register": False, "repair": True}):
        with pytest.raises(ValueError, match="single_target"):
            TrustConfig(single_target=True, **bad)
