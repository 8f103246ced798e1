"""Multi-target error metrics (docs/algorithms.md "Metrics"): OSPA, GOSPA, cardinality, RMSE."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from functools import cache

import numpy as np
from scipy.optimize import linear_sum_assignment


def _cost(X: np.ndarray, Y: np.ndarray, c: float, p: float) -> np.ndarray:
    D = np.linalg.norm(X[:, None, :] - Y[None, :, :], axis=-1)
    return np.minimum(D, c) ** p


def ospa(X: np.ndarray, Y: np.ndarray, c: float = 200.0, p: float = 2.0) -> float:
    """OSPA distance (Schuhmacher, Vo & Vo 2008) between point sets ``X (n, d)``, ``Y (m, d)``.

    ``(1/max(n,m) (min_pi sum_i min(c, |x_i - y_pi(i)|)^p + c^p |m - n|))^(1/p)``, the
    assignment by ``scipy.optimize.linear_sum_assignment``. Both empty: 0.
    """
    X, Y = np.atleast_2d(X), np.atleast_2d(Y)
    n, m = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
    if n == 0 and m == 0:
        return 0.0
    if n == 0 or m == 0:
        return float(c)
    C = _cost(X, Y, c, p)
    r, k = linear_sum_assignment(C)
    total = C[r, k].sum() + c**p * abs(m - n)
    return float((total / max(n, m)) ** (1.0 / p))


def gospa(X: np.ndarray, Y: np.ndarray, c: float = 200.0, p: float = 2.0,
          alpha: float = 2.0) -> float:
    """GOSPA (Rahmathullah, García-Fernández & Svensson 2017), unnormalised, ``0 < alpha <= 2``.

    Definition (for ``n <= m``): ``(min_pi sum_i min(c, d)^p + c^p / alpha (m - n))^(1/p)``.
    With ``alpha = 2`` (the default) this equals the assignment form
    ``min_gamma sum_assigned d^p + c^p / 2 (n + m - 2 |gamma|)``.
    """
    X, Y = np.atleast_2d(X), np.atleast_2d(Y)
    n, m = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
    if n == 0 and m == 0:
        return 0.0
    if n == 0 or m == 0:
        return float((c**p / alpha * (n + m)) ** (1.0 / p))
    # Every point of the smaller set is assigned at the cut-off distance min(c, d); only the
    # cardinality difference pays c^p / alpha. (For alpha = 2 a pair cut at c costs c^p, the
    # same as leaving both points unassigned; for alpha < 2 it must not cost 2 c^p / alpha.)
    C = _cost(X, Y, c, p)
    r, k = linear_sum_assignment(C)
    total = C[r, k].sum() + c**p / alpha * abs(m - n)
    return float(total ** (1.0 / p))


def gospa_parts(X: np.ndarray, Y: np.ndarray, c: float = 200.0,
                p: float = 2.0) -> tuple[float, float, int, int]:
    """GOSPA with ``alpha = 2`` split into what it charges: ``(gospa, localisation, missed,
    false)`` for estimates ``X (n, d)`` and truth ``Y (m, d)``.

    Rahmathullah, García-Fernández & Svensson 2017, Prop. 1: ``gospa^p = localisation
    + c^p / 2 (missed + false)``, where ``localisation`` sums ``d^p`` over the optimal
    assignment's pairs closer than ``c`` and a pair at or beyond ``c`` counts as one missed
    target and one false estimate (the same cost, ``c^p``). ``missed`` and ``false`` are counts.
    """
    X, Y = np.atleast_2d(X), np.atleast_2d(Y)
    n, m = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
    if n == 0 or m == 0:
        return float((c**p / 2 * (n + m)) ** (1.0 / p)), 0.0, m, n
    D = np.linalg.norm(X[:, None, :] - Y[None, :, :], axis=-1)
    C = np.minimum(D, c) ** p
    r, k = linear_sum_assignment(C)
    close = D[r, k] < c
    loc = float(C[r, k][close].sum())
    paired = int(close.sum())
    missed, false = m - paired, n - paired
    return float((loc + c**p / 2 * (missed + false)) ** (1.0 / p)), loc, missed, false


def ospa_gospa_parts(X: np.ndarray, Y: np.ndarray, c: float = 200.0, p: float = 2.0
                     ) -> tuple[float, tuple[float, float, int, int]]:
    """:func:`ospa` and :func:`gospa_parts` of the same sets from one cost matrix and one
    assignment (both minimise ``sum min(c, d)^p``; the same numbers as calling each). With one
    point on either side the assignment is the cheapest pair (any optimal pair gives the same
    sums: tied costs below ``c`` are tied distances), so the solver is not called."""
    X, Y = np.atleast_2d(X), np.atleast_2d(Y)
    n, m = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
    if n == 0 or m == 0:
        return ospa(X, Y, c, p), gospa_parts(X, Y, c, p)
    D = np.linalg.norm(X[:, None, :] - Y[None, :, :], axis=-1)
    C = np.minimum(D, c) ** p
    if n == 1 or m == 1:
        j = int(C.argmin())
        r, k = np.array([j // m]), np.array([j % m])
    else:
        r, k = linear_sum_assignment(C)
    Crk = C[r, k]
    o = float(((Crk.sum() + c**p * abs(m - n)) / max(n, m)) ** (1.0 / p))
    close = D[r, k] < c
    loc = float(Crk[close].sum())
    paired = int(close.sum())
    missed, false = m - paired, n - paired
    return o, (float((loc + c**p / 2 * (missed + false)) ** (1.0 / p)), loc, missed, false)


PERMUTED_UP_TO = 6
"""Largest ``max(n, m)`` that :func:`ospa_gospa_parts_many` solves by trying every
assignment at once (6! = 720 per problem); larger problems go to the solver one by one."""


@cache
def _permutations(s: int) -> np.ndarray:
    """``(s!, s)``: every permutation of ``range(s)``."""
    return np.array(list(itertools.permutations(range(s))), dtype=np.intp).reshape(-1, s)


def ospa_gospa_parts_many(problems: Sequence[tuple[np.ndarray, np.ndarray]],
                          c: float = 200.0, p: float = 2.0
                          ) -> list[tuple[float, tuple[float, float, int, int]]]:
    """``[ospa_gospa_parts(X, Y, c, p) for X, Y in problems]``, the small ones in one pass.

    A host scores its peers' estimates of a scan together. Each problem's cost matrix is
    padded to ``s x s`` (``s``: the largest ``max(n, m)`` of the batch, at most
    :data:`PERMUTED_UP_TO`): a padded row or column against a real point costs ``c^p`` (the
    cardinality penalty), padding against padding nothing, so the cheapest of the ``s!``
    permutations is an optimal assignment of the problem, and its real pairs give the same
    sums as :func:`ospa_gospa_parts`. Problems with an empty side, or larger, are solved alone.
    """
    out: list = [None] * len(problems)
    idx, Xs, Ys = [], [], []
    for i, (X, Y) in enumerate(problems):
        if type(X) is not np.ndarray or X.ndim != 2:
            X = np.atleast_2d(X)
        if type(Y) is not np.ndarray or Y.ndim != 2:
            Y = np.atleast_2d(Y)
        n, m = X.shape[0] if X.size else 0, Y.shape[0] if Y.size else 0
        if n == 0 or m == 0 or max(n, m) > PERMUTED_UP_TO:
            out[i] = ospa_gospa_parts(X, Y, c, p)
        else:
            idx.append(i)
            Xs.append(X)
            Ys.append(Y)
    if not idx:
        return out
    ns = np.array([len(X) for X in Xs])
    ms = np.array([len(Y) for Y in Ys])
    s = int(max(ns.max(), ms.max()))
    P, d = len(idx), Xs[0].shape[1]
    Xp = np.zeros((P, s, d))
    Yp = np.zeros((P, s, d))
    rows = np.arange(s)
    realx = rows[None, :] < ns[:, None]  # (P, s)
    realy = rows[None, :] < ms[:, None]
    Xp[realx] = np.concatenate(Xs)
    Yp[realy] = np.concatenate(Ys)
    diff = Xp[:, :, None, :] - Yp[:, None, :, :]
    D = np.sqrt(np.einsum("pijk,pijk->pij", diff, diff))  # (P, s, s)
    cp = c**p
    C = np.minimum(D, c) ** p
    one = realx[:, :, None] ^ realy[:, None, :]  # a real point against padding
    C = np.where(realx[:, :, None] & realy[:, None, :], C, np.where(one, cp, 0.0))
    perms = _permutations(s)
    totals = C[:, rows, perms].sum(axis=-1)  # (P, s!): cost of each assignment
    best = perms[totals.argmin(axis=1)]  # (P, s)
    pr = np.arange(P)[:, None]
    paired = realx & realy[pr, best]  # real pairs of the best assignment
    Dp, Cp = D[pr, rows, best], C[pr, rows, best]
    close = paired & (Dp < c)
    loc = np.where(close, Cp, 0.0).sum(axis=1)
    pairs = np.where(paired, Cp, 0.0).sum(axis=1)
    npair = close.sum(axis=1)
    o = ((pairs + cp * np.abs(ms - ns)) / np.maximum(ns, ms)) ** (1.0 / p)
    missed, false = ms - npair, ns - npair
    g = (loc + cp / 2 * (missed + false)) ** (1.0 / p)
    for i, *v in zip(idx, o.tolist(), g.tolist(), loc.tolist(), missed.tolist(),
                     false.tolist(), strict=True):
        out[i] = (v[0], tuple(v[1:]))
    return out


def cardinality_error(X: np.ndarray, Y: np.ndarray) -> int:
    """``|n - m|``: the difference in the number of estimated and true targets."""
    n = np.atleast_2d(X).shape[0] if np.size(X) else 0
    m = np.atleast_2d(Y).shape[0] if np.size(Y) else 0
    return abs(n - m)


def rmse(errors: np.ndarray, axis: int = 0) -> np.ndarray:
    """Root mean square of ``errors`` along ``axis``."""
    return np.sqrt(np.mean(np.square(errors), axis=axis))
