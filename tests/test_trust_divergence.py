"""The trust test's log overlaps (tracking/divergence.py) made once per unordered pair: the
old numbers to the bit (``benchmarks/trust_before.py`` keeps the code before), and against
an independent reference (SciPy's Gaussian log density, log-sum-exp'ed pair by pair)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal
from sensornet.tracking import divergence
from sensornet.tracking.divergence import log_overlaps, pair_terms
from sensornet.tracking.mixture import GaussianMixture

from benchmarks import trust_before


def _mixture(rng: np.random.Generator, size: int, d: int, spread: float) -> GaussianMixture:
    """``size`` random components in ``d`` dimensions (means over ``spread`` metres)."""
    if size == 0:
        return GaussianMixture.empty(d)
    A = rng.normal(0, 1, (size, d, d)) * rng.uniform(1, 40, (size, 1, 1))
    covs = A @ A.transpose(0, 2, 1) + np.eye(d)
    return GaussianMixture(rng.uniform(0.01, 1.0, size), rng.uniform(-spread, spread, (size, d)),
                           covs)


def _mixtures(rng: np.random.Generator, d: int, most: int) -> list[GaussianMixture]:
    """0-7 mixtures of 0..``most`` components (single-component ones often: a round of LMB
    summaries), some repeated, some near copies, some far (underflowing overlaps)."""
    out = []
    for _ in range(int(rng.integers(0, 8))):
        kind = rng.integers(0, 5)
        if kind == 0 and out:
            out.append(out[int(rng.integers(0, len(out)))])
        elif kind == 1 and out and len(out[0]):
            D = out[0]
            out.append(GaussianMixture(D.weights, D.means + rng.normal(0, 3, D.means.shape),
                                       D.covs))
        else:
            size = 1 if rng.random() < 0.5 else int(rng.integers(0, most + 1))
            out.append(_mixture(rng, size, d, float(rng.choice([100.0, 1e5]))))
    return out


@pytest.mark.parametrize("d", [2, 4, 6])
def test_log_overlaps_equal_old_to_the_bit(d):
    rng = np.random.default_rng(50 + d)
    finite = 0
    for _ in range(300):
        mixes = _mixtures(rng, d, 5)
        new, old = log_overlaps(mixes), trust_before.log_overlaps(mixes)
        assert new.shape == old.shape == (len(mixes), len(mixes))
        assert np.array_equal(new, old), (new, old)
        finite += int(np.isfinite(new).sum())
    assert finite > 1000  # most pairs overlap


def test_blocked_path_equal_old_to_the_bit(monkeypatch):
    """Beyond :data:`BLOCK_PAIRS` (made small here) both take the module's blocked path."""
    monkeypatch.setattr(divergence, "BLOCK_PAIRS", 40)
    rng = np.random.default_rng(9)
    for _ in range(100):
        mixes = _mixtures(rng, 4, 6)
        assert np.array_equal(log_overlaps(mixes), trust_before.log_overlaps(mixes))


def test_log_overlaps_against_scipy():
    """``log sum_a sum_b w_a w_b N(m_a; m_b, P_a + P_b)`` pair by pair with SciPy."""
    rng = np.random.default_rng(3)
    for _ in range(40):
        mixes = [_mixture(rng, int(rng.integers(0, 4)), 4, 300.0) for _ in range(4)]
        L = log_overlaps(mixes)
        for i, p in enumerate(mixes):
            for j, q in enumerate(mixes):
                terms = [np.log(wa * wb) + multivariate_normal.logpdf(ma, mb, Pa + Pb)
                         for wa, ma, Pa in zip(p.weights, p.means, p.covs, strict=True)
                         for wb, mb, Pb in zip(q.weights, q.means, q.covs, strict=True)]
                if not terms:
                    assert L[i, j] == -np.inf
                else:
                    assert L[i, j] == pytest.approx(logsumexp(terms), rel=1e-9, abs=1e-9)


def test_pair_terms_symmetric_and_each_pair_once():
    rng = np.random.default_rng(4)
    D = _mixture(rng, 7, 4, 500.0)
    G = pair_terms(np.log(D.weights), D.means, D.covs)
    assert np.array_equal(G, G.T)
    a = 2
    for b in range(7):
        want = np.log(D.weights[a] * D.weights[b] * multivariate_normal.pdf(
            D.means[a], D.means[b], D.covs[a] + D.covs[b]))
        assert G[a, b] == pytest.approx(want, rel=1e-10)
