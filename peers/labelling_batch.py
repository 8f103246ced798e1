"""The labels of many fused densities at once: :func:`peers.labelling.label_fused` of a peer
host's consensus rounds fused in one pass (:class:`peers.batching.FusionBatch`), stacked.

Why: one ``label_fused`` is ~60 small NumPy calls whatever its size, paid per peer and round
(about 18 % of an LMB peer-scan on the 50-peer twin, docs/labelled-tracking.md "50 peers:
labelled and watched"). Here the problems' input tracks, their (fused row, track) pairs and
every rule after the matching are computed once over all problems, each array carrying its
problem's index; only the SciPy assignments of inputs with a conflict stay one call each.
The results are each problem's own ``label_fused``'s to the bit (tests/test_labelling_batch.py
checks it on random problems): the same element-wise arithmetic on the same rows, sorts keyed
by the problem first. A change to ``label_fused``'s rule must be made here too (that test
then fails until it is).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.peers.label_support import LabelSupport
from sensornet.peers.labelling import (
    FRESH_BASE,
    LABEL_GATE,
    FusedLabels,
    kept_first,
    label_fused,
    next_labels,
)
from sensornet.tracking.label_keys import keys_equal, keys_isin
from sensornet.tracking.label_matching import RELEASE
from sensornet.tracking.labels import LabelMatch, as_labels, label_keys, precedes
from sensornet.tracking.mixture import GaussianMixture

_PKEY = np.dtype([("p", "<i8"), ("origin", "<i8"), ("birth_scan", "<i8"), ("index", "<i8")])


@dataclass(frozen=True)
class LabelProblem:
    """The arguments of one :func:`peers.labelling.label_fused` call (same names)."""

    fused: GaussianMixture
    inputs: Sequence[tuple[GaussianMixture, np.ndarray | None]]
    origin: int
    k: int
    fresh_start: int = 0
    gate: float = LABEL_GATE
    bump: np.ndarray | None = None
    copies: bool = False
    support: LabelSupport | None = None
    fallback: bool = False
    keep: np.ndarray | None = None
    settle: int = 1

    def alone(self) -> FusedLabels:
        """This problem's own :func:`label_fused`."""
        return label_fused(self.fused, self.inputs, self.origin, self.k, self.fresh_start,
                           self.gate, self.bump, self.copies, self.support, self.fallback,
                           self.keep, self.settle)


def _pkeys(prob: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """``(n,)`` sortable, ``np.isin``-able keys of (problem, label) rows."""
    a = np.empty((len(labels), 4), dtype=np.int64)
    a[:, 0] = prob
    a[:, 1:] = labels
    return a.view(_PKEY).reshape(-1)


def _tracks(problems: Sequence[LabelProblem]):
    """:func:`peers.labelling._all_tracks` of every problem at once: labels ``(T, 3)``, means,
    covariances, the input index ``src (T,)`` within its problem and the problem ``(T,)``,
    plus ``g (T,)`` the input's index over all problems (the matching's blocks); grouped by
    problem, then input, then label (heaviest row first), as each problem's own."""
    use = []
    for p, pr in enumerate(problems):
        for i, (mix, lab) in enumerate(pr.inputs):
            if lab is not None:
                lab = np.asarray(lab)
                if 0 < len(lab) <= len(mix):
                    use.append((p, i, mix, lab))
    if not use:
        z = np.zeros(0, dtype=np.int64)
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 0)), np.zeros((0, 0, 0)), z, z, z
    cnt = [len(lab) for *_, lab in use]
    lab = np.concatenate([lab for *_, lab in use]).astype(np.int64, copy=False)
    w = np.concatenate([mix.weights[:c] for (_, _, mix, _), c in zip(use, cnt, strict=True)])
    g = np.repeat(np.arange(len(use)), cnt)
    order = np.lexsort((-w, lab[:, 2], lab[:, 1], lab[:, 0], g))
    key = np.column_stack((g, lab))[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = (key[1:] != key[:-1]).any(axis=1)
    rows = order[first]
    means = np.concatenate([mix.means[:c] for (_, _, mix, _), c in zip(use, cnt, strict=True)])
    covs = np.concatenate([mix.covs[:c] for (_, _, mix, _), c in zip(use, cnt, strict=True)])
    g = g[rows]
    src = np.array([i for _, i, _, _ in use], dtype=np.int64)[g]
    prob = np.array([p for p, *_ in use], dtype=np.int64)[g]
    return lab[rows], means[rows], covs[rows], src, prob, g


def _pairs(Fm, FP, n, f_off, Tm, TP, T_cnt, t_off, Tg, gate):
    """:func:`peers.labelling._pairs` of every problem at once, on the (fused row, track)
    pairs of the same problem only (each problem's ``(n_p, T_p)`` block, row-major, one
    after another). Returns the matched pairs' global fused rows and tracks, ordered by
    problem, input, row."""
    c = n * T_cnt
    P = int(c.sum())
    if P == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z
    cs = np.cumsum(c) - c
    pp = np.repeat(np.arange(len(n)), c)
    q = np.arange(P) - cs[pp]
    Tp = T_cnt[pp]
    fi = f_off[pp] + q // Tp
    ti = t_off[pp] + q % Tp
    diff = Fm[fi] - Tm[ti]
    trace = np.trace(FP, axis1=1, axis2=2)[fi] + np.trace(TP, axis1=1, axis2=2)[ti]
    gp = gate[pp]
    near = np.einsum("pi,pi->p", diff, diff) <= gp * trace
    cost = np.full(P, np.inf)
    ii = np.flatnonzero(near)
    dn = diff[ii]
    cost[ii] = np.einsum("pi,pi->p", dn, np.linalg.solve(FP[fi[ii]] + TP[ti[ii]],
                                                       dn[..., None])[..., 0])
    inside = cost <= gp
    blk = Tg[ti]
    # the pairs of one fused row and one input are a run (tracks are grouped by input)
    runs = np.flatnonzero(np.r_[True, (fi[1:] != fi[:-1]) | (blk[1:] != blk[:-1])])
    deg = np.add.reduceat(inside.astype(np.int64), runs)
    row_deg = np.repeat(deg, np.diff(np.r_[runs, P]))
    col_deg = np.bincount(ti[inside], minlength=len(Tm))
    alone = inside & (row_deg == 1) & (col_deg[ti] == 1) & (cost < gp)
    conflict = np.flatnonzero(np.bincount(blk[inside & ~alone], minlength=int(Tg.max()) + 1))
    kept = alone
    if len(conflict):
        starts = np.flatnonzero(np.r_[True, Tg[1:] != Tg[:-1]])  # each input's first track
        ends = np.r_[starts[1:], len(Tg)]
        at = np.full(int(Tg.max()) + 1, -1)
        at[Tg[starts]] = np.arange(len(starts))
        prob_t = np.repeat(np.arange(len(n)), T_cnt)
        for b in conflict:  # per input with a conflict: its own assignment
            lo, hi = starts[at[b]], ends[at[b]]
            p = prob_t[lo]
            block = cost[cs[p]:cs[p] + c[p]].reshape(n[p], T_cnt[p])
            a, z = lo - t_off[p], hi - t_off[p]
            r, col = linear_sum_assignment(np.minimum(block[:, a:z], gate[p]))
            ok = block[r, a + col] <= gate[p]
            sub = kept[cs[p]:cs[p] + c[p]].reshape(n[p], T_cnt[p])  # a view of kept
            sub[:, a:z] = False
            sub[r[ok], a + col[ok]] = True
    k = np.flatnonzero(kept)
    by = np.lexsort((fi[k], blk[k]))
    return fi[k][by], ti[k][by]


def _distance2(Fm: np.ndarray, FP: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`peers.labelling._distance2` on the stacked fused rows."""
    dm = Fm[a] - Fm[b]
    return np.einsum("pi,pi->p", dm, np.linalg.solve(FP[a] + FP[b], dm[..., None])[..., 0])


def label_fused_many(problems: Sequence[LabelProblem]) -> list[FusedLabels]:
    """:func:`peers.labelling.label_fused` of each problem, computed together (module
    docstring): the same :class:`FusedLabels` as each problem's own call, in order."""
    out: list[FusedLabels | None] = [None] * len(problems)
    live = []
    for b, pr in enumerate(problems):
        if len(pr.fused):
            live.append(b)
        else:
            out[b] = pr.alone()
    if not live:
        return out
    probs = [problems[b] for b in live]
    B = len(probs)
    n = np.array([len(pr.fused) for pr in probs], dtype=np.int64)
    f_off = np.cumsum(n) - n
    N = int(n.sum())
    Fm = np.concatenate([pr.fused.means for pr in probs])
    FP = np.concatenate([pr.fused.covs for pr in probs])
    Fw = np.concatenate([pr.fused.weights for pr in probs])
    prob_f = np.repeat(np.arange(B), n)
    gate = np.array([pr.gate for pr in probs], dtype=float)
    kk = np.array([pr.k for pr in probs], dtype=np.int64)
    copies = np.array([bool(pr.copies) for pr in probs])
    t_lab, t_m, t_P, t_src, t_prob, t_g = _tracks(probs)
    T_cnt = np.bincount(t_prob, minlength=B)
    t_off = np.cumsum(T_cnt) - T_cnt
    J, t = _pairs(Fm, FP, n, f_off, t_m, t_P, T_cnt, t_off, t_g, gate)
    labels = np.empty((N, 3), dtype=np.int64)
    won = np.zeros(N, dtype=bool)
    keeper = np.arange(N)
    L, S = t_lab[t], t_src[t]
    pl = prob_f[J]  # each pair's problem (pairs are grouped by problem)
    edges = np.searchsorted(pl, np.arange(B + 1))
    if len(J):
        held = np.zeros(len(L), dtype=np.int64)
        kept = np.zeros(len(L), dtype=np.int64)
        for p, pr in enumerate(probs):
            e0, e1 = edges[p], edges[p + 1]
            if pr.support is not None and e1 > e0:
                held[e0:e1] = pr.support.counts(L[e0:e1])
            if pr.keep is not None and e1 > e0:
                kept[e0:e1] = kept_first(J[e0:e1] - f_off[p], L[e0:e1], int(n[p]), pr.keep,
                                         np.full(e1 - e0, pr.settle))
        order = np.lexsort((L[:, 2], L[:, 0], -held, L[:, 1], kept, J))  # per row, winner first
        Js = J[order]
        first = np.ones(len(Js), dtype=bool)
        first[1:] = Js[1:] != Js[:-1]
        labels[Js[first]] = L[order[first]]
        won[Js[first]] = True
        # a label won by two rows of one problem: the heavier keeps it
        wrows = np.flatnonzero(won)
        keys = label_keys(labels[wrows])
        wp = prob_f[wrows]
        by = np.lexsort((-Fw[wrows], keys, wp))
        dup = np.zeros(len(by), dtype=bool)
        dup[1:] = keys_equal(keys[by[1:]], keys[by[:-1]]) & (wp[by[1:]] == wp[by[:-1]])
        won[wrows[by[dup]]] = False
        keeper[wrows[by]] = wrows[by[np.maximum.accumulate(np.where(dup, 0, np.arange(len(by))))]]
        bumped = [(p, as_labels(pr.bump)) for p, pr in enumerate(probs)
                  if pr.bump is not None and len(pr.bump)]
        if bumped:
            labels = _corroborated(labels, won, J, S, prob_f, kk, bumped)
        won0 = won
        fall = np.array([bool(pr.fallback) for pr in probs])
        if fall.any():
            pend = np.zeros(N, dtype=bool)
            pend[J] = True
            pend &= ~won & fall[prob_f]
            r = np.flatnonzero(pend & copies[prob_f])
            if len(r):
                pend[r[_distance2(Fm, FP, r, keeper[r]) <= gate[prob_f[r]]]] = False
            if pend.any():
                labels, won = next_labels(labels, won, pend, Js, L[order], Fw, prob_f)
        own = (S == 0) & won0[J]
        own_lab, win = L[own], labels[J[own]]
        change = ~keys_equal(label_keys(own_lab), label_keys(win))
        cost = np.zeros(int(change.sum()))
        o, w = own_lab[change], win[change]
        po = pl[own][change]
        has_support = np.array([pr.support is not None for pr in probs])
        cost[has_support[po] & (o[:, 1] == w[:, 1]) & ~precedes(w, o)] = RELEASE
    lost = np.flatnonzero(~won)
    lp = prob_f[lost]
    fresh = np.bincount(lp, minlength=B)
    start = np.array([pr.fresh_start for pr in probs], dtype=np.int64)
    labels[lost, 0] = np.array([pr.origin for pr in probs], dtype=np.int64)[lp]
    labels[lost, 1] = kk[lp]
    labels[lost, 2] = FRESH_BASE + start[lp] + (np.arange(len(lost)) - (np.cumsum(fresh)
                                                                        - fresh)[lp])
    copy = np.zeros(N, dtype=bool)
    rel = np.zeros(len(J), dtype=bool)
    if len(J):
        # release_rows: an own track paired with a row that lost its label
        rel = (S == 0) & ~won0[J]
        r = np.flatnonzero(rel & copies[pl])
        if len(r):
            rel[r[_distance2(Fm, FP, J[r], keeper[J[r]]) <= gate[pl[r]]]] = False
        # copy_rows (problems with copies)
        rows = np.unique(J[~won0[J] & copies[pl]])
        if len(rows):
            copy[rows[_distance2(Fm, FP, rows, keeper[rows]) <= gate[prob_f[rows]]]] = True
    none = np.zeros((0, 3), dtype=np.int64)
    ce = np.searchsorted(po, np.arange(B + 1)) if len(J) else None
    re = np.searchsorted(pl[rel], np.arange(B + 1)) if len(J) else None
    Lr, Wr = (L[rel], labels[J[rel]]) if len(J) else (none, none)
    for p, b in enumerate(live):
        rows = slice(f_off[p], f_off[p] + n[p])
        if edges[p + 1] > edges[p]:  # the problem has pairs
            c0, c1, r0, r1 = ce[p], ce[p + 1], re[p], re[p + 1]
            if r1 > r0:
                match = LabelMatch(np.concatenate([o[c0:c1], Lr[r0:r1]]),
                                   np.concatenate([w[c0:c1], Wr[r0:r1]]),
                                   np.concatenate([cost[c0:c1], np.full(r1 - r0, RELEASE)]))
            else:
                match = LabelMatch(o[c0:c1], w[c0:c1], cost[c0:c1])
        else:
            match = LabelMatch(none, none.copy(), np.zeros(0))
        out[b] = FusedLabels(labels[rows], match, int(fresh[p]),
                             copy[rows] if copies[p] else None)
    return out


def _corroborated(labels, won, J, S, prob_f, kk, bumped):
    """:func:`peers.labelling.corroborated` of every problem with stamps (``bumped``:
    ``[(problem, bump (b, 3))]``), keyed by problem."""
    other = np.zeros(len(labels), dtype=bool)
    other[J[S != 0]] = True
    has = np.zeros(int(prob_f.max()) + 1, dtype=bool)
    has[[p for p, _ in bumped]] = True
    rows = np.flatnonzero(won & ~other & has[prob_f])
    bk = np.concatenate([_pkeys(np.full(len(b), p), b) for p, b in bumped])
    rp = prob_f[rows]
    hit = keys_isin(_pkeys(rp, labels[rows]), bk) & (labels[rows, 1] == kk[rp])
    rows, rp = rows[hit], rp[hit]
    if not len(rows):
        return labels
    moved = labels[rows].copy()
    moved[:, 1] = kk[rp] + 1
    ok = ~keys_isin(_pkeys(rp, moved), _pkeys(prob_f[won], labels[won]))
    labels = labels.copy()
    labels[rows[ok]] = moved[ok]
    return labels


__all__ = ["LabelProblem", "label_fused_many"]
