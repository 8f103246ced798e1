"""Marginal association probabilities for the LMB update (tracks x measurements).

The LMB update (Reuter, Vo, Vo & Dietmayer 2014, IEEE TSP 62(12), Sec. III-B) needs, for each
track ``i``, the probability that it takes measurement ``j`` or none, under the GLMB posterior
over all association hypotheses. Summing the existence of a track out of each hypothesis leaves
one weight per track and choice (Williams & Lau 2014, IEEE TAES 50(4), Sec. II):

* ``miss (n,)``: ``1 - r_i Pd`` (the track does not exist, or exists and is missed);
* ``detect (n, m)``: ``r_i Pd eta_i(z_j) / kappa(z_j)`` (exists and made ``z_j``);

and a hypothesis (an injective map of tracks to measurements-or-miss) weighs the product of
its choices. :func:`marginals_exact` enumerates every hypothesis; :func:`marginals_lbp` runs
Williams & Lau's loopy belief propagation (exact on trees, close elsewhere; on tightly coupled
small cases its existence is off by up to 0.066); :func:`marginals_gibbs` weighs the distinct
hypotheses a Gibbs sampler finds (Vo, Vo & Hoang 2017), tending to exact as they cover the
mass; :func:`marginals` splits the bipartite graph into independent clusters and solves the
small ones exactly and the rest by Gibbs (``method="auto"``; docs/labelled-tracking.md has the
errors and costs of each).

The exact enumeration lives in :mod:`tracking.lmb_exact`, LBP in :mod:`tracking.lmb_lbp`, Gibbs
in :mod:`tracking.lmb_gibbs` (issue 37); their names stay importable from here.
"""

from __future__ import annotations

import numpy as np
from sensornet.tracking.lmb_exact import (
    EXACT_MAX,
    _enumerate,
    _enumerate_sparse,
    hypotheses,
    hypothesis_count,
    marginals_exact,
)
from sensornet.tracking.lmb_gibbs import (
    EXPAND_MAX,
    GIBBS_CHAINS,
    GIBBS_MAX,
    GIBBS_MIN,
    GIBBS_PER_LINK,
    best_hypothesis,
    gibbs_sample_count,
    marginals_gibbs,
)
from sensornet.tracking.lmb_lbp import _row_scaled, lbp_scaled, marginals_lbp

METHODS = ("auto", "exact", "lbp", "gibbs")
"""Association methods :func:`marginals` accepts."""
SCALABLE = ("gibbs", "lbp")
"""What ``"auto"`` runs on a cluster with a cycle beyond ``exact_limit`` hypotheses."""
GIBBS_SEED = 33
"""Seed of the Generator :func:`marginals` makes when given none (one input, one answer)."""
EXACT_LIMIT = 20_000
"""Auto solves a cluster exactly up to this many hypotheses (6 tracks x 6 measurements is
13,327; 7 x 7 is 130,922), else by LBP."""
GIBBS_TRACKS = 12
"""Auto samples a loopy cluster beyond ``exact_limit`` by Gibbs only up to this many tracks;
a larger one keeps LBP's marginals (Williams & Lau 2014). Gibbs' CPU grows with tracks x
draws (a Python sweep per track, draws per link), so clusters of 15-33 tracks, which a peer
host that fell behind grew from spread tentative tracks, cost 70-190 ms a call and the host
fell further behind; LBP costs ~0.2 ms there. No on-time training run reached it
(docs/labelled-tracking.md, "A bound on the LMB step's association")."""

LINK_EPS = 1e-12
"""Auto drops links with ``detect_ij < LINK_EPS * max(miss_i, detect_i.)`` when it forms
clusters (their hypotheses change the marginals by about this relative amount)."""


def marginals(miss: np.ndarray, detect: np.ndarray, method: str = "auto",
              exact_limit: int = EXACT_LIMIT, tol: float = 1e-9, max_iter: int = 1000,
              scalable: str = "gibbs", rng: np.random.Generator | None = None,
              samples: int | None = None,
              gibbs_tracks: int | None = GIBBS_TRACKS) -> tuple[np.ndarray, np.ndarray]:
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
    ``exact_limit`` goes to :func:`marginals_gibbs` if it has at most ``gibbs_tracks`` tracks
    (None: any size), else keeps LBP's answer (:data:`GIBBS_TRACKS`: a bound on one step's
    cost). ``scalable="lbp"`` keeps LBP's answer on every large cluster. ``rng`` feeds the
    Gibbs draws (None: a fresh ``default_rng(GIBBS_SEED)``, so one input gives one answer);
    ``samples``: Gibbs draws per problem or cluster (None: :func:`gibbs_sample_count`). Auto,
    like LBP and Gibbs, gives a track whose miss weight is 0 (``r = Pd = 1``) ``1e-10`` of its
    largest weight.
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
    return _auto(miss, detect, exact_limit, tol, max_iter, scalable, rng, samples, DROP_BUDGET,
                 gibbs_tracks)


SPARSE_FROM = 500
"""Loopy clusters with at most this many dense hypotheses are enumerated densely, batched by
shape (:func:`hypotheses` tables, cached); larger ones through their links
(:func:`_enumerate_sparse`: at most as many hypotheses, and no table to build in Python)."""
DROP_BUDGET = 1e-3
""":func:`drop_weak_links`' bound on the mass of the hypotheses it removes from a cluster
beyond ``exact_limit`` (so on any marginal of it, up to a factor ``1 / (1 - bound)``)."""


def drop_weak_links(miss: np.ndarray, detect: np.ndarray, budget: float) -> np.ndarray:
    """``detect (n, m)`` with its weakest links set to 0: by ``detect_ij / miss_i`` ascending,
    while their sum stays at most ``budget``. Every hypothesis through link ``ij`` weighs
    ``detect_ij / miss_i`` times the one with track ``i`` missed instead, so the hypotheses
    removed carry at most that sum of the total mass. (A track with ``miss_i = 0`` keeps its
    links.)"""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(detect > 0, detect / miss[:, None], np.inf)
    flat = ratio.ravel()
    order = np.argsort(flat, kind="stable")
    cut = int(np.searchsorted(np.cumsum(flat[order]), budget, side="right"))
    out = detect.copy().ravel()
    out[order[:cut]] = 0.0
    return out.reshape(detect.shape)


def _auto(miss: np.ndarray, detect: np.ndarray, exact_limit: int, tol: float, max_iter: int,
          scalable: str, rng: np.random.Generator, samples: int | None,
          drop: float, gibbs_tracks: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`marginals` ``"auto"`` on row-scaled weights (each row's largest exactly 1) with
    the misses floored at 1e-10 and whose zero links are absent (so LBP runs on ``detect /
    miss`` with no second scaling); a large loopy cluster is thinned by ``drop`` (which keeps
    each row's largest) and solved again (``drop`` 0: Gibbs, on at most ``gibbs_tracks``
    tracks)."""
    n, m = detect.shape
    link = detect > 0
    p_miss, p = lbp_scaled(detect / miss[:, None], tol, max_iter)  # = marginals_lbp's answer
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
                           tol, max_iter, scalable, rng, samples, 0.0, gibbs_tracks)
        elif gibbs_tracks is not None and len(rows) > gibbs_tracks:
            continue  # LBP's answer stays: Gibbs' cost grows with the tracks (GIBBS_TRACKS)
        else:
            pm, pd = marginals_gibbs(miss[rows], sub, rng, samples)
        p_miss[rows] = pm
        p[np.ix_(rows, cols)] = pd
    return p_miss, p


def _clusters(link: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Connected components of the bipartite graph ``link (n, m)``: each node labelled by the
    smallest track index in its component (a measurement without links: ``n``). Min-label
    propagation over the dense matrix, one sweep per step of the graph's diameter."""
    n, m = link.shape
    t = np.arange(n)
    while True:
        z = np.where(link, t[:, None], n).min(axis=0)
        new = np.minimum(t, np.where(link, z[None, :], n).min(axis=1))
        if np.array_equal(new, t):
            return t, z
        t = new


def _by_cluster(comp: np.ndarray, linked: np.ndarray,
                ncomp: int) -> tuple[np.ndarray, np.ndarray]:
    """The linked nodes sorted by cluster ``(k,)`` and each cluster's first position
    ``(ncomp,)`` in that order."""
    idx = np.flatnonzero(linked)
    idx = idx[np.argsort(comp[idx], kind="stable")]
    return idx, np.searchsorted(comp[idx], np.arange(ncomp))


__all__ = ["DROP_BUDGET", "EXACT_LIMIT", "EXACT_MAX", "EXPAND_MAX", "GIBBS_CHAINS", "GIBBS_MAX",
           "GIBBS_MIN", "GIBBS_PER_LINK", "GIBBS_TRACKS", "METHODS", "SCALABLE",
           "best_hypothesis", "drop_weak_links", "gibbs_sample_count", "hypotheses",
           "hypothesis_count", "marginals", "marginals_exact", "marginals_gibbs", "marginals_lbp"]
