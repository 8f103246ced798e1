"""Mixture reduction: pruning, merging, capping, ISE weight re-fit (docs/algorithms.md "Reduction").

Two merge rules share one sweep (take the heaviest remaining component, merge its neighbours
into it by moment matching, repeat):

* ``"vo-ma"``: Vo & Ma 2006, Table II: merge ``i`` into the heaviest ``j`` when
  ``(m_i - m_j)^T P_i^-1 (m_i - m_j) <= U``.
* ``"weighted"``: seed 000 §3.3 level 1: merge when
  ``d^2 = (w_i w_j / (w_i + w_j)) (m_i - m_j)^T P_j^-1 (m_i - m_j) < eta``, ``P_j`` the
  heaviest component's covariance (our reading).

The sweep is computed in a few array operations (:func:`merge`): the close pairs at once (with
a cheap exact bound first when there are many components), then the groups in sweep order by
a Python loop over the close pairs only, then the moment matching of all small groups at once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import minimize
from sensornet.tracking.gaussian import c_einsum as _c_einsum
from sensornet.tracking.gaussian import inv_det_spd, inv_spd, log_gaussian
from sensornet.tracking.mixture import GaussianMixture

MERGE_RULES = ("vo-ma", "weighted")


def prune(mix: GaussianMixture, threshold: float) -> GaussianMixture:
    """Drop components with weight below ``threshold``."""
    if len(mix) == 0:
        return mix
    return mix.select(mix.weights >= threshold)


def keep_above(mix: GaussianMixture, threshold: float = 0.5) -> GaussianMixture:
    """Level-2 pruning before publishing (seed 000 §3.3): keep ``w > threshold`` only."""
    if len(mix) == 0:
        return mix
    return mix.select(mix.weights > threshold)


def cap(mix: GaussianMixture, max_components: int) -> GaussianMixture:
    """Keep the ``max_components`` heaviest components."""
    if len(mix) <= max_components:
        return mix
    return mix.select(cap_index(mix.weights, max_components))


def cap_index(weights: np.ndarray, max_components: int) -> np.ndarray:
    """The components :func:`cap` keeps, as sorted indices ``(k,)``."""
    if len(weights) <= max_components:
        return np.arange(len(weights))
    return np.sort(np.argsort(-weights, kind="stable")[:max_components])


def moment_match(weights: np.ndarray, means: np.ndarray, covs: np.ndarray):
    """One Gaussian with the mass, mean and covariance of a group ``(g,), (g,d), (g,d,d)``."""
    w = weights.sum()
    m = weights @ means / w
    diff = means - m
    P = (np.einsum("g,gij->ij", weights, covs) + np.einsum("g,gi,gj->ij", weights, diff, diff)) / w
    return w, m, 0.5 * (P + P.T)


def merge(mix: GaussianMixture, threshold: float, rule: str = "vo-ma") -> GaussianMixture:
    """Greedy merge around the heaviest remaining component (rule ``"vo-ma"`` or ``"weighted"``).

    The sweep of the module docstring, with no NumPy call per component: the pairs within the
    merge distance are found at once (:func:`_close_pairs`), the greedy groups follow from them
    in order of decreasing weight (:func:`_greedy_groups`), and the groups are moment-matched
    together (:func:`_moment_match_groups`). Output: one component per group, in the order the
    sweep takes their heaviest members; the same numbers as the plain sweep.
    """
    if rule not in MERGE_RULES:
        raise ValueError(f"unknown merge rule {rule!r}; expected one of {MERGE_RULES}")
    if len(mix) <= 1:
        return mix
    return _merge_in_order(mix, (-mix.weights).argsort(kind="stable"), threshold, rule)[0]


def merge_sources(mix: GaussianMixture, threshold: float,
                  rule: str = "vo-ma") -> tuple[GaussianMixture, np.ndarray]:
    """:func:`merge` (the same numbers) and, for each output component, the index into ``mix``
    of the heaviest member of its group (the sweep's centre): ``(n_out,)``. A merged
    component's tag is that member's (Panta, Clark & Vo 2009, §IV; tracking.labels)."""
    if rule not in MERGE_RULES:
        raise ValueError(f"unknown merge rule {rule!r}; expected one of {MERGE_RULES}")
    if len(mix) <= 1:
        return mix, np.arange(len(mix))
    order = (-mix.weights).argsort(kind="stable")
    out, kept = _merge_in_order(mix, order, threshold, rule)
    return out, order if kept is None else order[kept]


def sweep_labels(mix: GaussianMixture, threshold: float, rule: str = "vo-ma",
                 inv: np.ndarray | None = None) -> np.ndarray:
    """The group each component joins in :func:`merge`'s sweep: ``(n,)`` labels ``0..G-1``.

    The same close pairs and greedy groups as :func:`merge` (heaviest first), so a group here is
    exactly the set of components :func:`merge` would moment-match into one. Label ``g`` is the
    ``g``-th group in sweep order (its heaviest member first). ``inv``: ``inv_spd(mix.covs)``
    if the caller has it already (the same numbers the sweep would compute).
    """
    if rule not in MERGE_RULES:
        raise ValueError(f"unknown merge rule {rule!r}; expected one of {MERGE_RULES}")
    n = len(mix)
    if n <= 1:
        return np.zeros(n, dtype=np.intp)
    order = (-mix.weights).argsort(kind="stable")
    root = np.arange(n)
    if inv is not None and rule == "vo-ma" and n <= _ALL_PAIRS_UP_TO:
        # _close_pairs' every-pair test, gathering the pairs' rows straight from the unsorted
        # arrays (m[order][ci] is m[order[ci]]): the same numbers, four gathers fewer
        cj, ci = _upper_pairs(n)
        oi, oj = order[ci], order[cj]
        diff = mix.means[oi] - mix.means[oj]
        close = _c_einsum("gi,gij,gj->g", diff, inv[oi], diff) <= threshold
        ci, cj = ci[close], cj[close]
    else:
        ci, cj = _close_pairs(mix.weights[order], mix.means[order], mix.covs[order], threshold,
                              rule, None if inv is None else inv[order])
    if ci.size:
        centres, members = _greedy_groups(ci, cj)
        sizes = [len(g) for g in members]
        root[np.concatenate(members)] = np.repeat(centres, sizes)
    # the roots are the positions with root[i] == i (a centre is its own root), so a root's
    # rank among them is np.unique's inverse index, without the sort
    rank = np.cumsum(root == np.arange(n)) - 1
    labels_sorted = rank[root]
    labels = np.empty(n, dtype=np.intp)
    labels[order] = labels_sorted
    return labels


def merge_many(mixtures: Sequence[GaussianMixture], thresholds, rule: str = "vo-ma"
               ) -> list[GaussianMixture]:
    """``[merge(D, t, rule) for D, t in zip(mixtures, thresholds)]`` in one stacked call
    (:func:`merge_stacked`): the same components, each mixture's rows in its input order (a
    group's row where its heaviest member was) instead of :func:`merge`'s sweep order."""
    mixtures = list(mixtures)
    if not mixtures:
        return []
    sizes = np.array([len(D) for D in mixtures], dtype=np.intp)
    w, m, P, out_sizes = merge_stacked(np.concatenate([D.weights for D in mixtures]),
                                       np.concatenate([D.means for D in mixtures]),
                                       np.concatenate([D.covs for D in mixtures]),
                                       sizes, thresholds, rule)
    if out_sizes is sizes:  # nothing merged
        return mixtures
    ends = np.cumsum(out_sizes).tolist()
    return [GaussianMixture.trusted(w[e - k:e], m[e - k:e], P[e - k:e])
            for e, k in zip(ends, out_sizes.tolist(), strict=True)]


def merge_stacked(w: np.ndarray, m: np.ndarray, P: np.ndarray, sizes: np.ndarray, thresholds,
                  rule: str = "vo-ma"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`merge` of many mixtures laid end to end (mixture ``i`` the next ``sizes[i]`` rows
    of ``w (K,)``, ``m (K, d)``, ``P (K, d, d)``), mixture ``i`` at ``thresholds[i]`` (or one
    threshold for all), in one stacked sweep: the same groups and moment-matched numbers, each
    group's row where its heaviest member was, the rest in input order. Returns ``(w, m, P,
    sizes)``, the inputs themselves (``sizes`` the same object) when nothing merges.

    The pairs inside each mixture are tested at once, first by :func:`_close_pairs`' marginal
    bound (widened by 0.1 %), then exactly, with inverses only of the rows a candidate pair
    needs; the groups by :func:`_greedy_groups` in each mixture's sweep order (heaviest first,
    ties by index; a Python loop over the close pairs only); :func:`_moment_match_groups`.
    Rows of zero weight merge with nothing (a moment match of no mass is undefined); a row
    with a NaN fails every test. Issue 33: the inputs of the GCI product at once."""
    if rule not in MERGE_RULES:
        raise ValueError(f"unknown merge rule {rule!r}; expected one of {MERGE_RULES}")
    sizes = np.asarray(sizes, dtype=np.intp)
    K = len(w)
    t = np.broadcast_to(np.asarray(thresholds, dtype=float), sizes.shape)
    first = np.repeat(np.cumsum(sizes) - sizes, sizes)
    cnt = np.arange(K) - first  # row r pairs with the earlier rows of its mixture
    hi = np.repeat(np.arange(K), cnt)  # (pairs,): the later row of the pair
    lo = np.arange(hi.size) - np.repeat(np.cumsum(cnt) - cnt, cnt) + np.repeat(first, cnt)
    if not hi.size:
        return w, m, P, sizes
    # the sweep's centre j is the heavier row (ties: the earlier), the member i the other
    hi_first = w[hi] > w[lo]
    j = np.where(hi_first, hi, lo)
    i = np.where(hi_first, lo, hi)
    diff = m[i] - m[j]
    thr = np.repeat(t, sizes * (sizes - 1) // 2)
    Pd = np.diagonal(P, axis1=1, axis2=2)
    lim = thr * (1.0 + 1e-3)
    with np.errstate(invalid="ignore", divide="ignore"):  # NaN rows, zero weights: no pair
        if rule == "vo-ma":
            near = np.logical_and.reduce(np.square(diff) <= lim[:, None] * Pd[i], axis=1)
        else:
            f = w[i] * w[j] / (w[i] + w[j])
            near = np.logical_and.reduce(np.square(diff) * f[:, None] <= lim[:, None] * Pd[j],
                                         axis=1)
        near &= w[i] > 0  # w[j] >= w[i]: both rows carry mass
        cand = np.flatnonzero(near)
        if not cand.size:
            return w, m, P, sizes
        i, j, diff, thr = i[cand], j[cand], diff[cand], thr[cand]
        if rule == "vo-ma":
            close = _c_einsum("gi,gij,gj->g", diff, inv_spd(P[i]), diff) <= thr
        else:
            d2 = np.einsum("gi,gij,gj->g", diff, inv_spd(P[j]), diff)
            close = (w[i] * w[j] / (w[i] + w[j])) * d2 < thr
    if not close.any():
        return w, m, P, sizes
    i, j = i[close], j[close]
    # sweep order: by mixture, heaviest first, ties by index; pairs sorted by (centre, member)
    mix_of = np.repeat(np.arange(len(sizes)), sizes)
    order = np.lexsort((-w, mix_of))
    rank = np.empty(K, dtype=np.intp)
    rank[order] = np.arange(K)
    ri, rj = rank[i], rank[j]
    by_centre = np.lexsort((ri, rj))
    centres, members = _greedy_groups(ri[by_centre], rj[by_centre])
    centres = order[centres].tolist()
    members = [order[g].tolist() for g in members]
    out_w, out_m, out_P = w.copy(), m.copy(), P.copy()
    _moment_match_groups(w, m, P, centres, members, out_w, out_m, out_P)
    keep = np.ones(K, dtype=bool)
    keep[np.concatenate(members)] = False
    return (out_w[keep], out_m[keep], out_P[keep],
            np.bincount(mix_of[keep], minlength=len(sizes)).astype(np.intp))


def _merge_in_order(mix: GaussianMixture, order: np.ndarray, threshold: float,
                    rule: str) -> tuple[GaussianMixture, np.ndarray | None]:
    """:func:`merge` of the components ``order`` (at least two indices, heaviest first), and
    which positions of ``order`` the output rows come from (a boolean mask over ``order``;
    None: all of them). Each output row sits at its group's centre, the heaviest member."""
    n = len(order)
    w, m, P = mix.weights[order], mix.means[order], mix.covs[order]  # heaviest first
    ci, cj = _close_pairs(w, m, P, threshold, rule)
    if ci.size == 0:
        return GaussianMixture.trusted(w, m, P), None
    if ci.size == 1:  # one close pair (the usual case): its group, without the sweep
        centres, members = cj.tolist(), [ci.tolist()]
    else:
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
    The exact test uses the sweep's own inverses (:func:`inv_spd` of the whole stack, or
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
        inv = inv_spd(P)
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
    """Pairs ``(i, j)``, ``i > j``, passing the marginal bound of :func:`_close_pairs`."""
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


_ALL_PAIRS_UP_TO = 48
"""Up to this many components, :func:`_close_pairs` tests every pair exactly."""


@lru_cache(maxsize=_ALL_PAIRS_UP_TO + 1)
def _upper_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(j, i)`` for all ``j < i < n``, sorted by ``(j, i)`` (read-only, cached)."""
    j, i = np.triu_indices(n, 1)
    j.setflags(write=False)
    i.setflags(write=False)
    return j, i


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
    """Write :func:`moment_match` of each group ``[centre, *members]`` into row ``centre``.

    Groups of two and three are done together (a group of two padded with a zero-weight copy
    of its centre, which adds exact zeros), with :func:`moment_match`'s own operations in its
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
            out_w[c], out_m[c], out_P[c] = moment_match(w[group], m[group], P[group])
    if not small:
        return
    n, d = m.shape
    idx = np.array(small).T  # (3, k): member t of each of k groups
    gw = w[idx]
    pads = sum(c == g2 for c, _, g2 in small)
    if pads == len(small):  # only groups of two: the same zeros without the mask
        gw[2] = 0.0
    elif pads:
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


def ise_refit(original: GaussianMixture, reduced: GaussianMixture) -> GaussianMixture:
    """Re-fit the reduced weights to minimise the integral squared error to ``original``.

    ``ISE(w) = w^T A w - 2 b^T w + const`` with ``A_ij = N(m_i; m_j, P_i + P_j)`` over the
    reduced components and ``b_j = sum_a a_a N(m_a; m_j, P_a + P_j)`` (closed form of
    ``int N N``), minimised over ``w >= 0`` with the total mass kept (seed 000 §3.3).
    """
    n = len(reduced)
    if n <= 1 or len(original) == 0:
        return reduced
    A = _cross_overlap(reduced, reduced)
    b = _cross_overlap(reduced, original) @ original.weights
    mass = original.mass
    if mass <= 0:
        return GaussianMixture(np.zeros(n), reduced.means, reduced.covs)
    # Solve for the fractions y = w / mass with the objective scaled to O(1):
    # w^T A w - 2 b^T w = mass^2 s (y^T A' y - 2 b'^T y), A' = A / s, b' = b / (s mass).
    # SLSQP's stopping test on the objective is absolute (ftol), and the raw ISE of 4-D mixtures
    # with covariances of hundreds of m^2 is ~1e-6: unscaled, it stopped at the starting point.
    scale = float(np.max(np.diag(A)))
    As, bs = A / scale, b / (scale * mass)
    y0 = reduced.weights / reduced.mass if reduced.mass > 0 else np.full(n, 1.0 / n)
    res = minimize(
        lambda y: y @ As @ y - 2 * bs @ y,
        y0,
        jac=lambda y: 2 * (As @ y - bs),
        bounds=[(0.0, None)] * n,
        constraints=[{"type": "eq", "fun": lambda y: y.sum() - 1.0, "jac": lambda y: np.ones(n)}],
        method="SLSQP",
        options={"ftol": 1e-12, "maxiter": 200},
    )
    if not res.success or not np.all(np.isfinite(res.x)):
        return reduced
    return GaussianMixture(np.clip(res.x, 0.0, None) * mass, reduced.means, reduced.covs)


def _cross_overlap(g: GaussianMixture, h: GaussianMixture) -> np.ndarray:
    """``int N(x; m_i, P_i) N(x; n_j, Q_j) dx = N(m_i; n_j, P_i + Q_j)``: ``(len g, len h)``."""
    S = g.covs[:, None] + h.covs[None, :]
    inv, det = inv_det_spd(S)
    diff = g.means[:, None] - h.means[None, :]
    return np.exp(log_gaussian(diff, inv, det))


@dataclass(frozen=True)
class Reducer:
    """Level-1 reduction inside a filter: prune, merge, cap, optional ISE re-fit (§4)."""

    prune_threshold: float = 1e-5
    """Components lighter than this are dropped."""
    merge_threshold: float = 5.0
    """Merge distance threshold (``U`` for Vo–Ma, ``eta`` for the weighted rule)."""
    max_components: int = 100
    """Cap on the number of components kept (``Jmax``)."""
    merge_rule: str = "vo-ma"
    """``"vo-ma"`` (plain Mahalanobis) or ``"weighted"`` (seed 000 weighted distance)."""
    refit: bool = False
    """Re-fit the kept weights by minimising the integral squared error."""

    def __post_init__(self) -> None:
        if self.merge_rule not in MERGE_RULES:
            raise ValueError(f"unknown merge rule {self.merge_rule!r}; expected {MERGE_RULES}")

    def __call__(self, mix: GaussianMixture) -> GaussianMixture:
        return self._reduce(mix, False)[0]

    def with_sources(self, mix: GaussianMixture) -> tuple[GaussianMixture, np.ndarray]:
        """The reduction (the same numbers as calling the reducer) and, for each output
        component, the index into ``mix`` of the heaviest member of its merge group: ``(k,)``
        (pruning and capping drop rows; tag propagation, tracking.labels, reads this)."""
        out, src = self._reduce(mix, True)
        return out, src  # type: ignore[return-value]

    def _reduce(self, mix: GaussianMixture,
                sources: bool) -> tuple[GaussianMixture, np.ndarray | None]:
        """The reduction; with ``sources``, also each output's heaviest input member."""
        src = None
        if self.refit:
            kept = np.flatnonzero(mix.weights >= self.prune_threshold)
            pruned = mix.select(kept) if len(mix) else mix
            merged, msrc = merge_sources(pruned, self.merge_threshold, self.merge_rule)
            ci = cap_index(merged.weights, self.max_components)
            reduced = ise_refit(pruned, merged.select(ci) if len(ci) < len(merged) else merged)
            if sources:
                src = kept[msrc[ci]]
        else:  # prune then merge, with one gather: the kept indices in merge's order
            w = mix.weights
            above = w >= self.prune_threshold
            if np.logical_and.reduce(above) and len(w) > 1:  # nothing pruned (.all()): the
                # same order from fewer calls
                kept = order = (-w).argsort(kind="stable")
            else:
                kept = np.flatnonzero(above)
                order = kept[(-w[kept]).argsort(kind="stable")] if len(kept) > 1 else kept
            if len(kept) <= 1:
                reduced = mix.select(kept)
                src = kept
            else:
                reduced, rows = _merge_in_order(mix, order, self.merge_threshold,
                                                self.merge_rule)
                if sources:
                    src = order if rows is None else order[rows]
            if len(reduced) > self.max_components:
                ci = cap_index(reduced.weights, self.max_components)
                reduced = reduced.select(ci)
                if sources:
                    src = src[ci]
        P = reduced.covs
        return GaussianMixture.trusted(reduced.weights, reduced.means,
                                       0.5 * (P + P.swapaxes(-1, -2))), src  # symmetrise


__all__ = [
    "MERGE_RULES",
    "Reducer",
    "cap",
    "cap_index",
    "ise_refit",
    "keep_above",
    "merge",
    "merge_many",
    "merge_stacked",
    "merge_sources",
    "moment_match",
    "prune",
    "sweep_labels",
]
