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
"""

from __future__ import annotations

from functools import lru_cache
from itertools import combinations, permutations

import numpy as np
from scipy.optimize import linear_sum_assignment

METHODS = ("auto", "exact", "lbp", "gibbs")
"""Association methods :func:`marginals` accepts."""
SCALABLE = ("gibbs", "lbp")
"""What ``"auto"`` runs on a cluster with a cycle beyond ``exact_limit`` hypotheses."""
GIBBS_SEED = 33
"""Seed of the Generator :func:`marginals` makes when given none (one input, one answer)."""
EXACT_LIMIT = 20_000
"""Auto solves a cluster exactly up to this many hypotheses (6 tracks x 6 measurements is
13,327; 7 x 7 is 130,922), else by LBP."""
EXACT_MAX = 2_000_000
"""``method="exact"`` refuses problems with more hypotheses than this (memory)."""
LINK_EPS = 1e-12
"""Auto drops links with ``detect_ij < LINK_EPS * max(miss_i, detect_i.)`` when it forms
clusters (their hypotheses change the marginals by about this relative amount)."""


def hypothesis_count(n: int, m: int) -> int:
    """Injective maps of ``n`` tracks into ``m`` measurements-or-miss:
    ``sum_k C(n, k) m! / (m - k)!``."""
    total, term = 0, 1
    for k in range(min(n, m) + 1):  # term = C(n, k) m! / (m - k)!
        total += term
        term = term * (n - k) * (m - k) // (k + 1)
    return total


@lru_cache(maxsize=64)
def hypotheses(n: int, m: int) -> np.ndarray:
    """Every hypothesis as a row ``(H, n)`` of choices: 0 = miss, ``j + 1`` = measurement ``j``
    (read-only, cached per shape)."""
    rows = []
    for k in range(min(n, m) + 1):
        for tracks in combinations(range(n), k):
            for meas in permutations(range(m), k):
                row = [0] * n
                for t, z in zip(tracks, meas, strict=True):
                    row[t] = z + 1
                rows.append(row)
    out = np.array(rows, dtype=np.intp).reshape(-1, n)
    out.setflags(write=False)
    return out


def _row_scaled(miss: np.ndarray, detect: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each track's weights divided by its largest: every hypothesis has one choice per track,
    so row scaling leaves the marginals unchanged and keeps the numbers at most 1."""
    top = np.maximum(miss, detect.max(axis=1, initial=0.0))
    top = np.where(top > 0, top, 1.0)
    return miss / top, detect / top[:, None]


def marginals_exact(miss: np.ndarray, detect: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact marginals by enumerating every hypothesis: ``p_miss (n,)``, ``p (n, m)``.

    ``p_ij = sum_{theta: theta(i) = j} w(theta) / sum_theta w(theta)`` with ``w(theta) =
    prod_i W[i, theta(i)]``, ``W = [miss | detect]``; in logs so long products do not underflow.
    """
    n, m = detect.shape
    if n == 0:
        return np.zeros(0), np.zeros((0, m))
    count = hypothesis_count(n, m)
    if count > EXACT_MAX:
        raise ValueError(f"exact association of {n} tracks x {m} measurements has {count} "
                         f"hypotheses (limit {EXACT_MAX}); use method='lbp' or 'auto'")
    pm, pd = _enumerate(miss[None], detect[None], hypotheses(n, m))
    return pm[0], pd[0]


@lru_cache(maxsize=64)
def _cells(n: int, m: int) -> np.ndarray:
    """``i (m + 1) + A[h, i]`` for :func:`hypotheses` ``A``: each choice's cell in
    ``(n, m + 1)``, ``(H, n)``."""
    return hypotheses(n, m) + np.arange(n) * (m + 1)


def _enumerate(miss: np.ndarray, detect: np.ndarray,
               A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`marginals_exact` of ``C`` problems of one shape at once: ``miss (C, n)``,
    ``detect (C, n, m)``, hypotheses ``A (H, n)``; returns ``(C, n)``, ``(C, n, m)``."""
    C, n, m = detect.shape
    W = np.concatenate((miss[:, :, None], detect), axis=2)  # (C, n, m + 1)
    top = W.max(axis=2, keepdims=True)
    with np.errstate(divide="ignore"):
        logW = np.log(W / np.where(top > 0, top, 1.0))
    logw = logW[:, np.arange(n)[None, :], A].sum(axis=2)  # (C, H)
    logw -= logw.max(axis=1, keepdims=True)
    w = np.exp(logw)
    w /= w.sum(axis=1, keepdims=True)
    cell = _cells(n, m)  # (H, n): flat index i (m + 1) + A[h, i] of each choice
    flat = (np.arange(C)[:, None, None] * (n * (m + 1)) + cell[None]).ravel()
    P = np.bincount(flat, np.repeat(w.ravel(), n), C * n * (m + 1)).reshape(C, n, m + 1)
    return P[:, :, 0], P[:, :, 1:]


def _enumerate_sparse(miss: np.ndarray, detect: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`marginals_exact` of one problem through its links only: the hypotheses are grown
    track by track (each partial one extended by the track's miss and each linked measurement
    it leaves free), so the work is the number of hypotheses of nonzero weight, at most
    ``prod_i (1 + links_i)``, not :func:`hypothesis_count`'s dense count. ``(n,)``, ``(n, m)``."""
    n, m = detect.shape
    W = np.concatenate((miss[:, None], detect), axis=1)  # (n, m + 1)
    with np.errstate(divide="ignore"):
        logW = np.log(W / np.maximum(W.max(axis=1, keepdims=True), 1e-300))
    hyps = np.zeros((1, 0), dtype=np.intp)
    used = np.zeros((1, m + 1), dtype=bool)  # measurement j + 1 taken (column 0 never)
    lw = np.zeros(1)
    for i in range(n):
        ch = np.flatnonzero(W[i] > 0)
        h, e = np.nonzero(~used[:, ch])
        c = ch[e]
        hyps = np.concatenate((hyps[h], c[:, None]), axis=1)
        used = used[h]
        used[np.arange(len(h)), c] = True
        used[:, 0] = False
        lw = lw[h] + logW[i, c]
    if len(lw) == 0:  # no hypothesis of nonzero weight (a track with nothing): as dense
        return _enumerate(miss[None], detect[None], hypotheses(n, m))
    w = np.exp(lw - lw.max())
    w /= w.sum()
    P = np.bincount((hyps + np.arange(n) * (m + 1)).ravel(), np.repeat(w, n),
                    n * (m + 1)).reshape(n, m + 1)
    return P[:, 0], P[:, 1:]


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


GIBBS_CHAINS = 32
"""Parallel Gibbs chains of :func:`marginals_gibbs` (NumPy rows, one sweep moves them all)."""
GIBBS_PER_LINK = 50
"""Gibbs draws per link (nonzero ``detect_ij``) of a problem, within ``[GIBBS_MIN,
GIBBS_MAX]`` (benchmarks/bench_lmb_association.py measured the error against this)."""
GIBBS_MIN = 1000
GIBBS_MAX = 20_000
EXPAND_MAX = 2_000_000
"""At most this many one-move neighbours (hypotheses x links) are formed; beyond it only the
heaviest sampled hypotheses are expanded (memory)."""


def gibbs_sample_count(links: int) -> int:
    """Gibbs draws for a problem with ``links`` nonzero detection weights: grows with the size
    of the problem (more links, more hypotheses of weight to find), within
    ``[GIBBS_MIN, GIBBS_MAX]``."""
    return int(min(GIBBS_MAX, max(GIBBS_MIN, GIBBS_PER_LINK * links)))


def best_hypothesis(miss: np.ndarray, detect: np.ndarray) -> np.ndarray:
    """The heaviest hypothesis ``(n,)`` (0 = miss, ``j + 1`` = measurement ``j``): a linear
    assignment on ``-log`` weights with one private miss column per track (the 1-best of
    Vo, Vo & Hoang 2017, Sec. III-A, by the Hungarian method instead of Murty's)."""
    n, m = detect.shape
    big = 1e6  # a weight of 0 (or an absent miss column): never chosen while any other is
    with np.errstate(divide="ignore"):
        cost = np.full((n, m + n), big)
        cost[:, :m] = np.minimum(-np.log(detect), big)
        cost[np.arange(n), m + np.arange(n)] = np.minimum(-np.log(miss), big)
    rows, cols = linear_sum_assignment(cost)
    out = np.zeros(n, dtype=np.intp)
    out[rows] = np.where(cols < m, cols + 1, 0)
    return out


def marginals_gibbs(miss: np.ndarray, detect: np.ndarray, rng: np.random.Generator,
                    samples: int | None = None,
                    chains: int = GIBBS_CHAINS) -> tuple[np.ndarray, np.ndarray]:
    """Marginals over the distinct hypotheses a Gibbs sampler finds and their one-move
    neighbours, each weighed by its true weight: ``p_ij = sum_{theta in T: theta(i) = j}
    w(theta) / sum_{theta in T} w(theta)``.

    The sampler is Vo, Vo & Hoang 2017 ("An efficient implementation of the generalized
    labeled multi-Bernoulli filter", IEEE TSP 65(8), Sec. III-B, Algorithm 1) on the LMB's
    collapsed choices (existence summed out, as in the module docstring): ``chains`` chains
    side by side as rows of a ``(chains, n)`` array, all from the heaviest hypothesis
    (:func:`best_hypothesis`, so ``T`` always holds it); a sweep draws each track's choice in
    turn from its conditional ``W[i, c]`` over the choices the other tracks of its chain leave
    free (the miss always free), then a Metropolis swap of two random tracks' choices per chain
    (single-site Gibbs swaps two tracks only through a miss, which may weigh ~0 when
    ``r Pd ~ 1``). ``T`` is every state drawn plus every hypothesis one move away from one
    (a track moved to the miss or to a measurement its hypothesis leaves free): the
    neighbours cost one bincount, not sampling, and take most of the mass the samples miss
    (on 8 of benchmarks/bench_lmb_association.py's 7 x 7 cases, one run, the largest
    existence error fell from 0.028 to 0.002 with them). As ``T`` covers the mass the answer
    tends to the exact marginals; the weight of the hypotheses outside ``T`` is the error.
    ``samples``: total draws (default :func:`gibbs_sample_count`). A track whose miss weight is
    0 gets ``1e-10`` of its largest weight, as in :func:`marginals_lbp`.
    """
    n, m = detect.shape
    if n == 0 or m == 0:
        return np.ones(n), np.zeros((n, m))
    miss, detect = _row_scaled(miss, detect)
    W = np.concatenate((np.maximum(miss, 1e-10)[:, None], detect), axis=1)  # (n, m + 1)
    if samples is None:
        samples = gibbs_sample_count(int(np.count_nonzero(detect)))
    K = int(chains)
    sweeps = max(1, -(-int(samples) // K))
    theta = np.tile(best_hypothesis(W[:, 0], W[:, 1:]), (K, 1))  # (K, n)
    kk = np.arange(K)
    free = np.ones((K, m + 1))  # 1: choice j free in the chain (the miss, j = 0, always)
    free[kk[:, None], theta] = 0.0
    free[:, 0] = 1.0
    seen = [theta.copy()]
    for _ in range(sweeps):
        u = rng.random((n, K, 1))
        for i in range(n):
            free[kk, theta[:, i]] = 1.0
            cdf = np.cumsum(free * W[i], axis=1)  # (K, m + 1)
            c = np.minimum((cdf <= u[i] * cdf[:, -1:]).sum(axis=1), m)
            theta[:, i] = c
            free[kk, c] = 0.0
            free[:, 0] = 1.0
        if n > 1:
            a = rng.integers(0, n, size=K)
            b = (a + rng.integers(1, n, size=K)) % n
            ta, tb = theta[kk, a], theta[kk, b]
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = W[a, tb] * W[b, ta] / (W[a, ta] * W[b, tb])
            swap = rng.random(K) < ratio
            theta[kk[swap], a[swap]], theta[kk[swap], b[swap]] = tb[swap], ta[swap]
        seen.append(theta.copy())
    return _expanded(np.concatenate(seen), W)


@lru_cache(maxsize=64)
def _zobrist(n: int, k: int) -> np.ndarray:
    """Random 63-bit codes ``(n, k)`` of (track, choice), fixed per shape: a hypothesis's key
    is the XOR of its choices' codes (Zobrist hashing; two of ``H`` distinct hypotheses share
    a key with probability about ``H^2 / 2^64``)."""
    out = np.random.default_rng([n, k]).integers(0, 2**63, size=(n, k), dtype=np.int64)
    out.setflags(write=False)
    return out


def _expanded(S: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Marginals over the distinct hypotheses of ``S (N, n)`` and every hypothesis one choice
    away from one of them, each weighed once by ``prod_i W[i, theta_i]`` (``W (n, k)``).
    Neighbours are never formed as rows: a candidate is ``(h, i, c)``, hypothesis ``h`` with
    track ``i`` on choice ``c``; its key is ``h``'s with two codes XOR-ed, its log weight
    ``h``'s plus ``log W[i, c] - log W[i, theta_h(i)]``."""
    n, k = W.shape
    Zc = _zobrist(n, k)
    ar = np.arange(n)
    key = np.bitwise_xor.reduce(Zc[ar, S], axis=1)  # (N,)
    _, first = np.unique(key, return_index=True)
    T, key = S[first], key[first]  # (H, n) distinct samples
    H = len(T)
    with np.errstate(divide="ignore"):
        logW = np.log(W)
    own = logW[ar, T]  # (H, n)
    logw = own.sum(axis=1)  # (H,)
    li, lc = np.nonzero(W > 0)  # (L,) the links, misses included: the only moves of weight
    L = len(li)
    grow = np.arange(H)
    if H * L > EXPAND_MAX:  # expand the heaviest only
        grow = np.argsort(-logw, kind="stable")[:max(1, EXPAND_MAX // L)]
    G = len(grow)  # tracks of each expanded hypothesis on each choice:
    occ = np.bincount((T[grow] + (np.arange(G) * k)[:, None]).ravel(),
                      minlength=G * k).reshape(G, k)
    cur = T[grow][:, li]  # (G, L): where each link's track is now
    free = (lc == 0) | (occ[:, lc] - (cur == lc) == 0)  # (G, L): track li may move to lc
    g, e = np.nonzero(free)
    h = np.concatenate((grow[g], np.arange(H)))  # and each sampled hypothesis itself
    i = np.concatenate((li[e], np.zeros(H, dtype=np.intp)))
    c = np.concatenate((lc[e], T[:, 0]))
    lw = logw[h] + logW[i, c] - own[h, i]
    ckey = key[h] ^ Zc[i, T[h, i]] ^ Zc[i, c]
    keep = np.isfinite(lw)
    _, u = np.unique(ckey[keep], return_index=True)
    sel = np.flatnonzero(keep)[u]
    h, i, c, lw = h[sel], i[sel], c[sel], lw[sel]
    w = np.exp(lw - lw.max())
    w /= w.sum()
    # each candidate is T[h] with track i on c: T[h]'s cells get its weight, then track i moves
    P = np.bincount((T + ar * k).ravel(), np.repeat(np.bincount(h, w, H), n), n * k)
    P += np.bincount(i * k + c, w, n * k) - np.bincount(i * k + T[h, i], w, n * k)
    P = np.maximum(P.reshape(n, k), 0.0)
    return P[:, 0], P[:, 1:]


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


__all__ = ["DROP_BUDGET", "EXACT_LIMIT", "GIBBS_CHAINS", "METHODS", "SCALABLE",
           "best_hypothesis", "drop_weak_links", "gibbs_sample_count", "hypotheses",
           "hypothesis_count", "marginals", "marginals_exact", "marginals_gibbs",
           "marginals_lbp"]
