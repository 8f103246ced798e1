"""Trajectory GOSPA (García-Fernández, Rahmathullah & Svensson 2020, IEEE TSP 68, "A metric on
the space of finite sets of trajectories for evaluation of multi-target tracking algorithms").

Trajectories are dense arrays over a common scan grid: ``est (T, n, d)`` and ``truth (T, m, d)``
with NaN rows where a trajectory is absent (built by :mod:`tracking.track_metrics`).

The metric (alpha = 2) is ``d^p = min over assignment sequences W^1..W^T of
sum_t tr(D^t' W^t) + gamma^p / 2 sum_t sum_{i<=n, j<=m} |W^{t+1}_ij - W^t_ij|`` where ``W^t`` is
an ``(n+1) x (m+1)`` assignment matrix (last row/column: unassigned) and ``D^t_ij`` is
``min(|x - y|, c)^p`` when both exist, ``c^p / 2`` when exactly one exists, 0 when neither does
(and ``c^p / 2`` against the dummy for a present trajectory). The LP relaxation (``W`` real,
the paper's Section IV) is itself a metric and is what :func:`trajectory_gospa` solves by
default; ``integer=True`` solves the binary programme (the assignment form of the metric,
Definition 2: a full switch costs ``gamma^p``, assigned <-> unassigned half of it).

Reduced programme solved here (same optimum, fewer variables): substitute the dummy entries by
``1 - sum`` so only pairs ``e = (i, j)`` that are ever both present closer than ``c`` keep a
variable; any other pair costs exactly the dummies' ``c^p / 2 + c^p / 2`` (or ``c^p / 2 + 0``,
or ``0``) at every scan, so moving its weight to the dummies leaves the localisation cost
unchanged and cannot raise the switching term (dummy entries are not in it). Per scan the
reduced cost of ``w_te`` is ``min(d^p - c^p, 0)`` when both are present, else 0, plus the
constant ``c^p / 2 (|x_t| + |y_t|)``; row sums are ``<= 1``; ``z_te >= |w_{t+1,e} - w_te|``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import Bounds, LinearConstraint, linprog, milp


@dataclass(frozen=True)
class TGospa:
    """Trajectory GOSPA and what it charges (all in units of ``distance^p`` except
    ``distance`` itself, and the counts, which are fractional if the LP optimum is).

    ``distance = (localisation + c^p / 2 (missed + false) + switching)^(1/p)``; ``missed``,
    ``false``: target-scans left unlocalised; ``switches = switching / gamma^p`` (a full switch
    counts 1, assigned <-> unassigned 1/2).
    ``per_scan``: ``(T, 3)`` localisation, missed, false costs per scan; ``switch_per_scan``:
    ``(T-1,)`` switching cost between consecutive scans. ``integral``: the optimal weights are
    0/1 (then the LP value equals the integer metric)."""

    distance: float
    localisation: float
    missed: float
    false: float
    switches: float
    switching: float
    integral: bool
    per_scan: np.ndarray
    switch_per_scan: np.ndarray


def _presence(X: np.ndarray, name: str) -> np.ndarray:
    if X.ndim != 3:
        raise ValueError(f"{name} must be (T, tracks, d), got shape {X.shape}")
    return ~np.isnan(X).any(axis=-1)


def trajectory_gospa(est: np.ndarray, truth: np.ndarray, c: float = 200.0, p: float = 2.0,
                     gamma: float = 200.0, integer: bool = False) -> TGospa:
    """Trajectory GOSPA with ``alpha = 2`` between ``est (T, n, d)`` and ``truth (T, m, d)``
    (NaN = absent), by the reduced linear programme (module docstring) with HiGHS;
    ``integer=True`` solves it as a mixed-integer programme (the assignment-form metric)."""
    est, truth = np.asarray(est, float), np.asarray(truth, float)
    ex, ty = _presence(est, "est"), _presence(truth, "truth")
    if est.shape[0] != truth.shape[0] or est.shape[2] != truth.shape[2]:
        raise ValueError(f"est {est.shape} and truth {truth.shape} differ in scans or dimension")
    if not (c > 0 and p >= 1 and gamma > 0):
        raise ValueError(f"need c > 0, p >= 1, gamma > 0; got c={c}, p={p}, gamma={gamma}")
    T = est.shape[0]
    cp, half = c**p, c**p / 2
    D = np.linalg.norm(est[:, :, None, :] - truth[:, None, :, :], axis=-1)  # (T, n, m), NaN
    both = ex[:, :, None] & ty[:, None, :]
    close = both & (D < c)
    ei, ej = np.nonzero(close.any(axis=0))  # pairs that may take weight
    K = ei.size
    if K == 0:
        w = np.zeros((T, 0))
    else:
        Dp = np.where(close[:, ei, ej], D[:, ei, ej] ** p, cp)  # (T, K); >= c^p: no gain
        r = np.minimum(Dp - cp, 0.0)
        nw, nz = T * K, (T - 1) * K
        cost = np.concatenate([r.ravel(), np.full(nz, gamma**p / 2)])
        t_of = np.repeat(np.arange(T), K)
        e_of = np.tile(np.arange(K), T)
        n, m = est.shape[1], truth.shape[1]
        # each estimate, each truth: at most one unit of weight per scan
        A_est = sparse.coo_array((np.ones(nw), (t_of * n + ei[e_of], np.arange(nw))),
                                 shape=(T * n, nw + nz))
        A_tru = sparse.coo_array((np.ones(nw), (t_of * m + ej[e_of], np.arange(nw))),
                                 shape=(T * m, nw + nz))
        # z_te >= +-(w_{t+1,e} - w_te)
        k = np.arange(nz)
        rows = np.concatenate([k, k, k])
        cols = np.concatenate([k + K, k, nw + k])
        up = sparse.coo_array((np.concatenate([np.ones(nz), -np.ones(nz), -np.ones(nz)]),
                               (rows, cols)), shape=(nz, nw + nz))
        down = sparse.coo_array((np.concatenate([-np.ones(nz), np.ones(nz), -np.ones(nz)]),
                                 (rows, cols)), shape=(nz, nw + nz))
        A = sparse.vstack([A_est, A_tru, up, down]).tocsr()
        ub = np.concatenate([np.ones(T * n + T * m), np.zeros(2 * nz)])
        hi = np.concatenate([np.ones(nw), np.full(nz, np.inf)])
        if integer:
            res = milp(cost, constraints=LinearConstraint(A, -np.inf, ub),
                       bounds=Bounds(np.zeros(nw + nz), hi),
                       integrality=np.concatenate([np.ones(nw), np.zeros(nz)]))
        else:
            res = linprog(cost, A_ub=A, b_ub=ub, bounds=np.stack([np.zeros(nw + nz), hi], 1),
                          method="highs")
        if res.status != 0:
            raise RuntimeError(f"trajectory GOSPA programme failed: {res.message}")
        w = np.clip(res.x[:nw].reshape(T, K), 0.0, 1.0)
    # decomposition (the paper's Section IV-C): weights on close pairs localise
    wc = np.where(close[:, ei, ej], w, 0.0) if K else w
    loc_t = (wc * np.nan_to_num(D[:, ei, ej]) ** p).sum(axis=1) if K else np.zeros(T)
    n_m = np.zeros((T, truth.shape[1]))
    n_f = np.zeros((T, est.shape[1]))
    for arr, idx in ((n_m, ej), (n_f, ei)):
        np.add.at(arr, (slice(None), idx), wc)
    missed_t = (ty * (1.0 - n_m)).sum(axis=1)
    false_t = (ex * (1.0 - n_f)).sum(axis=1)
    sw_t = gamma**p / 2 * np.abs(np.diff(w, axis=0)).sum(axis=1)
    total = loc_t.sum() + half * (missed_t.sum() + false_t.sum()) + sw_t.sum()
    integral = bool(np.all(np.minimum(w, 1.0 - w) < 1e-7))
    return TGospa(distance=float(max(total, 0.0) ** (1.0 / p)),
                  localisation=float(loc_t.sum()), missed=float(missed_t.sum()),
                  false=float(false_t.sum()), switches=float(sw_t.sum() / gamma**p),
                  switching=float(sw_t.sum()), integral=integral,
                  per_scan=np.stack([loc_t, half * missed_t, half * false_t], axis=1),
                  switch_per_scan=sw_t)
