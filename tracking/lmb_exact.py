"""Exact LMB association marginals: every hypothesis enumerated, densely by shape or through
the links (split from :mod:`tracking.lmb_association`, issue 37, whose docstring has the model).
"""

from __future__ import annotations

from functools import lru_cache
from itertools import combinations, permutations

import numpy as np

EXACT_MAX = 2_000_000
"""``method="exact"`` refuses problems with more hypotheses than this (memory)."""


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


__all__ = ["EXACT_MAX", "hypotheses", "hypothesis_count", "marginals_exact"]
