"""LMB association marginals by Gibbs sampling (Vo, Vo & Hoang 2017) over the distinct
hypotheses found and their one-move neighbours (split from :mod:`tracking.lmb_association`,
issue 37).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.lmb_lbp import _row_scaled

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


__all__ = ["EXPAND_MAX", "GIBBS_CHAINS", "GIBBS_MAX", "GIBBS_MIN", "GIBBS_PER_LINK",
           "best_hypothesis", "gibbs_sample_count", "marginals_gibbs"]
