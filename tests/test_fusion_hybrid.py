"""The hybrid rule (AA target weights, GCI locations), level-2 pruning in consensus, and why the
exact-Poisson (EMD) GCI under-counts: hand-made mixtures against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sensornet.tracking.fusion import gci_fuse, gci_product
from sensornet.tracking.fusion_rules import aa_fuse, hybrid_fuse, metropolis_weights
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer, keep_above, merge, moment_match, sweep_labels

P0 = np.diag([100.0, 25.0, 100.0, 25.0])
A = np.array([0.0, 1.0, 0.0, -1.0])
B = np.array([500.0, 0.0, -400.0, 2.0])


def mix(*comps) -> GaussianMixture:
    """``(weight, mean, cov)`` triples -> a mixture."""
    w, m, P = zip(*comps, strict=True)
    return GaussianMixture(np.array(w, float), np.array(m, float), np.array(P, float))


def test_sweep_labels_are_the_groups_merge_moment_matches():
    rng = np.random.default_rng(3)
    n = 30
    means = rng.normal(0, 30, (n, 4))
    covs = np.tile(P0, (n, 1, 1)) * rng.uniform(0.5, 2.0, (n, 1, 1))
    m = GaussianMixture(rng.uniform(0.05, 1.0, n), means, covs)
    labels = sweep_labels(m, 4.0)
    merged = merge(m, 4.0)
    assert labels.max() + 1 == len(merged) < n  # some groups merged
    expected = []
    for g in range(labels.max() + 1):
        idx = labels == g
        expected.append(moment_match(m.weights[idx], m.means[idx], m.covs[idx]))
    # merge orders its output by the groups' heaviest members, as the labels do
    np.testing.assert_allclose([e[0] for e in expected], merged.weights, rtol=1e-12)
    np.testing.assert_allclose(np.array([e[1] for e in expected]), merged.means, atol=1e-9)
    np.testing.assert_allclose(np.array([e[2] for e in expected]), merged.covs, atol=1e-9)


def test_sweep_labels_with_given_inverses_are_the_same_labels():
    """The caller's inverses (hybrid_fuse passes the union's) give the labels the sweep finds
    computing them itself: every-pair sizes and the candidate path above 48, both rules."""
    from sensornet.tracking.gaussian import inv_spd

    rng = np.random.default_rng(11)
    for n in (2, 5, 12, 30, 48, 49, 80):
        for rule, threshold in (("vo-ma", 4.0), ("weighted", 2.0)):
            means = rng.normal(0, 30, (n, 4))
            covs = np.tile(P0, (n, 1, 1)) * rng.uniform(0.5, 2.0, (n, 1, 1))
            m = GaussianMixture(rng.uniform(0.05, 1.0, n), means, covs)
            labels = sweep_labels(m, threshold, rule)
            assert labels.max() + 1 < n or n < 12  # groups formed
            np.testing.assert_array_equal(
                sweep_labels(m, threshold, rule, inv=inv_spd(m.covs)), labels)


def test_hybrid_weight_is_the_arithmetic_mean_and_location_the_covariance_intersection():
    # three peers see target A (slightly apart, different covariances); the third missed B
    Pa = [P0, 2.0 * P0, np.diag([50.0, 10.0, 300.0, 40.0])]
    ma = [A, A + np.array([15.0, 0.5, -10.0, 0.2]), A + np.array([-8.0, 0.0, 12.0, -0.3])]
    wa = [0.95, 0.9, 0.8]
    D = [mix((wa[0], ma[0], Pa[0]), (0.9, B, P0)),
         mix((wa[1], ma[1], Pa[1]), (0.85, B + 5.0, P0)),
         mix((wa[2], ma[2], Pa[2]))]
    om = [0.5, 0.3, 0.2]
    fused = hybrid_fuse(D, om)
    assert len(fused) == 2
    ia = int(np.argmin(np.linalg.norm(fused.means - A, axis=1)))
    ib = 1 - ia
    # weights: the AA of each target's masses (a miss counts as 0, not as a factor 0)
    assert fused.weights[ia] == pytest.approx(sum(o * w for o, w in zip(om, wa, strict=True)))
    assert fused.weights[ib] == pytest.approx(0.5 * 0.9 + 0.3 * 0.85)
    assert fused.mass == pytest.approx(aa_fuse(D, om).mass)
    # location of A: covariance intersection of the three Gaussians = normalised GCI of them
    ci = gci_fuse([mix((1.0, m, P)) for m, P in zip(ma, Pa, strict=True)], om, normalise=True)
    np.testing.assert_allclose(fused.means[ia], ci.means[0], atol=1e-9)
    np.testing.assert_allclose(fused.covs[ia], ci.covs[0], rtol=1e-9)
    # location of B: only the two peers that have it, their omegas renormalised (5/8, 3/8)
    ci_b = gci_fuse([mix((1.0, B, P0)), mix((1.0, B + 5.0, P0))], [0.625, 0.375], normalise=True)
    np.testing.assert_allclose(fused.means[ib], ci_b.means[0], atol=1e-9)
    # GCI (a product) erases B: the third peer has no mass there
    gci = gci_fuse(D, om, cardinality="separate")
    assert gci.weights[np.linalg.norm(gci.means - B, axis=1) < 100].sum() < 1e-6


def test_hybrid_moment_matches_one_peers_split_components_before_intersecting():
    split = mix((0.5, A - [6.0, 0, 0, 0], P0), (0.45, A + [6.0, 0, 0, 0], P0))
    whole = mix((0.95, A, P0))
    fused = hybrid_fuse([split, whole], [0.5, 0.5])
    assert len(fused) == 1
    w, m, P = moment_match(split.weights, split.means, split.covs)
    ci = gci_fuse([mix((1.0, m, P)), mix((1.0, A, P0))], [0.5, 0.5], normalise=True)
    assert fused.weights[0] == pytest.approx(0.5 * w + 0.5 * 0.95)
    np.testing.assert_allclose(fused.means[0], ci.means[0], atol=1e-9)
    np.testing.assert_allclose(fused.covs[0], ci.covs[0], rtol=1e-9)


def test_hybrid_of_empty_and_zero_weight_inputs():
    assert len(hybrid_fuse([GaussianMixture.empty(4)] * 2, [0.5, 0.5])) == 0
    one = mix((0.9, A, P0))
    out = hybrid_fuse([one, GaussianMixture.empty(4)], [0.5, 0.5])
    assert out.weights[0] == pytest.approx(0.45)  # the empty input's share is a miss
    np.testing.assert_allclose(out.means[0], A)
    out = hybrid_fuse([one, mix((0.9, B, P0))], [1.0, 0.0])  # omega 0: not an input
    assert len(out) == 1 and out.weights[0] == pytest.approx(0.9)


def _consensus(local: list[GaussianMixture], adjacency: np.ndarray, rounds: int, fuse,
               threshold: float = 0.5) -> list[GaussianMixture]:
    """``rounds`` consensus rounds as the peers run them: round 0 publishes the level-2 pruned
    local posteriors (the peer fuses its own pruned one too), later rounds the fused ones."""
    W = metropolis_weights(adjacency)
    current = [keep_above(D, threshold) for D in local]
    for _ in range(rounds):
        current = [fuse([current[j] for j in np.flatnonzero(W[i])], W[i][W[i] > 0])
                   for i in range(len(local))]
    return current


def _weight_near(D: GaussianMixture, x: np.ndarray) -> float:
    return float(D.weights[np.linalg.norm(D.means[:, [0, 2]] - x[[0, 2]], axis=1) < 50].sum())


@pytest.mark.parametrize("rounds", [1, 2, 3])
def test_a_target_pruned_at_one_peer_survives_every_later_round(rounds):
    # a ring of 6 peers; peer 2 missed target A this scan (weight 0.3 < 0.5: not published)
    n = 6
    adj = np.zeros((n, n), bool)
    for i in range(n):
        adj[i, (i + 1) % n] = adj[(i + 1) % n, i] = True
    local = [mix((0.3 if i == 2 else 0.95, A + i, P0), (0.9, B, P0)) for i in range(n)]
    hybrid = _consensus(local, adj, rounds, lambda D, w: hybrid_fuse(D, w, Reducer()))
    for i, D in enumerate(hybrid):
        assert _weight_near(D, A) > 0.5, (i, _weight_near(D, A))  # extracted at every peer
        assert _weight_near(D, B) == pytest.approx(0.9)
    # GCI: the pruned input is a zero in the product; the target is gone at peer 2 and,
    # round by round, at every peer within `rounds` hops of it
    gci = _consensus(local, adj, rounds,
                     lambda D, w: gci_fuse(D, w, Reducer(), cardinality="separate"))
    gone = [i for i, D in enumerate(gci) if _weight_near(D, A) < 1e-6]
    hops = [i for i in range(n) if min(abs(i - 2), n - abs(i - 2)) <= rounds]
    assert gone == hops


def test_emd_mass_is_the_closed_form_overlap_of_the_estimates():
    """Why ``cardinality = "emd"`` under-counts: for one target estimated by ``n`` consistent
    peers (means scattered by their covariance ``P``), the exponential mixture's mass is
    ``exp(-1/2 sum_i omega_i |m_i - m|^2_(P^-1))``, whose mean over the scatter is
    ``(1 + 1/n)^(-d (n - 1) / 2)`` for equal weights: 0.23 for 5 peers in 4-D, per fusion."""
    rng = np.random.default_rng(7)
    n, d = 5, 4
    om = np.full(n, 1.0 / n)
    L = np.linalg.cholesky(P0)
    masses, closed = [], []
    for _ in range(400):
        means = A + rng.standard_normal((n, d)) @ L.T
        D = [mix((1.0, m, P0)) for m in means]
        masses.append(gci_product(D, om, "emd").mass)
        e = means - om @ means
        closed.append(math.exp(-0.5 * np.einsum("i,ij,jk,ik->", om, e, np.linalg.inv(P0), e)))
        # the separate rule keeps the geometric mean of the masses (1 here)
        assert gci_product(D, om, "separate").mass == pytest.approx(1.0)
    np.testing.assert_allclose(masses, closed, rtol=1e-9)
    expected = (1 + 1 / n) ** (-d * (n - 1) / 2)
    assert np.mean(masses) == pytest.approx(expected, abs=4 * np.std(masses) / math.sqrt(400))
    assert expected < 0.25
