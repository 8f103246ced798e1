"""A young fused track's pooled existence also weighs the peer's own scan when its own track
set holds nothing of it (issue 33, docs/labelled-tracking.md, "Young fused tracks and the
peer's own scan").

At 20 LMB peers and Pd 0.9 the young false fused tracks are rows that exactly two of a peer's
five inputs hold: two neighbours' clutter tracks at one place, each at 0.13-0.5, pooled about
the prior 0.01 (``tracking.support.pooled_weights``) to 0.7-0.97. An input without a track
there is left out of that pool: its existence is only known to be below its publication
threshold, no evidence either way about a prior of 0.01. The centralised LMB instead updates a
birth with every sensor's scan, so a one-sensor clutter track meets nineteen misses. The peer's
own scan is at hand: where its own input holds none of a young row's mass, this module
multiplies the row's pooled existence odds by the own scan's measurement likelihood ratio

    L = 1 - Pd + Pd sum_z N(z; H m, H P H' + R) / kappa

(the LMB existence update ``r' = r L / (1 - r + r L)``, S. Reuter, B.-T. Vo, B.-N. Vo and
K. Dietmayer, "The labeled multi-Bernoulli filter", IEEE TSP 62(12), 2014, eq. (21)-(22),
for one Bernoulli and position plots): a plot near the row raises it (a real target is
detected with Pd), none lowers its odds to about ``1 - Pd``. The own sensor's scans are
independent of the neighbours' (each input is its peer's own local density), so this adds
evidence the pool did not count; a row the own input holds already counted it.
"""

from __future__ import annotations

import numpy as np
from sensornet.tracking.gaussian import inv_spd


def own_scan_ratio(means: np.ndarray, covs: np.ndarray, z: np.ndarray, pd: float,
                   kappa: float, sigma: float, pos: tuple[int, int] = (0, 2)) -> np.ndarray:
    """``(n,)`` the own scan's likelihood ratio, target at each state vs none (module
    docstring): ``means (n, d)``, ``covs (n, d, d)``, plots ``z (m, 2)`` (x-y), detection
    probability ``pd``, clutter intensity ``kappa`` (per m^2), plot noise ``sigma`` (m, per
    axis); ``pos``: the state's x and y indices."""
    means = np.asarray(means, dtype=float)
    covs = np.asarray(covs, dtype=float)
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    if not (0.0 < pd <= 1.0 and kappa > 0 and sigma > 0) or not np.isfinite(kappa * sigma):
        raise ValueError(f"need 0 < pd <= 1, kappa > 0 and sigma > 0 finite, got {pd}, "
                         f"{kappa}, {sigma}")
    if not np.isfinite(z).all():
        raise ValueError("own scan plots must be finite")
    n = len(means)
    if n == 0 or len(z) == 0:
        return np.full(n, 1.0 - pd)
    ix = np.asarray(pos)
    S = covs[:, ix][:, :, ix] + sigma**2 * np.eye(2)  # (n, 2, 2)
    Si = inv_spd(S)
    d = z[None, :, :] - means[:, None, ix]  # (n, m, 2)
    q = np.einsum("nmi,nij,nmj->nm", d, Si, d)
    g = np.exp(-0.5 * q) / (2.0 * np.pi * np.sqrt(np.linalg.det(S)))[:, None]
    return 1.0 - pd + pd * g.sum(axis=1) / kappa


def own_scan_weights(pooled: np.ndarray, fused: np.ndarray, labels: np.ndarray, k: int,
                     own_mass: np.ndarray, young: int, ratio: np.ndarray) -> np.ndarray:
    """``(n,)`` extraction weights: a row the pool raised (``pooled > fused``), at most
    ``young`` scans old (its label's second column, at scan ``k``) and of which the own input
    holds no mass (``own_mass (n,)``, column 0 of ``tracking.support.input_mass``) weighs
    ``r L / (1 - r + r L)`` with ``r`` its pooled weight and ``L`` its ``ratio``, at least its
    fused weight; every other row keeps ``pooled``."""
    pooled = np.asarray(pooled, dtype=float)
    fused = np.asarray(fused, dtype=float)
    labels = np.asarray(labels, dtype=np.int64).reshape(-1, 3)
    n = len(pooled)
    if not (len(fused) == len(labels) == len(own_mass) == len(ratio) == n):
        raise ValueError(f"pooled, fused, labels, own_mass and ratio need {n} rows, got "
                         f"{len(fused)}, {len(labels)}, {len(own_mass)} and {len(ratio)}")
    pick = (pooled > fused) & (np.asarray(own_mass) <= 0) & (k - labels[:, 1] <= young)
    out = pooled.copy()
    r, L = pooled[pick], np.asarray(ratio, dtype=float)[pick]
    out[pick] = np.maximum(fused[pick], r * L / (1.0 - r + r * L))
    return out


__all__ = ["own_scan_ratio", "own_scan_weights"]
