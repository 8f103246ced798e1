"""Multi-target error metrics (docs/algorithms.md "Metrics"): OSPA, GOSPA, cardinality, RMSE."""

from __future__ import annotations

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


def cardinality_error(X: np.ndarray, Y: np.ndarray) -> int:
    """``|n - m|``: the difference in the number of estimated and true targets."""
    n = np.atleast_2d(X).shape[0] if np.size(X) else 0
    m = np.atleast_2d(Y).shape[0] if np.size(Y) else 0
    return abs(n - m)


def rmse(errors: np.ndarray, axis: int = 0) -> np.ndarray:
    """Root mean square of ``errors`` along ``axis``."""
    return np.sqrt(np.mean(np.square(errors), axis=axis))
