"""``gci_fuse``'s product at once beyond ``NARY_MAX_COMBINATIONS`` (issue 33,
:func:`tracking.gci_product.gci_product_gated`): own + 8 neighbours of 10 tracks are 11^9
combinations, the gate keeps about 26, so one product and one reduction replace eight of each.

References: the exact n-ary product of every combination (``gci_product``, ungated) on cases
small enough to form it, the powered products integrated on a 1-D grid, the exact-pair gate of
``gci_product(gate=True)``, and the sequential path (``gci_fuse(..., sequential=True)``), which
reduces after each of its steps and so differs where a reduction on the way changes something.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from sensornet.tracking import gci_product as product_module
from sensornet.tracking.fusion import NARY_MAX_COMBINATIONS, gci_fuse
from sensornet.tracking.gci_product import gci_product, gci_product_gated
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer, merge_many

from tests.test_gci_sequential import spread


def bench_inputs() -> list[GaussianMixture]:
    """``bench_lmb``'s own + 8 neighbours of 10 tracks (seed 2014)."""
    from benchmarks.bench_lmb import labelled_inputs

    return [mix for mix, _ in labelled_inputs(9, 10, np.random.default_rng(2014))]


def matches(got: GaussianMixture, full: GaussianMixture) -> np.ndarray:
    """For each component of ``got``, the index of the component of ``full`` with its mean
    (within 1e-9 of the mean's scale): ``(len got,)``."""
    scale = np.linalg.norm(full.means, axis=1) + np.sqrt(np.trace(full.covs, axis1=1, axis2=2))
    dist = np.linalg.norm(got.means[:, None] - full.means[None], axis=-1) / scale[None]
    idx = dist.argmin(axis=1)
    assert np.all(dist[np.arange(len(got)), idx] <= 1e-9)
    return idx


@pytest.mark.parametrize("cardinality", ["emd", "separate"])
@pytest.mark.parametrize("d", [2, 4])
def test_gated_product_is_the_exact_product_less_negligible_combinations(d, cardinality):
    """Random far-apart targets (4-6 densities, 4,096-7,776 combinations, the gate widened
    above 4,096): each kept combination is the exact product's, in its order, to 1e-10; each
    left out weighs below 1e-20 times its components' weight product, all of them together
    below 1e-14 of the kept mass; and the gate does leave some out."""
    for seed, sizes in enumerate([(4, 4, 4, 4, 4, 4), (5, 6, 5, 6, 5), (6, 6, 6, 6, 6)]):
        rng = np.random.default_rng([d, seed])
        dens = spread(rng, sizes, d, n_targets=int(rng.integers(3, 6)), sep=300.0, sigma=5.0)
        omegas = rng.dirichlet(np.ones(len(sizes)))
        full = gci_product(dens, omegas, cardinality)  # every combination
        got = gci_product_gated(dens, omegas, cardinality, limit=100_000)
        assert got is not None and 0 < len(got) < len(full)
        idx = matches(got, full)
        assert np.all(np.diff(idx) > 0)  # the exact product's order
        np.testing.assert_allclose(got.weights, full.weights[idx], rtol=1e-10)
        np.testing.assert_allclose(got.covs, full.covs[idx], rtol=1e-10,
                                   atol=1e-12 * np.abs(full.covs).max())
        out = np.ones(len(full), dtype=bool)
        out[idx] = False
        if cardinality == "separate":  # before the scaling: the product of the normalised
            dens = [D.scaled(1.0 / D.mass) for D in dens]
        raw = gci_product(dens, omegas, "emd")
        logs = [np.log(D.weights) * o for D, o in zip(dens, omegas, strict=True)]
        bound = np.exp(sum(np.meshgrid(*logs, indexing="ij"))).reshape(-1)  # prod w^omega
        assert np.all(raw.weights[out] <= 1e-20 * bound[out])
        assert raw.weights[out].sum() <= 1e-14 * raw.weights[~out].sum()


def test_components_are_the_powered_products_integrated_on_a_grid():
    """1-D brute force: each kept component is ``prod_i (w_i N_i(x))^(omega_i)`` (cross terms
    dropped, §3) integrated on a fine grid (mass, mean, variance); the far-apart combinations
    are not formed."""
    a = GaussianMixture(np.array([0.9, 0.4]), np.array([[0.0], [300.0]]),
                        np.array([[[40.0]], [[90.0]]]))
    b = GaussianMixture(np.array([0.8, 0.6]), np.array([[6.0], [290.0]]),
                        np.array([[[60.0]], [[30.0]]]))
    c = GaussianMixture(np.array([0.7, 0.5]), np.array([[-4.0], [305.0]]),
                        np.array([[[50.0]], [[45.0]]]))
    omegas = np.array([0.5, 0.3, 0.2])
    got = gci_product_gated([a, b, c], omegas)
    assert got is not None and len(got) == 2  # (0, 0, 0) and (1, 1, 1)
    x = np.linspace(-200.0, 500.0, 200_001)
    pdf = lambda m, P: np.exp(-0.5 * (x - m) ** 2 / P) / np.sqrt(2 * np.pi * P)  # noqa: E731
    for k in (0, 1):
        f = np.prod([(D.weights[k] * pdf(D.means[k, 0], D.covs[k, 0, 0])) ** o
                     for D, o in zip((a, b, c), omegas, strict=True)], axis=0)
        w = np.trapezoid(f, x)
        m = np.trapezoid(x * f, x) / w
        np.testing.assert_allclose(got.weights[k], w, rtol=1e-9)
        np.testing.assert_allclose(got.means[k, 0], m, rtol=1e-9)
        np.testing.assert_allclose(got.covs[k, 0, 0], np.trapezoid((x - m) ** 2 * f, x) / w,
                                   rtol=1e-9)


def test_marginal_gate_keeps_what_the_exact_pair_gate_keeps():
    """On ``bench_lmb``'s inputs (11^9 combinations): every combination of
    ``gci_product(gate=True)`` at the same widened gate (pair terms formed exactly) is kept,
    with the same numbers; the few more the marginal bound keeps carry no mass."""
    dens = bench_inputs()
    omegas = [1 / 9] * 9
    got = gci_product_gated(dens, omegas, "emd")
    total = math.prod(len(D) for D in dens)
    saved = product_module._GATE
    try:
        product_module._GATE = saved + 2.0 * math.log(total / product_module._GATE_COUNT)
        exact = gci_product(dens, omegas, "emd", gate=True)
    finally:
        product_module._GATE = saved
    assert got is not None and 10 <= len(exact) <= len(got) <= 40
    idx = matches(exact, got)
    np.testing.assert_allclose(exact.weights, got.weights[idx], rtol=1e-12)
    extra = np.ones(len(got), dtype=bool)
    extra[idx] = False
    assert got.weights[extra].sum() <= 1e-14 * got.mass


@pytest.mark.parametrize("cardinality", ["emd", "separate"])
def test_order_of_the_densities_does_not_matter(cardinality):
    """The product at once is order-free (the steps are not, once they reduce): the densities
    reversed give the same components, to round-off, once the negligible ones are set aside."""
    dens = bench_inputs()
    omegas = list(np.random.default_rng(4).dirichlet(np.ones(9)))
    one = gci_product_gated(dens, omegas, cardinality)
    two = gci_product_gated(dens[::-1], omegas[::-1], cardinality)
    assert one is not None and two is not None
    one, two = (m.select(m.weights > 1e-12 * m.mass) for m in (one, two))
    assert len(one) == len(two) >= 10
    idx = matches(one, two)
    assert len(set(idx.tolist())) == len(one)
    np.testing.assert_allclose(one.weights, two.weights[idx], rtol=1e-9)
    np.testing.assert_allclose(one.covs, two.covs[idx], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("cardinality", ["emd", "separate"])
def test_bench_fusion_is_one_product_reduced_once(cardinality):
    """``gci_fuse`` on ``bench_lmb``'s own + 8 neighbours: exactly the gated product of the
    pre-merged inputs (each density's rows within ``U / omega_i`` of each other merged; some
    inputs lose a row) reduced once; against the sequential path (eight products, eight
    reductions) the same 10 tracks, means within 1 m, covariances within 6 % of the largest
    entry (measured 0.42 m, 4.8 %: the merged rows are wider; against the exact integral's
    moments the pre-merged product is within 4.7 % on every track, the steps 5.1 %); the
    weights of the tracks some input holds as two rows differ (measured emd 0.13, separate
    0.31; without the pre-merge 0.15, 0.22: the steps still power the newcomers' rows apart
    and over-count those tracks, which ``separate``'s normalisation takes from the others),
    ``separate``'s total not (both prod N_i^omega_i)."""
    dens = bench_inputs()
    omegas = [1 / 9] * 9
    reducer = Reducer()
    got = gci_fuse(dens, omegas, reducer, cardinality=cardinality)
    ref = reducer(gci_product_gated(dens, omegas, cardinality, NARY_MAX_COMBINATIONS,
                                    premerge=(reducer.merge_threshold, reducer.merge_rule)))
    np.testing.assert_array_equal(got.weights, ref.weights)
    np.testing.assert_array_equal(got.means, ref.means)
    merged = merge_many(dens, reducer.merge_threshold * 9, reducer.merge_rule)
    assert sum(map(len, merged)) < sum(map(len, dens))
    steps = gci_fuse(dens, omegas, reducer, cardinality=cardinality, sequential=True)
    assert len(got) == len(steps) == 10
    idx = np.linalg.norm(got.means[:, None, [0, 2]] - steps.means[None, :, [0, 2]],
                         axis=-1).argmin(axis=1)
    assert sorted(idx.tolist()) == list(range(10))
    assert np.abs(got.means - steps.means[idx]).max() <= 1.0
    rel = np.abs(got.covs - steps.covs[idx]).max(axis=(1, 2)) / np.abs(steps.covs).max()
    assert rel.max() <= 0.06
    assert np.abs(got.weights - steps.weights[idx]).max() <= (0.15 if cardinality == "emd"
                                                              else 0.35)
    if cardinality == "separate":
        assert got.mass == pytest.approx(steps.mass, rel=1e-6)


def test_too_many_kept_falls_back_to_the_steps():
    """Nine overlapping densities (10^9 combinations, all within the gate; each density's
    components 8 sigma apart on a grid, beyond the pre-merge's ``U / omega = 45``): no product
    at once (None), and ``gci_fuse`` gives the sequential path's result to the bit."""
    rng = np.random.default_rng(3)
    grid = np.stack(np.meshgrid(np.arange(4.0), np.arange(3.0)), -1).reshape(-1, 2)[:10] * 80.0
    dens = []
    for _ in range(9):
        means = np.zeros((10, 4))
        means[:, [0, 2]] = grid + rng.normal(size=(10, 2))
        dens.append(GaussianMixture(rng.uniform(0.5, 1.0, 10), means,
                                    np.tile(np.eye(4) * 100.0, (10, 1, 1))))
    assert [len(D) for D in merge_many(dens, 45.0)] == [10] * 9
    assert gci_product_gated(dens, [1 / 9] * 9, "separate", NARY_MAX_COMBINATIONS,
                             premerge=(5.0, "vo-ma")) is None
    got = gci_fuse(dens, [1 / 9] * 9, Reducer(), cardinality="separate")
    steps = gci_fuse(dens, [1 / 9] * 9, Reducer(), cardinality="separate", sequential=True)
    np.testing.assert_array_equal(got.weights, steps.weights)
    np.testing.assert_array_equal(got.covs, steps.covs)


@pytest.mark.parametrize("cardinality", ["emd", "separate"])
def test_bad_inputs(cardinality):
    """An empty density or one with no mass: an empty result, as the steps give; a NaN mean:
    that component combines with nothing, the rest is fused (finite); one density: itself; a
    bad cardinality or weights that do not match the densities: one-line errors."""
    dens = bench_inputs()
    omegas = [1 / 9] * 9
    reducer = Reducer()
    empty = dens[:3] + [GaussianMixture.empty(4)] + dens[4:]
    zero = dens[:3] + [GaussianMixture(np.zeros(len(dens[3])), dens[3].means, dens[3].covs)]
    zero += dens[4:]
    for bad in (empty, zero):
        assert len(gci_fuse(bad, omegas, reducer, cardinality=cardinality)) == 0
        assert len(gci_fuse(bad, omegas, reducer, cardinality=cardinality,
                            sequential=True)) == 0
    means = dens[0].means.copy()
    means[2, 0] = np.nan
    nan = [GaussianMixture(dens[0].weights, means, dens[0].covs)] + dens[1:]
    out = gci_fuse(nan, omegas, reducer, cardinality=cardinality)
    assert 0 < len(out) and np.isfinite(out.means).all() and np.isfinite(out.weights).all()
    assert gci_product_gated(dens[:1], [1.0], cardinality) is dens[0]
    with pytest.raises(ValueError, match="cardinality") as err:
        gci_product_gated(dens, omegas, "bogus")
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="one weight per density"):
        gci_product_gated(dens, omegas[:-1])


def test_more_combinations_than_a_float_holds():
    """310 densities of 10 far-apart tracks: 10^310 combinations (beyond a float's range; the
    count is only taken as a log), 10 kept, each track's weight the geometric mean of its
    inputs' (``separate``: ``prod N_i^omega_i`` = 9 in total)."""
    rng = np.random.default_rng(0)
    targets = rng.uniform(-1e4, 1e4, size=(10, 4))
    n = 310
    dens = [GaussianMixture(np.full(10, 0.9), targets + rng.normal(size=(10, 4)),
                            np.tile(np.eye(4) * 25.0, (10, 1, 1))) for _ in range(n)]
    out = gci_fuse(dens, [1 / n] * n, Reducer(), cardinality="separate")
    assert len(out) == 10
    assert out.mass == pytest.approx(9.0, rel=1e-12)
    np.testing.assert_allclose(np.sort(out.means[:, 0]), np.sort(targets[:, 0]), atol=1.0)


def test_weights_against_the_exact_gci_integral():
    """The product at once against the exact GCI mass of each track, ``int prod_i D_i(x)^
    (omega_i) dx`` over the inputs' whole mixtures (importance sampling, 30,000 draws from the
    fused Gaussian widened 4x, ~1 % standard error), ``emd`` weights. Dropping the cross terms
    over-counts a track an input holds as two or three close rows when they are powered apart:
    without the pre-merge the product at once gives 0.38-0.53 where the exact mass is
    0.24-0.39 (5 of 10 tracks, up to +75 %), the steps (newcomers' rows powered apart, merged
    after) 0.25-0.41 (up to +50 %); with each input's rows within ``U / omega`` merged first,
    every track is within 6 % of exact (measured with 400,000 draws: max 3.2 %, mean 0.6 %;
    on the split tracks 3.2 % / 0.8 %; those numbers are this test's inputs, evaluated once;
    the rule was chosen on bench_lmb's inputs of seeds 100-104: max 4.6 %, mean 1.4 % over 48
    tracks, none 77 % / 12 %). The steps stay the reference path, over-counting at least as
    much where they differ by more than 1 %."""
    from sensornet.tracking.gaussian import gaussian_pdf_points

    dens = bench_inputs()
    omegas = np.full(9, 1 / 9)
    once = gci_fuse(dens, list(omegas), Reducer(), cardinality="emd")
    steps = gci_fuse(dens, list(omegas), Reducer(), cardinality="emd", sequential=True)
    apart = Reducer()(gci_product_gated(dens, omegas, "emd", NARY_MAX_COMBINATIONS))
    near = lambda mix, m: np.linalg.norm(  # noqa: E731
        mix.means[:, [0, 2]] - m[[0, 2]], axis=1).argmin()
    rng = np.random.default_rng(0)
    split, worst_apart = 0, 0.0
    for k in range(len(once)):
        m, P = once.means[k], 4.0 * once.covs[k]
        x = m + rng.standard_normal((30_000, 4)) @ np.linalg.cholesky(P).T
        log_q = np.log(gaussian_pdf_points(x, m[None], P[None])[:, 0])
        log_f = sum(o * np.log(np.maximum(gaussian_pdf_points(x, D.means, D.covs) @ D.weights,
                                          1e-300)) for D, o in zip(dens, omegas, strict=True))
        exact = float(np.mean(np.exp(log_f - log_q)))
        a, s = once.weights[k], steps.weights[near(steps, m)]
        assert a == pytest.approx(exact, rel=0.06)
        worst_apart = max(worst_apart, apart.weights[near(apart, m)] / exact)
        if abs(a - s) > 0.01 * a:  # the steps power some rows apart: they over-count
            split += 1
            assert s >= a
    assert split >= 3 and worst_apart >= 1.5


@pytest.mark.parametrize("rule", ["vo-ma", "weighted"])
def test_premerge_is_merge_of_each_density(rule):
    """``merge_many`` (the pre-merge's stacked sweep, one call for all densities) gives each
    density what :func:`merge` gives it at its own threshold, to the bit, its rows in input
    order; on random cases (0-13 components, 1-5 targets, tight to wide spreads) where many
    rows merge. Zero-weight rows and a NaN row merge with nothing; a bad rule: one-line error."""
    from sensornet.tracking.reduction import merge

    merged = 0
    for seed in range(30):
        rng = np.random.default_rng(seed)
        n, d = int(rng.integers(1, 9)), int(rng.choice([2, 4]))
        dens = spread(rng, rng.integers(0, 14, n), d, int(rng.integers(1, 6)), 300.0,
                      float(rng.choice([2.0, 8.0, 20.0])))
        thresholds = rng.uniform(1.0, 60.0, n) / (20.0 if rule == "weighted" else 1.0)
        for D, t, got in zip(dens, thresholds, merge_many(dens, thresholds, rule), strict=True):
            ref = merge(D, float(t), rule)
            assert len(got) == len(ref)
            merged += len(D) - len(got)
            if len(ref):
                idx = matches(ref, got)
                assert sorted(idx.tolist()) == list(range(len(got)))
                np.testing.assert_array_equal(got.weights[idx], ref.weights)
                np.testing.assert_array_equal(got.means[idx], ref.means)
                np.testing.assert_array_equal(got.covs[idx], ref.covs)
    assert merged > 500
    a = GaussianMixture(np.array([0.0, 0.0, 1.0]), np.zeros((3, 2)), np.tile(np.eye(2), (3, 1, 1)))
    means = np.array([[0.0, 0.0], [np.nan, 0.0], [0.1, 0.0]])
    b = GaussianMixture(np.ones(3), means, np.tile(np.eye(2), (3, 1, 1)))
    out = merge_many([a, b], 5.0, rule)
    assert len(out[0]) == 3 and len(out[1]) == 2 and np.isnan(out[1].means).any()
    with pytest.raises(ValueError, match="merge rule") as err:
        merge_many([a], 5.0, "bogus")
    assert "\n" not in str(err.value)
