"""A young pooled fused track also weighs the peer's own scan (tracking.own_scan,
``fusion.existence_own``; docs/labelled-tracking.md "Young fused tracks and the peer's own
scan"): the likelihood ratio against a loop over plots with SciPy's Gaussian, the existence
update by hand (Reuter et al. 2014), the traced false track (two neighbours' clutter tracks at
0.2, the own scan without a plot there) dropped at a peer and kept with a plot on it, rows the
rule leaves alone, bad input, and the scenario's value."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import multivariate_normal
from sensornet.sim.run.peers import consensus_options, make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.own_scan import own_scan_ratio, own_scan_weights

PD, KAPPA, SIGMA = 0.9, 2.5e-6, 20.0


def _states(n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    means = rng.normal(0.0, 300.0, (n, 4))
    A = rng.normal(0.0, 5.0, (n, 4, 4))
    return means, A @ A.transpose(0, 2, 1) + 100.0 * np.eye(4)


def test_ratio_against_a_loop():
    """``1 - Pd + Pd sum_z N(z; Hm, HPH' + R) / kappa``, H the x and y rows, to 1e-12."""
    rng = np.random.default_rng(3)
    means, covs = _states(5, rng)
    z = np.concatenate([means[:3][:, [0, 2]] + rng.normal(0, 20, (3, 2)),
                        rng.uniform(-1000, 1000, (4, 2))])
    got = own_scan_ratio(means, covs, z, PD, KAPPA, SIGMA)
    for i in range(5):
        S = covs[i][np.ix_([0, 2], [0, 2])] + SIGMA**2 * np.eye(2)
        g = sum(multivariate_normal(means[i, [0, 2]], S).pdf(p) for p in z)
        np.testing.assert_allclose(got[i], 1 - PD + PD * g / KAPPA, rtol=1e-12)
    assert got[:3].min() > 1.0  # a plot on the state: evidence for it
    np.testing.assert_array_equal(own_scan_ratio(means, covs, np.zeros((0, 2)), PD, KAPPA,
                                                 SIGMA), np.full(5, 1 - PD))


def test_weights_by_hand():
    """Rows: pooled young without own mass (updated: ``r L / (1 - r + r L)``, at least the
    fused weight), own input holding it, too old, not raised by the pool (all unchanged)."""
    pooled = np.array([0.86, 0.86, 0.86, 0.3, 0.97])
    fused = np.array([0.08, 0.08, 0.08, 0.3, 0.2])
    labels = np.array([[0, 62, 1], [0, 62, 2], [0, 59, 3], [0, 62, 4], [0, 62, 5]])
    own = np.array([0.0, 0.2, 0.0, 0.0, 0.0])
    ratio = np.array([0.1, 0.1, 0.1, 0.1, 1e-6])
    got = own_scan_weights(pooled, fused, labels, 62, own, 2, ratio)
    r = 0.86
    np.testing.assert_allclose(got, [r * 0.1 / (1 - r + r * 0.1), 0.86, 0.86, 0.3, 0.2],
                               rtol=1e-12)


def test_bad_input_is_a_one_line_error():
    m, P = np.zeros((1, 4)), np.eye(4)[None]
    for pd, kappa, sigma in ((0.0, KAPPA, SIGMA), (PD, 0.0, SIGMA), (PD, KAPPA, -1.0),
                             (PD, np.inf, SIGMA)):
        with pytest.raises(ValueError, match="pd"):
            own_scan_ratio(m, P, np.zeros((1, 2)), pd, kappa, sigma)
    with pytest.raises(ValueError, match="finite"):
        own_scan_ratio(m, P, np.array([[np.nan, 0.0]]), PD, KAPPA, SIGMA)
    with pytest.raises(ValueError, match="rows"):
        own_scan_weights(np.ones(2), np.ones(2), np.zeros((2, 3)), 1, np.zeros(1), 2,
                         np.ones(2))


def _peer(own: int):
    """A seed 000 LMB peer (three sensors of 20 m plots, Pd 0.9) with the rule on or off; its
    extraction takes the given inputs (own density first) as the round's mixtures."""
    scn = load_scenario("seed000", overrides={"network.filter": "lmb",
                                              "fusion.existence_own": own})
    c = make_peer(scn, scn.sensor_names[0], 0).consensus
    c._input_mixtures = lambda inputs: inputs
    return c


def _extracted(own: int, plots: np.ndarray) -> int:
    """The traced case (circ20 Pd 0.9 run 100, p04 at scan 62): a young fused row that two
    neighbours' tracks hold at 0.2 (their clutter at one place), the own input none of it."""
    c = _peer(own)
    k, x = 62, np.array([-916.0, 0.0, -744.0, 0.0])
    P = np.diag([18.0**2, 10.0**2, 18.0**2, 10.0**2])[None]
    fused = GaussianMixture(np.array([0.08]), x[None], P)
    held = GaussianMixture(np.array([0.2]), x[None], P)
    empty = GaussianMixture(np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)))
    c._scan = SimpleNamespace(k=k, z=plots)
    out = c._tracks(k, fused, 0.0, np.array([[0, k, 7]]), [empty, held, held])
    return len(out[0].states)


def test_two_neighbours_clutter_meets_the_own_miss():
    """Pooled about 0.01 the two inputs give 0.86 (reported without the rule); the own scan
    without a plot near it multiplies its odds by about ``1 - Pd`` (0.38: not reported); with a
    plot on it the row stays."""
    far = np.array([[500.0, 500.0], [-100.0, 300.0]])
    assert _extracted(0, far) == 1
    assert _extracted(1, far) == 0
    assert _extracted(1, np.array([[-910.0, -750.0], *far])) == 1


@pytest.mark.parametrize(("kind", "value", "on"), [("lmb", 1, True), ("lmb", 0, False),
                                                   ("gmphd", 1, False)])
def test_scenario_value(kind, value, on):
    """``(Pd, kappa, sigma)`` of the peer's own linear sensor for LMB peers that pool young
    tracks, with the option on (off by default); GM-PHD peers never."""
    scn = load_scenario("seed000", overrides={"network.filter": kind,
                                              "fusion.existence_own": value})
    got = consensus_options(scn, scn.sensor_names[0]).existence_own
    if on:
        (x0, x1), (y0, y1) = scn.region
        s = scn.sensors[0]
        np.testing.assert_allclose(got, (s.detection_probability,
                                         s.clutter_rate / ((x1 - x0) * (y1 - y0)), s.sigma_r))
    else:
        assert got == ()
    assert load_scenario("seed000").fusion.existence_own == 0
