"""LMB association marginals by loopy belief propagation (Williams & Lau 2014), and the row
scaling LBP and Gibbs share (split from :mod:`tracking.lmb_association`, issue 37).
"""

from __future__ import annotations

import numpy as np


def _row_scaled(miss: np.ndarray, detect: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each track's weights divided by its largest: every hypothesis has one choice per track,
    so row scaling leaves the marginals unchanged and keeps the numbers at most 1."""
    top = np.maximum(miss, detect.max(axis=1, initial=0.0))
    top = np.where(top > 0, top, 1.0)
    return miss / top, detect / top[:, None]


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
    return lbp_scaled(detect / np.maximum(miss, 1e-10)[:, None], tol, max_iter)


def lbp_scaled(psi: np.ndarray, tol: float = 1e-9,
               max_iter: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """:func:`marginals_lbp` from ``psi = detect / miss (n, m)`` (``n, m > 0``) of weights
    already row-scaled with the miss floored (:func:`lmb_association.marginals` has them: a
    second scaling divides by exactly 1, so it is left out)."""
    n, m = psi.shape
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


__all__ = ["lbp_scaled", "marginals_lbp"]
