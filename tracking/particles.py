"""The IMM particle filter (its summaries and fusion: :mod:`tracking.particle_fusion`).

Seed 001 (docs/algorithms.md "IMM models and the particle fusion rule"). Particles of all models
live in one array ``X (M, N, 6)`` (M models, N particles per model); every step is array code over
particles and models, with no Python loop over particles.

Cycle per scan (seed 001 eq. 13-18, our reading of the interaction step for particles):

1. interaction: model ``j`` draws its N particles from ``sum_i mu_(i|j) p_i(x)`` (systematic
   sampling over the M*N equally weighted particles with weights ``mu_(i|j) / N``);
2. model-matched prediction ``x = F_j x + G_j w`` and weighting ``w ∝ p(z | x)`` (prior as
   proposal, bootstrap);
3. model probabilities ``mu_j ∝ c_j Lambda_j``, ``Lambda_j = (1/N) sum_n p(z | x_j^n)``;
4. residual resampling per model;
5. output ``x = sum_j mu_j x_j`` (from the weighted particles, before resampling);
6. regularisation (docs/seed001.md): after resampling each model's particles are jittered by
   ``h`` times that model's posterior spread, either added (``"add"``: covariance grows by
   ``h^2``, like extra process noise) or with Liu & West (2001) shrinkage (``"shrink"``:
   ``x -> a x + (1-a) mean + h L e``, ``a = sqrt(1-h^2)``, mean and covariance kept).

An external log-likelihood (the particle fusion rule's ratio, eq. 19-21) can be added to the
sensor's own before step 3 (:meth:`IMMParticleFilter.update`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from sensornet.tracking.gaussian import symmetrise
from sensornet.tracking.imm import STATE_DIM, IMMParams, ModelConditioned, mixing, model_posterior
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.particle_fusion import (  # re-exported: tracking.particles.X keeps working
    GaussianRatio,
    RatioConfig,
    collapse_to_models,
    floored,
    gci_summaries,
    kmeans_summary,
    marginal,
    moment_summary,
)
from sensornet.tracking.particle_ops import (
    counts_to_indices,
    interaction_indices,
    residual_counts,
    systematic_counts,
    weighted_moments,
)

try:  # the ufuncs np.linalg calls (NumPy 1.x and 2.x)
    from numpy.linalg import _umath_linalg as _lapack
except ImportError:  # pragma: no cover
    _lapack = None


@dataclass(frozen=True)
class ParticleParams:
    """Particle-filter settings of the IMM-PF (seed 001 §4;
    docs/algorithms.md "IMM models and the particle fusion rule")."""

    n_particles: int = 800
    """Particles per model ``N``."""
    jitter: float = 0.3
    """Regularisation ``h``: jitter spread as a fraction of the model's posterior spread."""
    jitter_kind: str = "add"
    """``"add"`` (covariance grows by h^2) or ``"shrink"`` (Liu-West, moments kept)."""
    cov_floor: float = 1e-9
    """Added to covariance diagonals before Cholesky (the CV acceleration has zero spread)."""


@dataclass
class ParticlePrediction:
    """Predicted particles of every model (equal weights within a model)."""

    particles: np.ndarray
    """(M, N, 6) predicted particles."""
    probs: np.ndarray
    """(M,) predicted model probabilities ``c_j``."""

    @cached_property
    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-model mean ``(M, 6)`` and covariance ``(M, 6, 6)`` of the predicted particles."""
        N = self.particles.shape[1]
        return weighted_moments(self.particles, np.full(self.particles.shape[:2], 1.0 / N))

    def summary(self) -> GaussianMixture:
        """Predicted-density summary: one moment-matched component per model (weights ``c``)."""
        return GaussianMixture(self.probs, *self.moments)


@dataclass(frozen=True)
class ParticleState(ModelConditioned):
    """The IMM-PF posterior after one scan."""

    particles: np.ndarray
    """(M, N, 6) resampled (and jittered) particles, equal weights."""
    probs: np.ndarray
    """(M,) model probabilities ``mu_j``."""
    means: np.ndarray
    """(M, 6) model-conditioned posterior means (weighted particles, before resampling)."""
    covs: np.ndarray
    """(M, 6, 6) model-conditioned posterior covariances (same)."""
    log_likelihoods: np.ndarray | None = None
    """(M,) ``log Lambda_j`` of the last update."""


def _model_moments(X: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`weighted_moments` of dimension-major particles ``X (d, M, N)`` with weights
    ``w (M, N)``, one model at a time (the same products; ``(d, N)`` temporaries)."""
    d, M, _ = X.shape
    means = np.empty((M, d))
    covs = np.empty((M, d, d))
    for j in range(M):
        Xj = X[:, j]
        np.matmul(Xj, w[j], out=means[j])
        D = Xj - means[j][:, None]
        np.matmul(D * w[j], D.T, out=covs[j])
    return means, symmetrise(covs)


def _cholesky(A: np.ndarray) -> np.ndarray:
    """``np.linalg.cholesky(A)`` (the same LAPACK call and numbers) without its Python wrapper,
    which costs more than factorising two 6x6 matrices; a stack that is not positive definite
    goes through ``np.linalg.cholesky`` (and its error) unchanged."""
    if _lapack is None or A.dtype != np.float64:
        return np.linalg.cholesky(A)
    with np.errstate(all="ignore"):
        L = _lapack.cholesky_lo(A, signature="d->d")
    if not np.isfinite(L).all():
        return np.linalg.cholesky(A)
    return L


def _dim_major(X: np.ndarray) -> np.ndarray:
    """Particles ``X (M, N, d)`` as a C-contiguous ``(d, M, N)`` array (a view when ``X`` is
    already the transposed view of one, as the filter's own states are)."""
    return np.ascontiguousarray(X.transpose(2, 0, 1))


@dataclass(frozen=True)
class IMMParticleFilter:
    """IMM particle filter (seed 001), vectorised over particles and models."""

    params: IMMParams = field(default_factory=IMMParams)
    """Models, Markov matrix and initial probabilities."""
    particle: ParticleParams = field(default_factory=ParticleParams)
    """Particle count and regularisation."""

    @cached_property
    def _F(self) -> np.ndarray:
        return np.stack([m.F for m in self.params.models()])  # (M, 6, 6)

    @cached_property
    def _G(self) -> np.ndarray:
        return np.stack([m.sigma * m.G for m in self.params.models()])  # (M, 6, 2)

    @cached_property
    def _P(self) -> np.ndarray:
        return self.params.P

    def _floor_eye(self, d: int) -> np.ndarray:
        """``cov_floor * np.eye(d)`` (built once per dimension)."""
        cache = self.__dict__.setdefault("_floor_eyes", {})
        if d not in cache:
            cache[d] = self.particle.cov_floor * np.eye(d)
        return cache[d]

    def initialise(self, mean: np.ndarray, cov: np.ndarray,
                   rng: np.random.Generator) -> ParticleState:
        """N particles per model from ``N(mean, cov)``, initial model probabilities."""
        M, N = len(self.params.initial_probs), self.particle.n_particles
        L = np.linalg.cholesky(cov + self.particle.cov_floor * np.eye(len(mean)))
        X = mean + rng.standard_normal((M, N, len(mean))) @ L.T
        probs = np.asarray(self.params.initial_probs, float)
        means, covs = weighted_moments(X, np.full((M, N), 1.0 / N))
        return ParticleState(X, probs, means, covs)

    def from_gaussians(self, probs: np.ndarray, means: np.ndarray, covs: np.ndarray,
                       rng: np.random.Generator) -> ParticleState:
        """A state whose model ``j`` particles are drawn from ``N(means_j, covs_j)`` (used when
        a fused Gaussian summary replaces the posterior, e.g. after GCI)."""
        M, N = means.shape[0], self.particle.n_particles
        L = np.linalg.cholesky(covs + self.particle.cov_floor * np.eye(means.shape[1]))
        X = means[:, None, :] + rng.standard_normal((M, N, means.shape[1])) @ np.swapaxes(L, 1, 2)
        return ParticleState(X, np.asarray(probs, float), means, covs)

    # The step keeps the particles dimension-major, ``(d, M, N)`` C-contiguous, and hands out
    # the ``(M, N, d)`` transposed view: every per-coordinate operation (likelihood, moments,
    # gathers) then runs over contiguous rows. The arithmetic is the same as the particle-major
    # form's, operation for operation (the same random draws, in the same order).

    def predict(self, state: ParticleState, rng: np.random.Generator) -> ParticlePrediction:
        """Interaction (mixing) and model-matched propagation (steps 1-2)."""
        X = _dim_major(state.particles)
        d, M, N = X.shape
        c, mu = mixing(state.probs, self._P)  # mu[i, j] = mu_(i|j)
        idx = interaction_indices(mu, N, rng.random(M))  # (M*N,) into the M*N particles
        X0 = X.reshape(d, M * N).take(idx, axis=1).reshape(d, M, N)
        E = rng.standard_normal((M, N, 2))
        Xp = np.empty((d, M, N))
        F, G = self._F, self._G
        for j in range(M):  # x' = F_j x + G_j w per model, as (d, N) products
            np.matmul(F[j], X0[:, j], out=Xp[:, j])
            Xp[:, j] += G[j] @ E[j].T
        return ParticlePrediction(Xp.transpose(1, 2, 0), c)

    def update(self, pred: ParticlePrediction, log_lik: np.ndarray,
               rng: np.random.Generator) -> ParticleState:
        """Weighting, model probabilities, output, residual resampling, jitter (steps 2-6).

        ``log_lik (M, N)``: ``log p(z | x)`` at the predicted particles, plus any fusion
        log-ratio (eq. 19-21). ``log Lambda_j = log mean_n exp(log_lik_jn)``.
        """
        X = _dim_major(pred.particles)
        d, M, N = X.shape
        top = log_lik.max(axis=1, keepdims=True)
        lik = np.exp(log_lik - top)
        s = lik.sum(axis=1)
        log_Lambda = np.log(s) + top[:, 0] - np.log(N)
        probs = model_posterior(pred.probs, log_Lambda)
        w = lik / s[:, None]
        means, covs = _model_moments(X, w)
        counts = residual_counts(w, N, rng)  # (M, N), rows sum to N
        idx = np.arange(M * N).repeat(counts.reshape(-1))  # (M*N,) row j within model j
        Xr = X.reshape(d, M * N).take(idx, axis=1).reshape(d, M, N)
        Xr = self._regularise(Xr, means, covs, rng)
        return ParticleState(Xr.transpose(1, 2, 0), probs, means, covs, log_Lambda)

    def _regularise(self, X: np.ndarray, means: np.ndarray, covs: np.ndarray,
                    rng: np.random.Generator) -> np.ndarray:
        """Jitter the resampled particles ``X (d, M, N)`` (dimension-major; step 6)."""
        h = self.particle.jitter
        if h <= 0.0:
            return X
        kind = self.particle.jitter_kind
        if kind not in ("add", "shrink"):
            raise ValueError(f"unknown jitter_kind {kind!r}; expected 'add' or 'shrink'")
        d, M, N = X.shape
        L = _cholesky(covs + self._floor_eye(d))
        Z = rng.standard_normal((M, N, d))
        if kind == "shrink":
            a = np.sqrt(1.0 - h * h)
            X *= a
            X += ((1.0 - a) * means).T[:, :, None]
        for j in range(M):  # per model: (d, N) temporaries that stay in cache
            E = L[j] @ Z[j].T  # L_j e per particle
            E *= h
            X[:, j] += E
        return X

    def step(self, state: ParticleState, log_lik_fn, rng: np.random.Generator,
             extra_log_lik=None) -> tuple[ParticleState, ParticlePrediction]:
        """One scan. ``log_lik_fn(X (M, N, 6)) -> (M, N)``; ``extra_log_lik`` likewise
        (e.g. the particle fusion rule's ratio) or None. Returns posterior and prediction."""
        pred = self.predict(state, rng)
        ll = log_lik_fn(pred.particles)
        if extra_log_lik is not None:
            ll = ll + extra_log_lik(pred.particles)
        return self.update(pred, ll, rng), pred


__all__ = [
    "STATE_DIM",
    "GaussianRatio",
    "IMMParticleFilter",
    "ParticleParams",
    "ParticlePrediction",
    "ParticleState",
    "RatioConfig",
    "collapse_to_models",
    "counts_to_indices",
    "floored",
    "gci_summaries",
    "interaction_indices",
    "kmeans_summary",
    "marginal",
    "moment_summary",
    "residual_counts",
    "systematic_counts",
    "weighted_moments",
]
