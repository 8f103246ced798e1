"""Mixture reduction (tracking.reduction) against hand computations and naive references."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import (
    Reducer,
    cap,
    ise_refit,
    keep_above,
    merge,
    moment_match,
    prune,
)


def random_spd(rng, d, scale=1.0):
    A = rng.normal(size=(d, d))
    return (A @ A.T + 0.5 * np.eye(d)) * scale


def clustered_mixture(rng, n, d=4, n_clusters=3, spread=3.0, sep=40.0):
    """Components scattered around a few centres so that merges happen."""
    centres = rng.normal(size=(n_clusters, d)) * sep
    which = rng.integers(0, n_clusters, size=n)
    means = centres[which] + rng.normal(size=(n, d)) * spread
    covs = np.stack([random_spd(rng, d, scale=rng.uniform(1.0, 4.0)) for _ in range(n)])
    weights = rng.uniform(0.01, 1.0, size=n)
    return GaussianMixture(weights, means, covs)


def hand_moment_match(w, m, P):
    W = sum(w)
    mean = sum(wi * mi for wi, mi in zip(w, m, strict=True)) / W
    cov = sum(wi * (Pi + np.outer(mi - mean, mi - mean)) for wi, mi, Pi in zip(w, m, P,
                                                                                  strict=True))
    return W, mean, cov / W


def naive_merge(mix, threshold, rule):
    """Greedy merge with explicit double loops (the definition, no vectorisation)."""
    n = len(mix)
    order = sorted(range(n), key=lambda i: -mix.weights[i])  # stable
    remaining = list(order)
    out = []
    while remaining:
        j = remaining[0]
        group = []
        for i in remaining:
            diff = mix.means[i] - mix.means[j]
            if rule == "vo-ma":
                d2 = diff @ np.linalg.solve(mix.covs[i], diff)
                close = d2 <= threshold
            else:
                wi, wj = mix.weights[i], mix.weights[j]
                d2 = wi * wj / (wi + wj) * (diff @ np.linalg.solve(mix.covs[j], diff))
                close = d2 < threshold
            if close or i == j:
                group.append(i)
        out.append(hand_moment_match([mix.weights[i] for i in group],
                                     [mix.means[i] for i in group],
                                     [mix.covs[i] for i in group]))
        remaining = [i for i in remaining if i not in group]
    return out


def npdf(x, mean, cov):
    """N(x; mean, cov) with numpy.linalg (a per-point reference)."""
    diff = x - mean
    _, logdet = np.linalg.slogdet(2 * np.pi * cov)
    return float(np.exp(-0.5 * (diff @ np.linalg.solve(cov, diff) + logdet)))


def ise(f: GaussianMixture, g: GaussianMixture) -> float:
    """Integral squared error between two mixtures, closed form, one pair at a time."""

    def cross(a, b):
        return sum(
            a.weights[i] * b.weights[j] * npdf(a.means[i], b.means[j], a.covs[i] + b.covs[j])
            for i in range(len(a))
            for j in range(len(b))
        )

    return float(cross(f, f) - 2 * cross(f, g) + cross(g, g))


def test_npdf_reference_matches_scipy():
    rng = np.random.default_rng(0)
    P = random_spd(rng, 3)
    m, x = rng.normal(size=3), rng.normal(size=3)
    assert npdf(x, m, P) == pytest.approx(multivariate_normal(m, P).pdf(x), rel=1e-12)


# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("rule,thr", [("vo-ma", 4.0), ("weighted", 2.0)])
@pytest.mark.parametrize("seed", range(5))
def test_merge_equals_naive_double_loop(seed, rule, thr):
    rng = np.random.default_rng(seed)
    mix = clustered_mixture(rng, n=25)
    out = merge(mix, thr, rule)
    ref = naive_merge(mix, thr, rule)
    assert len(ref) < len(mix)  # something merged
    assert len(out) == len(ref)
    for k, (w, m, P) in enumerate(ref):
        assert out.weights[k] == pytest.approx(w, rel=1e-12)
        np.testing.assert_allclose(out.means[k], m, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(out.covs[k], P, rtol=1e-10, atol=1e-10)
    assert out.mass == pytest.approx(mix.mass, rel=1e-12)


@pytest.mark.parametrize("rule", ["vo-ma", "weighted"])
def test_merge_keeps_mass_and_moment_matches_a_group(rule):
    rng = np.random.default_rng(11)
    d = 4
    base = np.array([10.0, 1.0, -5.0, 0.5])
    means = np.stack([base, base + [0.3, 0.1, -0.2, 0.0], base + [-0.2, 0.0, 0.3, 0.1],
                      base + 1000.0])
    covs = np.stack([random_spd(rng, d, 2.0) + 2 * np.eye(d) for _ in range(4)])
    weights = np.array([0.8, 0.5, 0.3, 0.9])
    mix = GaussianMixture(weights, means, covs)
    out = merge(mix, 4.0, rule)
    assert len(out) == 2
    assert out.mass == pytest.approx(weights.sum(), rel=1e-14)
    # Output order: heaviest leader first -> the far component (0.9) first, then the group.
    np.testing.assert_array_equal(out.means[0], means[3])
    np.testing.assert_array_equal(out.covs[0], covs[3])
    W, m, P = hand_moment_match(weights[:3], means[:3], covs[:3])
    assert out.weights[1] == pytest.approx(W)
    np.testing.assert_allclose(out.means[1], m, rtol=1e-13)
    np.testing.assert_allclose(out.covs[1], P, rtol=1e-12)
    # The merged Gaussian has the first two moments of the group (mixture.moments).
    gm, gP = mix.select(np.arange(3)).moments()
    np.testing.assert_allclose(out.means[1], gm, rtol=1e-13)
    np.testing.assert_allclose(out.covs[1], gP, rtol=1e-12)
    w2, m2, P2 = moment_match(weights[:3], means[:3], covs[:3])
    assert w2 == pytest.approx(W)
    np.testing.assert_allclose(P2, P, rtol=1e-12)


def two_components(wi, wj, diff, Pi, Pj):
    """Heavier component j at the origin, lighter i at ``diff``."""
    assert wj > wi or wj == wi
    means = np.stack([np.zeros(4), np.asarray(diff, float)])
    return GaussianMixture(np.array([wj, wi]), means, np.stack([Pj, Pi]))


def test_vo_ma_and_weighted_rules_differ_as_their_formulas_say():
    I4 = np.eye(4)
    # Equal weights, equal unit covariances, distance 2: Vo-Ma d2 = 4, weighted d2 = 0.5*4 = 2.
    mix = two_components(1.0, 1.0, [2.0, 0, 0, 0], I4, I4)
    assert len(merge(mix, 3.0, "vo-ma")) == 2  # 4 > 3
    assert len(merge(mix, 3.0, "weighted")) == 1  # 2 < 3
    # Just either side of the thresholds (Vo-Ma "<=", weighted "<").
    assert len(merge(mix, 4.0 + 1e-9, "vo-ma")) == 1
    assert len(merge(mix, 4.0 - 1e-9, "vo-ma")) == 2
    assert len(merge(mix, 2.0 + 1e-9, "weighted")) == 1
    assert len(merge(mix, 2.0 - 1e-9, "weighted")) == 2
    # Vo-Ma uses the candidate's covariance P_i, the weighted rule the leader's P_j.
    mix = two_components(1.0, 1.0, [2.0, 0, 0, 0], 100 * I4, I4)
    assert len(merge(mix, 1.0, "vo-ma")) == 1  # 4/100 = 0.04
    assert len(merge(mix, 1.0, "weighted")) == 2  # 0.5 * 4 / 1 = 2
    mix = two_components(1.0, 1.0, [2.0, 0, 0, 0], I4, 100 * I4)
    assert len(merge(mix, 1.0, "vo-ma")) == 2  # 4
    assert len(merge(mix, 1.0, "weighted")) == 1  # 0.5 * 4 / 100 = 0.02
    # The weighted rule shrinks with a light partner: w_i w_j/(w_i+w_j) = 0.01/1.01.
    mix = two_components(0.01, 1.0, [10.0, 0, 0, 0], I4, I4)
    assert len(merge(mix, 4.0, "vo-ma")) == 2  # 100
    assert len(merge(mix, 4.0, "weighted")) == 1  # ~0.99
    with pytest.raises(ValueError):
        merge(mix, 4.0, "nearest")


def test_prune_cap_keep_above():
    rng = np.random.default_rng(2)
    n = 12
    w = rng.permutation(np.linspace(0.05, 1.2, n))
    mix = GaussianMixture(w, rng.normal(size=(n, 4)), np.broadcast_to(np.eye(4), (n, 4, 4)))
    p = prune(mix, 0.3)
    np.testing.assert_array_equal(p.weights, w[w >= 0.3])
    np.testing.assert_array_equal(p.means, mix.means[w >= 0.3])
    c = cap(mix, 5)
    heaviest = np.sort(w)[-5:]
    np.testing.assert_array_equal(np.sort(c.weights), heaviest)
    # cap keeps the original order of the survivors and their means
    idx = np.flatnonzero(np.isin(w, heaviest))
    np.testing.assert_array_equal(c.means, mix.means[idx])
    assert cap(mix, 50) is mix
    k = keep_above(mix, 0.5)
    np.testing.assert_array_equal(k.weights, w[w > 0.5])
    exact = GaussianMixture(np.array([0.5, 0.50001, 0.49999]), np.zeros((3, 4)),
                            np.broadcast_to(np.eye(4), (3, 4, 4)))
    np.testing.assert_array_equal(keep_above(exact, 0.5).weights, [0.50001])
    np.testing.assert_array_equal(prune(exact, 0.5).weights, [0.5, 0.50001])
    empty = GaussianMixture.empty(4)
    assert len(prune(empty, 0.1)) == len(cap(empty, 3)) == len(keep_above(empty)) == 0


@pytest.mark.parametrize("d", [2, 4])
@pytest.mark.parametrize("seed", range(3))
def test_ise_refit_keeps_mass_and_does_not_increase_ise(seed, d):
    rng = np.random.default_rng(40 + seed)
    original = clustered_mixture(rng, n=12, d=d, n_clusters=3, spread=2.0, sep=6.0)
    reduced = merge(original, 4.0, "vo-ma")
    assert 1 < len(reduced) < len(original)
    fitted = ise_refit(original, reduced)
    assert fitted.mass == pytest.approx(original.mass, rel=1e-6)
    assert np.all(fitted.weights >= 0)
    np.testing.assert_array_equal(fitted.means, reduced.means)
    np.testing.assert_array_equal(fitted.covs, reduced.covs)
    e_fit, e_red = ise(original, fitted), ise(original, reduced)
    assert e_fit <= e_red + 1e-9 * max(1.0, e_red)
    # The refit is (close to) the constrained optimum: random feasible weights do no better.
    for _ in range(20):
        w = rng.dirichlet(np.ones(len(reduced))) * original.mass
        w = 0.5 * w + 0.5 * fitted.weights  # stay near the optimum to probe it locally too
        cand = GaussianMixture(w, reduced.means, reduced.covs)
        assert ise(original, cand) >= e_fit - 1e-6 * max(1.0, e_fit)


def exact_refit_weights(original, reduced):
    """Reference: min_w w^T A w - 2 b^T w s.t. w >= 0, sum w = mass, by trying every support.

    The objective is convex; on a support S the equality-constrained optimum solves a KKT
    linear system; the best non-negative one over all supports is the global optimum.
    """
    from itertools import combinations

    n = len(reduced)
    A = np.array([[npdf(reduced.means[i], reduced.means[j], reduced.covs[i] + reduced.covs[j])
                   for j in range(n)] for i in range(n)])
    b = np.array([
        sum(original.weights[a]
            * npdf(reduced.means[i], original.means[a], reduced.covs[i] + original.covs[a])
            for a in range(len(original)))
        for i in range(n)
    ])
    mass = original.mass
    best, best_w = np.inf, None
    for k in range(1, n + 1):
        for S in combinations(range(n), k):
            S = list(S)
            K = np.zeros((k + 1, k + 1))
            K[:k, :k] = 2 * A[np.ix_(S, S)]
            K[:k, k] = K[k, :k] = 1.0
            sol = np.linalg.solve(K, np.concatenate([2 * b[S], [mass]]))
            if np.any(sol[:k] < -1e-12):
                continue
            w = np.zeros(n)
            w[S] = np.clip(sol[:k], 0, None)
            f = w @ A @ w - 2 * b @ w
            if f < best:
                best, best_w = f, w
    return best_w


@pytest.mark.parametrize("seed", range(3))
def test_ise_refit_after_cap_is_the_constrained_optimum(seed):
    # Capping drops mass; the refit puts the original mass back onto the kept components. This
    # can raise the ISE above that of the capped mixture (the mass constraint), but it must be
    # the constrained optimum and beat the simply rescaled capped mixture.
    rng = np.random.default_rng(9 + seed)
    original = clustered_mixture(rng, n=8, d=2, n_clusters=4, spread=0.5, sep=10.0)
    reduced = cap(original, 3)
    assert reduced.mass < original.mass
    fitted = ise_refit(original, reduced)
    assert fitted.mass == pytest.approx(original.mass, rel=1e-6)
    rescaled = reduced.scaled(original.mass / reduced.mass)
    assert ise(original, fitted) <= ise(original, rescaled) + 1e-9
    w_ref = exact_refit_weights(original, reduced)
    e_ref = ise(original, GaussianMixture(w_ref, reduced.means, reduced.covs))
    assert ise(original, fitted) == pytest.approx(e_ref, rel=1e-4, abs=1e-7)
    np.testing.assert_allclose(fitted.weights, w_ref, atol=1e-4 * original.mass)


def test_ise_refit_at_tracking_scale():
    # 4-D components with covariances of hundreds of m^2 (a GM-PHD posterior): the raw ISE is
    # ~1e-6, which must not stop the optimiser at its starting point.
    rng = np.random.default_rng(1)
    n = 10
    means = np.zeros((n, 4))
    means[:, [0, 2]] = rng.normal(size=(n, 2)) * 30
    means[:, [1, 3]] = rng.normal(size=(n, 2)) * 3
    covs = np.broadcast_to(np.diag([400.0, 25, 400, 25]), (n, 4, 4)).copy()
    original = GaussianMixture(rng.uniform(0.1, 1, n), means, covs)
    reduced = cap(original, 4)
    fitted = ise_refit(original, reduced)
    w_ref = exact_refit_weights(original, reduced)
    assert np.abs(w_ref - reduced.weights * original.mass / reduced.mass).max() > 0.1
    np.testing.assert_allclose(fitted.weights, w_ref, atol=1e-4 * original.mass)
    e_ref = ise(original, GaussianMixture(w_ref, reduced.means, reduced.covs))
    assert ise(original, fitted) == pytest.approx(e_ref, rel=1e-6)


def test_ise_refit_merge_case_matches_exact_optimum():
    rng = np.random.default_rng(41)
    original = clustered_mixture(rng, n=12, d=2, n_clusters=3, spread=2.0, sep=6.0)
    reduced = merge(original, 4.0, "vo-ma")
    assert 1 < len(reduced) <= 6
    fitted = ise_refit(original, reduced)
    w_ref = exact_refit_weights(original, reduced)
    e_ref = ise(original, GaussianMixture(w_ref, reduced.means, reduced.covs))
    assert ise(original, fitted) == pytest.approx(e_ref, rel=1e-4, abs=1e-7)


def test_reducer_pipeline():
    rng = np.random.default_rng(13)
    mix = clustered_mixture(rng, n=40)
    w = mix.weights.copy()
    w[:5] = 1e-7
    mix = GaussianMixture(w, mix.means, mix.covs)
    red = Reducer(prune_threshold=1e-5, merge_threshold=4.0, max_components=2)
    out = red(mix)
    pruned = prune(mix, 1e-5)
    expected = cap(merge(pruned, 4.0, "vo-ma"), 2)
    np.testing.assert_allclose(out.weights, expected.weights)
    np.testing.assert_allclose(out.means, expected.means)
    np.testing.assert_allclose(out.covs, np.swapaxes(out.covs, -1, -2), rtol=0, atol=0)
    assert len(out) == 2
    with pytest.raises(ValueError):
        Reducer(merge_rule="bogus")
