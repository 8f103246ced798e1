"""Many LMB local steps (predict, likelihoods, update) as one stacked array computation.

A peer host steps the LMB filters of many peers at one instant. Each step is a few tracks times
a few measurements, so it costs the overhead of the ~100 NumPy calls of
:meth:`tracking.lmb.LmbFilter.predict` and :func:`tracking.lmb.update`, not arithmetic. Here
``P`` steps are laid side by side (as :mod:`tracking.gmphd_batch` does for the GM-PHD): every
track and component of every problem in one stack, each problem's survivors then its births
(Reuter et al. 2014, eqs. 9-12), the likelihoods ``w_ik N(z_j; H m_ik, S_ik)`` of every
component against its own problem's measurements in one ``(N, M)`` block (``M`` the most
measurements of a problem; the columns beyond a problem's own are never read), and the
Kalman-updated components and their weights (Reuter eqs. 20-21) in one pass, then every
track's mixture reduction, the pruning and the confirmation counts
(:meth:`tracking.lmb.LmbFilter.finish`). What stays per problem: the association marginals
(:func:`tracking.lmb_association.marginals`, each with its filter's own Gibbs Generator, so the
draws are the ones its own step makes) and each adaptive birth existence's sum (Reuter eq. 31).

Every number is the one the filter's own ``step`` computes, to the bit (tests/test_lmb_batch.py):
each element goes through the same operations in the same order. The one operation whose order
NumPy picks by shape, the quadratic form ``nu^T S^-1 nu`` (``einsum`` chooses its summation
order from the operands' shapes and strides), is written out in the order it takes on most
shapes, and recomputed with ``einsum`` on the problem's own arrays for the shapes where it takes
another (:func:`_quad_in_order`).

Stacked together: filters whose sensor picks two state entries (``selected``) and with the same
motion model and motion steps, survival probability, gate and mixture reduction settings. ``Pd``,
clutter intensity, ``R``, births, labels and association settings may differ per problem.
Arrays: ``N`` components and ``T`` tracks of all problems; ``M`` measurement columns.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from sensornet.tracking.gaussian import LOG_2PI, _lapack_inv, c_einsum, inv_det_spd, inv_det_sym4
from sensornet.tracking.gmphd_batch import _interleave
from sensornet.tracking.label_keys import cell_index
from sensornet.tracking.lmb import (
    EDGE_FLAG,
    LmbFilter,
    LmbState,
    _empty_mixture,
    adaptive_birth_existence,
    check_scan,
)
from sensornet.tracking.lmb_association import marginals
from sensornet.tracking.lmb_sets import LabelledBernoulliSet, merge_close
from sensornet.tracking.mixture import GaussianMixture


def batch_key(filt: LmbFilter, steps: int) -> tuple | None:
    """What must be equal for two steps (``steps`` of motion) to be stacked; None: never."""
    model = filt.sensor.model
    if model.selected is None or model.dim != 2 or len(model.selected) != 2 or steps < 1:
        return None
    return (type(model), tuple(model.selected), filt.motion, filt.survival_probability,
            filt.gate, filt.component_prune, filt.merge_threshold, filt.max_components,
            int(steps))


def step_many(filters: Sequence[LmbFilter], states: Sequence[LmbState],
              scans: Sequence[np.ndarray], ks: Sequence[int]) -> list:
    """``f.step(state, z, k)`` of every problem, stacked where the filters allow it
    (:func:`batch_key`): each problem's ``(posterior state, Generator state after its draws)``,
    or None for a problem its own step would refuse (a bad scan, ``k`` not ahead of the state).
    Each filter's Generator is left where it was; the state after the step's draws is returned
    so that the step, if taken, continues the stream exactly as its own step would have."""
    out: list = [None] * len(filters)
    groups: dict[tuple, list[int]] = {}
    zs: list = [None] * len(filters)
    for p, (f, st, z, k) in enumerate(zip(filters, states, scans, ks, strict=True)):
        k = int(k)
        if k <= st.k:
            continue
        try:
            zs[p] = check_scan(z, f.sensor.model.dim)
        except ValueError:
            continue
        key = batch_key(f, k - st.k if st.k >= 0 else 1)
        if key is None:
            out[p] = _own(f, st, zs[p], k)
        else:
            groups.setdefault(key, []).append(p)
    for ps in groups.values():
        if len(ps) == 1:
            out[ps[0]] = _own(filters[ps[0]], states[ps[0]], zs[ps[0]], int(ks[ps[0]]))
            continue
        fs = [filters[p] for p in ps]
        if len({id(f._rng) for f in fs}) < len(fs):  # one Generator twice: not prepared
            continue
        gens = [f._rng.bit_generator for f in fs]
        before = [g.state for g in gens]
        try:  # each problem's marginals draw from its own Generator, as in its own step
            res = _stacked(fs, [states[p] for p in ps], [zs[p] for p in ps],
                           [int(ks[p]) for p in ps])
            for p, r, g in zip(ps, res, gens, strict=True):
                out[p] = None if r is None else (r, g.state)
        finally:
            for g, s in zip(gens, before, strict=True):
                g.state = s
    return out


def _own(f: LmbFilter, state: LmbState, z: np.ndarray, k: int) -> tuple[LmbState, dict] | None:
    """The filter's own step, its Generator put back (its state after the draws returned);
    None if it raises (the peer's own step meets the error)."""
    bg = f._rng.bit_generator
    before = bg.state
    try:
        post = f.step(state, z, k)
        return post, bg.state
    except Exception:  # noqa: BLE001 - not prepared: the step raises it again, counted there
        return None
    finally:
        bg.state = before


def _stacked(filters: list[LmbFilter], states: list[LmbState], scans: list[np.ndarray],
             ks: list[int]) -> list[LmbState | None]:
    """Predict, update, reduce and settle every problem together, the marginals one by one
    (None for a problem whose marginals raised: its own step meets the error)."""
    f0 = filters[0]
    steps = ks[0] - states[0].k if states[0].k >= 0 else 1
    F, Q = f0.motion.transition(steps)
    tr = [s.tracks for s in states]
    # -- predict (LmbFilter.predict): survivors, then each problem's births -------------
    s_tracks = np.array([len(t) for t in tr])
    s_comps = np.array([len(t.weights) for t in tr])
    exist = np.concatenate([t.existence for t in tr]) * f0.survival_probability**steps
    means = np.concatenate([t.means for t in tr]) @ F.T
    covs = F @ np.concatenate([t.covs for t in tr]) @ F.T + Q
    weights = np.concatenate([t.weights for t in tr])
    per_track = np.concatenate([np.bincount(t.owner, minlength=len(t)) for t in tr])
    pend = [s.pending for s in states]
    pend_means = np.concatenate([q.means for q in pend]) @ F.T
    pend_covs = F @ np.concatenate([q.covs for q in pend]) @ F.T + Q
    b_w, b_m, b_P, b_lab, b_lens = [], [], [], [], []
    at = 0
    for f, q in zip(filters, pend, strict=True):
        nq = len(q)
        if f.birth is not None:
            b_w.append(np.clip(f.birth.weights, 0.0, 1.0))
            b_m.append(f.birth.means)
            b_P.append(f.birth.covs)
        if nq:
            b_w.append(np.clip(q.weights, 0.0, 1.0))
            b_m.append(pend_means[at:at + nq])
            b_P.append(pend_covs[at:at + nq])
        at += nq
        b_lens.append(nq + (0 if f.birth is None else len(f.birth)))
    b_lens = np.array(b_lens)
    b_lab = [_birth_labels(filters, pend, ks, b_lens)]
    t_idx = _interleave(s_tracks, b_lens)  # each problem's survivors, then its births
    c_idx = _interleave(s_comps, b_lens)
    nb_all = int(b_lens.sum())
    labels = np.concatenate([t.labels for t in tr] + b_lab)[t_idx]
    exist = np.concatenate([exist, *b_w])[t_idx]
    hits = np.concatenate([s.hits for s in states] + [np.zeros(nb_all, np.int64)])[t_idx]
    weights = np.concatenate((weights, np.ones(nb_all)))[c_idx]
    means = np.concatenate((means, *b_m))[c_idx]
    covs = np.concatenate((covs, *b_P))[c_idx]
    n_lens = s_tracks + b_lens  # tracks per problem
    c_lens = s_comps + b_lens  # components per problem
    owner = np.repeat(np.arange(len(exist)),
                      np.concatenate((per_track, np.ones(nb_all, np.int64)))[t_idx])
    failed: set[int] = set()
    (r, w, mean, P, owner), r_u = _update(filters, labels, exist, weights, means, covs, owner,
                                          n_lens, c_lens, scans, failed)
    prob_t = np.repeat(np.arange(len(filters)), n_lens)
    w, mean, P, owner = _reduce(w, mean, P, owner, prob_t, len(filters), f0.component_prune,
                                f0.merge_threshold, f0.max_components)
    return _settle(filters, states, scans, ks, labels, r, w, mean, P, owner, hits, prob_t, r_u,
                   failed)


def _settle(filters, states, scans, ks, labels, r, w, mean, P, owner, hits, prob_t, r_u,
            failed) -> list[LmbState | None]:
    """:meth:`tracking.lmb.LmbFilter.settle` of every problem on its reduced posterior: the
    tracks below ``existence_prune`` deleted and the confirmations counted in the stack; each
    problem's adaptive births from its own ``r_U`` (its own sum, as its own step takes it)."""
    n_prob = len(filters)
    ep = np.array([f.existence_prune for f in filters])
    ce = np.array([f.confirm_existence for f in filters])
    keep = r >= ep[prob_t]
    hits = (hits[keep] + (r[keep] >= ce[prob_t[keep]])).astype(np.int64)
    comp = np.flatnonzero(keep[owner])
    renumber = np.cumsum(keep) - 1
    n_kept = np.bincount(prob_t[keep], minlength=n_prob)
    tracks = _split(labels[keep], r[keep], w[comp], mean[comp], P[comp], renumber[owner[comp]],
                    n_kept, np.bincount(prob_t[owner[comp]], minlength=n_prob))
    d = mean.shape[1]
    r_b, born_at, covs = [], [], []
    for p, f in enumerate(filters):  # each problem's r_B (Reuter eq. 31) from its own sum
        if f.adaptive_birth and len(scans[p]):
            r_b.append(adaptive_birth_existence(r_u[p], f.birth_rate, f.birth_max_existence))
            born_at.append(np.full(len(scans[p]), p))
            covs.append(f._birth_cov)
        else:
            covs.append(np.zeros((d, d)))
    pend = [_empty_mixture(d)] * n_prob
    if r_b:
        rb = np.concatenate(r_b)
        pb = np.concatenate(born_at)
        born = rb >= ep[pb]
        nb = np.bincount(pb[born], minlength=n_prob)
        cols = list(filters[0].sensor.model.selected)
        means = np.zeros((int(nb.sum()), d))
        means[:, cols] = np.concatenate([scans[p] for p in np.unique(pb).tolist()])[born]
        bw, bP = rb[born], np.stack(covs)[pb[born]]
        at = 0
        for p in np.unique(pb).tolist():
            pend[p] = GaussianMixture.trusted(bw[at:at + nb[p]], means[at:at + nb[p]],
                                              bP[at:at + nb[p]])
            at += nb[p]
    t0 = 0
    out: list = []
    for p, k in enumerate(ks):
        t1 = t0 + int(n_kept[p])
        out.append(None if p in failed else LmbState(tracks[p], hits[t0:t1], k, pend[p]))
        t0 = t1
    return out


def _birth_labels(filters, pend, ks, b_lens) -> np.ndarray:
    """The labels of every problem's births, problem by problem, as
    :meth:`tracking.lmb.LmbFilter.predict` gives them: ``(origin, k, i)``, or with a
    ``shared_origin`` the fixed births ``(shared, k, i)`` and the pending ones by the cell of
    their plot (:func:`tracking.label_keys.shared_births`: two in one cell, the likelier keeps
    it; near a cell edge flagged with :data:`tracking.lmb.EDGE_FLAG`)."""
    n_prob, total = len(filters), int(b_lens.sum())
    prob = np.repeat(np.arange(n_prob), b_lens)
    local = np.arange(total) - np.repeat(np.cumsum(b_lens) - b_lens, b_lens)
    k = np.array(ks, dtype=np.int64)
    out = np.empty((total, 3), dtype=np.int64)
    out[:, 0] = np.array([f.origin for f in filters], dtype=np.int64)[prob]
    out[:, 1] = k[prob]
    out[:, 2] = local
    shared = [p for p, f in enumerate(filters) if f.shared_origin is not None and b_lens[p]]
    if not shared:
        return out
    nf = np.array([0 if f.birth is None else len(f.birth) for f in filters])
    so = np.array([-1 if f.shared_origin is None else f.shared_origin for f in filters],
                  dtype=np.int64)
    is_shared = so[prob] >= 0
    out[is_shared & (local < nf[prob]), 0] = so[prob][is_shared & (local < nf[prob])]
    rows = np.flatnonzero(is_shared & (local >= nf[prob]))  # pending births of shared problems
    if not len(rows):
        return out
    sel = list(filters[0].sensor.model.selected)
    plots = np.concatenate([pend[p].means for p in shared])[:, sel]
    pp = prob[rows]
    cell = np.array([f.birth_cell for f in filters])
    index = np.empty(len(rows), dtype=np.int64)
    for size in np.unique(cell[pp]).tolist():  # cell_index takes one size
        at = cell[pp] == size
        index[at] = cell_index(plots[at], size)
    prio = np.concatenate([pend[p].weights for p in shared])
    order = np.lexsort((-prio, index, pp))  # stable: ties, the first (shared_births per problem)
    first = np.ones(len(rows), dtype=bool)
    first[1:] = (index[order[1:]] != index[order[:-1]]) | (pp[order[1:]] != pp[order[:-1]])
    keep = np.zeros(len(rows), dtype=bool)
    keep[order] = first
    out[rows[keep], 0] = so[pp[keep]]
    out[rows[keep], 2] = index[keep]
    edge = np.array([f.birth_edge for f in filters])[pp]
    if (edge > 0).any():  # a plot near a cell edge: another peer's may be across it
        c = cell[pp][:, None]
        frac = plots / c - np.floor(plots / c)
        near = (c * np.minimum(frac, 1.0 - frac) < edge[:, None]).any(axis=1) & (edge > 0)
        out[rows[near & keep], 2] += EDGE_FLAG
    return out


def _update(filters, labels, r, w, mean, P, owner, n_lens, c_lens, scans,
            failed: set[int]) -> tuple[tuple, list]:
    """:func:`tracking.lmb.update` of every problem: the stacked posterior ``(r, w, mean, P,
    owner)`` (each problem's components together, its tracks' owners) and each ``r_U`` (the
    problems whose marginals raised are added to ``failed``; their rows are not theirs)."""
    f0 = filters[0]
    model, n_prob = f0.sensor.model, len(filters)
    dz, cols = model.dim, list(model.selected)
    T, N = len(r), len(w)
    prob_t = np.repeat(np.arange(n_prob), n_lens)
    prob_c = np.repeat(np.arange(n_prob), c_lens)
    m_lens = np.array([len(z) for z in scans])
    M = int(m_lens.max(initial=0))
    Pd = np.array([f.sensor.detection_probability for f in filters])
    kappa = np.array([f.sensor.clutter_intensity for f in filters])
    Pd_t = Pd[prob_t]
    miss = 1.0 - r * Pd_t
    stay = np.divide(r * (1.0 - Pd_t), miss, out=np.zeros(T), where=miss > 0)
    active = (n_lens > 0) & (m_lens > 0)  # lmb.update's early return for the others
    t_start = np.cumsum(n_lens) - n_lens
    c_start = np.cumsum(c_lens) - c_lens
    p_miss = np.ones(T)
    p_sum = np.zeros(T)
    r_u = [np.zeros(m) for m in m_lens]
    if not active.any() or N == 0:
        return (stay, w, mean, P, owner), r_u
    R = np.stack([f.sensor.model.R for f in filters])
    zhat, PHt = mean[:, cols], P[:, :, cols]  # (N, dz), (N, d, dz)
    S = PHt[:, cols, :] + R[prob_c]
    S_inv, S_det = inv_det_spd(S)
    scan = np.zeros((n_prob, M, dz))
    for p, z in enumerate(scans):
        scan[p, :len(z)] = z
    nu = model.residual(scan[prob_c], zhat[:, None, :])  # (N, M, dz)
    d2 = _quad(nu, S_inv)
    for p in np.flatnonzero(active).tolist():
        c, m = int(c_lens[p]), int(m_lens[p])
        if not _quad_in_order(c, m, _layout(scans[p])):
            rows = slice(c_start[p], c_start[p] + c)
            d2[rows, :m] = _own_quad(model, mean[rows], P[rows], R[p], scans[p])
    wq = np.exp(-0.5 * (d2 + (np.log(S_det) + dz * LOG_2PI)[:, None])) * w[:, None]  # (N, M)
    if f0.gate is not None:
        wq[d2 > f0.gate] = 0.0
    eta = np.add.reduceat(wq, np.searchsorted(owner, np.arange(T)), axis=0)  # (T, M)
    detect = (r * Pd_t)[:, None] * eta / kappa[prob_t][:, None]
    p = np.zeros((T, M))
    for q in np.flatnonzero(active).tolist():
        f, m = filters[q], int(m_lens[q])
        rows = slice(t_start[q], t_start[q] + n_lens[q])
        try:
            pm, pq = marginals(miss[rows], np.ascontiguousarray(detect[rows, :m]), f.method,
                               f.exact_limit, f.lbp_tol, scalable=f.scalable, rng=f._rng,
                               samples=f.gibbs_samples, gibbs_tracks=f.gibbs_tracks)
        except Exception:  # noqa: BLE001 - its own step meets the error; the others go on
            failed.add(q)
            continue
        p_miss[rows], p[rows, :m] = pm, pq
        p_sum[rows] = pq.sum(axis=1)
        r_u[q] = pq.sum(axis=0)
    exist_miss = p_miss * stay
    r_post = exist_miss + p_sum
    inv_r = np.divide(1.0, r_post, out=np.zeros(T), where=r_post > 0)
    coef = np.divide(p, eta, out=np.zeros((T, M)), where=eta > 0) * inv_r[:, None]
    rel = wq * coef[owner]  # (N, M)
    valid = np.arange(M) < m_lens[prob_c][:, None]
    min_weight = f0.component_prune
    ci, zj = np.nonzero(((rel > min_weight) if min_weight > 0 else (rel >= 0)) & valid)
    K = PHt @ S_inv  # (N, d, dz)
    P_upd = P - K @ PHt.swapaxes(1, 2)
    P_upd = 0.5 * (P_upd + P_upd.swapaxes(1, 2))
    means_upd = mean[ci] + c_einsum("kij,kj->ki", K[ci], nu[ci, zj])
    act_t, act_c = active[prob_t], active[prob_c]
    r_post = np.where(act_t, r_post, stay)
    w_miss = np.where(act_c, w * (exist_miss * inv_r)[owner], w)
    all_owner = np.concatenate((owner, owner[ci]))
    order = np.argsort(all_owner, kind="stable")
    W = np.concatenate((w_miss, rel[ci, zj]))[order]
    Mn = np.concatenate((mean, means_upd))[order]
    Pn = np.concatenate((P, P_upd[ci]))[order]
    return (r_post, W, Mn, Pn, all_owner[order]), r_u


def _reduce(w, m, P, own, prob_t, n_prob, prune, threshold, cap) -> tuple:
    """:func:`tracking.lmb_sets.reduce_components` of every problem's tracks at once (``own``
    the stacked tracks' indices, ``prob_t`` each track's problem): prune, the Vo-Ma sweep in
    every track, cap, renormalise, as each problem's own call does; the merge's inverses as
    each problem takes them (LAPACK up to 200 pairs of 4-D components, else the closed form:
    :func:`tracking.gaussian.inv_spd`), and a problem none of whose pairs is close keeps its
    components untouched (its own call returns before the merge's arithmetic)."""
    n = len(prob_t)
    if n == 0:
        return w, m, P, own
    order = np.lexsort((-w, own))
    ws, os_ = w[order], own[order]
    first = np.empty(len(ws), dtype=bool)  # each track's heaviest
    first[0] = True
    np.not_equal(os_[1:], os_[:-1], out=first[1:])
    keep = order[(ws >= prune) | first]
    w, m, P, own = w[keep], m[keep], P[keep], own[keep]
    sizes = np.bincount(own, minlength=n)
    if sizes.max() > 1:
        w, m, P, own = _merge(w, m, P, own, sizes, threshold, prob_t, n_prob)
        order = np.lexsort((-w, own))  # the same order where nothing merged
        w, m, P, own = w[order], m[order], P[order], own[order]
        sizes = np.bincount(own, minlength=n)
    if sizes.max() > cap:
        rank = np.arange(len(w)) - (np.cumsum(sizes) - sizes)[own]
        kept = rank < cap
        w, m, P, own = w[kept], m[kept], P[kept], own[kept]
    total = np.add.reduceat(w, np.searchsorted(own, np.arange(n)))[own]
    w = np.divide(w, total, out=1.0 / np.bincount(own, minlength=n)[own], where=total > 0)
    return w, m, P, own


def _merge(w, m, P, own, sizes, threshold, prob_t, n_prob) -> tuple:
    """:func:`tracking.lmb_sets._merge_within` of every problem at once (see :func:`_reduce`)."""
    c, d = len(w), m.shape[1]
    idx = np.arange(c)
    rank = idx - (np.cumsum(sizes) - sizes)[own]
    counts = sizes[own] - rank - 1  # later (lighter) components of the same track
    centre = np.repeat(idx, counts)
    member = centre + 1 + np.arange(centre.size) - np.repeat(np.cumsum(counts) - counts, counts)
    pp = prob_t[own[member]]  # each pair's problem
    lapack = (np.bincount(pp, minlength=n_prob)[pp] <= 200) if d == 4 else np.ones(len(pp), bool)
    inv = np.empty((len(pp), d, d))
    if lapack.any():
        got = _lapack_inv(P[member[lapack]])
        if got is None:  # singular or not finite: each problem's own reduction meets it
            raise FloatingPointError("a merge covariance is not invertible")
        inv[lapack] = 0.5 * (got + np.swapaxes(got, -1, -2))
    if not lapack.all():
        inv[~lapack] = inv_det_sym4(P[member[~lapack]])[0]
    diff = m[member] - m[centre]
    close = c_einsum("gi,gij,gj->g", diff, inv, diff) <= threshold
    if not close.any():
        return w, m, P, own
    W, mean, WP, centres = merge_close(w, m, P, member[close], centre[close])
    with np.errstate(divide="ignore", invalid="ignore"):  # rows of problems that keep theirs
        cov = WP[centres] / W[centres, None, None]
    merged = (np.bincount(pp[close], minlength=n_prob) > 0)[prob_t[own[centres]]]
    return (np.where(merged, W[centres], w[centres]),
            np.where(merged[:, None], mean[centres], m[centres]),
            np.where(merged[:, None, None], 0.5 * (cov + cov.swapaxes(1, 2)), P[centres]),
            own[centres])


def _split(labels, r, w, mean, P, owner, n_lens, c_lens) -> list[LabelledBernoulliSet]:
    """The stacked set cut into each problem's (owners counted from 0 in each)."""
    out = []
    t0 = c0 = 0
    for n, c in zip(n_lens.tolist(), c_lens.tolist(), strict=True):
        out.append(LabelledBernoulliSet.trusted(labels[t0:t0 + n], r[t0:t0 + n],
                                                w[c0:c0 + c], mean[c0:c0 + c], P[c0:c0 + c],
                                                owner[c0:c0 + c] - t0))
        t0, c0 = t0 + n, c0 + c
    return out


def _quad(nu: np.ndarray, S_inv: np.ndarray) -> np.ndarray:
    """``nu^T S^-1 nu`` of ``nu (N, M, 2)``, ``S_inv (N, 2, 2)``, summed as
    :func:`tracking.lmb.update`'s ``c_einsum`` sums on most shapes: ``i`` outer, ``j`` inner,
    each term ``(nu_i S_ij) nu_j`` (elementwise, so any layout gives the same numbers)."""
    a, b = nu[..., 0], nu[..., 1]
    s00, s01 = S_inv[:, None, 0, 0], S_inv[:, None, 0, 1]
    s10, s11 = S_inv[:, None, 1, 0], S_inv[:, None, 1, 1]
    out = a * s00 * a
    out += a * s01 * b
    out += b * s10 * a
    out += b * s11 * b
    return out


def _own_quad(model, mean: np.ndarray, P: np.ndarray, R: np.ndarray,
              scan: np.ndarray) -> np.ndarray:
    """``nu^T S^-1 nu (c, m)`` exactly as :func:`tracking.lmb.update` computes it on one
    problem's predicted components ``mean (c, d)``, ``P (c, d, d)`` and ``scan (m, dz)``: the
    same calls on arrays of the same layouts (``einsum``'s summation order follows them)."""
    cols = list(model.selected)
    zhat, PHt = mean[:, cols], P[:, :, cols]
    S_inv = inv_det_spd(PHt[:, cols, :] + R)[0]
    nu = model.residual(scan[None, :, :], zhat[:, None, :])
    return c_einsum("cmi,cij,cmj->cm", nu, S_inv, nu)


def _layout(scan: np.ndarray) -> str | None:
    """``"C"`` or ``"F"``: how ``scan``'s rows lie in memory; None: neither."""
    return "C" if scan.flags.c_contiguous else "F" if scan.flags.f_contiguous else None


def _quad_in_order(c: int, m: int, layout: str | None) -> bool:
    """Whether :func:`_quad` gives :func:`_own_quad`'s numbers to the bit on a problem of ``c``
    components and ``m`` plots laid out in ``layout`` order: NumPy's ``einsum`` picks its
    summation order from its operands' shapes and strides, and on the layouts
    :func:`tracking.lmb.update` makes it sums as :func:`_quad` does except with one component
    and at most two plots (its iterator drops the length-1 axis), measured over ``c`` 1-300,
    ``m`` 1-44, plots in C and Fortran order, NumPy 2.4 (tests/test_lmb_batch.py checks it)."""
    return layout is not None and not (c == 1 and m <= 2)


__all__ = ["batch_key", "step_many"]
