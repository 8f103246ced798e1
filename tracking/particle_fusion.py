"""A particle posterior as Gaussian mixtures, and fusion for single-target peers (seed 001).

Summaries of an IMM particle filter's posterior (one moment-matched component per model, or
k-means clusters), the particle fusion rule's Gaussian ratio (seed 001 eq. 19-21, our reading:
docs/algorithms.md "IMM models and the particle fusion rule") and GCI of single-target summaries.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sensornet.tracking.fusion import gci_fuse
from sensornet.tracking.fusion_rules import optimal_omega
from sensornet.tracking.gaussian import symmetrise
from sensornet.tracking.imm import POS
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.particle_ops import weighted_moments

# -- mixture summaries of a particle posterior --------------------------------------------------


def moment_summary(X: np.ndarray, w: np.ndarray, probs: np.ndarray) -> GaussianMixture:
    """One moment-matched component per model: ``X (M, N, d)``, ``w (M, N)`` rows normalised,
    ``probs (M,)``. Mean and covariance of the whole weighted particle set are kept exactly
    (law of total covariance)."""
    return GaussianMixture(probs, *weighted_moments(X, w))


def kmeans_summary(X: np.ndarray, w: np.ndarray, k: int, rng: np.random.Generator,
                   iterations: int = 5, dims: tuple[int, ...] = POS) -> GaussianMixture:
    """A K-component summary of weighted particles ``X (n, d)``, ``w (n,)``: a few weighted
    k-means iterations on the ``dims`` coordinates (scaled to unit spread), then each cluster
    moment-matched (hard assignment, so the mixture's overall moments equal the particles').
    Empty clusters are dropped."""
    X = X.reshape(-1, X.shape[-1])
    w = (w / w.sum()).reshape(-1)
    Y = X[:, list(dims)]
    Y = (Y - w @ Y) / np.sqrt(np.maximum(w @ (Y - w @ Y) ** 2, 1e-12))
    centres = Y[rng.choice(len(Y), size=k, replace=False, p=w if np.all(w > 0) else None)]
    for _ in range(iterations):
        lab = np.argmin(((Y[:, None, :] - centres[None]) ** 2).sum(-1), axis=1)
        R = np.zeros((len(Y), k))
        R[np.arange(len(Y)), lab] = w
        mass = R.sum(0)
        centres = np.where(mass[:, None] > 0, (R.T @ Y) / np.maximum(mass, 1e-300)[:, None],
                           centres)
    lab = np.argmin(((Y[:, None, :] - centres[None]) ** 2).sum(-1), axis=1)
    R = np.zeros((len(Y), k))
    R[np.arange(len(Y)), lab] = w
    mass = R.sum(0)
    keep = mass > 0
    R, mass = R[:, keep], mass[keep]
    means = (R.T @ X) / mass[:, None]
    D = X[None, :, :] - means[:, None, :]  # (k, n, d)
    covs = np.einsum("kn,kna,knb->kab", R.T, D, D) / mass[:, None, None]
    return GaussianMixture(mass, means, symmetrise(covs))


def marginal(mix: GaussianMixture, dims: tuple[int, ...]) -> GaussianMixture:
    """The mixture's marginal on the state entries ``dims``."""
    ix = list(dims)
    return GaussianMixture(mix.weights, mix.means[:, ix], mix.covs[:, ix][:, :, ix])


# -- fusion: the particle fusion rule (eq. 19-21) and GCI feedback -----------------------------


RATIO_SPACES = ("position", "full")


@dataclass(frozen=True)
class RatioConfig:
    """How a peer's ``posterior / prediction`` ratio is formed (our reading:
    docs/algorithms.md "IMM models and the particle fusion rule")."""

    space: str = "position"
    """``"position"``: ratio of the (px, py) marginals; ``"full"``: of the 6-D densities."""
    clip: bool = True
    """Drop negative information: keep only the positive eigen-directions of ``Y_post - Y_pred``."""
    rel_tol: float = 1e-9
    """Eigenvalues below ``rel_tol * max eigenvalue`` count as zero when clipping."""


@dataclass(frozen=True)
class GaussianRatio:
    """``log r(x) = -1/2 (s - c)^T A (s - c) + (s - c)^T b`` on the sub-vector ``s = x[dims]``:
    the ratio of two Gaussians ``N(s; m_p, P_p) / N(s; m_q, P_q)`` up to a constant, with
    ``A = P_p^-1 - P_q^-1`` and ``b = P_p^-1 (m_p - c) - P_q^-1 (m_q - c)`` (centre ``c``)."""

    dims: tuple[int, ...]
    """State entries the ratio depends on."""
    A: np.ndarray
    """(k, k) information difference (PSD after clipping)."""
    b: np.ndarray
    """(k,) information-vector difference about ``centre``."""
    centre: np.ndarray
    """(k,) expansion point (the posterior mean), for round-off."""

    @classmethod
    def from_summaries(cls, post: GaussianMixture, pred: GaussianMixture,
                       cfg: RatioConfig = RatioConfig()) -> GaussianRatio:
        """The ratio of another peer's posterior and predicted summaries (each collapsed to its
        moment-matched Gaussian on ``cfg.space``). Theory: ``p(x|z_1:k) / p(x|z_1:k-1) ∝
        p(z_k | x)``, which for a radar depends on position only, so ``"position"`` loses
        nothing in exact arithmetic and removes Monte Carlo noise in the other entries."""
        if cfg.space not in RATIO_SPACES:
            raise ValueError(f"unknown ratio space {cfg.space!r}; expected {RATIO_SPACES}")
        dims = POS if cfg.space == "position" else tuple(range(post.dim))
        mp, Pp = marginal(post, dims).moments()
        mq, Pq = marginal(pred, dims).moments()
        Yp, Yq = np.linalg.inv(Pp), np.linalg.inv(Pq)
        A = symmetrise(Yp - Yq)
        b = Yq @ (mp - mq)  # Yp (mp - c) = 0 with c = mp
        if cfg.clip:
            lam, V = np.linalg.eigh(A)
            keep = lam > cfg.rel_tol * max(lam.max(), 0.0) if lam.max() > 0 else np.zeros_like(
                lam, bool)
            Vk = V[:, keep]
            A = (Vk * lam[keep]) @ Vk.T
            b = Vk @ (Vk.T @ b)
        return cls(dims, A, b, mp)

    def log_eval(self, X: np.ndarray) -> np.ndarray:
        """``log r`` at states ``X (..., d)``: returns ``(...)``."""
        S = X[..., list(self.dims)] - self.centre
        return -0.5 * np.einsum("...i,ij,...j->...", S, self.A, S) + S @ self.b

    def apply_gaussian(self, means: np.ndarray, covs: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closed-form product ``N(x; m_j, P_j) r(x)`` for Gaussians ``(M, d)``, ``(M, d, d)``
        (the fusion rule of seed 001 eq. 19-21 for an IMM-EKF): new means, covariances and
        ``log int N r dx (M,)`` (the factor the model probabilities are multiplied by).

        With ``H`` selecting ``dims``, ``P_s = H P H^T``, ``B = I + A P_s`` and the gradient
        ``g = b - A (m_s - c)`` of ``log r`` at the marginal mean: ``P' = (P^-1 + H^T A H)^-1 =
        P - P H^T B^-1 A H P`` and ``m' = m + P H^T B^-1 g`` (a Kalman update with a
        pseudo-measurement of information ``A``); the normaliser is :func:`_log_ratio_normaliser`.
        """
        ix = list(self.dims)
        PHt = covs[:, :, ix]  # (M, d, k)
        Ps = PHt[:, ix, :]  # (M, k, k)
        ms = means[:, ix] - self.centre  # (M, k)
        B = np.eye(len(ix)) + self.A @ Ps  # (M, k, k): I + A P_s
        Binv = np.linalg.inv(B)
        g = self.b - np.einsum("ij,mj->mi", self.A, ms)  # (M, k) gradient of log r at m_s
        K = PHt @ Binv  # (M, d, k)
        new_means = means + np.einsum("mdk,mk->md", K, g)
        new_covs = symmetrise(covs - K @ self.A @ np.swapaxes(PHt, 1, 2))
        log_norm = _log_ratio_normaliser(self.A, self.b, ms, Ps, B, g)
        return new_means, new_covs, log_norm


def _log_ratio_normaliser(A: np.ndarray, b: np.ndarray, ms: np.ndarray, Ps: np.ndarray,
                          B: np.ndarray, g: np.ndarray) -> np.ndarray:
    """``log int N(s; m_s, P_s) exp(-1/2 s^T A s + s^T b) ds`` over stacks ``(M, ...)``, ``s``
    and ``m_s`` taken about the ratio's centre (seed 001 eq. 21 in closed form).

    With ``s = m_s + u``, ``log r(s) = log r(m_s) - 1/2 u^T A u + u^T g``, and
    ``int N(u; 0, P_s) exp(-1/2 u^T A u + u^T g) du = det(I + A P_s)^-1/2
    exp(1/2 g^T (P_s^-1 + A)^-1 g)``. ``(P_s^-1 + A)^-1 = P_s (I + A P_s)^-1 = P_s B^-1``
    (not ``B^-1 P_s``: ``A`` and ``P_s`` need not commute), so the quadratic term is
    ``g^T P_s x`` with ``B x = g``.
    """
    _, logdet = np.linalg.slogdet(B)
    x = np.linalg.solve(B, g[:, :, None])[:, :, 0]  # B^-1 g
    quad = np.einsum("mi,mij,mj->m", g, Ps, x)
    log_r_ms = -0.5 * np.einsum("mi,ij,mj->m", ms, A, ms) + ms @ b
    return -0.5 * logdet + 0.5 * quad + log_r_ms


def gci_summaries(own: GaussianMixture, others: list[GaussianMixture],
                  omega: float | str | None = None) -> GaussianMixture:
    """GCI of normalised single-target mixtures (``tracking.fusion.gci_fuse(..., normalise=True)``;
    with one Gaussian each it is covariance intersection). ``omega``: weight of each other peer
    (own gets the rest); None gives uniform weights; ``"det"`` or ``"chernoff"`` (one other peer
    only) chooses it per call with ``tracking.fusion.optimal_omega``."""
    n = 1 + len(others)
    if isinstance(omega, str):
        if len(others) != 1:
            raise ValueError("an optimised omega needs exactly one other peer")
        omega = optimal_omega(own.normalised(), others[0].normalised(), omega)
    if omega is None:
        weights = [1.0 / n] * n
    else:
        weights = [1.0 - omega * (n - 1)] + [omega] * (n - 1)
    return gci_fuse([own, *others], weights, normalise=True)


def collapse_to_models(fused: GaussianMixture, n_models: int, cov_floor: float = 0.0
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-own-model Gaussians from a fused mixture whose components are ordered own-model
    major (the pair order of ``gci_pair``): probs ``(M,)``, means ``(M, d)``, covs ``(M, d, d)``.
    Component ``(a, b...)`` belongs to own model ``a``; each group is moment-matched."""
    n, d = len(fused), fused.dim
    per = n // n_models
    w = fused.weights.reshape(n_models, per)
    mass = w.sum(axis=1)
    wn = w / np.maximum(mass, 1e-300)[:, None]
    m = fused.means.reshape(n_models, per, d)
    P = fused.covs.reshape(n_models, per, d, d)
    means = np.einsum("mk,mkd->md", wn, m)
    D = m - means[:, None, :]
    covs = np.einsum("mk,mkab->mab", wn, P) + np.einsum("mk,mka,mkb->mab", wn, D, D)
    covs = symmetrise(covs) + cov_floor * np.eye(d)
    probs = mass / mass.sum()
    return probs, means, covs


def floored(mix: GaussianMixture, floor: float) -> GaussianMixture:
    """The mixture with ``floor`` added to every covariance diagonal (keeps the CV component's
    zero acceleration variance invertible for GCI)."""
    return GaussianMixture(mix.weights, mix.means, mix.covs + floor * np.eye(mix.dim))
