"""Marginal association probabilities for the LMB update (tracks x measurements).

The LMB update (Reuter, Vo, Vo & Dietmayer 2014, IEEE TSP 62(12), Sec. III-B) needs, for each
track ``i``, the probability that it takes measurement ``j`` or none, under the GLMB posterior
over all association hypotheses. Summing the existence of a track out of each hypothesis leaves
one weight per track and choice (Williams & Lau 2014, IEEE TAES 50(4), Sec. II):

* ``miss (n,)``: ``1 - r_i Pd`` (the track does not exist, or exists and is missed);
* ``detect (n, m)``: ``r_i Pd eta_i(z_j) / kappa(z_j)`` (exists and made ``z_j``);

and a hypothesis (an injective map of tracks to measurements-or-miss) weighs the product of
its choices. :func:`marginals_exact` enumerates every hypothesis; :func:`marginals_lbp` runs
Williams & Lau's loopy belief propagation (exact on trees, close elsewhere);
:func:`marginals` splits the bipartite graph into independent clusters and solves the small
ones exactly and the rest by LBP (``method="auto"``).
"""

from __future__ import annotations

from functools import lru_cache
from itertools import combinations, permutations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

METHODS = ("auto", "exact", "lbp")
"""Association methods :func:`marginals` accepts."""
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
    onehot = np.zeros((A.shape[0], n, m + 1))
    onehot[np.arange(A.shape[0])[:, None], np.arange(n)[None, :], A] = 1.0
    P = (w @ onehot.reshape(A.shape[0], -1)).reshape(C, n, m + 1)
    return P[:, :, 0], P[:, :, 1:]


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


def marginals(miss: np.ndarray, detect: np.ndarray, method: str = "auto",
              exact_limit: int = EXACT_LIMIT, tol: float = 1e-9,
              max_iter: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """Marginal association probabilities ``p_miss (n,)``, ``p (n, m)`` (rows sum to 1).

    ``"exact"``: every hypothesis of the whole problem; ``"lbp"``: :func:`marginals_lbp`;
    ``"auto"``: the connected clusters of the links above :data:`LINK_EPS` (a cluster's
    marginals do not depend on the others), each solved exactly if it has at most
    ``exact_limit`` hypotheses (clusters of one shape enumerated together), the rest by LBP.
    """
    if method not in METHODS:
        raise ValueError(f"unknown association method {method!r}; expected one of {METHODS}")
    miss = np.asarray(miss, dtype=float)
    detect = np.asarray(detect, dtype=float)
    n, m = detect.shape
    if method == "exact":
        return marginals_exact(miss, detect)
    if method == "lbp" or n == 0 or m == 0:
        return marginals_lbp(miss, detect, tol, max_iter)
    miss, detect = _row_scaled(miss, detect)
    ti, zj = np.nonzero(detect > LINK_EPS)
    p_miss, p = np.ones(n), np.zeros((n, m))
    if ti.size == 0:
        return p_miss, p
    graph = coo_matrix((np.ones(ti.size), (ti, n + zj)), shape=(n + m, n + m))
    _, comp = connected_components(graph, directed=False)
    # clusters: tracks with links (a linkless track keeps p_miss = 1) and their measurements
    tcomp, zcomp = comp[:n], comp[n:]
    linked_t = np.zeros(n, bool)
    linked_t[ti] = True
    linked_z = np.zeros(m, bool)
    linked_z[zj] = True
    labels, nt = np.unique(tcomp[linked_t], return_counts=True)
    nz = np.bincount(zcomp[linked_z], minlength=comp.max() + 1)[labels]
    big = []
    by_shape: dict[tuple[int, int], list[int]] = {}
    for c, a, b in zip(labels.tolist(), nt.tolist(), nz.tolist(), strict=True):
        if hypothesis_count(a, b) <= exact_limit:
            by_shape.setdefault((a, b), []).append(c)
        else:
            big.append(c)
    for (a, b), cs in by_shape.items():
        cs_arr = np.asarray(cs)
        rows = _members(tcomp, linked_t, cs_arr, a)  # (C, a)
        cols = _members(zcomp, linked_z, cs_arr, b)  # (C, b)
        d = np.where(detect[rows[:, :, None], cols[:, None, :]] > LINK_EPS,
                     detect[rows[:, :, None], cols[:, None, :]], 0.0)
        pm, pd = _enumerate(miss[rows], d, hypotheses(a, b))
        p_miss[rows] = pm
        p[rows[:, :, None], cols[:, None, :]] = pd
    if big:
        t_rows = np.flatnonzero(linked_t & np.isin(tcomp, big))
        z_cols = np.flatnonzero(linked_z & np.isin(zcomp, big))
        sub = detect[np.ix_(t_rows, z_cols)]
        pm, pd = marginals_lbp(miss[t_rows], np.where(sub > LINK_EPS, sub, 0.0), tol, max_iter)
        p_miss[t_rows] = pm
        p[np.ix_(t_rows, z_cols)] = pd
    return p_miss, p


def _members(comp: np.ndarray, linked: np.ndarray, clusters: np.ndarray,
             size: int) -> np.ndarray:
    """Indices ``(C, size)`` of the linked nodes of each cluster, in index order."""
    idx = np.flatnonzero(linked & np.isin(comp, clusters))
    order = np.argsort(comp[idx], kind="stable")
    return idx[order].reshape(len(clusters), size)


__all__ = ["EXACT_LIMIT", "METHODS", "hypotheses", "hypothesis_count", "marginals",
           "marginals_exact", "marginals_lbp"]
