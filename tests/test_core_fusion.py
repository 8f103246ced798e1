"""GCI / AA fusion, Metropolis weights and omega choice (tracking.fusion) against references."""

from __future__ import annotations

from contextlib import contextmanager
from itertools import permutations

import numpy as np
import pytest
import sensornet.tracking.fusion as fusion
from scipy.stats import multivariate_normal
from sensornet.tracking.fusion import gci_fuse, gci_pair, gci_product
from sensornet.tracking.fusion_rules import aa_fuse, metropolis_weights, optimal_omega
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer


def random_spd(rng, d, scale=1.0):
    A = rng.normal(size=(d, d))
    return (A @ A.T + 0.5 * np.eye(d)) * scale


def random_mixture(rng, n, d, spread=5.0, scale=1.0):
    return GaussianMixture(
        rng.uniform(0.1, 1.5, size=n),
        rng.normal(size=(n, d)) * spread,
        np.stack([random_spd(rng, d, scale) for _ in range(n)]),
    )


def single(w, m, P):
    return GaussianMixture(np.array([w]), np.asarray(m, float)[None], np.asarray(P, float)[None])


def power_product_integral(weights, means, covs, omegas):
    """``int prod_i (w_i N(x; m_i, P_i))^omega_i dx`` in closed form (completing the square).

    Also returns the normalised product's mean and covariance (information-weighted average).
    """
    d = len(means[0])
    Y = sum(o * np.linalg.inv(P) for o, P in zip(omegas, covs, strict=True))
    h = sum(o * np.linalg.solve(P, m) for o, m, P in zip(omegas, means, covs, strict=True))
    k = sum(o * m @ np.linalg.solve(P, m) for o, m, P in zip(omegas, means, covs, strict=True))
    logdets = sum(o * np.linalg.slogdet(P)[1] for o, P in zip(omegas, covs, strict=True))
    s = sum(omegas)
    cov = np.linalg.inv(Y)
    mean = cov @ h
    log_int = (
        -0.5 * s * d * np.log(2 * np.pi)
        - 0.5 * logdets
        + 0.5 * d * np.log(2 * np.pi)
        - 0.5 * np.linalg.slogdet(Y)[1]
        + 0.5 * (h @ mean - k)
    )
    log_w = sum(o * np.log(w) for o, w in zip(omegas, weights, strict=True))
    return float(np.exp(log_int + log_w)), mean, cov


# ---------------------------------------------------------------------------------------------
# two single Gaussians: covariance intersection


@pytest.mark.parametrize("d", [2, 4])
@pytest.mark.parametrize("omega", [0.1, 0.3, 0.5, 0.77, 0.95])
def test_gci_single_gaussians_is_covariance_intersection(omega, d):
    rng = np.random.default_rng(int(omega * 100) + d)
    Pa, Pb = random_spd(rng, d, 3.0), random_spd(rng, d, 5.0)
    ma, mb = rng.normal(size=d) * 2, rng.normal(size=d) * 2
    wa, wb = 0.7, 1.3
    out = gci_pair(single(wa, ma, Pa), single(wb, mb, Pb), omega)
    assert len(out) == 1
    # Covariance intersection in information form.
    Y = (1 - omega) * np.linalg.inv(Pa) + omega * np.linalg.inv(Pb)
    P = np.linalg.inv(Y)
    m = P @ ((1 - omega) * np.linalg.solve(Pa, ma) + omega * np.linalg.solve(Pb, mb))
    np.testing.assert_allclose(out.covs[0], P, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out.means[0], m, rtol=1e-9, atol=1e-12)
    # Weight: w_a^(1-w) w_b^w int N_a^(1-w) N_b^w dx.
    W, m2, P2 = power_product_integral([wa, wb], [ma, mb], [Pa, Pb], [1 - omega, omega])
    assert out.weights[0] == pytest.approx(W, rel=1e-9)
    np.testing.assert_allclose(m2, m, rtol=1e-9)


def test_gci_single_gaussian_weight_by_quadrature():
    # An independent numerical check of the closed-form integral used above (2-D grid).
    Pa = np.array([[2.0, 0.6], [0.6, 1.0]])
    Pb = np.array([[1.0, -0.3], [-0.3, 3.0]])
    ma, mb = np.array([0.5, -0.2]), np.array([-1.0, 1.0])
    omega = 0.35
    g = np.linspace(-12, 12, 401)
    X, Yg = np.meshgrid(g, g, indexing="ij")
    pts = np.stack([X.ravel(), Yg.ravel()], axis=1)
    f = multivariate_normal(ma, Pa).pdf(pts) ** (1 - omega) * multivariate_normal(mb, Pb).pdf(
        pts
    ) ** omega
    integral = f.sum() * (g[1] - g[0]) ** 2
    out = gci_pair(single(1.0, ma, Pa), single(1.0, mb, Pb), omega)
    assert out.weights[0] == pytest.approx(integral, rel=1e-6)


# ---------------------------------------------------------------------------------------------
# mixtures: numerical integration on a grid


def grid_box(centre, half, step):
    g0 = np.arange(centre[0] - half, centre[0] + half + step / 2, step)
    g1 = np.arange(centre[1] - half, centre[1] + half + step / 2, step)
    X, Y = np.meshgrid(g0, g1, indexing="ij")
    return np.stack([X.ravel(), Y.ravel()], axis=1), step * step


def mixture_pdf(mix, pts):
    """2-D mixture intensity at ``pts (p, 2)``, written out (fast on large grids)."""
    out = np.zeros(len(pts))
    for w, m, P in zip(mix.weights, mix.means, mix.covs, strict=True):
        Y = np.linalg.inv(P)
        dx, dy = pts[:, 0] - m[0], pts[:, 1] - m[1]
        q = Y[0, 0] * dx * dx + 2 * Y[0, 1] * dx * dy + Y[1, 1] * dy * dy
        out += w * np.exp(-0.5 * q) / (2 * np.pi * np.sqrt(np.linalg.det(P)))
    return out


def test_mixture_pdf_helper_matches_scipy():
    rng = np.random.default_rng(0)
    mix = random_mixture(rng, 3, 2)
    pts = rng.normal(size=(5, 2)) * 5
    ref = sum(w * multivariate_normal(m, P).pdf(pts)
              for w, m, P in zip(mix.weights, mix.means, mix.covs, strict=True))
    np.testing.assert_allclose(mixture_pdf(mix, pts), ref, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("omega", [0.25, 0.5, 0.8])
def test_gci_separated_mixtures_match_grid_integration(omega):
    # Three clusters 100 apart; each density has one component per cluster, slightly offset.
    centres = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
    Di = GaussianMixture(
        np.array([0.9, 0.6, 0.3]),
        centres + [[0.5, -0.3], [-0.4, 0.2], [0.0, 0.6]],
        np.stack([np.diag([2.0, 1.0]), [[1.5, 0.4], [0.4, 1.0]], np.diag([1.0, 3.0])]),
    )
    Dj = GaussianMixture(
        np.array([0.8, 0.9, 0.2]),
        centres + [[-0.6, 0.4], [0.3, 0.5], [0.5, -0.5]],
        np.stack([np.diag([1.0, 2.0]), [[2.0, -0.5], [-0.5, 1.5]], np.diag([2.5, 1.0])]),
    )
    fused = gci_pair(Di, Dj, omega)
    assert len(fused) == 9
    total_grid = 0.0
    for c in centres:
        pts, dA = grid_box(c, 15.0, 0.05)
        f = mixture_pdf(Di, pts) ** (1 - omega) * mixture_pdf(Dj, pts) ** omega
        mass = f.sum() * dA
        mean = (f[:, None] * pts).sum(axis=0) * dA / mass
        diff = pts - mean
        cov = np.einsum("p,pi,pj->ij", f, diff, diff) * dA / mass
        total_grid += mass
        near = np.linalg.norm(fused.means - c, axis=1) < 20
        sub = fused.select(near)
        # One component per cluster and density: the dropped cross terms are ~exp(-1000), so
        # the approximation is exact up to quadrature error here.
        assert sub.mass == pytest.approx(mass, rel=1e-6)
        m_s, P_s = sub.moments()
        np.testing.assert_allclose(m_s, mean, atol=1e-6)
        np.testing.assert_allclose(P_s, cov, rtol=1e-5, atol=1e-6)
    # Cross-cluster pairs carry negligible mass; the total matches the grid.
    assert fused.mass == pytest.approx(total_grid, rel=1e-6)


def grid_fused_moments(Di, Dj, omega, half=20.0, step=0.05):
    pts, dA = grid_box((0.0, 0.0), half, step)
    f = mixture_pdf(Di, pts) ** (1 - omega) * mixture_pdf(Dj, pts) ** omega
    mass = f.sum() * dA
    mean = (f[:, None] * pts).sum(axis=0) * dA / mass
    diff = pts - mean
    return mass, mean, np.einsum("p,pi,pj->ij", f, diff, diff) * dA / mass


@pytest.mark.parametrize("omega", [0.25, 0.5, 0.8])
def test_gci_two_component_clusters_approximation(omega):
    # Each density has two components 2*sep apart (unit-ish covariances). The power of a mixture
    # is approximated by dropping cross terms: within a few percent at 8 sigma, and the error
    # shrinks as the components separate.
    def case(sep):
        Di = GaussianMixture(np.array([0.9, 0.7]), np.array([[-sep, 0.0], [sep, 0.5]]),
                             np.stack([np.eye(2), np.diag([1.5, 0.8])]))
        Dj = GaussianMixture(np.array([1.2, 0.5]), np.array([[-sep + 0.5, 0.3], [sep - 0.3, 0.0]]),
                             np.stack([np.diag([1.2, 0.9]), np.diag([1.0, 1.3])]))
        fused = gci_pair(Di, Dj, omega)
        mass, mean, cov = grid_fused_moments(Di, Dj, omega)
        m, P = fused.moments()
        return (fused.mass / mass - 1, np.abs(m - mean).max(),
                np.abs(P - cov).max() / np.abs(cov).max())

    err4 = case(4.0)
    assert abs(err4[0]) < 0.05 and err4[1] < 0.05 and err4[2] < 0.05
    err6 = case(6.0)
    assert abs(err6[0]) < 1e-3 and err6[1] < 1e-3 and err6[2] < 1e-3
    assert abs(err6[0]) < abs(err4[0])


# ---------------------------------------------------------------------------------------------
# batched pairs against a per-pair loop


def reference_gci_pair(Di, Dj, omega):
    d = Di.dim
    W, M, C = [], [], []

    def kappa(o, P):
        return np.sqrt(np.linalg.det(2 * np.pi * P / o)) / np.linalg.det(2 * np.pi * P) ** (o / 2)

    for a in range(len(Di)):
        for b in range(len(Dj)):
            Pa, Pb = Di.covs[a], Dj.covs[b]
            ma, mb = Di.means[a], Dj.means[b]
            Ya, Yb = np.linalg.inv(Pa), np.linalg.inv(Pb)
            P = np.linalg.inv((1 - omega) * Ya + omega * Yb)
            m = P @ ((1 - omega) * Ya @ ma + omega * Yb @ mb)
            w = (
                Di.weights[a] ** (1 - omega)
                * Dj.weights[b] ** omega
                * kappa(1 - omega, Pa)
                * kappa(omega, Pb)
                * multivariate_normal(np.zeros(d), Pa / (1 - omega) + Pb / omega).pdf(ma - mb)
            )
            W.append(w)
            M.append(m)
            C.append(P)
    return np.array(W), np.array(M), np.array(C)


@pytest.mark.parametrize(
    "d,na,nb", [(4, 3, 5), (4, 1, 7), (4, 230, 2), (2, 4, 3), (3, 2, 5), (1, 3, 2)]
)
@pytest.mark.parametrize("omega", [0.2, 0.5, 0.9])
def test_gci_pair_equals_per_pair_loop(d, na, nb, omega):
    rng = np.random.default_rng(d * 100 + na * 10 + nb)
    Di = random_mixture(rng, na, d, spread=3.0, scale=2.0)
    Dj = random_mixture(rng, nb, d, spread=3.0, scale=2.0)
    out = gci_pair(Di, Dj, omega)
    W, M, C = reference_gci_pair(Di, Dj, omega)
    assert len(out) == na * nb
    np.testing.assert_allclose(out.weights, W, rtol=1e-8, atol=1e-300)
    np.testing.assert_allclose(out.means, M, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(out.covs, C, rtol=1e-8, atol=1e-10)
    np.testing.assert_array_equal(out.covs, np.swapaxes(out.covs, -1, -2))


def test_gci_pair_edge_omegas_and_empty():
    rng = np.random.default_rng(3)
    Di, Dj = random_mixture(rng, 2, 4), random_mixture(rng, 3, 4)
    assert gci_pair(Di, Dj, 0.0) is Di
    assert gci_pair(Di, Dj, 1.0) is Dj
    empty = GaussianMixture.empty(4)
    for a, b in [(Di, empty), (empty, Dj), (empty, empty)]:
        out = gci_pair(a, b, 0.5)
        assert len(out) == 0 and out.dim == 4
    with pytest.raises(ValueError):
        gci_pair(Di, Dj, 1.5)
    # A zero-weight component gives zero-weight pairs, not NaN.
    Dz = GaussianMixture(np.array([0.0, 1.0]), Di.means, Di.covs)
    out = gci_pair(Dz, Dj, 0.4)
    assert np.all(np.isfinite(out.weights))
    np.testing.assert_array_equal(out.weights[:3], 0.0)


# ---------------------------------------------------------------------------------------------
# n-ary GCI


@pytest.mark.parametrize("omegas", [(1 / 3, 1 / 3, 1 / 3), (0.2, 0.3, 0.5)])
@pytest.mark.parametrize("d", [2, 4])
def test_gci_fuse_three_single_gaussians(omegas, d):
    rng = np.random.default_rng(17 + d)
    ws = [0.8, 1.1, 0.5]
    ms = [rng.normal(size=d) * 2 for _ in range(3)]
    Ps = [random_spd(rng, d, 2.0) for _ in range(3)]
    dens = [single(w, m, P) for w, m, P in zip(ws, ms, Ps, strict=True)]
    W, m, P = power_product_integral(ws, ms, Ps, list(omegas))
    out = gci_fuse(dens, omegas)
    assert len(out) == 1
    assert out.weights[0] == pytest.approx(W, rel=1e-9)
    np.testing.assert_allclose(out.means[0], m, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out.covs[0], P, rtol=1e-9, atol=1e-12)
    # Order of the inputs does not matter.
    for perm in permutations(range(3)):
        o = gci_fuse([dens[i] for i in perm], [omegas[i] for i in perm])
        assert o.weights[0] == pytest.approx(W, rel=1e-9)
        np.testing.assert_allclose(o.means[0], m, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(o.covs[0], P, rtol=1e-9, atol=1e-12)
    # normalise -> a probability density (covariance intersection for single targets).
    n = gci_fuse(dens, omegas, normalise=True)
    assert n.mass == pytest.approx(1.0)
    np.testing.assert_allclose(n.means[0], m, rtol=1e-9, atol=1e-12)


def test_gci_fuse_skips_zero_weights_and_reduces():
    rng = np.random.default_rng(5)
    dens = [random_mixture(rng, 3, 4) for _ in range(3)]
    out = gci_fuse(dens, [0.0, 0.4, 0.6])
    ref = gci_pair(dens[1], dens[2], 0.6)
    np.testing.assert_allclose(out.weights, ref.weights)
    calls = []

    def reduce(m):
        calls.append(len(m))
        return Reducer(prune_threshold=0.0, merge_threshold=4.0)(m)

    gci_fuse(dens, [0.3, 0.3, 0.4], reduce=reduce)
    assert calls == [18]  # 3 x 2 x 3 (density 1's two close rows pre-merged, gci_fuse), once
    calls.clear()
    with sequential_fusion():
        gci_fuse(dens, [0.3, 0.3, 0.4], reduce=reduce)
    assert calls[0] == 9 and len(calls) == 2  # pair by pair, reduced after each step
    assert gci_fuse([dens[0]], [1.0]) is dens[0]
    with pytest.raises(ValueError):
        gci_fuse(dens, [0.5, 0.5, 0.5])
    with pytest.raises(ValueError):
        gci_fuse(dens, [0.5, 0.5])
    with pytest.raises(ValueError):
        gci_fuse([], [])


@contextmanager
def sequential_fusion():
    """Make :func:`gci_fuse` take its pair-by-pair path whatever the sizes."""
    saved = fusion.NARY_MAX_COMBINATIONS
    fusion.NARY_MAX_COMBINATIONS = 0
    try:
        yield
    finally:
        fusion.NARY_MAX_COMBINATIONS = saved


@pytest.mark.parametrize("cardinality", ["emd", "separate"])
@pytest.mark.parametrize("d", [2, 4, 6])
def test_gci_product_equals_sequential_pairing(d, cardinality):
    """One batched n-ary product == sequential pair steps before any reduction (§3)."""
    rng = np.random.default_rng(100 + d)
    for n in (2, 3, 5):
        dens = [random_mixture(rng, int(rng.integers(1, 4)), d, spread=2.0, scale=2.0)
                for _ in range(n)]
        omegas = rng.uniform(0.1, 1.0, n)
        omegas /= omegas.sum()
        one = gci_product(dens, omegas, cardinality)
        with sequential_fusion():
            seq = gci_fuse(dens, omegas, cardinality=cardinality)
        assert len(one) == len(seq) == np.prod([len(D) for D in dens])
        np.testing.assert_allclose(one.weights, seq.weights, rtol=1e-8, atol=1e-14)
        np.testing.assert_allclose(one.means, seq.means, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(one.covs, seq.covs, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(gci_fuse(dens, omegas, cardinality=cardinality).weights,
                                   one.weights)


def test_gci_product_components_match_closed_form_per_combination():
    """Each fused component is ``int prod_i (w_i N_i)^omega_i`` of its combination, computed
    one combination at a time by completing the square (far from the origin: no cancellation)."""
    rng = np.random.default_rng(7)
    dens = [random_mixture(rng, k, 4, spread=30.0, scale=20.0) for k in (2, 3, 2)]
    for D in dens:
        D.means[:] += 5000.0  # positions far from the origin, as in the scenarios
    omegas = [0.5, 0.3, 0.2]
    out = gci_product(dens, omegas)
    c = 0
    for a in range(2):
        for b in range(3):
            for e in range(2):
                picks = [(dens[0], a), (dens[1], b), (dens[2], e)]
                W, m, P = power_product_integral([D.weights[i] for D, i in picks],
                                                 [D.means[i] for D, i in picks],
                                                 [D.covs[i] for D, i in picks], omegas)
                assert out.weights[c] == pytest.approx(W, rel=1e-7)
                np.testing.assert_allclose(out.means[c], m, rtol=1e-10)
                np.testing.assert_allclose(out.covs[c], P, rtol=1e-8, atol=1e-9)
                c += 1


def test_gci_product_empty_and_disjoint_inputs():
    rng = np.random.default_rng(3)
    a, b = random_mixture(rng, 2, 4), random_mixture(rng, 3, 4)
    assert len(gci_product([a, GaussianMixture.empty(4), b], [0.3, 0.3, 0.4])) == 0
    far = GaussianMixture(b.weights, b.means + 1e6, b.covs)
    assert len(gci_product([a, far], [0.5, 0.5], "separate")) == 0  # nothing in common
    with pytest.raises(ValueError):
        gci_product([a, b], [0.5, 0.5], "bogus")


# ---------------------------------------------------------------------------------------------
# AA fusion


def test_aa_fuse_mass_and_components():
    rng = np.random.default_rng(8)
    dens = [random_mixture(rng, 2, 4), GaussianMixture.empty(4), random_mixture(rng, 3, 4)]
    om = [0.5, 0.2, 0.3]
    out = aa_fuse(dens, om)
    assert out.mass == pytest.approx(sum(o * D.mass for o, D in zip(om, dens, strict=True)))
    assert len(out) == 5
    np.testing.assert_allclose(out.weights[:2], 0.5 * dens[0].weights)
    np.testing.assert_allclose(out.weights[2:], 0.3 * dens[2].weights)
    np.testing.assert_array_equal(out.means[2:], dens[2].means)
    # The fused intensity is the weighted sum of the intensities.
    x = rng.normal(size=(7, 4)) * 3
    ref = sum(o * D.pdf(x) for o, D in zip(om, dens, strict=True))
    np.testing.assert_allclose(out.pdf(x), ref, rtol=1e-12)
    red = aa_fuse(dens, om, reduce=Reducer(merge_threshold=1e6))
    assert len(red) == 1 and red.mass == pytest.approx(out.mass)
    empty = aa_fuse([GaussianMixture.empty(4)] * 2, [0.5, 0.5])
    assert len(empty) == 0


# ---------------------------------------------------------------------------------------------
# Metropolis weights


def adjacency(n, edges):
    A = np.zeros((n, n), dtype=bool)
    for i, j in edges:
        A[i, j] = A[j, i] = True
    return A


def test_metropolis_ring():
    n = 5
    W = metropolis_weights(adjacency(n, [(i, (i + 1) % n) for i in range(n)]))
    ref = np.zeros((n, n))
    for i in range(n):
        ref[i, i] = ref[i, (i + 1) % n] = ref[i, (i - 1) % n] = 1 / 3
    np.testing.assert_allclose(W, ref, rtol=1e-15)


def test_metropolis_star_and_path():
    W = metropolis_weights(adjacency(5, [(0, k) for k in range(1, 5)]))
    ref = np.zeros((5, 5))
    ref[0, 0] = 1 - 4 / 5
    for k in range(1, 5):
        ref[0, k] = ref[k, 0] = 1 / 5
        ref[k, k] = 4 / 5
    np.testing.assert_allclose(W, ref, rtol=1e-15, atol=1e-16)
    W = metropolis_weights(adjacency(3, [(0, 1), (1, 2)]))
    ref = np.array([[2 / 3, 1 / 3, 0], [1 / 3, 1 / 3, 1 / 3], [0, 1 / 3, 2 / 3]])
    np.testing.assert_allclose(W, ref, rtol=1e-15, atol=1e-16)


@pytest.mark.parametrize("seed", range(5))
def test_metropolis_random_graph_doubly_stochastic(seed):
    rng = np.random.default_rng(seed)
    n = 9
    A = np.triu(rng.random((n, n)) < 0.35, 1)
    A = A | A.T
    A[2, 2] = True  # a self-loop is ignored
    W = metropolis_weights(A)
    np.testing.assert_allclose(W.sum(axis=1), 1.0, rtol=1e-14)
    np.testing.assert_allclose(W, W.T, rtol=0, atol=0)
    assert np.all(W >= 0)
    deg = (A & ~np.eye(n, dtype=bool)).sum(axis=1)
    for i in range(n):
        for j in range(n):
            if i != j:
                expected = 1 / (1 + max(deg[i], deg[j])) if A[i, j] else 0.0
                assert W[i, j] == pytest.approx(expected)


def test_metropolis_rejects_asymmetric():
    A = np.zeros((3, 3), dtype=bool)
    A[0, 1] = True
    with pytest.raises(ValueError):
        metropolis_weights(A)


# ---------------------------------------------------------------------------------------------
# omega choice


def test_optimal_omega_det():
    a = single(1.0, [0.0, 0.0], np.diag([1.0, 100.0]))
    b = single(1.0, [1.0, -1.0], np.diag([100.0, 1.0]))
    assert optimal_omega(a, b, "det") == pytest.approx(0.5, abs=0.01)
    good = single(1.0, [0.0, 0.0], np.eye(2))
    bad = single(2.0, [1.0, 1.0], 100 * np.eye(2))
    # D_i^(1-w) D_j^w: the better (smaller covariance) density gets all the weight.
    assert optimal_omega(good, bad, "det") < 0.01
    assert optimal_omega(bad, good, "det") > 0.99


def test_optimal_omega_det_is_argmin_over_a_grid():
    rng = np.random.default_rng(12)
    a = single(1.0, rng.normal(size=2), random_spd(rng, 2, 3.0))
    b = single(1.0, rng.normal(size=2), random_spd(rng, 2, 3.0))
    grid = np.linspace(0.001, 0.999, 999)

    def logdet(o):
        Y = (1 - o) * np.linalg.inv(a.covs[0]) + o * np.linalg.inv(b.covs[0])
        return -np.linalg.slogdet(Y)[1]

    best = grid[np.argmin([logdet(o) for o in grid])]
    assert optimal_omega(a, b, "det") == pytest.approx(best, abs=0.01)


def test_optimal_omega_chernoff_symmetric_case():
    P = np.array([[2.0, 0.3], [0.3, 1.0]])
    a = single(3.0, [0.0, 0.0], P)
    b = single(0.5, [2.0, 1.0], P)
    # Equal covariances: the Chernoff point is 1/2 (inputs are normalised first).
    assert optimal_omega(a, b, "chernoff") == pytest.approx(0.5, abs=0.01)
    with pytest.raises(ValueError):
        optimal_omega(a, b, "bogus")


def test_optimal_omega_empty_inputs():
    a = single(1.0, [0.0, 0.0], np.eye(2))
    assert optimal_omega(GaussianMixture.empty(2), a) == 0.5
    assert optimal_omega(a, GaussianMixture.empty(2)) == 0.5


def test_small_gci_path_equals_the_batched_path():
    """Few pairs go through plain LAPACK calls; they must agree with the batched closed form."""
    rng = np.random.default_rng(42)
    for d in (2, 4, 6):
        for na, nb in ((1, 1), (2, 3), (4, 5)):
            A = rng.normal(size=(na, d, d))
            B = rng.normal(size=(nb, d, d))
            Di = GaussianMixture(rng.uniform(0.1, 2.0, na), rng.normal(size=(na, d)) * 3,
                                 A @ np.swapaxes(A, 1, 2) + np.eye(d))
            Dj = GaussianMixture(rng.uniform(0.1, 2.0, nb), rng.normal(size=(nb, d)) * 3,
                                 B @ np.swapaxes(B, 1, 2) + np.eye(d))
            small = fusion._gci_pair_small(Di, Dj, 0.3)
            saved = fusion._SMALL_PAIRS
            fusion._SMALL_PAIRS = 0
            try:
                batched = fusion.gci_pair(Di, Dj, 0.3)
            finally:
                fusion._SMALL_PAIRS = saved
            np.testing.assert_allclose(small.weights, batched.weights, rtol=1e-10)
            np.testing.assert_allclose(small.means, batched.means, rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(small.covs, batched.covs, rtol=1e-10, atol=1e-10)
