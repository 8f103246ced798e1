"""Many independent hybrid fusions (and their reductions) as one stacked array computation.

A peer host runs the consensus rounds of many peers; each round's fusion
(:func:`tracking.fusion_rules.hybrid_fuse`, then the level-1 :class:`~tracking.reduction.Reducer`)
has a handful of components per input, so one fusion costs its ~60 NumPy calls' overhead, not
arithmetic. Here ``P`` fusion problems are laid side by side: every component of every
problem in one stack (its problem's id beside it), the sweep's close pairs of every problem
in one test, the cells and groups of every problem in one ``reduceat``, one inverse per stack.
Problems never mix: a pair, a cell and a group lie inside one problem (global indices are
offset per problem, sort keys lead with the problem), so problem ``p``'s result is what
:func:`hybrid_fuse` and the reducer give for it alone: the same equations in the same order
of summation (equal to round-off; ``tests/test_fusion_batch.py`` checks it on random mixtures).

What the stacked path does not cover is handed to the per-problem functions unchanged: a
problem whose union or fused mixture has more components than the sweep's every-pair test
covers (:data:`tracking.reduction._ALL_PAIRS_UP_TO`), a reducer with the ISE re-fit, a
non-finite inverse. Arrays: ``N`` components of all problems, ``(N,)``, ``(N, d)``,
``(N, d, d)``; ``d`` the state dimension, the same for every problem of one call.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from sensornet.tracking.fusion import check_weights
from sensornet.tracking.fusion_rules import HYBRID_GATE, hybrid_fuse
from sensornet.tracking.gaussian import c_einsum, inv_spd, symmetrise
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import (
    _ALL_PAIRS_UP_TO,
    Reducer,
    _greedy_groups,
    _moment_match_groups,
    _upper_pairs,
    cap,
    cap_index,
)

try:  # the ufunc np.linalg.inv calls (NumPy 1.x and 2.x)
    from numpy.linalg import _umath_linalg as _lapack
except ImportError:  # pragma: no cover
    _lapack = None

Problem = tuple[Sequence[GaussianMixture], Sequence[float]]
"""One fusion: the densities ``[own, *neighbours]`` and their weights (sum 1)."""


def hybrid_fuse_many(problems: Sequence[Problem], reduce: Reducer | None = None,
                     gate: float = HYBRID_GATE) -> list[GaussianMixture]:
    """``[hybrid_fuse(D, w, reduce, gate) for D, w in problems]``, computed stacked.

    Bad input raises as :func:`hybrid_fuse` would, for the first problem that has it.
    """
    checked = [check_weights(D, w) for D, w in problems]
    out: list[GaussianMixture | None] = [None] * len(checked)
    if not checked:
        return []
    d = checked[0][0][0].dim
    # per problem, the inputs it uses (weight > 0 and a component at least)
    comps, lens, oms, srcs, sizes, stacked = [], [], [], [], [], []
    for p, (dens, weights) in enumerate(checked):
        used = [(D, w, n) for D, w in zip(dens, weights, strict=True)
                if w > 0.0 and (n := D.weights.shape[0])]
        n_union = sum(u[2] for u in used)
        if n_union > _ALL_PAIRS_UP_TO or any(D.means.shape[1] != d for D in dens):
            out[p] = hybrid_fuse(dens, weights, reduce, gate)  # the per-problem path
            continue
        if not used:
            out[p] = GaussianMixture.empty(d)
            continue
        stacked.append(p)
        sizes.append(n_union)
        for i, (D, w, n) in enumerate(used):
            comps.append(D)
            lens.append(n)
            oms.append(w)
            srcs.append(i)
    if not stacked:
        return out  # type: ignore[return-value]
    lens_a, sizes_a = np.array(lens), np.array(sizes)
    fused = _hybrid_stacked(comps, np.repeat(np.array(srcs, dtype=np.intp), lens_a),
                            np.repeat(np.array(oms), lens_a),
                            np.repeat(np.arange(len(stacked)), sizes_a), sizes_a, gate)
    if fused is None:  # a non-finite inverse: each on its own, with its own errors
        for p in stacked:
            out[p] = hybrid_fuse(*checked[p], reduce, gate)
        return out  # type: ignore[return-value]
    w, m, P, prob = fused
    if reduce is not None:
        parts = reduce_many(reduce, w, m, P, prob, len(stacked))
    else:
        parts = _split(w, m, P, prob, len(stacked))
    for p, mix in zip(stacked, parts, strict=True):
        out[p] = mix
    return out  # type: ignore[return-value]


def _hybrid_stacked(comps: list[GaussianMixture], src: np.ndarray, om: np.ndarray,
                    prob: np.ndarray, sizes: np.ndarray, gate: float):
    """The hybrid rule of every stacked problem: ``(w, m, P, prob)`` of the fused components
    (problem-major, each problem's groups in its sweep order), or None if an inverse failed.

    ``comps``: the used inputs of every problem in order; ``src (N,)`` each component's input
    index in its problem, ``om (N,)`` that input's weight, ``prob (N,)`` its problem,
    ``sizes (P,)`` the components per problem.
    """
    own_w = np.concatenate([D.weights for D in comps])
    m_u = np.concatenate([D.means for D in comps])
    P_u = np.concatenate([D.covs for D in comps])
    uw = own_w * om  # the AA's union weights
    N = len(uw)
    Yu = _inv_exact(P_u)
    if Yu is None:
        return None
    sym = (P_u == P_u.swapaxes(1, 2)).all(axis=(1, 2))  # exactly symmetric per component
    labels = _sweep_labels_stacked(uw, m_u, Yu, prob, sizes, gate)
    # (group, input) cells: sorted by group (problem-major), then input, stably
    n_in = int(src.max()) + 1
    key = labels * n_in + src
    order = np.argsort(key, kind="stable")
    key_s = key[order]
    starts = np.flatnonzero(np.concatenate(([True], key_s[1:] != key_s[:-1])))
    cells = key_s[starts]
    cnt = np.diff(np.append(starts, N))
    cell_of = np.repeat(np.arange(len(cells)), cnt)
    w, m, P = own_w[order], m_u[order], P_u[order]
    W = np.add.reduceat(w, starts)
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero-mass cell: plain mean
        wn = np.where(W[cell_of] > 0, w / W[cell_of], 1.0 / cnt[cell_of])
    mean = np.add.reduceat(wn[:, None] * m, starts)  # moment match per cell (one member: itself)
    diff = m - mean[cell_of]
    cov = np.add.reduceat(wn[:, None, None] * (P + diff[:, :, None] * diff[:, None, :]), starts)
    # a cell of one exactly symmetric component: its inverse is the union's (hybrid_fuse's
    # shortcut; the same numbers as inverting it again); the others' inverses computed
    first = order[starts]
    reuse = (cnt == 1) & sym[first]
    Y = np.empty_like(cov)
    Y[reuse] = Yu[first[reuse]]
    if not reuse.all():
        Yo = _inv_exact(symmetrise(cov[~reuse]))
        if Yo is None:
            return None
        Y[~reuse] = Yo
    g, i = np.divmod(cells, n_in)
    om_c = om[first]  # omega of each cell's input
    gstarts = np.flatnonzero(np.concatenate(([True], g[1:] != g[:-1])))
    present = np.add.reduceat(om_c, gstarts)  # sum of omega over the inputs in each group
    om_t = om_c / present[np.repeat(np.arange(len(gstarts)), np.diff(np.append(gstarts,
                                                                                 len(g))))]
    Ysum = np.add.reduceat(om_t[:, None, None] * Y, gstarts)
    hsum = np.add.reduceat(om_t[:, None] * c_einsum("cij,cj->ci", Y, mean), gstarts)
    Pf = _inv_exact(Ysum)
    if Pf is None:
        return None
    mf = c_einsum("gij,gj->gi", Pf, hsum)
    wf = np.bincount(g, weights=om_c * W, minlength=len(gstarts))
    return wf, mf, Pf, prob[first[gstarts]]


def _sweep_labels_stacked(w: np.ndarray, m: np.ndarray, Y: np.ndarray, prob: np.ndarray,
                          sizes: np.ndarray, gate: float) -> np.ndarray:
    """:func:`tracking.reduction.sweep_labels` (rule vo-ma, every pair tested, inverses
    ``Y``) of every problem at once: ``(N,)`` labels, problem ``p``'s groups numbered after
    those of the problems before it, each problem's in its own sweep order."""
    N = len(w)
    order = np.lexsort((-w, prob))  # by problem, then decreasing weight, ties by index
    ci, cj = _pairs(sizes)
    root = np.arange(N)
    if ci.size:
        oi, oj = order[ci], order[cj]
        diff = m[oi] - m[oj]
        close = c_einsum("gi,gij,gj->g", diff, Y[oi], diff) <= gate
        ci, cj = ci[close], cj[close]
    if ci.size:
        centres, members = _greedy_groups(ci, cj)
        root[np.concatenate(members)] = np.repeat(centres, [len(g) for g in members])
    rank = np.cumsum(root == np.arange(N)) - 1
    labels = np.empty(N, dtype=np.intp)
    labels[order] = rank[root]
    return labels


def _pairs(sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair ``(i, j)``, ``j < i``, inside each block of ``sizes`` consecutive positions,
    sorted by block, then ``(j, i)`` (as :func:`tracking.reduction._upper_pairs` per block)."""
    offsets = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    js, is_ = [], []
    for n, o in zip(sizes.tolist(), offsets.tolist(), strict=True):
        if n > 1:
            j, i = _upper_pairs(n)
            js.append(j + o)
            is_.append(i + o)
    if not js:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    return np.concatenate(is_), np.concatenate(js)


def reduce_many(reduce: Reducer, w: np.ndarray, m: np.ndarray, P: np.ndarray,
                prob: np.ndarray, n_problems: int, sources: bool = False) -> list:
    """``reduce`` of each problem's mixture (the components of problem ``p`` are those with
    ``prob == p``, ``prob`` non-decreasing), stacked as :meth:`Reducer.__call__` without the
    ISE re-fit: prune, merge (each problem's sweep in its order of decreasing weight), cap.

    ``sources``: each problem's ``(mixture, src)`` instead, ``src (k,)`` for each output
    component the index (inside its problem's block) of the heaviest member of its merge
    group, as :meth:`Reducer.with_sources` (the same numbers; tag propagation reads it)."""
    own = reduce.with_sources if sources else reduce
    if reduce.refit:
        return [own(mix) for mix in _split(w, m, P, prob, n_problems)]
    keep = np.flatnonzero(w >= reduce.prune_threshold)
    kp = prob[keep]
    counts = np.bincount(kp, minlength=n_problems)
    big = counts > _ALL_PAIRS_UP_TO
    if big.any():  # beyond the every-pair test: those on their own, the rest stacked
        small = ~big
        sel = small[prob]
        rest = reduce_many(reduce, w[sel], m[sel], P[sel],
                           np.cumsum(small)[prob[sel]] - 1, int(small.sum()), sources)
        it, parts = iter(rest), _split(w, m, P, prob, n_problems)
        return [own(parts[p]) if big[p] else next(it) for p in range(n_problems)]
    order = keep[np.lexsort((-w[keep], kp))]  # kept, by problem, heaviest first
    wo, mo, Po, po = w[order], m[order], P[order], prob[order]
    src = order  # each row's index into the stacked input
    ci, cj = _pairs(counts)
    if ci.size:
        inv = _inv_exact(Po)
        if inv is None:
            return [own(mix) for mix in _split(w, m, P, prob, n_problems)]
        diff = mo[ci] - mo[cj]
        if reduce.merge_rule == "vo-ma":
            close = c_einsum("gi,gij,gj->g", diff, inv[ci], diff) <= reduce.merge_threshold
        else:
            d2 = np.einsum("gi,gij,gj->g", diff, inv[cj], diff)
            close = (wo[ci] * wo[cj] / (wo[ci] + wo[cj])) * d2 < reduce.merge_threshold
        ci, cj = ci[close], cj[close]
    if ci.size:
        centres, members = _greedy_groups(ci, cj)
        out_w, out_m, out_P = wo.copy(), mo.copy(), Po.copy()
        _moment_match_groups(wo, mo, Po, centres, members, out_w, out_m, out_P)
        kept = np.ones(len(wo), dtype=bool)
        kept[np.concatenate(members)] = False
        wo, mo, Po, po, src = out_w[kept], out_m[kept], out_P[kept], po[kept], src[kept]
    Po = 0.5 * (Po + Po.swapaxes(-1, -2))  # symmetrise
    out = _split(wo, mo, Po, po, n_problems)
    if not sources:
        return [cap(mix, reduce.max_components) for mix in out]
    starts = np.searchsorted(prob, np.arange(n_problems))  # each problem's first input row
    bounds = np.searchsorted(po, np.arange(n_problems + 1)).tolist()
    res = []
    for p, (mix, a, b) in enumerate(zip(out, bounds[:-1], bounds[1:], strict=True)):
        s = src[a:b] - starts[p]
        if len(mix) > reduce.max_components:
            ci = cap_index(mix.weights, reduce.max_components)
            mix, s = mix.select(ci), s[ci]
        res.append((mix, s))
    return res


def _split(w, m, P, prob, n_problems: int) -> list[GaussianMixture]:
    """The stacked components back into one mixture per problem (``prob`` non-decreasing)."""
    bounds = np.searchsorted(prob, np.arange(n_problems + 1)).tolist()
    return [GaussianMixture.trusted(w[a:b], m[a:b], P[a:b])
            for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _inv_exact(P: np.ndarray) -> np.ndarray | None:
    """Symmetrised inverses of a stack, each by the LAPACK call :func:`inv_spd` uses for the
    small per-problem stacks (so each matrix's inverse is the one the per-problem path gets,
    however many are stacked); None if one is singular or not finite."""
    if len(P) == 0:
        return P.copy()
    if _lapack is None or P.dtype != np.float64 or P.shape[-1] in (1, 2):
        inv = inv_spd(P)  # the closed forms per matrix (1x1, 2x2): stack-independent too
        return inv if np.isfinite(inv).all() else None
    with np.errstate(all="ignore"):
        inv = _lapack.inv(P, signature="d->d")
    if not np.isfinite(inv).all():
        return None
    return 0.5 * (inv + inv.swapaxes(-1, -2))


__all__ = ["hybrid_fuse_many", "reduce_many"]
