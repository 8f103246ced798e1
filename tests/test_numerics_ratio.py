"""The closed-form Gaussian-ratio fusion rule (``GaussianRatio.apply_gaussian``, seed 001
eq. 19-21) against numerical quadrature, with full (non-diagonal, non-commuting) matrices.

The IMM tests use diagonal matrices, where ``A`` and ``P_s`` commute and a transposed factor in
the normaliser cannot show; here every case has ``A P_s != P_s A``.
"""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.particles import GaussianRatio

DIMS = (0, 3)
GRID = 1201
"""Points per axis of the quadrature grid (0.02 standard deviations of the product apart)."""


def _spd(rng: np.random.Generator, d: int, scale: float) -> np.ndarray:
    """A random full SPD matrix."""
    L = rng.normal(size=(d, d))
    return scale * (L @ L.T + 0.3 * np.eye(d))


def _case(seed: int, indefinite: bool = False):
    """A 6-D prior ``N(m, P)`` and a ratio on (px, py) with full ``A``; ``indefinite``: an ``A``
    with one negative eigenvalue, small enough that ``P_s^-1 + A`` stays positive definite
    (the unclipped ratio, ``RatioConfig(clip=False)``)."""
    rng = np.random.default_rng(seed)
    P = _spd(rng, 6, 4.0)
    m = rng.normal(size=6) * 3.0
    Ps = P[np.ix_(DIMS, DIMS)]
    A = _spd(rng, 2, 1.0) @ np.linalg.inv(Ps) / 3.0
    A = 0.5 * (A + A.T)
    if indefinite:
        lam, V = np.linalg.eigh(A)
        lam_ps = np.linalg.eigvalsh(np.linalg.inv(Ps)).min()
        A = (V * np.array([-0.5 * lam_ps, lam[1]])) @ V.T
    b = rng.normal(size=2) * 0.5
    centre = m[list(DIMS)] + rng.normal(size=2)
    return m, P, GaussianRatio(DIMS, A, b, centre)


def _grid_moments(ms: np.ndarray, Ps: np.ndarray, r: GaussianRatio):
    """``log int N(s; m_s, P_s) r(s) ds`` and the mean and covariance of ``N r / int N r`` on
    ``s = x[dims]``, by the trapezoid rule on a fine grid (spectrally accurate for these
    smooth, fast-decaying integrands). Two passes: a wide grid locates the product, the second
    covers +-12 of its standard deviations."""
    centre, sd = ms, 40 * np.sqrt(np.diag(Ps))
    for _ in range(2):
        log_z, mean, cov = _trapezoid(ms, Ps, r, centre, sd)
        centre, sd = mean, 12 * np.sqrt(np.diag(cov))
    return log_z, mean, cov


def _trapezoid(ms, Ps, r, centre, half_width):
    """One pass of :func:`_grid_moments` on the box ``centre +- half_width``."""
    axes = [np.linspace(c - h, c + h, GRID) for c, h in zip(centre, half_width, strict=True)]
    S = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)  # (G, G, 2)
    D = S - ms
    Y = np.linalg.inv(Ps)
    log_n = (-0.5 * np.einsum("...i,ij,...j->...", D, Y, D)
             - 0.5 * np.linalg.slogdet(2 * np.pi * Ps)[1])
    X = np.zeros((*S.shape[:2], 6))
    X[..., list(DIMS)] = S
    f = np.exp(log_n + r.log_eval(X))
    cell = (axes[0][1] - axes[0][0]) * (axes[1][1] - axes[1][0])
    w = np.ones(GRID)
    w[[0, -1]] = 0.5
    W = f * np.outer(w, w) * cell
    Z = W.sum()
    mean = np.einsum("ab,abi->i", W, S) / Z
    C = S - mean
    cov = np.einsum("ab,abi,abj->ij", W, C, C) / Z
    return np.log(Z), mean, cov


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("indefinite", [False, True])
def test_ratio_normaliser_and_moments_match_quadrature(seed, indefinite):
    """``log_norm`` and the fused moments on ``dims`` equal a fine-grid integration; the
    fused 6-D mean and covariance equal the information form ``(P^-1 + H^T A H)^-1``."""
    m, P, r = _case(seed, indefinite)
    ix = list(DIMS)
    Ps = P[np.ix_(ix, ix)]
    assert np.abs(r.A @ Ps - Ps @ r.A).max() > 0.05 * np.abs(r.A @ Ps).max()  # non-commuting
    new_m, new_P, log_norm = r.apply_gaussian(m[None], P[None])
    log_z, mean_s, cov_s = _grid_moments(m[ix], Ps, r)
    assert abs(log_norm[0] - log_z) < 1e-9
    np.testing.assert_allclose(new_m[0, ix], mean_s, rtol=0, atol=1e-9 * np.sqrt(Ps.max()))
    np.testing.assert_allclose(new_P[0][np.ix_(ix, ix)], cov_s, rtol=0, atol=1e-9 * Ps.max())
    # the whole state: information form, written independently of apply_gaussian
    H = np.eye(6)[ix]
    Y = np.linalg.inv(P) + H.T @ r.A @ H
    P_ref = np.linalg.inv(Y)
    m_ref = P_ref @ (np.linalg.inv(P) @ m + H.T @ (r.b + r.A @ r.centre))
    np.testing.assert_allclose(new_m[0], m_ref, rtol=0, atol=1e-10 * np.abs(m_ref).max())
    np.testing.assert_allclose(new_P[0], P_ref, rtol=0, atol=1e-10 * np.abs(P_ref).max())


def test_ratio_normaliser_batched_over_models():
    """A stack of priors gives each its own normaliser (the IMM-EKF passes one per model)."""
    cases = [_case(s) for s in (4, 5, 6)]
    r = cases[0][2]
    means = np.stack([c[0] for c in cases])
    covs = np.stack([c[1] for c in cases])
    _, _, log_norm = r.apply_gaussian(means, covs)
    ix = list(DIMS)
    for j in range(3):
        log_z, _, _ = _grid_moments(means[j, ix], covs[j][np.ix_(ix, ix)], r)
        assert abs(log_norm[j] - log_z) < 1e-9
