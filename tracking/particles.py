"""The IMM particle filter, its Gaussian-mixture summaries, and fusion for single-target peers.

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

from tracking.fusion import gci_fuse, optimal_omega
from tracking.gaussian import symmetrise
from tracking.imm import POS, STATE_DIM, IMMParams, ModelConditioned, mixing, model_posterior
from tracking.mixture import GaussianMixture

try:  # the ufuncs np.linalg calls (NumPy 1.x and 2.x)
    from numpy.linalg import _umath_linalg as _lapack
except ImportError:  # pragma: no cover
    _lapack = None

# -- resampling ---------------------------------------------------------------------------------


def systematic_counts(weights: np.ndarray, n: np.ndarray | int, u: np.ndarray) -> np.ndarray:
    """Systematic-sampling counts per row: ``weights (R, K)`` normalised rows, ``n`` draws per
    row (scalar or ``(R,)``), offsets ``u (R,)`` in [0, 1). Returns integer ``(R, K)``.

    Points ``(k + u) / n``, ``k < n``; the count in ``(C_(i-1), C_i]`` is
    ``floor(n C_i - u) - floor(n C_(i-1) - u)`` with ``C`` the cumulative weights.
    """
    R, K = weights.shape
    C = np.empty((R, K + 1))
    C[:, 0] = 0.0
    np.cumsum(weights, axis=1, out=C[:, 1:])
    C[:, 1:] /= C[:, -1:]
    C[:, -1] = 1.0
    C *= np.asarray(n, dtype=float).reshape(-1, 1) if np.ndim(n) else float(n)
    C -= u[:, None]
    np.floor(C, out=C)  # floor(n C - u), in place
    f = C[:, 1:] - C[:, :-1]
    return f.astype(np.int64)


def residual_counts(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Residual resampling counts (Liu & Chen 1998) per row of ``weights (R, K)``: ``(R, K)``.

    Deterministic part ``floor(n w_i)`` exactly; the ``n - sum floor(n w)`` remaining draws are
    systematic over the residual weights ``n w_i - floor(n w_i)``.
    """
    nw = weights / weights.sum(axis=1, keepdims=True)
    nw *= n  # n w
    base = np.floor(nw)
    rest = nw
    rest -= base  # n w - floor(n w)
    left = n - base.sum(axis=1)  # (R,) integer-valued
    total = rest.sum(axis=1, keepdims=True)
    if not np.all(total > 0):
        rest = np.where(total > 0, rest, 1.0)
    counts = base.astype(np.int64)
    counts += systematic_counts(rest, left, rng.random(len(weights)))
    return counts


def interaction_indices(mu: np.ndarray, n: int, u: np.ndarray) -> np.ndarray:
    """The IMM-PF interaction draws: for each model ``j``, ``n`` systematic draws (offset
    ``u_j``) from the ``M*n`` particles, model ``i``'s ``n`` particles each weighted
    ``mu_(i|j) / n``. Returns indices ``(M*n,)`` into the particles (model-major), row ``j``
    sorted: the same as ``counts_to_indices(systematic_counts(np.repeat(mu.T, n, axis=1), n,
    u))``, computed from the ``M`` block boundaries instead of a cumulative sum over ``M*n``.

    Draw ``t_k = (k + u_j) / n`` lands in block ``i`` with ``B_(i-1) < t <= B_i`` (``B`` the
    cumulative ``mu_(.|j)``, normalised) and on particle ``l`` of it with
    ``B_(i-1) + l v < t <= B_(i-1) + (l + 1) v``, ``v = mu_(i|j) / n``: ``l = ceil((t -
    B_(i-1)) / v) - 1``. (Empty blocks are skipped: their two boundaries are equal.)
    """
    M = mu.shape[0]
    t = np.arange(n) + u[:, None]
    t /= n  # (j, k) the draws
    if M == 2:  # the same arithmetic on Python floats (IEEE doubles, as NumPy's)
        b0 = [mu[0, j] / (mu[0, j] + mu[1, j]) for j in (0, 1)]  # end of block 0
        hi = t > np.array(b0)[:, None]
        t -= np.where(hi, np.array(b0)[:, None], 0.0)
        t /= np.where(hi, np.array([(1.0 - b) / n for b in b0])[:, None],
                      np.array([b / n for b in b0])[:, None])
        block = np.where(hi, n, 0)
    else:
        B = np.cumsum(mu.T, axis=1)  # (j, i) block ends
        B /= B[:, -1:]
        B[:, -1] = 1.0
        start = np.zeros_like(B)
        start[:, 1:] = B[:, :-1]
        v = (B - start) / n  # (j, i) the mass of one particle of block i
        b = (t[:, :, None] > B[:, None, :-1]).sum(axis=2)
        t -= np.take_along_axis(start, b, axis=1)
        t /= np.take_along_axis(v, b, axis=1)
        block = b * n
    np.ceil(t, out=t)
    t -= 1.0
    np.maximum(t, 0.0, out=t)
    np.minimum(t, n - 1, out=t)
    g = t.astype(np.intp)
    g += block
    return g.reshape(-1)


def counts_to_indices(counts: np.ndarray) -> np.ndarray:
    """Column indices ``(R, n)`` from per-row counts ``(R, K)`` that each sum to ``n``."""
    R, K = counts.shape
    return np.repeat(np.tile(np.arange(K), R), counts.reshape(-1)).reshape(R, -1)


# -- the filter -------------------------------------------------------------------------------


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


def weighted_moments(X: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(..., d)`` and covariance ``(..., d, d)`` of particles ``X (..., N, d)`` with
    normalised weights ``w (..., N)``.

    Two matrix products per stack entry (BLAS, any memory layout of ``X``, including the
    filter's dimension-major particles): ``mean = w^T X``, ``cov = (D w)^T D``, ``D = X - mean``.
    """
    mean = np.matmul(w[..., None, :], X)[..., 0, :]
    D = X - mean[..., None, :]
    cov = np.matmul(np.swapaxes(D * w[..., None], -1, -2), D)
    return mean, symmetrise(cov)


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


# -- mixture summaries of a particle posterior ------------------------------------------------


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
