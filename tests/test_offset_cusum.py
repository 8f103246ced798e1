"""The sequential offset test (:func:`peers.trust_checks.offset_cusum`, Page's CUSUM of a
30 m-class bias): the recursion against the brute-force maximum over windows of closed-form
Gaussian log-likelihood ratios, how soon a constant bias crosses, and an honest, zero-mean
sequence with the training runs' correlation over scans that does not."""

from __future__ import annotations

import numpy as np
from sensornet.peers.trust import Trust, TrustConfig
from sensornet.peers.trust_checks import cusum_directions, offset_cusum, offset_increments
from sensornet.tracking.mixture import GaussianMixture


def _cfg(**kw) -> TrustConfig:
    """The test alone (no registration, no repair: both on by default), which these
    tests are about; :mod:`tests.test_trust_repair` has the repairs."""
    return TrustConfig(**{"register": False, "repair": False, **kw})


CFG = _cfg()
S = np.diag([210.0, 210.0])
"""Summed position covariance of one matched pair, seed 000-like (13-15 m honest offset
deviation per axis on the training runs, normalised variance about 0.8)."""
RHO = 0.65
"""Lag-1 correlation of honest offsets over scans on seed 000's training runs (0.5-0.7)."""


def _log_normal(d: np.ndarray, m: np.ndarray, P: np.ndarray) -> float:
    r = d - m
    return float(-0.5 * r @ np.linalg.solve(P, r) - 0.5 * np.log(np.linalg.det(2 * np.pi * P)))


def _scan(rng, n_pairs: int, bias: np.ndarray):
    """One scan: matched pairs' differences and covariances, and their ``(I, y)``."""
    S_i = [np.diag(rng.uniform(100.0, 400.0, 2)) + 20.0 * np.eye(2) for _ in range(n_pairs)]
    d_i = [bias + np.linalg.cholesky(P) @ rng.standard_normal(2) for P in S_i]
    I = sum(np.linalg.inv(P) for P in S_i)
    y = sum(np.linalg.solve(P, d) for P, d in zip(S_i, d_i, strict=True))
    return d_i, S_i, (I, y)


def test_cusum_is_the_largest_window_sum_of_gaussian_log_likelihood_ratios():
    rng = np.random.default_rng(3)
    dirs = cusum_directions(8)
    g = np.zeros(8)
    llr = []  # per scan, per direction: brute force from the Gaussian densities
    for k in range(25):
        n = int(rng.integers(0, 3))  # 0: nothing matched this scan
        bias = np.array([25.0, -10.0]) if k >= 10 else np.zeros(2)
        d_i, S_i, info = _scan(rng, n, bias) if n else ([], [], (np.zeros((2, 2)), np.zeros(2)))
        row = [sum(_log_normal(d, 30.0 * u, P) - _log_normal(d, np.zeros(2), P)
                   for d, P in zip(d_i, S_i, strict=True)) for u in dirs]
        llr.append(row)
        np.testing.assert_allclose(offset_increments(info, 30.0, dirs), row, atol=1e-9)
        g = offset_cusum(g, info, 30.0, dirs)
        L = np.array(llr)  # (k + 1, 8)
        brute = np.maximum(0.0, np.max([L[j:].sum(axis=0) for j in range(k + 1)], axis=0))
        np.testing.assert_allclose(g, brute, atol=1e-9)


def _bias_info(d: np.ndarray):
    I = np.linalg.inv(S)
    return I, I @ d


def test_a_constant_30m_bias_crosses_when_the_closed_form_says():
    """Noise-free: each scan adds ``b' S^-1 b / 2`` along the bias (a chart's direction), so
    the CUSUM crosses at ``ceil(h / that)`` scans; the threshold is above any single scan."""
    dirs = cusum_directions(CFG.bias_cusum_directions)
    b = np.array([30.0, 0.0])
    per_scan = 0.5 * b @ np.linalg.solve(S, b)
    expected = int(np.ceil(CFG.bias_cusum_threshold / per_scan))
    g, crossed = np.zeros(len(dirs)), None
    for k in range(1, 40):
        g = offset_cusum(g, _bias_info(b), CFG.bias_cusum_offset, dirs)
        if crossed is None and g.max() > CFG.bias_cusum_threshold:
            crossed = k
    assert crossed == expected and expected > 1
    # between two charts' directions a bias loses at most cos(pi / 8) of its increment
    b2 = 30.0 * np.array([np.cos(np.pi / 8), np.sin(np.pi / 8)])
    inc = offset_increments(_bias_info(b2), CFG.bias_cusum_offset, dirs).max()
    worst = CFG.bias_cusum_offset * 30.0 * np.cos(np.pi / 8) / S[0, 0] - per_scan
    assert inc >= worst - 1e-9


def _ar1(rng, scans: int, bias: np.ndarray) -> np.ndarray:
    """Offsets ``(scans, 2)``: ``bias`` plus zero-mean AR(1) noise of lag-1 correlation
    :data:`RHO` and stationary covariance ``0.8 S``."""
    L = np.linalg.cholesky(0.8 * S)
    e = np.zeros((scans, 2))
    e[0] = L @ rng.standard_normal(2)
    for k in range(1, scans):
        e[k] = RHO * e[k - 1] + np.sqrt(1 - RHO**2) * (L @ rng.standard_normal(2))
    return bias + e


def test_honest_correlated_offsets_stay_under_and_a_correlated_bias_crosses():
    """An honest neighbour's offsets, correlated over scans like the training runs', keep
    the CUSUM under its threshold on (nearly) every scan; the same noise around a 30 m bias
    crosses, later than the noise-free bias (the price of the threshold's margin for the
    correlation)."""
    rng = np.random.default_rng(11)
    dirs = cusum_directions(CFG.bias_cusum_directions)
    above, scans, delays = 0, 0, []
    for _ in range(40):
        for bias, out in ((np.zeros(2), None), (np.array([0.0, 30.0]), delays)):
            g, first = np.zeros(len(dirs)), None
            for k, d in enumerate(_ar1(rng, 100, bias), start=1):
                g = offset_cusum(g, _bias_info(d), CFG.bias_cusum_offset, dirs)
                over = g.max() > CFG.bias_cusum_threshold
                if out is None:
                    above += over
                    scans += 1
                elif first is None and over:
                    first = k
            if out is not None:
                out.append(first)
    assert above / scans <= 0.005
    assert all(d is not None for d in delays)
    assert 8 <= np.median(delays) <= 25


def test_trust_quarantines_a_biased_neighbour_by_the_cusum_alone():
    """Two neighbours (no relative offset), one 30 m off: the 3-scan window's chi-square
    stays at 3 x 900 / 210 = 12.9, under its 32 (the long window is switched off here); the
    CUSUM crosses at its closed-form scan, and without it the neighbour is never caught."""
    P = np.diag([105.0, 25.0, 105.0, 25.0])  # own + neighbour: S = 210 per axis
    m = np.array([0.0, 0.0, 0.0, 0.0])
    own = GaussianMixture(np.array([1.0]), m[None], P[None])
    # repeat=False: these hand-made densities are the same every scan
    cfg = _cfg(bias_windows=(3, 32), bias_thresholds=(32.0, 1e9), repeat=False)
    t = Trust(cfg, ("biased", "h"))
    low = None
    for k in range(1, 30):
        lie = GaussianMixture(np.array([1.0]), (m + [30.0, 0, 0, 0])[None], P[None])
        honest = GaussianMixture(np.array([1.0]), m[None], P[None])
        w = t.weigh(k, 0, own, {"biased": lie, "h": honest}, [1 / 3] * 3)
        if low is None and w[1] <= 0.1:
            low = k
    per_scan = 0.5 * 900.0 / 210.0
    assert low == int(np.ceil(cfg.bias_cusum_threshold / per_scan))
    off = Trust(_cfg(bias_cusum=False, bias_windows=(3, 32),
                            bias_thresholds=(32.0, 1e9), repeat=False), ("biased", "h"))
    for k in range(1, 30):
        lie = GaussianMixture(np.array([1.0]), (m + [30.0, 0, 0, 0])[None], P[None])
        w = off.weigh(k, 0, own, {"biased": lie, "h": own}, [1 / 3] * 3)
        assert w[1] > 0.1  # without the CUSUM (and the long window) never


def test_registration_repairs_a_biased_neighbour_instead_of_leaving_it_out():
    """:attr:`TrustConfig.register`: once the CUSUM crosses, the neighbour's offset (its
    least-squares estimate over the window) is subtracted from its density, which is then
    fused at full weight; before the crossing it is passed as received."""
    P = np.diag([105.0, 25.0, 105.0, 25.0])
    m = np.zeros(4)
    one = np.array([1.0])
    own = GaussianMixture(one, m[None], P[None])
    cfg = _cfg(bias_windows=(3, 32), bias_thresholds=(32.0, 1e9), repeat=False,
                      register=True)
    t = Trust(cfg, ("biased", "h"))
    cross = int(np.ceil(cfg.bias_cusum_threshold / (0.5 * 900.0 / 210.0)))
    for k in range(1, 20):
        lie = GaussianMixture(one, (m + [30.0, 0, -12.0, 0])[None], P[None])
        w = t.weigh(k, 0, own, {"biased": lie, "h": own}, [1 / 3] * 3)
        fixed = t.shift("biased", lie)
        assert w[1] > 0.1  # never left out
        if k < cross:
            assert fixed is lie
        else:
            np.testing.assert_allclose(fixed.means, own.means, atol=1e-9)
            np.testing.assert_allclose(fixed.covs, lie.covs)
