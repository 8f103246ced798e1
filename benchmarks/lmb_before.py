"""The LMB filter's scan step as it was before the CPU work of 4 Dec 2026 (issue 33's "50
labelled peers in real time": commit 211455b's ``tracking/lmb.py``, ``lmb_sets.py``,
``lmb_association.py``, ``lmb_lbp.py`` and ``label_keys.py``), kept as the same-run reference of
``bench_lmb_step.py`` and of tests/test_lmb_step_exact.py (the new step must give the same
numbers to the bit): :class:`LmbFilterBefore` is an :class:`LmbFilter` whose ``predict``,
``correct`` and ``step`` run the functions below."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.tracking.gaussian import LOG_2PI, inv_det_spd, inv_spd
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import CELL_BASE, CELL_BITS, new_labels
from sensornet.tracking.lmb import LmbFilter, LmbState, adaptive_birth_existence, check_scan
from sensornet.tracking.lmb_association import (
    DROP_BUDGET,
    EXACT_LIMIT,
    GIBBS_SEED,
    LINK_EPS,
    METHODS,
    SCALABLE,
    SPARSE_FROM,
    _by_cluster,
    _clusters,
    _enumerate,
    _enumerate_sparse,
    drop_weak_links,
    hypotheses,
    hypothesis_count,
    marginals_exact,
    marginals_gibbs,
)
from sensornet.tracking.lmb_lbp import _row_scaled
from sensornet.tracking.lmb_sets import LabelledBernoulliSet
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity


def predict(tracks: LabelledBernoulliSet, motion: ConstantVelocity, survival_probability: float,
            steps: int = 1) -> LabelledBernoulliSet:
    """Survivors: ``r+ = Ps^steps r``, each component ``F m``, ``F P F^T + Q`` (Reuter eqs. 9-12
    with a state-independent ``Ps``)."""
    if steps == 0 or len(tracks) == 0:
        return tracks
    F, Q = motion.transition(steps)
    return LabelledBernoulliSet.trusted(
        tracks.labels, tracks.existence * survival_probability**steps, tracks.weights,
        tracks.means @ F.T, F @ tracks.covs @ F.T + Q, tracks.owner)


def update(tracks: LabelledBernoulliSet, scan: np.ndarray, sensor: SensorParams,
           method: str = "auto", gate: float | None = None, min_weight: float = 0.0,
           exact_limit: int = EXACT_LIMIT, tol: float = 1e-9, scalable: str = "gibbs",
           rng: np.random.Generator | None = None,
           samples: int | None = None) -> tuple[LabelledBernoulliSet, np.ndarray]:
    """The LMB posterior after scan ``Z (m, dz)`` (Reuter eqs. 20-21) and ``r_U (m,)``, each
    measurement's probability of belonging to a track (the adaptive birth's input, eq. 31).

    ``eta_i(z) = sum_k w_ik N(z; H m_ik, S_ik)``; association weights ``1 - r_i Pd`` (miss)
    and ``r_i Pd eta_i(z_j) / kappa`` (detect) give the marginals ``p_miss``, ``p``; then
    ``r_i' = p_miss_i r_i (1 - Pd) / (1 - r_i Pd) + sum_j p_ij`` and the track's density is
    its prior (weight of the first term) plus one Kalman-updated copy per measurement (weight
    ``p_ij``), normalised by ``r_i'``. ``gate``: pairs with ``nu^T S^-1 nu`` above it get
    likelihood 0. ``min_weight``: detection components lighter than this within their track
    are not materialised (pruning them early). No reduction here: see :func:`reduce_components`.
    ``method``, ``exact_limit``, ``tol``, ``scalable``, ``rng``, ``samples``: the association
    (:func:`lmb_association.marginals`).
    """
    Pd, kappa = sensor.detection_probability, sensor.clutter_intensity
    n, dz = len(tracks), sensor.model.dim
    scan = np.asarray(scan, dtype=float).reshape(-1, dz)
    m = len(scan)
    r, w, mean, P, owner = (tracks.existence, tracks.weights, tracks.means, tracks.covs,
                            tracks.owner)
    with np.errstate(invalid="ignore", divide="ignore"):
        stay = np.where(1.0 - r * Pd > 0, r * (1.0 - Pd) / (1.0 - r * Pd), 0.0)
    if n == 0 or m == 0:
        return LabelledBernoulliSet.trusted(tracks.labels, stay, w, mean, P, owner), np.zeros(m)
    cols = sensor.model.selected
    if cols is not None:  # H picks state entries: H P H^T and P H^T are sub-blocks of P
        cols = list(cols)
        zhat, PHt = mean[:, cols], P[:, :, cols]  # (c, dz), (c, d, dz)
        S = PHt[:, cols, :] + sensor.model.R
    else:
        zhat, H = sensor.model.predict(mean)
        PHt = P @ H.swapaxes(1, 2)
        S = H @ PHt + sensor.model.R
    S_inv, S_det = inv_det_spd(S)
    nu = sensor.model.residual(scan[None, :, :], zhat[:, None, :])  # (c, m, dz)
    d2 = np.einsum("cmi,cij,cmj->cm", nu, S_inv, nu)
    wq = np.exp(-0.5 * (d2 + (np.log(S_det) + dz * LOG_2PI)[:, None])) * w[:, None]  # (c, m)
    if gate is not None:
        wq[d2 > gate] = 0.0
    starts = tracks.starts()
    eta = np.add.reduceat(wq, starts, axis=0)  # (n, m)
    p_miss, p = marginals(1.0 - r * Pd, (r * Pd)[:, None] * eta / kappa, method, exact_limit,
                          tol, scalable=scalable, rng=rng, samples=samples)
    exist_miss = p_miss * stay
    r_post = exist_miss + p.sum(axis=1)
    inv_r = np.divide(1.0, r_post, out=np.zeros(n), where=r_post > 0)
    coef = np.divide(p, eta, out=np.zeros((n, m)), where=eta > 0) * inv_r[:, None]
    rel = wq * coef[owner]  # (c, m): each detection component's weight within its track
    ci, zj = np.nonzero(rel > min_weight) if min_weight > 0 else np.nonzero(rel >= 0)
    K = PHt @ S_inv  # (c, d, dz)
    P_upd = P - K @ PHt.swapaxes(1, 2)
    P_upd = 0.5 * (P_upd + P_upd.swapaxes(1, 2))
    means_upd = mean[ci] + np.einsum("kij,kj->ki", K[ci], nu[ci, zj])
    all_owner = np.concatenate((owner, owner[ci]))
    order = np.argsort(all_owner, kind="stable")
    post = LabelledBernoulliSet.trusted(
        tracks.labels, r_post,
        np.concatenate((w * (exist_miss * inv_r)[owner], rel[ci, zj]))[order],
        np.concatenate((mean, means_upd))[order],
        np.concatenate((P, P_upd[ci]))[order], all_owner[order])
    return post, p.sum(axis=0)


def reduce_components(tracks: LabelledBernoulliSet, prune: float, merge_threshold: float,
                      max_components: int) -> LabelledBernoulliSet:
    """Each track's mixture pruned, merged and capped, then renormalised (all tracks at once).

    Components below ``prune`` go (each track keeps its heaviest); within a track, the Vo-Ma
    sweep (Vo & Ma 2006, Table II; as :func:`tracking.reduction.merge`) merges into the heaviest
    remaining component every one with ``(m_i - m_j)^T P_i^-1 (m_i - m_j) <= U``; the
    ``max_components`` heaviest are kept. The pairs tested are the same-track pairs only.
    """
    n = len(tracks)
    if n == 0:
        return tracks
    order = np.lexsort((-tracks.weights, tracks.owner))
    w, own = tracks.weights[order], tracks.owner[order]
    rank = np.arange(len(w)) - np.searchsorted(own, np.arange(n))[own]
    keep = order[(w >= prune) | (rank == 0)]
    w, m, P, own = tracks.weights[keep], tracks.means[keep], tracks.covs[keep], tracks.owner[keep]
    sizes = np.bincount(own, minlength=n)
    if sizes.max() > 1:
        w, m, P, own = _merge_within(w, m, P, own, sizes, merge_threshold)
        order = np.lexsort((-w, own))
        w, m, P, own = w[order], m[order], P[order], own[order]
        sizes = np.bincount(own, minlength=n)
    if sizes.max() > max_components:
        rank = np.arange(len(w)) - (np.cumsum(sizes) - sizes)[own]
        cap = rank < max_components
        w, m, P, own = w[cap], m[cap], P[cap], own[cap]
    total = np.add.reduceat(w, np.searchsorted(own, np.arange(n)))[own]
    # a track whose every weight underflowed to 0 (deleted by its existence in the same step)
    # gets equal weights, not 0/0
    w = np.divide(w, total, out=1.0 / np.bincount(own, minlength=n)[own], where=total > 0)
    return LabelledBernoulliSet.trusted(tracks.labels, tracks.existence, w, m, P, own)


def _merge_within(w, m, P, own, sizes, threshold):
    """The Vo-Ma sweep in every track at once; components sorted by (owner, -weight)."""
    c = len(w)
    rank = np.arange(c) - (np.cumsum(sizes) - sizes)[own]
    counts = sizes[own] - rank - 1  # later (lighter) components of the same track
    centre = np.repeat(np.arange(c), counts)
    member = centre + 1 + np.arange(centre.size) - np.repeat(np.cumsum(counts) - counts, counts)
    diff = m[member] - m[centre]
    close = np.einsum("gi,gij,gj->g", diff, inv_spd(P[member]), diff) <= threshold
    if not close.any():
        return w, m, P, own
    root = np.arange(c)
    taken = np.zeros(c, dtype=bool)
    for i, j in zip(member[close].tolist(), centre[close].tolist(), strict=True):
        if taken[j] or taken[i]:  # sweep order: centres heaviest first, pairs sorted (j, i)
            continue
        root[i] = j
        taken[i] = True
    W = np.bincount(root, w, minlength=c)
    centres = np.flatnonzero(root == np.arange(c))
    Wm = np.zeros_like(m)
    np.add.at(Wm, root, w[:, None] * m)
    mean = Wm / np.where(W > 0, W, 1.0)[:, None]
    diff = m - mean[root]
    WP = np.zeros_like(P)
    np.add.at(WP, root, w[:, None, None] * (P + diff[:, :, None] * diff[:, None, :]))
    cov = WP[centres] / W[centres, None, None]
    return W[centres], mean[centres], 0.5 * (cov + cov.swapaxes(1, 2)), own[centres]


def marginals(miss: np.ndarray, detect: np.ndarray, method: str = "auto",
              exact_limit: int = EXACT_LIMIT, tol: float = 1e-9, max_iter: int = 1000,
              scalable: str = "gibbs", rng: np.random.Generator | None = None,
              samples: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Marginal association probabilities ``p_miss (n,)``, ``p (n, m)`` (rows sum to 1).

    ``"exact"``: every hypothesis of the whole problem; ``"lbp"``: :func:`marginals_lbp`;
    ``"gibbs"``: :func:`marginals_gibbs` over the whole problem; ``"auto"``: links below
    :data:`LINK_EPS` dropped, LBP over the whole problem (exact on every cluster of the
    bipartite track-measurement graph that is a tree: Williams & Lau 2014, Sec. III), then each
    cluster with a cycle (a cluster's marginals do not depend on the others) enumerated exactly
    if it has at most ``exact_limit`` hypotheses (clusters of one shape together). A larger
    one, with ``scalable="gibbs"``, loses its weakest links (:func:`drop_weak_links`, error at
    most :data:`DROP_BUDGET`), which splits most such clusters (in benchmarks/bench_lmb.py,
    births linked to clutter) into trees and small ones, solved as above; what stays beyond
    ``exact_limit`` goes to :func:`marginals_gibbs`. ``scalable="lbp"`` keeps LBP's answer on
    large clusters. ``rng`` feeds the Gibbs draws (None: a fresh ``default_rng(GIBBS_SEED)``,
    so one input gives one answer); ``samples``: Gibbs draws per problem or cluster (None:
    :func:`gibbs_sample_count`). Auto, like LBP and Gibbs, gives a track whose miss weight is
    0 (``r = Pd = 1``) ``1e-10`` of its largest weight.
    """
    if method not in METHODS:
        raise ValueError(f"unknown association method {method!r}; expected one of {METHODS}")
    if scalable not in SCALABLE:
        raise ValueError(f"unknown scalable association {scalable!r}; expected one of {SCALABLE}")
    miss = np.asarray(miss, dtype=float)
    detect = np.asarray(detect, dtype=float)
    n, m = detect.shape
    if rng is None:
        rng = np.random.default_rng(GIBBS_SEED)
    if method == "exact":
        return marginals_exact(miss, detect)
    if method == "gibbs":
        return marginals_gibbs(miss, detect, rng, samples)
    if method == "lbp" or n == 0 or m == 0:
        return marginals_lbp(miss, detect, tol, max_iter)
    miss, detect = _row_scaled(miss, detect)
    miss = np.maximum(miss, 1e-10)  # r = Pd = 1: as LBP and Gibbs (else 0 / 0 when too few
    detect = np.where(detect > LINK_EPS, detect, 0.0)  # measurements are left for such tracks)
    return _auto(miss, detect, exact_limit, tol, max_iter, scalable, rng, samples, DROP_BUDGET)


def _auto(miss: np.ndarray, detect: np.ndarray, exact_limit: int, tol: float, max_iter: int,
          scalable: str, rng: np.random.Generator, samples: int | None,
          drop: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`marginals` ``"auto"`` on row-scaled weights whose zero links are absent; a large
    loopy cluster is thinned by ``drop`` and solved again (``drop`` 0: Gibbs)."""
    n, m = detect.shape
    link = detect > 0
    p_miss, p = marginals_lbp(miss, detect, tol, max_iter)
    ti, zj = np.nonzero(link)
    if ti.size < 4:  # a cycle needs 2 tracks and 2 measurements with 4 links
        return p_miss, p
    tcomp, zcomp = _clusters(link)
    ncomp = n
    linked_t, linked_z = link.any(axis=1), link.any(axis=0)
    nt = np.bincount(tcomp[linked_t], minlength=ncomp)
    nz = np.bincount(zcomp[linked_z], minlength=ncomp)
    edges = np.bincount(tcomp[ti], minlength=ncomp)
    loopy = np.flatnonzero((edges > 0) & (edges >= nt + nz))  # a tree has nodes - 1 edges
    if loopy.size == 0:
        return p_miss, p
    t_sorted, t_start = _by_cluster(tcomp, linked_t, ncomp)
    z_sorted, z_start = _by_cluster(zcomp, linked_z, ncomp)
    by_shape: dict[tuple[int, int], list[int]] = {}
    sparse: list[int] = []
    large: list[int] = []
    # a bound on each cluster's hypotheses of nonzero weight: prod over its tracks of 1 + links
    logbound = np.bincount(tcomp, np.log1p(link.sum(axis=1)), ncomp)
    for c in loopy.tolist():
        a, b = int(nt[c]), int(nz[c])
        dense = hypothesis_count(a, b)
        bound = float(np.exp(logbound[c]))
        if dense <= min(SPARSE_FROM, exact_limit):
            by_shape.setdefault((a, b), []).append(c)
        elif dense <= exact_limit or (drop == 0 and bound <= exact_limit):
            sparse.append(c)  # at most min(dense, bound) hypotheses, no table to build
        elif scalable == "gibbs":
            large.append(c)  # else LBP's answer stays
    for (a, b), cs in by_shape.items():
        rows = t_sorted[t_start[cs][:, None] + np.arange(a)]  # (C, a)
        cols = z_sorted[z_start[cs][:, None] + np.arange(b)]  # (C, b)
        pm, pd = _enumerate(miss[rows], detect[rows[:, :, None], cols[:, None, :]],
                            hypotheses(a, b))
        p_miss[rows] = pm
        p[rows[:, :, None], cols[:, None, :]] = pd
    for c in sparse:
        rows = t_sorted[t_start[c]:t_start[c] + nt[c]]
        cols = z_sorted[z_start[c]:z_start[c] + nz[c]]
        p_miss[rows], p[np.ix_(rows, cols)] = _enumerate_sparse(miss[rows],
                                                                detect[np.ix_(rows, cols)])
    for c in large:  # rare (a cluster beyond exact_limit): thinned, or one Gibbs run
        rows = t_sorted[t_start[c]:t_start[c] + nt[c]]
        cols = z_sorted[z_start[c]:z_start[c] + nz[c]]
        sub = detect[np.ix_(rows, cols)]
        if drop > 0:
            pm, pd = _auto(miss[rows], drop_weak_links(miss[rows], sub, drop), exact_limit,
                           tol, max_iter, scalable, rng, samples, 0.0)
        else:
            pm, pd = marginals_gibbs(miss[rows], sub, rng, samples)
        p_miss[rows] = pm
        p[np.ix_(rows, cols)] = pd
    return p_miss, p


def marginals_lbp(miss: np.ndarray, detect: np.ndarray, tol: float = 1e-9,
                  max_iter: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """Marginals by loopy belief propagation (Williams & Lau 2014, Sec. III, eqs. 30-31).

    With rows scaled to ``miss_i = 1`` (``psi = detect / miss``), messages track -> meas
    ``mu_ij = psi_ij / (1 + sum_{j' != j} psi_ij' nu_ij')`` and meas -> track
    ``nu_ij = 1 / (1 + sum_{i' != i} mu_i'j)``, iterated from ``nu = 1`` until no ``nu`` moves
    by ``tol``; then ``p_ij ∝ psi_ij nu_ij``, ``p_miss ∝ 1``. All arrays ``(n, m)`` at once.
    A track whose miss weight is 0 (``r = 1``, ``Pd = 1``) gets ``1e-10`` of its largest.
    """
    n, m = detect.shape
    if n == 0 or m == 0:
        return np.ones(n), np.zeros((n, m))
    miss, detect = _row_scaled(miss, detect)
    psi = detect / np.maximum(miss, 1e-10)[:, None]
    nu = np.ones((n, m))
    for _ in range(max_iter):
        pn = psi * nu
        mu = psi / (1.0 + pn.sum(axis=1, keepdims=True) - pn)
        new = 1.0 / (1.0 + mu.sum(axis=0, keepdims=True) - mu)
        delta = np.abs(new - nu).max()
        nu = new
        if delta < tol:
            break
    pn = psi * nu
    denom = 1.0 + pn.sum(axis=1)
    return 1.0 / denom, pn / denom[:, None]


def cell_index(points: np.ndarray, size: float) -> np.ndarray:
    """The grid cell of each point ``(n, dz)`` (cells ``size`` wide, edges at multiples of
    ``size`` from the origin) as a label index ``CELL_BASE + code`` ``(n,)`` int64: the cell
    numbers per axis, offset and packed in :data:`CELL_BITS` bits (``CELL_BITS // dz`` each,
    the first axis highest), so every peer computes the same index for the same cell and the
    order of indices is a fixed order of cells. Cells beyond the packed range (2^15 cells from
    the origin per axis in 2-D: 6,500 km at 200 m) are clipped to the edge cell."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or not 1 <= pts.shape[1] <= 4:
        raise ValueError(f"points has shape {pts.shape}, expected (n, dz) with 1 <= dz <= 4")
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"cell size must be a positive finite number, got {size!r}")
    bits = CELL_BITS // pts.shape[1]
    half = 1 << (bits - 1)
    cells = np.clip(np.floor(pts / size), -half, half - 1).astype(np.int64) + half
    shifts = bits * np.arange(pts.shape[1] - 1, -1, -1, dtype=np.int64)
    return CELL_BASE + (cells << shifts).sum(axis=1)


def shared_births(index: np.ndarray, priority: np.ndarray, shared: int, origin: int, k: int,
                  start: int) -> np.ndarray:
    """Labels ``(n, 3)`` of ``n`` births at scan ``k`` that every peer makes alike: ``(shared,
    k, index[i])``, except where two births share an index (two plots in one cell): the one of
    highest ``priority (n,)`` (then the first) keeps it, the others take own labels ``(origin,
    k, start + i)`` (a label stays one track at a peer)."""
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    n = len(index)
    order = np.lexsort((np.arange(n), -np.asarray(priority, dtype=float), index))
    first = np.ones(n, dtype=bool)
    first[1:] = index[order[1:]] != index[order[:-1]]
    keep = np.zeros(n, dtype=bool)
    keep[order] = first
    out = new_labels(origin, k, n, start)
    out[keep, 0] = shared
    out[keep, 2] = index[keep]
    return out

class LmbFilterBefore(LmbFilter):
    """:class:`LmbFilter` with the step of commit 211455b (the functions of this module)."""

    def predict(self, state: LmbState, k: int | None = None) -> LmbState:
        """Survivors and births at scan ``k`` (default ``state.k + 1``): the fixed births get
        labels ``(origin, k, 0..nb-1)``, the pending adaptive ones ``nb..``; the pending births
        move through the motion model over the same steps."""
        k = state.k + 1 if k is None else int(k)
        if k <= state.k:
            raise ValueError(f"cannot predict from scan {state.k} to scan {k}")
        steps = k - state.k if state.k >= 0 else 1
        parts = [predict(state.tracks, self.motion, self.survival_probability, steps)]
        born = [GaussianMixture.empty(self.motion.dim) if self.birth is None else self.birth]
        if len(state.pending):
            F, Q = self.motion.transition(steps)
            pend = state.pending
            born.append(GaussianMixture.trusted(pend.weights, pend.means @ F.T,
                                                F @ pend.covs @ F.T + Q))
        births = GaussianMixture.concatenate(born)
        if len(births):
            b = LabelledBernoulliSet.births(births, self.origin, k)
            if self.shared_origin is not None:
                b = LabelledBernoulliSet.trusted(self._shared_labels(state.pending, k),
                                                 b.existence, b.weights, b.means, b.covs,
                                                 b.owner)
            parts.append(b)
        hits = np.concatenate((state.hits, np.zeros(len(births), dtype=np.int64)))
        return LmbState(LabelledBernoulliSet.concatenate(parts), hits, k,
                        GaussianMixture.empty(self.motion.dim))

    def _shared_labels(self, pending: GaussianMixture, k: int) -> np.ndarray:
        """Labels ``(nb, 3)`` of scan ``k``'s births (fixed components, then ``pending``, the
        adaptive births at their plots) made alike at every peer (:attr:`shared_origin`)."""
        nf = 0 if self.birth is None else len(self.birth)
        fixed = new_labels(self.shared_origin, k, nf)
        if not len(pending):
            return fixed
        plots = pending.means[:, list(self.sensor.model.selected)]
        cells = shared_births(cell_index(plots, self.birth_cell), pending.weights,
                              self.shared_origin, self.origin, k, nf)
        return np.concatenate((fixed, cells))

    def correct(self, state: LmbState, scan: np.ndarray) -> LmbState:
        """Update with scan ``Z (m, dz)``, reduce each track's mixture, delete tracks below
        ``existence_prune``, count confirmations and queue the adaptive births."""
        scan = check_scan(scan, self.sensor.model.dim)
        post, r_u = update(state.tracks, scan, self.sensor, self.method, self.gate,
                           self.component_prune, self.exact_limit, self.lbp_tol, self.scalable,
                           self._rng, self.gibbs_samples)
        post = reduce_components(post, self.component_prune, self.merge_threshold,
                                 self.max_components)
        keep = post.existence >= self.existence_prune
        hits = state.hits[keep] + (post.existence[keep] >= self.confirm_existence)
        pending = GaussianMixture.empty(self.motion.dim)
        if self.adaptive_birth and len(scan):
            r_b = adaptive_birth_existence(r_u, self.birth_rate, self.birth_max_existence)
            born = r_b >= self.existence_prune
            nb = int(born.sum())
            means = np.zeros((nb, self.motion.dim))
            means[:, list(self.sensor.model.selected)] = scan[born]
            pending = GaussianMixture.trusted(r_b[born], means,
                                              np.broadcast_to(self._birth_cov, (nb,) +
                                                              self._birth_cov.shape).copy())
        return LmbState(post.select(keep), hits.astype(np.int64), state.k, pending)

    def step(self, state: LmbState, scan: np.ndarray, k: int | None = None) -> LmbState:
        """Predict to scan ``k`` (default the next), then correct with its scan."""
        return self.correct(self.predict(state, k), scan)
