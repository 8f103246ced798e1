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
    ``"auto"``: links below :data:`LINK_EPS` dropped, LBP over the whole problem (exact on
    every cluster of the bipartite track-measurement graph that is a tree: Williams & Lau 2014,
    Sec. III), then each cluster with a cycle (a cluster's marginals do not depend on the
    others) enumerated exactly if it has at most ``exact_limit`` hypotheses (clusters of one
    shape together); larger ones keep LBP's answer.
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
    link = detect > LINK_EPS
    detect = np.where(link, detect, 0.0)
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
    for c in loopy.tolist():
        a, b = int(nt[c]), int(nz[c])
        if hypothesis_count(a, b) <= exact_limit:
            by_shape.setdefault((a, b), []).append(c)
    for (a, b), cs in by_shape.items():
        rows = t_sorted[t_start[cs][:, None] + np.arange(a)]  # (C, a)
        cols = z_sorted[z_start[cs][:, None] + np.arange(b)]  # (C, b)
        pm, pd = _enumerate(miss[rows], detect[rows[:, :, None], cols[:, None, :]],
                            hypotheses(a, b))
        p_miss[rows] = pm
        p[rows[:, :, None], cols[:, None, :]] = pd
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


__all__ = ["EXACT_LIMIT", "METHODS", "hypotheses", "hypothesis_count", "marginals",
           "marginals_exact", "marginals_lbp"]
