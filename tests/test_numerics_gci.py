"""GCI fusion with ill-conditioned covariances against an exact-arithmetic reference.

``gci_product`` (n-ary, one batched step) and ``gci_pair`` (pairwise, also chained for n > 2)
are compared with the same products computed in exact rational arithmetic (``fractions``) on
the very same double inputs, at covariance condition numbers 1e6, 1e9 and 1e12 and for 2 to 4
densities. No double-precision algorithm can beat the inputs' own conditioning, about
``eps * cond`` relative error, so the tolerances are a small multiple of that (measured worst
cases over 25 seeds: 0.8 ``eps * cond``). Before the centred form the n-ary weights were off by
up to 7e-3 at cond 1e6 and overflowed at 1e9.
"""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import numpy as np
import pytest
from scipy.linalg import expm
from sensornet.tracking import gci_product as product_module
from sensornet.tracking.fusion import gci_pair, gci_product
from sensornet.tracking.mixture import GaussianMixture

EPS = float(np.finfo(float).eps)
CONDS = (1e6, 1e9, 1e12)
TOL = 4.0
"""Allowed relative error in units of ``eps * cond``."""
MIN_LOG_W = -30.0
"""Combinations lighter than ``exp(MIN_LOG_W)`` (non-matching targets) are not compared."""

# ---------------------------------------------------------------------------------------------
# inputs: ill-conditioned mixtures whose matching combinations overlap


def _rotation(rng: np.random.Generator, d: int) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(d, d)))
    return q * np.sign(np.diag(r))


def _small_rotation(rng: np.random.Generator, d: int, angle: float) -> np.ndarray:
    S = rng.normal(size=(d, d))
    S = (S - S.T) / 2
    return expm(S * angle / np.linalg.norm(S, 2))


def _targets(rng: np.random.Generator, n: int, d: int, cond: float, sep: float = 1000.0,
             n_targets: int = 2, scale: float = 100.0) -> list[GaussianMixture]:
    """``n`` densities, one component per target, targets about ``sep`` apart (far from the
    origin, as in the scenarios). Each target's covariances share an eigenbasis up to a
    rotation of ``0.3 / sqrt(cond)``, eigenvalues ``scale * [1 .. 1/cond]``, and its means
    differ by about half a standard deviation along each axis, so matching combinations
    overlap (weights of order one) while the others vanish."""
    lam = scale * np.geomspace(1.0, 1.0 / cond, d)
    bases = [_rotation(rng, d) for _ in range(n_targets)]
    centres = [rng.normal(size=d) * sep / 2 for _ in range(n_targets)]
    out = []
    for _ in range(n):
        means, covs = [], []
        for R0, c in zip(bases, centres, strict=True):
            R = _small_rotation(rng, d, 0.3 / np.sqrt(cond)) @ R0
            P = (R * lam) @ R.T
            covs.append(0.5 * (P + P.T))
            means.append(c + R0 @ (rng.normal(size=d) * np.sqrt(lam) * 0.5))
        out.append(GaussianMixture(rng.uniform(0.2, 1.0, n_targets), np.array(means),
                                   np.array(covs)))
    return out


# ---------------------------------------------------------------------------------------------
# exact reference


def _fr_matrix(A: np.ndarray) -> list[list[Fraction]]:
    return [[Fraction(float(x)) for x in row] for row in A]


def _inv_det(A: list[list[Fraction]]) -> tuple[list[list[Fraction]], Fraction]:
    """Exact inverse and determinant (Gauss-Jordan)."""
    n = len(A)
    M = [row[:] + [Fraction(int(i == j)) for j in range(n)] for i, row in enumerate(A)]
    det = Fraction(1)
    for c in range(n):
        p = next(r for r in range(c, n) if M[r][c] != 0)
        if p != c:
            M[c], M[p], det = M[p], M[c], -det
        det *= M[c][c]
        M[c] = [x / M[c][c] for x in M[c]]
        for r in range(n):
            if r != c and M[r][c] != 0:
                f = M[r][c]
                M[r] = [x - f * y for x, y in zip(M[r], M[c], strict=True)]
    return [row[n:] for row in M], det


def _mv(A, x):
    return [sum(a * b for a, b in zip(row, x, strict=True)) for row in A]


def _log(q: Fraction) -> float:
    return math.log(q.numerator) - math.log(q.denominator)


def exact_product(densities: list[GaussianMixture], omegas) -> tuple[np.ndarray, ...]:
    """``prod_i (w_ic N_ic)^omega_i`` per combination (first density slowest), exact until the
    final logarithms: ``log w (C,)``, means ``(C, d)``, covariances ``(C, d, d)``. ``Y = sum
    omega_i P_i^-1``, ``m = Y^-1 sum omega_i P_i^-1 m_i``, ``log w = sum omega_i log w_i -
    1/2 [sum omega_i log det P_i + log det Y + sum omega_i (m_i - m)' P_i^-1 (m_i - m)]``."""
    d = densities[0].dim
    om = [Fraction(float(o)) for o in omegas]
    comps = [[(math.log(w), [Fraction(float(x)) for x in m], *_inv_det(_fr_matrix(P)))
              for w, m, P in zip(D.weights, D.means, D.covs, strict=True)] for D in densities]
    log_w, means, covs = [], [], []
    for combo in itertools.product(*comps):
        Y = [[sum(o * c[2][i][j] for o, c in zip(om, combo, strict=True)) for j in range(d)]
             for i in range(d)]
        h = [sum(o * v for o, c in zip(om, combo, strict=True) for v in [_mv(c[2], c[1])[i]])
             for i in range(d)]
        P, det_y = _inv_det(Y)
        m = _mv(P, h)
        quad = Fraction(0)
        for o, (_, mi, Yi, _) in zip(om, combo, strict=True):
            e = [a - b for a, b in zip(mi, m, strict=True)]
            quad += o * sum(a * b for a, b in zip(e, _mv(Yi, e), strict=True))
        log_det = sum(float(o) * _log(c[3]) for o, c in zip(om, combo, strict=True)) + _log(det_y)
        log_w.append(sum(float(o) * c[0] for o, c in zip(om, combo, strict=True))
                     - 0.5 * (log_det + float(quad)))
        means.append([float(x) for x in m])
        covs.append([[float(x) for x in row] for row in P])
    return np.array(log_w), np.array(means), np.array(covs)


# ---------------------------------------------------------------------------------------------
# comparisons


def rel_errors(fused: GaussianMixture, log_w: np.ndarray, means: np.ndarray,
               covs: np.ndarray) -> tuple[float, float, float]:
    """Largest relative errors over the combinations that matter: weight ``|w/w_ref - 1|``,
    mean ``|m - m_ref| / sqrt(tr P_ref)``, covariance ``max|P - P_ref| / max|P_ref|``."""
    keep = log_w > MIN_LOG_W
    w = np.abs(fused.weights[keep] / np.exp(log_w[keep]) - 1)
    m = (np.linalg.norm(fused.means - means, axis=1)
         / np.sqrt(np.trace(covs, axis1=1, axis2=2)))[keep]
    P = (np.abs(fused.covs - covs).max(axis=(1, 2)) / np.abs(covs).max(axis=(1, 2)))[keep]
    return float(w.max()), float(m.max()), float(P.max())


def chained_pairs(densities: list[GaussianMixture], omegas) -> GaussianMixture:
    """Sequential pairwise GCI (``gci_fuse``'s path beyond the n-ary size limit)."""
    acc, s = densities[0], omegas[0]
    for D, w in zip(densities[1:], omegas[1:], strict=True):
        acc = gci_pair(acc, D, w / (s + w))
        s += w
    return acc


@pytest.fixture(params=["gathered", "grid"])
def product_path(request, monkeypatch):
    """Run a test through each of ``gci_product``'s two evaluation paths (few combinations are
    gathered into flat arrays, many summed on the combination grid)."""
    limit = 10**9 if request.param == "gathered" else 0
    monkeypatch.setattr(product_module, "_SMALL_COMBINATIONS", limit)
    return request.param


def _case(cond: float, n: int, d: int, seed: int):
    rng = np.random.default_rng([int(np.log10(cond)), n, d, seed])
    dens = _targets(rng, n, d, cond)
    omegas = rng.dirichlet(np.ones(n))
    return dens, omegas


@pytest.mark.parametrize("d", [2, 4])
@pytest.mark.parametrize("n", [2, 3, 4])
@pytest.mark.parametrize("cond", CONDS)
def test_gci_product_matches_exact_reference(cond, n, d, product_path):
    """n-ary product: weights, means and covariances within a few ``eps * cond``."""
    tol = TOL * EPS * cond
    for seed in range(3):
        dens, omegas = _case(cond, n, d, seed)
        ref = exact_product(dens, omegas)
        assert np.sum(ref[0] > MIN_LOG_W) == 2  # the matching combinations, weights O(1)
        assert np.all(ref[0][ref[0] > MIN_LOG_W] > -5)
        errs = rel_errors(gci_product(dens, omegas), *ref)
        assert max(errs) < tol, f"seed {seed}: weight/mean/cov errors {errs}, tol {tol:.1e}"


@pytest.mark.parametrize("d", [2, 4])
@pytest.mark.parametrize("cond", CONDS)
def test_gci_pair_weights_match_exact_reference(cond, d):
    """One pairwise step: weights and covariances within a few ``eps * cond`` as well. (Its
    means, formed as ``P_ab ((1-omega) Y_a m_a + omega Y_b m_b)``, lose more far from the
    origin: up to about 350 ``eps * cond`` for targets 500 m out.)"""
    tol = TOL * EPS * cond
    for seed in range(3):
        dens, omegas = _case(cond, 2, d, seed)
        ref = exact_product(dens, omegas)
        w_err, _, P_err = rel_errors(gci_pair(dens[0], dens[1], omegas[1]), *ref)
        assert max(w_err, P_err) < tol, f"seed {seed}: {w_err:.1e} / {P_err:.1e}, tol {tol:.1e}"


@pytest.mark.parametrize("n", [2, 3, 4])
@pytest.mark.parametrize("cond", CONDS)
def test_gci_product_and_chained_pairs_agree_near_the_origin(cond, n, product_path):
    """The n-ary product and the chain of pairwise steps give the same mixture (and both the
    reference) when the means are near the origin, where the pairwise means keep full accuracy
    too; the inputs are :func:`_targets` moved so that one target sits at the origin."""
    d, tol = 4, TOL * EPS * cond
    for seed in range(2):
        dens, omegas = _case(cond, n, d, seed)
        shift = dens[0].means[0].copy()
        dens = [GaussianMixture(D.weights[:1], D.means[:1] - shift, D.covs[:1]) for D in dens]
        ref = exact_product(dens, omegas)
        one, chain = gci_product(dens, omegas), chained_pairs(dens, omegas)
        assert max(rel_errors(one, *ref)) < tol
        assert max(rel_errors(chain, *ref)) < tol
        np.testing.assert_allclose(one.weights, chain.weights, rtol=2 * tol)


@pytest.mark.parametrize("d", [1, 2, 4, 6])
def test_gci_product_paths_agree(d, monkeypatch):
    """The gathered and the grid evaluation of :func:`gci_product` give the same mixture."""
    rng = np.random.default_rng(d)
    for sizes in [(1, 2), (2, 3, 1), (3, 2, 2, 2), (2, 2, 2, 2, 2)]:
        dens = []
        for k in sizes:
            L = rng.normal(size=(k, d, d))
            dens.append(GaussianMixture(rng.uniform(0.1, 1.0, k), rng.normal(size=(k, d)) * 2,
                                        L @ np.swapaxes(L, 1, 2) + np.eye(d)))
        omegas = rng.dirichlet(np.ones(len(sizes)))
        monkeypatch.setattr(product_module, "_SMALL_COMBINATIONS", 10**9)
        gathered = gci_product(dens, omegas)
        monkeypatch.setattr(product_module, "_SMALL_COMBINATIONS", 0)
        grid = gci_product(dens, omegas)
        np.testing.assert_allclose(gathered.weights, grid.weights, rtol=1e-12)
        np.testing.assert_allclose(gathered.means, grid.means, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(gathered.covs, grid.covs, rtol=1e-12, atol=1e-12)
        assert np.array_equal(grid.covs, np.swapaxes(grid.covs, 1, 2))
        assert np.array_equal(gathered.covs, np.swapaxes(gathered.covs, 1, 2))


def _spread(rng, sizes, d, n_targets, sep, sigma):
    """Densities whose components sit near ``n_targets`` points ``sep`` apart (a PHD per peer)."""
    centres = rng.normal(size=(n_targets, d)) * sep
    dens = []
    for k in sizes:
        L = rng.normal(size=(k, d, d))
        who = rng.permutation(k) % n_targets  # every peer sees every target (k >= n_targets)
        dens.append(GaussianMixture(rng.uniform(0.05, 1.0, k),
                                    centres[who] + rng.normal(size=(k, d)) * sigma,
                                    sigma**2 * (L @ np.swapaxes(L, 1, 2) + np.eye(d))))
    return dens


@pytest.mark.parametrize("d", [2, 4])
def test_gated_product_keeps_every_combination_that_matters(d, monkeypatch):
    """``gate=True`` leaves out only combinations whose weight bound is negligible: every
    combination it drops weighs less than 1e-20 times its components' weight product, all of
    them together less than 1e-14 of the kept mass, the kept ones equal the
    full product's (gathered evaluation, to the last bits), and far-apart targets are not
    combined at all."""
    monkeypatch.setattr(product_module, "_SMALL_COMBINATIONS", 0)
    rng = np.random.default_rng(7 + d)
    for sizes in [(3, 4, 3, 4, 3), (5, 5, 5, 5), (3, 6, 3)]:
        dens = _spread(rng, sizes, d, n_targets=3, sep=300.0, sigma=5.0)
        omegas = rng.dirichlet(np.ones(len(sizes)))
        comps = product_module._Components(dens, omegas)
        rows, left_out = product_module._gated_rows(comps)
        everything = np.indices(sizes).reshape(len(sizes), -1) + comps.start[:, None]
        full = product_module._centred_gathered(comps, everything)
        kept = {tuple(c) for c in rows.T}
        assert len(kept) < math.prod(sizes)  # the gate does leave combinations out
        is_kept = np.array([tuple(c) in kept for c in everything.T])
        w = np.exp(full[0])
        w_bound = np.exp((np.log(np.concatenate([D.weights for D in dens]))[everything]
                          * omegas[:, None]).sum(axis=0))  # prod_i w_ic^omega_i
        assert np.all(w[~is_kept] <= 1e-20 * w_bound[~is_kept])
        assert w[~is_kept].sum() <= left_out <= 1e-14 * w[is_kept].sum()
        gated = gci_product(dens, omegas, gate=True)
        np.testing.assert_allclose(gated.weights, w[is_kept], rtol=1e-13)  # same formula, the
        np.testing.assert_allclose(gated.means, full[1][is_kept], rtol=1e-13)  # last bit aside


def test_gated_product_falls_back_when_what_is_left_out_could_matter(monkeypatch):
    """Densities that barely overlap: the kept mass is tiny, the bound on what the gate left out
    is not negligible beside it, so every combination is formed (same as ``gate=False``)."""
    monkeypatch.setattr(product_module, "_SMALL_COMBINATIONS", 0)
    rng = np.random.default_rng(3)
    dens = _spread(rng, (3, 3, 3), 2, n_targets=3, sep=300.0, sigma=5.0)
    comps = product_module._Components(dens, np.array([0.3, 0.3, 0.4]))
    assert product_module._gated_rows(comps) is not None
    dens[2] = GaussianMixture(dens[2].weights, dens[2].means + 60.0, dens[2].covs)
    omegas = np.array([0.3, 0.3, 0.4])
    monkeypatch.setattr(product_module, "_GATE", 4.0)  # a gate this tight leaves out real mass
    plain, gated = gci_product(dens, omegas), gci_product(dens, omegas, gate=True)
    assert len(gated) == len(plain) == 27
    np.testing.assert_array_equal(gated.weights, plain.weights)


def test_gci_fuse_with_a_reducer_equals_the_ungated_product_reduced():
    """What a peer's fusion returns (n-ary GCI, then prune/merge) does not change with the gate."""
    from sensornet.tracking.fusion import gci_fuse
    from sensornet.tracking.reduction import Reducer

    rng = np.random.default_rng(11)
    reduce = Reducer()
    for card in ("emd", "separate"):
        dens = _spread(rng, (4, 4, 4, 4, 4), 4, n_targets=4, sep=300.0, sigma=8.0)
        omegas = list(rng.dirichlet(np.ones(5)))
        fused = gci_fuse(dens, omegas, reduce, cardinality=card)
        ref = reduce(gci_product(dens, omegas, card))
        np.testing.assert_allclose(fused.weights, ref.weights, rtol=1e-12)
        np.testing.assert_allclose(fused.means, ref.means, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(fused.covs, ref.covs, rtol=1e-10, atol=1e-9)
