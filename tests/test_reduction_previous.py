"""The Reducer against a frozen copy of its implementation before the small-mixture changes
(issue 33): the same output, to the bit, on random mixtures of 1-200 components (ties in weight,
merges, prunes, caps, both merge rules, with and without sources)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.gaussian import _generic_inverse, inv_spd
from sensornet.tracking.gaussian import c_einsum as _c_einsum
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer, _upper_pairs, merge_sources

try:
    from numpy.linalg import _umath_linalg as _lapack
except ImportError:  # pragma: no cover
    _lapack = None

_ALL_PAIRS_UP_TO = 48

# --- the reduction as of 7afeb7b (tracking/reduction.py), copied unchanged -------------------


def old_reduce(mix: GaussianMixture, prune_threshold: float, merge_threshold: float,
               max_components: int, rule: str):
    """Reducer._reduce (no re-fit) as of 7afeb7b: the reduced mixture and the sources."""
    src = None
    w = mix.weights
    kept = np.flatnonzero(w >= prune_threshold)
    if len(kept) <= 1:
        reduced = mix.select(kept)
        src = kept
    else:
        order = kept[(-w[kept]).argsort(kind="stable")]
        reduced, rows = _merge_in_order(mix, order, merge_threshold, rule)
        src = order if rows is None else order[rows]
    if len(reduced) > max_components:
        ci = np.sort(np.argsort(-reduced.weights, kind="stable")[:max_components])
        reduced = reduced.select(ci)
        src = src[ci]
    P = reduced.covs
    return GaussianMixture.trusted(reduced.weights, reduced.means,
                                   0.5 * (P + P.swapaxes(-1, -2))), src


def _moment_match(weights: np.ndarray, means: np.ndarray, covs: np.ndarray):
    """One Gaussian with the mass, mean and covariance of a group ``(g,), (g,d), (g,d,d)``."""
    w = weights.sum()
    m = weights @ means / w
    diff = means - m
    P = (np.einsum("g,gij->ij", weights, covs) + np.einsum("g,gi,gj->ij", weights, diff, diff)) / w
    return w, m, 0.5 * (P + P.T)


def _merge_in_order(mix: GaussianMixture, order: np.ndarray, threshold: float,
                    rule: str) -> tuple[GaussianMixture, np.ndarray | None]:
    """``merge` of the components ``order`` (at least two indices, heaviest first), and
    which positions of ``order`` the output rows come from (a boolean mask over ``order``;
    None: all of them). Each output row sits at its group's centre, the heaviest member."""
    n = len(order)
    w, m, P = mix.weights[order], mix.means[order], mix.covs[order]  # heaviest first
    ci, cj = _close_pairs(w, m, P, threshold, rule)
    if ci.size == 0:
        return GaussianMixture.trusted(w, m, P), None
    centres, members = _greedy_groups(ci, cj)
    out_w, out_m, out_P = w.copy(), m.copy(), P.copy()
    _moment_match_groups(w, m, P, centres, members, out_w, out_m, out_P)
    keep = np.ones(n, dtype=bool)
    keep[[i for g in members for i in g]] = False
    return GaussianMixture.trusted(out_w[keep], out_m[keep], out_P[keep]), keep


def _close_pairs(w: np.ndarray, m: np.ndarray, P: np.ndarray, threshold: float,
                 rule: str, inv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)``, ``i > j`` (``w`` sorted decreasing), where ``i`` merges into centre ``j``.

    Returned sorted by ``(j, i)``. Up to :data:`_ALL_PAIRS_UP_TO` components every pair is
    tested; above, candidates come first from a bound: the quadratic form over the full state
    is at least the one over one coordinate's marginal, ``x^T P^-1 x >= x_k^2 / P_kk``. So
    vo-ma needs ``(m_i - m_j)_k^2 <= U (P_i)_kk`` and the weighted rule ``(m_i - m_j)_k^2
    w_i w_j <= eta (P_j)_kk (w_i + w_j)`` on every coordinate ``k``; the two positions are
    tested, with the bound widened by 0.1 % (far above round-off), so no close pair is lost.
    The exact test uses the sweep's own inverses (``inv_spd` of the whole stack, or
    ``inv`` if given).
    """
    n = len(w)
    if n <= _ALL_PAIRS_UP_TO:
        cj, ci = _upper_pairs(n)
    else:
        ci, cj = _candidate_pairs(w, m, P, threshold * (1.0 + 1e-3), rule)
        if ci.size == 0:
            return ci, cj
    if inv is None:
        inv = _inv_spd(P)
    diff = m[ci] - m[cj]
    if rule == "vo-ma":
        close = _c_einsum("gi,gij,gj->g", diff, inv[ci], diff) <= threshold
    else:
        d2 = np.einsum("gi,gij,gj->g", diff, inv[cj], diff)
        close = (w[ci] * w[cj] / (w[ci] + w[cj])) * d2 < threshold
    ci, cj = ci[close], cj[close]
    if n <= _ALL_PAIRS_UP_TO:
        return ci, cj
    by_centre = np.lexsort((ci, cj))
    return ci[by_centre], cj[by_centre]


def _candidate_pairs(w: np.ndarray, m: np.ndarray, P: np.ndarray, lim: float,
                     rule: str) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)``, ``i > j``, passing the marginal bound of ``_close_pairs`."""
    n = len(w)
    ky = min(2, m.shape[1] - 1)  # px and py in [px, vx, py, vy]
    x, y = m[:, 0], m[:, ky]
    if rule == "vo-ma":
        # member i against every centre within x_i +- sqrt(lim (P_i)_xx), from a sort on x
        r = np.sqrt(max(lim, 0.0) * P[:, 0, 0])
        by_x = np.argsort(x, kind="stable")
        xs = x[by_x]
        lo = np.searchsorted(xs, x - r, "left")
        count = np.searchsorted(xs, x + r, "right") - lo
        ci = np.repeat(np.arange(n), count)
        cj = by_x[np.arange(ci.size) - np.repeat(np.cumsum(count) - count - lo, count)]
        ok = (cj < ci) & (np.square(y[ci] - y[cj]) <= lim * P[ci, ky, ky])
    else:
        ww = w[:, None] * w
        ws = w[:, None] + w
        near = (np.square(x[:, None] - x) * ww <= (lim * P[:, 0, 0]) * ws) & (
            np.square(y[:, None] - y) * ww <= (lim * P[:, ky, ky]) * ws)  # [i, j]
        ci, cj = np.nonzero(near)
        ok = cj < ci
    return ci[ok], cj[ok]


def _inv_spd(P: np.ndarray) -> np.ndarray:
    """``tracking.gaussian.inv_spd` (the same numbers: the same LAPACK call) without
    ``np.linalg.inv``'s Python wrapper, which costs more than inverting a few 4x4 matrices; a
    singular or non-finite stack goes through ``inv_spd`` (and its errors) unchanged."""
    if _lapack is None or not _generic_inverse(P) or P.dtype != np.float64:
        return inv_spd(P)
    with np.errstate(all="ignore"):
        inv = _lapack.inv(P, signature="d->d")
    if not np.isfinite(inv).all():
        return inv_spd(P)
    return 0.5 * (inv + inv.swapaxes(-1, -2))


def _greedy_groups(ci: np.ndarray, cj: np.ndarray) -> tuple[list[int], list[list[int]]]:
    """The sweep's groups from the close pairs sorted by ``(j, i)``.

    Taking centres in order of decreasing weight, a centre ``j`` not yet absorbed takes every
    ``i`` close to it that no earlier centre took. Returns the centres with at least one member
    and, for each, its members in sweep order.
    """
    taken: set[int] = set()
    groups: dict[int, list[int]] = {}
    for i, j in zip(ci.tolist(), cj.tolist(), strict=True):
        if j in taken or i in taken:
            continue
        groups.setdefault(j, []).append(i)
        taken.add(i)
    return list(groups), list(groups.values())


def _moment_match_groups(w, m, P, centres, members, out_w, out_m, out_P) -> None:
    """Write ``moment_match` of each group ``[centre, *members]`` into row ``centre``.

    Groups of two and three are done together (a group of two padded with a zero-weight copy
    of its centre, which adds exact zeros), with ``moment_match`'s own operations in its
    order of summation, so the results agree with it to the last bit where NumPy sums short
    vectors in order; larger groups call it directly.
    """
    small = []
    vectorise = m.shape[1] > 1  # NumPy reduces 1-D einsums in another order
    for c, g in zip(centres, members, strict=True):
        if len(g) <= 2 and vectorise:
            small.append((c, g[0], g[1] if len(g) == 2 else c))
        else:
            group = [c, *g]
            out_w[c], out_m[c], out_P[c] = _moment_match(w[group], m[group], P[group])
    if not small:
        return
    n, d = m.shape
    idx = np.array(small).T  # (3, k): member t of each of k groups
    gw = w[idx]
    gw[2, idx[2] == idx[0]] = 0.0  # the padding of groups of two
    X = np.concatenate((m, P.reshape(n, d * d)), axis=1)[idx]  # (3, k, d + d*d)
    wX = gw[:, :, None] * X
    # np.add.reduce over the first axis adds the rows in order: (x0 + x1) + x2
    tw = np.add.reduce(gw, axis=0)
    tX = np.add.reduce(wX, axis=0)  # sum w m | sum w P
    mean = tX[:, :d] / tw[:, None]
    diff = X[:, :, :d] - mean  # (3, k, d)
    outer = (gw[:, :, None] * diff)[:, :, :, None] * diff[:, :, None, :]
    cov = (tX[:, d:].reshape(-1, d, d) + np.add.reduce(outer, axis=0)) / tw[:, None, None]
    c = idx[0]
    out_w[c] = tw
    out_m[c] = mean
    out_P[c] = 0.5 * (cov + cov.swapaxes(1, 2))


# --- the tests ---------------------------------------------------------------------------------


def _spd(rng, n, d, cond):
    """``n`` random SPD ``d x d`` matrices with condition numbers up to ``cond``."""
    Q, _ = np.linalg.qr(rng.normal(size=(n, d, d)))
    ev = np.exp(rng.uniform(0.0, np.log(cond), size=(n, d))) * rng.uniform(1.0, 50.0, (n, 1))
    P = np.einsum("nij,nj,nkj->nik", Q, ev, Q)
    return 0.5 * (P + P.swapaxes(1, 2))


def random_mixture(rng, n, d=4, clusters=None, tie=False, light=False, cond=1e3):
    """Components around a few centres, so that groups of two, three and more merge."""
    clusters = clusters or max(1, n // 4)
    centres = rng.normal(size=(clusters, d)) * 60.0
    means = centres[rng.integers(0, clusters, n)] + rng.normal(size=(n, d)) * rng.uniform(
        0.5, 6.0)
    weights = rng.uniform(0.01, 1.0, n)
    if tie:  # equal weights: the stable order decides the sweep
        weights = np.round(weights * 4) / 4 + 0.25
    if light:  # some below the prune threshold, some at it
        weights[rng.random(n) < 0.3] = 1e-7
        weights[rng.random(n) < 0.1] = 1e-5
    if rng.random() < 0.3:  # exact duplicates: distance zero
        k = rng.integers(0, n)
        means[rng.integers(0, n)] = means[k]
    return GaussianMixture(weights, means, _spd(rng, n, d, cond))


def _same(a: GaussianMixture, b: GaussianMixture) -> None:
    for x, y in ((a.weights, b.weights), (a.means, b.means), (a.covs, b.covs)):
        assert x.shape == y.shape
        assert x.tobytes() == y.tobytes()  # to the bit


CASES = [(n, seed) for seed in range(6) for n in (1, 2, 3, 5, 11, 12, 30, 48, 49, 120, 200)]


@pytest.mark.parametrize("n,seed", CASES)
@pytest.mark.parametrize("rule", ["vo-ma", "weighted"])
def test_reducer_equals_previous_implementation_to_the_bit(n, seed, rule):
    rng = np.random.default_rng(1000 * seed + n)
    merges = 0
    for k in range(4):
        mix = random_mixture(rng, n, tie=k % 2 == 1, light=k >= 2,
                             cond=1e8 if k == 3 else 1e3)
        jmax = int(rng.integers(1, n + 2))
        red = Reducer(merge_threshold=float(rng.choice([1.0, 4.0, 25.0])), merge_rule=rule,
                      max_components=jmax)
        want, want_src = old_reduce(mix, red.prune_threshold, red.merge_threshold, jmax, rule)
        _same(red(mix), want)
        got, src = red.with_sources(mix)
        _same(got, want)
        assert np.array_equal(src, want_src)
        merges += len(want) < int((mix.weights >= red.prune_threshold).sum())
    if n >= 5:
        assert merges > 0  # the cases do exercise the merge


def test_single_close_pair_and_no_pair_paths():
    """One close pair (no sweep), none (no merge), a chain (the sweep's greedy order)."""
    rng = np.random.default_rng(7)
    P = _spd(rng, 5, 4, 10.0)
    far = np.arange(5)[:, None] * np.array([1e3, 0.0, 1e3, 0.0])
    for means in (far, far + np.eye(5, 4)[[0, 0, 2, 3, 4]] * 0.0,
                  np.concatenate((far[:3], far[3:4], far[3:4] + 0.1)),
                  np.cumsum(np.full((5, 4), 0.9), axis=0)):
        mix = GaussianMixture(rng.uniform(0.1, 1.0, 5), means, P)
        want, _ = old_reduce(mix, 1e-5, 5.0, 100, "vo-ma")
        _same(Reducer()(mix), want)
    out, src = merge_sources(mix, 5.0)
    assert len(out) < 5 and len(src) == len(out)
