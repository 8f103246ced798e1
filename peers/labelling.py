"""Labels of a fused density: one network-wide id per target (issue 33, item 3).

After each consensus round a peer gives every component of its fused mixture a label taken
from the labelled inputs it fused (its own density and the neighbours' estimates that carry
labels): per input, the fused components are paired with that input's tracks as
:func:`tracking.labels.match_labels` pairs them (SciPy ``linear_sum_assignment`` on the
Mahalanobis distance ``(m_f - m_i)^T (P_f + P_i)^-1 (m_f - m_i)``, gated at
:data:`LABEL_GATE`; the distances of all inputs in one batch, the solver only for an input
with a conflict: :func:`_pairs`), and a
fused component takes the network rule's winner among the labels it was paired with (the
earliest birth, then the lowest origin: :func:`tracking.labels.precedes`). A fused component
paired with nothing gets a fresh label of this peer. Labels never add, drop or move a
component: the fused numbers are the fuser's (a miss at one input still cannot erase a target
under the hybrid rule). The peer's own estimator then takes each winner for the own label it
beat (:meth:`peers.estimators.GmphdEstimator.relabel`), so the earliest label spreads over the
graph hop by hop, and peers converge on one id per target (our reading of the label-matching
approach of Wang et al. 2016 and Fantacci et al. 2018's label-mismatch problem, with the
deterministic rule of Li 2022's label-consistent AA fusion).

Inputs without labels (older peers, other kinds, estimates a receiver had to reduce) are
fused as before and simply offer no labels. Arrays: ``n`` fused components, labels ``(n, 3)``
int64 ``(origin, birth_scan, index)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path
from sensornet.peers.label_support import LabelSupport
from sensornet.tracking.label_keys import keys_equal, keys_isin
from sensornet.tracking.label_matching import RELEASE
from sensornet.tracking.labels import LabelMatch, as_labels, label_keys, new_labels, precedes
from sensornet.tracking.mixture import GaussianMixture

LABEL_GATE = 26.0
"""Squared Mahalanobis gate of a (fused component, input track) pair: the hybrid rule's
grouping gate (tracking.fusion_rules.HYBRID_GATE), so every input component the rule fused
into a component can pass it (the pair's distance uses the sum of both covariances)."""
FRESH_BASE = 1 << 32
"""Index offset of the labels a fusion creates (``(origin, k, FRESH_BASE + c)``), apart from
the filter's births and splits of the same scan (small indices)."""


SETTLE_MARGIN = 2
"""Scans added to a peer's eccentricity (beyond one hop) in :func:`settle_scans`: a label is
relayed only by peers whose own tracks carry it, and at Pd 0.9 a relay's track is sometimes
unpublished for a scan, so a label can take more than one scan per hop. Chosen on training
runs 100-101 of the labelled study (docs/labelled-tracking.md): the smallest margin with no
confirmed identity switch at any peer, both kinds, Pd 0.99 and 0.9, 20 peers of degree 4."""


def settle_scans(adjacency: np.ndarray, i: int, margin: int = SETTLE_MARGIN) -> int:
    """Scans a label must be old before peer ``i`` confirms it (tracking.labels.Confirmation
    ``settle``): the peer's eccentricity ``e`` in hops on the graph ``adjacency (n, n)``
    (nonzero = link), plus ``margin`` if ``e > 1``. An earlier label published anywhere
    reaches the peer within ``e`` scans when each hop relays it at once (the margin covers
    relays that skip a scan; a peer linked to every other has no relay), so its confirmed ids
    do not switch to a late arrival. Peers out of reach do not count (they cannot send a
    label); a peer without links: 0."""
    hops = shortest_path(csr_matrix(np.asarray(adjacency) != 0), unweighted=True, indices=i)
    reach = hops[np.isfinite(hops)]
    ecc = int(reach.max()) if reach.size > 1 else 0
    return ecc + margin if ecc > 1 else ecc


def origin_of(names: Sequence[str], name: str) -> int:
    """A peer's label origin: its index in the network's sensor names sorted (by code
    point), the same in every process that reads the same scenario; ValueError if absent."""
    ordered = sorted(names)
    if name not in ordered:
        raise ValueError(f"no sensor named {name!r} among {', '.join(ordered)}")
    return ordered.index(name)


def input_tracks(mix: GaussianMixture, labels: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One row per label of a labelled density (the heaviest component carrying it):
    ``labels (t, 3)``, ``means (t, d)``, ``covs (t, d, d)``. ``labels`` may label only the
    first rows of ``mix`` (a prediction appends births): the rest are not tracks."""
    n = len(labels)
    w = mix.weights[:n]
    keys = label_keys(labels)
    order = np.lexsort((-w, keys))  # by label, heaviest first
    first = np.ones(n, dtype=bool)
    first[1:] = keys[order[1:]] != keys[order[:-1]]
    rows = order[first]
    return labels[rows], mix.means[rows], mix.covs[rows]


@dataclass(frozen=True)
class FusedLabels:
    """What :func:`label_fused` gives: ``labels (n, 3)`` of the fused components, and
    ``own`` (own label -> the winner of the fused component it was paired with, for the own
    estimator's :meth:`relabel`; only pairs whose winner differs)."""

    labels: np.ndarray
    own: LabelMatch
    fresh: int
    """Fresh labels created (fused components paired with no input)."""
    copies: np.ndarray | None = None
    """``(n,)`` bool with ``copies`` (AA), else None: the rows that lost their label to a
    heavier row within the gate, the same target's copies (:func:`copy_rows`); their fresh
    label is no young target's (tracking.support.pooled_weights ``skip``)."""


def _all_tracks(inputs: Sequence[tuple[GaussianMixture, np.ndarray]]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`input_tracks` of every labelled input at once: ``labels (T, 3)``, ``means (T,
    d)``, ``covs (T, d, d)`` and ``src (T,)`` (the input's index), grouped by input in input
    order and, within an input, in :func:`input_tracks`' order (by label). Inputs without
    labels, or whose labels outnumber their rows, give none."""
    use = [(i, mix, np.asarray(lab)) for i, (mix, lab) in enumerate(inputs)
           if lab is not None and 0 < len(lab) <= len(mix)]
    if not use:
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 0)), np.zeros((0, 0, 0)), \
            np.zeros(0, dtype=np.int64)
    lab = np.concatenate([lab for _, _, lab in use]).astype(np.int64, copy=False)
    w = np.concatenate([mix.weights[:len(la)] for _, mix, la in use])
    src = np.repeat([i for i, _, _ in use], [len(la) for _, _, la in use])
    order = np.lexsort((-w, lab[:, 2], lab[:, 1], lab[:, 0], src))  # by input, label; heaviest
    key = np.column_stack((src, lab))[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = (key[1:] != key[:-1]).any(axis=1)
    rows = order[first]
    means = np.concatenate([mix.means[:len(la)] for _, mix, la in use])
    covs = np.concatenate([mix.covs[:len(la)] for _, mix, la in use])
    return lab[rows], means[rows], covs[rows], src[rows]


def _pairs(fused: GaussianMixture, t_m: np.ndarray, t_P: np.ndarray, src: np.ndarray,
           gate: float) -> tuple[np.ndarray, np.ndarray]:
    """Per input, :func:`tracking.labels.match_labels` of the fused components with that input's
    tracks, all inputs in one computation: the squared Mahalanobis distances ``(m_f - m_t)^T
    (P_f + P_t)^-1 (m_f - m_t)`` of every (fused, track) pair at once (only pairs that can pass
    the gate are solved, by match_labels' trace bound), then SciPy ``linear_sum_assignment`` on
    an input's capped costs only where that input has a conflict. A pair inside the gate whose
    fused component has no other candidate in that input and whose track has no other
    candidate is in every optimal assignment (the assignment maximises the sum of ``gate - C``
    over the pairs it keeps), so an input whose pairs are all such needs no solver. Returns
    the matched pairs' fused rows and track indices ``(p,)``, ordered by input then row."""
    n, T = len(fused), len(t_m)
    diff = fused.means[:, None, :] - t_m[None, :, :]  # (n, T, d)
    trace = np.trace(fused.covs, axis1=1, axis2=2)[:, None] + np.trace(t_P, axis1=1, axis2=2)
    near = np.einsum("abi,abi->ab", diff, diff) <= gate * trace
    cost = np.full((n, T), np.inf)
    ii, jj = np.nonzero(near)
    dn = diff[ii, jj]
    cost[ii, jj] = np.einsum("pi,pi->p", dn, np.linalg.solve(fused.covs[ii] + t_P[jj],
                                                           dn[..., None])[..., 0])
    inside = cost <= gate
    starts = np.flatnonzero(np.r_[True, src[1:] != src[:-1]])  # the inputs' column blocks
    block = np.cumsum(np.r_[False, src[1:] != src[:-1]])  # (T,) block of each track
    row_deg = np.add.reduceat(inside, starts, axis=1)  # (n, B) candidates per fused row, input
    alone = inside & (row_deg[:, block] == 1) & (inside.sum(axis=0) == 1) & (cost < gate)
    conflict = np.logical_or.reduceat(inside & ~alone, starts, axis=1).any(axis=0)  # (B,)
    kept = alone
    for b in np.flatnonzero(conflict):  # per input with a conflict: its own assignment
        lo = starts[b]
        hi = starts[b + 1] if b + 1 < len(starts) else T
        r, c = linear_sum_assignment(np.minimum(cost[:, lo:hi], gate))
        ok = cost[r, lo + c] <= gate
        kept[:, lo:hi] = False
        kept[r[ok], lo + c[ok]] = True
    J, t = np.nonzero(kept)
    by = np.lexsort((J, block[t]))
    return J[by], t[by]


def label_fused(fused: GaussianMixture, inputs: Sequence[tuple[GaussianMixture, np.ndarray]],
                origin: int, k: int, fresh_start: int = 0,
                gate: float = LABEL_GATE, bump: np.ndarray | None = None,
                copies: bool = False, support: LabelSupport | None = None,
                fallback: bool = False, keep: np.ndarray | None = None,
                settle: int = 1) -> FusedLabels:
    """Labels of the fused components from the labelled ``inputs`` (``[(mixture, labels)]``,
    the own density first; a label array may cover only the first rows). Fresh labels are
    ``(origin, k, FRESH_BASE + fresh_start + i)``, in fused order. Two fused components that
    won one label: the heavier keeps it, the other takes a fresh one (two targets never share
    an id). The per-input matching is :func:`_pairs` (one batched cost computation).

    ``bump (b, 3)``: the own labels stamped at their first publication this scan (the
    estimator's ``fresh_stamps``). One that wins a fused component which no other input's track
    was paired with (uncorroborated: no neighbour holds the track) becomes ``(o, k + 1, i)``,
    for the fused component and, through ``own``, the own estimator (:func:`corroborated`).

    ``copies``: the fuser keeps every input's components at reduced weight (AA: Li 2022's
    ``sum_i omega_i D_i``, reduced), so a row that lost its label to a heavier row within
    ``gate`` of it is the same target's copy, not a second target: its own track is not released
    (:func:`release_rows`).

    ``support``: the holder masks of shared labels (:class:`peers.label_support.LabelSupport`);
    among labels of one scan the one more peers stamped wins (order ``(birth_scan, -holders,
    origin, index)``), and an own label that loses so to a later-ordered one is handed the
    winner as a release pair (:func:`tracking.label_matching.adopt_labels` takes only earlier
    labels otherwise).

    ``fallback``: a row that lost the label it won to a heavier row (and, with ``copies``, lies
    outside ``gate`` of it) takes the next label it was paired with in the same order that no
    row holds (:func:`next_labels`) instead of a fresh one; its own track is released to it.

    ``keep``: sorted :func:`tracking.labels.label_keys` of the labels this peer reported the
    scan before; a row paired with one of them does not take a label born ``settle`` scans or
    more before it (:func:`kept_first`: not the same target's label on its way, which would
    have arrived by then, but another target's track passing by)."""
    n = len(fused)
    none = np.zeros((0, 3), dtype=np.int64)
    if n == 0:
        return FusedLabels(none, LabelMatch(none, none.copy(), np.zeros(0)), 0,
                           np.zeros(0, dtype=bool) if copies else None)
    t_lab, t_m, t_P, t_src = _all_tracks(inputs)
    labels = np.empty((n, 3), dtype=np.int64)
    won = np.zeros(n, dtype=bool)
    copy = np.zeros(n, dtype=bool) if copies else None
    J = np.zeros(0, dtype=np.int64)
    if len(t_lab):
        J, t = _pairs(fused, t_m, t_P, t_src, gate)
    if len(J):
        L, S = t_lab[t], t_src[t]
        held = np.zeros(len(L), dtype=np.int64) if support is None else support.counts(L)
        kept = kept_first(J, L, n, keep, np.full(len(L), settle))
        order = np.lexsort((L[:, 2], L[:, 0], -held, L[:, 1], kept, J))  # per row, winner first
        Js = J[order]
        first = np.ones(len(Js), dtype=bool)
        first[1:] = Js[1:] != Js[:-1]
        labels[Js[first]] = L[order[first]]
        won[Js[first]] = True
        # a label won by two rows: the heavier keeps it
        wrows = np.flatnonzero(won)
        keys = label_keys(labels[wrows])
        by = np.lexsort((-fused.weights[wrows], keys))
        dup = np.zeros(len(by), dtype=bool)
        dup[1:] = keys_equal(keys[by[1:]], keys[by[:-1]])
        won[wrows[by[dup]]] = False
        keeper = np.arange(n)  # the row that kept each won label (a lost row: its heavier row)
        keeper[wrows[by]] = wrows[by[np.maximum.accumulate(np.where(dup, 0, np.arange(len(by))))]]
        if bump is not None and len(bump):
            labels = corroborated(labels, won, J, S, bump, k)
        won0 = won
        if fallback:
            pend = np.zeros(n, dtype=bool)
            pend[J] = True
            pend &= ~won
            r = np.flatnonzero(pend)
            if copies and len(r):
                pend[r[_distance2(fused, r, keeper[r]) <= gate]] = False
            if pend.any():
                labels, won = next_labels(labels, won, pend, Js, L[order], fused.weights,
                                          np.zeros(n, dtype=np.int64))
        # own pairs whose winner is another label: what the own estimator adopts
        own = (S == 0) & won0[J]
        own_lab, win = L[own], labels[J[own]]
        change = ~keys_equal(label_keys(own_lab), label_keys(win))
        cost = np.zeros(int(change.sum()))
        if support is not None:  # won by support, not by the order: the own track takes it
            o, w = own_lab[change], win[change]
            cost[(o[:, 1] == w[:, 1]) & ~precedes(w, o)] = RELEASE
        match = LabelMatch(own_lab[change], win[change], cost)
    else:
        match = LabelMatch(none, none.copy(), np.zeros(0))
    lost = np.flatnonzero(~won)
    labels[lost] = new_labels(origin, k, len(lost), FRESH_BASE + fresh_start)
    if len(J):
        # an own track paired with a row that lost its label to a heavier row (a label two
        # targets held) releases it: it takes the row's fresh label (a RELEASE pair), else it
        # keeps the duplicated label and the row gets a new id every scan (docs/real-traffic.md)
        rel = release_rows(fused, J, (S == 0) & ~won0[J], keeper, gate, copies)
        if copies:
            copy = copy_rows(fused, J, won0, keeper, gate)
        if rel.any():
            match = LabelMatch(np.concatenate([match.own, L[rel]]),
                               np.concatenate([match.nbr, labels[J[rel]]]),
                               np.concatenate([match.cost, np.full(int(rel.sum()), RELEASE)]))
    return FusedLabels(labels, match, len(lost), copy)


def kept_first(J: np.ndarray, L: np.ndarray, n: int, keep: np.ndarray | None,
               settle: np.ndarray) -> np.ndarray:
    """``(p,)`` int sort key of the pairs (fused rows ``J (p,)`` of ``n``, labels ``L (p,
    3)``): 1 for a label born ``settle (p,)`` scans (at least 1) or more before the earliest
    label of ``keep`` (reported the scan before) its row was paired with, which then cannot
    win the row; 0 otherwise (all 0 without ``keep``). Why (docs/real-traffic.md, "The switches
    traced"): a slow radar's track born earlier and drifting to a neighbouring aircraft was
    paired with a young aircraft's reported row and won it by the earliest-birth rule (392af3
    at tick 528: a switch at every peer). The same target's earlier label reaches every peer
    within its settle scans (:func:`settle_scans`: the eccentricity), so one born that much
    before the reported label is not it; a label born within that window still wins as
    before, so labels converge over sparse graphs as they did (keeping every reported label
    cut the confirmed label agreement on the 20-peer ring to 66 %)."""
    out = np.zeros(len(L), dtype=np.int64)
    if keep is None or not len(keep) or not len(L):
        return out
    kept = keys_isin(label_keys(L), keep)
    if not kept.any():
        return out
    first = np.full(n, np.iinfo(np.int64).max)
    np.minimum.at(first, J[kept], L[kept, 1])
    out[(L[:, 1] <= first[J] - np.maximum(settle, 1)) & ~kept] = 1
    return out


def _row_keys(prob: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """``(n,)`` sortable keys of (problem, label) rows (one problem: ``prob`` all 0)."""
    a = np.empty((len(labels), 4), dtype=np.int64)
    a[:, 0] = prob
    a[:, 1:] = labels
    return a.view(_ROW_KEY).reshape(-1)


_ROW_KEY = np.dtype([("p", "<i8"), ("origin", "<i8"), ("birth_scan", "<i8"), ("index", "<i8")])


def next_labels(labels: np.ndarray, won: np.ndarray, pending: np.ndarray, Jo: np.ndarray,
                Lo: np.ndarray, weights: np.ndarray, prob: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`label_fused` ``fallback``: each ``pending (n,)`` row takes the first label after
    its winner in its pairs' precedence order (``Jo (p,)`` rows, ``Lo (p, 3)`` labels, sorted
    by row then the network rule) that no row of its problem (``prob (n,)``) holds yet; rows
    wanting one label in one pass: the heavier (``weights (n,)``). One pass per rank (at most
    the inputs' number). Returns the labels and ``won`` with the rows that took one. Why
    (docs/real-traffic.md, "The switches traced"): a young aircraft's row paired with a slow
    radar's track that had moved onto it from its neighbour lost that label to the neighbour's
    heavier row and took a fresh one, so the label three inputs held and it was reported under
    gave way to a new id (a switch per peer); the next paired label is that id."""
    labels, won, pending = labels.copy(), won.copy(), pending.copy()
    if not len(Jo):
        return labels, won
    start = np.flatnonzero(np.r_[True, Jo[1:] != Jo[:-1]])
    rank = np.arange(len(Jo)) - np.repeat(start, np.diff(np.r_[start, len(Jo)]))
    taken = _row_keys(prob[won], labels[won])
    for r in range(1, int(rank.max()) + 1):
        sel = np.flatnonzero((rank == r) & pending[Jo])
        if not len(sel):
            continue
        rows, lab = Jo[sel], Lo[sel]
        keys = _row_keys(prob[rows], lab)
        ok = ~keys_isin(keys, taken)
        rows, lab, keys = rows[ok], lab[ok], keys[ok]
        if not len(rows):
            continue
        by = np.lexsort((-weights[rows], lab[:, 2], lab[:, 1], lab[:, 0], prob[rows]))
        first = np.ones(len(by), dtype=bool)
        first[1:] = ~keys_equal(keys[by[1:]], keys[by[:-1]])
        rows, lab, keys = rows[by[first]], lab[by[first]], keys[by[first]]
        labels[rows] = lab
        won[rows] = True
        pending[rows] = False
        taken = np.concatenate([taken, keys])
    return labels, won


def release_rows(fused: GaussianMixture, J: np.ndarray, rel: np.ndarray, keeper: np.ndarray,
                 gate: float, copies: bool) -> np.ndarray:
    """Which own pairs ``rel (p,)`` (of fused rows ``J (p,)``, lost their label to
    ``keeper[J]``) release their label: all of them, unless ``copies``, then only those whose
    row is outside ``gate`` of its keeper (the squared Mahalanobis distance of
    :func:`_pairs`). Why (docs/labelled-tracking.md, "The study"): under AA each input's
    component of one target survives at reduced weight, every input's track of it pairs with
    its own copy, so one label is won by the target's copies; a release then gave the own track
    a second id for its own target, two ids on one target (dup) that flipped back a scan later
    (8542ee5: AA fused OSPA(2) 73.5 -> 92.0 m, confirmed switches 0 -> 8.0 per 1,000)."""
    if not copies or not rel.any():
        return rel
    r = np.flatnonzero(rel)
    out = rel.copy()
    out[r[_distance2(fused, J[r], keeper[J[r]]) <= gate]] = False
    return out


def _distance2(fused: GaussianMixture, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(p,)`` the squared Mahalanobis distances of :func:`_pairs` between fused rows
    ``a (p,)`` and ``b (p,)``."""
    dm = fused.means[a] - fused.means[b]
    return np.einsum("pi,pi->p", dm, np.linalg.solve(fused.covs[a] + fused.covs[b],
                                                    dm[..., None])[..., 0])


def copy_rows(fused: GaussianMixture, J: np.ndarray, won: np.ndarray, keeper: np.ndarray,
              gate: float) -> np.ndarray:
    """``(n,)`` bool: the fused rows paired with some input track (``J (p,)``) that lost
    their label (``~won``) to a heavier row ``keeper`` within ``gate`` of them: under AA the
    same target's copy (:func:`release_rows`). Such a row takes a fresh label every scan, so
    it always looks young; pooling its inputs' existences (tracking.support.pooled_weights)
    reported it, under that fresh label, instead of the target's labelled row (traced on
    circ20 training run 100, docs/labelled-tracking.md "AA's copies were pooled as young
    tracks")."""
    out = np.zeros(len(won), dtype=bool)
    rows = np.unique(J[~won[J]])
    if len(rows):
        out[rows[_distance2(fused, rows, keeper[rows]) <= gate]] = True
    return out


def copy_keepers(fused: GaussianMixture, copies: np.ndarray, gate: float = LABEL_GATE
                 ) -> np.ndarray:
    """``(n,)`` int: each fused row's label row for the AA rule's per-label existence
    (tracking.fusion_rules.aa_label_density): a row not in ``copies (n,)`` (``FusedLabels.
    copies``, :func:`copy_rows`) is its own; a copy goes to the nearest (the squared
    Mahalanobis distance of :func:`_pairs`) row at least as heavy that is no copy, within
    ``gate``, else stays its own. Why the nearest and not the row that kept its label: a copy
    lost its label to a heavier row within ``gate`` (so that row qualifies), and which one it
    was is not kept past :func:`label_fused`; two labelled rows both within the gate of a copy
    are two targets closer than the label gate, whose copies either could hold."""
    n = len(fused)
    copies = np.asarray(copies, dtype=bool)
    if copies.shape != (n,):
        raise ValueError(f"copies has shape {copies.shape}, expected ({n},)")
    out = np.arange(n)
    c, q = np.flatnonzero(copies), np.flatnonzero(~copies)
    if not len(c) or not len(q):
        return out
    w = fused.weights
    diff = fused.means[c][:, None, :] - fused.means[q][None, :, :]  # (nc, nq, d)
    trace = (np.trace(fused.covs[c], axis1=1, axis2=2)[:, None]
             + np.trace(fused.covs[q], axis1=1, axis2=2)[None, :])
    near = (np.einsum("abi,abi->ab", diff, diff) <= gate * trace) & (w[q][None, :] >= w[c][:, None])
    ii, jj = np.nonzero(near)
    if not len(ii):
        return out
    d2 = np.full(near.shape, np.inf)
    d2[ii, jj] = _distance2(fused, c[ii], q[jj])
    best = np.argmin(d2, axis=1)
    ok = d2[np.arange(len(c)), best] <= gate
    out[c[ok]] = q[best[ok]]
    return out


def corroborated(labels: np.ndarray, won: np.ndarray, J: np.ndarray, S: np.ndarray,
                 bump: np.ndarray, k: int) -> np.ndarray:
    """A label's network scan is its first *corroborated* one: ``labels (n, 3)`` of the fused
    rows with each won (``won (n,)``) own label of ``bump (b, 3)`` (stamped at its first
    publication at scan ``k``) whose row no other input was paired with (pairs: fused rows
    ``J (p,)``, their inputs ``S (p,)``, 0 the own) moved to ``(o, k + 1, i)``, unless another
    row holds that label. Why (docs/labelled-tracking.md, "Corroborated stamps"): on 20 peers a
    clutter plot beside a new target's birth point one scan before it appears, at one peer of
    twenty, starts a track that takes the target's first detections and, as the earliest label
    on the network, replaced the id of the target at most other peers, hop by hop (15 switches
    in 20 peers); a track no neighbour holds at its first publication is stamped with the next
    scan, the scan most peers stamp the target's track, so the ids agree from the start."""
    other = np.zeros(len(labels), dtype=bool)
    other[J[S != 0]] = True
    rows = np.flatnonzero(won & ~other)
    rows = rows[keys_isin(label_keys(labels[rows]), label_keys(as_labels(bump)))
                & (labels[rows, 1] == k)]
    if not len(rows):
        return labels
    moved = labels[rows].copy()
    moved[:, 1] = k + 1
    ok = ~keys_isin(label_keys(moved), label_keys(labels[won]))
    labels = labels.copy()
    labels[rows[ok]] = moved[ok]
    return labels


def take_moves(labels: np.ndarray, match: LabelMatch, fresh: np.ndarray | None
               ) -> tuple[np.ndarray, LabelMatch]:
    """The moves of :func:`corroborated` in an own estimator's ``labels (n, 3)``: each pair of
    ``match`` whose own label is one of ``fresh (b, 3)`` (stamped this scan) and whose winner is
    that label a scan later replaces it (the network rule, :func:`tracking.labels.adopt_labels`,
    takes only earlier labels); returns the labels and the pairs left for the rule."""
    if fresh is None or not len(fresh) or not len(match) or not len(labels):
        return labels, match
    own, nbr = as_labels(match.own), as_labels(match.nbr)
    later = own.copy()
    later[:, 1] += 1
    move = (keys_isin(label_keys(own), label_keys(as_labels(fresh)))
            & keys_equal(label_keys(nbr), label_keys(later)))
    if not move.any():
        return labels, match
    keys = label_keys(labels)
    by = np.argsort(label_keys(own[move]))
    src, dst = label_keys(own[move])[by], nbr[move][by]
    pos = np.searchsorted(src, keys).clip(max=len(src) - 1)
    hit = keys_equal(src[pos], keys)
    out = labels.copy()
    out[hit] = dst[pos[hit]]
    rest = ~move
    return out, LabelMatch(own[rest], nbr[rest], np.asarray(match.cost)[rest])


__all__ = ["FRESH_BASE", "LABEL_GATE", "SETTLE_MARGIN", "FusedLabels", "copy_keepers", "copy_rows",
           "corroborated", "input_tracks", "kept_first", "label_fused", "next_labels", "origin_of",
           "release_rows", "settle_scans", "take_moves"]
