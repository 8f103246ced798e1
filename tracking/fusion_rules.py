"""Fusion rules besides GCI: the arithmetic average (AA), the hybrid (AA target weights, GCI
locations), Metropolis consensus weights and the choice of the GCI weight omega.

Formulas and our readings: docs/algorithms.md "GCI fusion"; the GCI formula itself is
:mod:`tracking.fusion`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import expit, logit
from sensornet.tracking.fusion import Reduce, check_weights, gci_combine, gci_pair
from sensornet.tracking.gaussian import (
    c_einsum,
    inv_spd,
    symmetrise,
)
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import sweep_labels


def aa_fuse(
    densities: Sequence[GaussianMixture],
    weights: Sequence[float],
    reduce: Reduce | None = None,
) -> GaussianMixture:
    """Arithmetic average ``sum_i omega_i D_i`` (seed 004 baseline): union, scaled, reduced."""
    densities, weights = check_weights(densities, weights)
    fused = GaussianMixture.concatenate([D.scaled(w) for D, w in zip(densities, weights,
                                                                       strict=True)])
    return reduce(fused) if reduce is not None else fused


AA_LABEL_STATES = ("mean", "heaviest")
"""State rules of :func:`aa_label_density`."""


def aa_label_density(weights: np.ndarray, means: np.ndarray, covs: np.ndarray,
                     group: np.ndarray, state: str = "mean"
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The AA fusion of LMB densities per label (Li 2022, "Arithmetic average density fusion,
    part II", arXiv 2209.10433, the LMB case): label ``l``'s fused existence is ``r(l) =
    sum_i w_i r_i(l)`` and its spatial density the ``w_i r_i(l)``-weighted mixture of the
    inputs' densities of ``l``. An AA-fused PHD mixture (:func:`aa_fuse`) holds each input's
    component of a target as its own row at weight ``w_i r_i(l)`` (a copy), so a target every
    input holds at 0.9 is three rows at 0.3, each under an existence test's 0.5.

    ``group (n,)``: each row's label row (a row of its own label: itself; a copy: the row that
    kept the label, :func:`peers.labelling.copy_keepers`), never a row that is itself a copy.
    Returns ``(weights, means, covs)`` of the same ``n`` rows: a label row's weight is its
    group's sum capped at 1 (``r(l)``), a copy's 0 (so extraction reports a label once); its
    state, ``"mean"``, is the moments of the group's weighted mixture (mean ``sum w m / r``,
    covariance ``sum w (P + (m - mean)(m - mean)^T) / r``, the fused label density's), or,
    ``"heaviest"``, the label row's own (the row whose label the peers agree on). ValueError on
    bad input."""
    w = np.asarray(weights, dtype=float)
    m = np.asarray(means, dtype=float)
    P = np.asarray(covs, dtype=float)
    g = np.asarray(group)
    n = len(w)
    if state not in AA_LABEL_STATES:
        raise ValueError(f"AA label state must be one of {AA_LABEL_STATES}, got {state!r}")
    if g.shape != (n,) or len(m) != n or len(P) != n:
        raise ValueError(f"group {g.shape}, means {m.shape} and covs {P.shape} must have "
                         f"the {n} rows of the weights")
    if n == 0:
        return w.copy(), m.copy(), P.copy()
    if not np.issubdtype(g.dtype, np.integer) or g.min() < 0 or g.max() >= n \
            or (g[g] != g).any():
        raise ValueError("group must index rows in [0, n) that are their own group")
    total = np.bincount(g, weights=w, minlength=n)
    out_w = np.where(g == np.arange(n), np.minimum(total, 1.0), 0.0)
    if state == "heaviest" or (g == np.arange(n)).all():
        return out_w, m.copy(), P.copy()
    safe = np.where(total > 0, total, 1.0)
    mean = np.zeros_like(m)
    np.add.at(mean, g, w[:, None] * m)
    mean /= safe[:, None]
    d = m - mean[g]
    cov = np.zeros_like(P)
    np.add.at(cov, g, w[:, None, None] * (P + d[:, :, None] * d[:, None, :]))
    cov /= safe[:, None, None]
    roots = g == np.arange(n)
    use = roots & (total > 0)  # a group of zero weight keeps its row's own state
    out_m, out_P = m.copy(), P.copy()
    out_m[use], out_P[use] = mean[use], cov[use]
    return out_w, out_m, out_P


HYBRID_GATE = 26.0
"""Default association gate of :func:`hybrid_fuse`: ``(m_i - m_j)' P_i^-1 (m_i - m_j)``. Two
consistent estimates of one target differ by about ``2 P``, so the form is about twice a
chi-square with ``d`` degrees of freedom: 26 keeps 99 % of same-target pairs in 4-D (twice the
99 % point 13.3)."""


POOL_CLIP = 1e-9
"""Existences are clipped to ``[POOL_CLIP, 1 - POOL_CLIP]`` before :func:`pool_existence`."""


def pool_existence(W: np.ndarray, group: np.ndarray, n_groups: int,
                   prior: float) -> np.ndarray:
    """``(n_groups,)`` fused existence of each group from its inputs' existences ``W (c,)``
    (one per (group, input) cell, ``group (c,)`` its group), as if the inputs' evidence were
    independent given a common prior existence ``prior``: the independent-likelihood pool
    ``f(X | Z_1..Z_n) ∝ f(X) prod_i f(X | Z_i) / f(X)`` (Chong, Mori & Chang 1990; Bayes' rule
    with conditionally independent data) on a Bernoulli's ``X = ∅`` / ``{x}`` masses, the
    spatial factor taken as 1 (the group is the association): in log-odds,
    ``logit r = logit r0 + sum_i (logit r_i - logit r0)``. Unlike the AA existence (Li 2022:
    ``sum_i omega_i r_i``) and the GCI one (Fantacci et al. 2018: for agreeing densities the
    odds' weighted geometric mean ``prod_i (r_i / (1 - r_i))^omega_i``), both means of the
    inputs, each input's evidence adds, as the centralised update's sensors' does. Exact only
    for a static existence and inputs that share no data (``network.feedback`` off, one
    round): a track's posterior after a death is not prior x likelihood, so callers pool
    young tracks only (:mod:`tracking.support`)."""
    if not 0.0 < prior < 1.0:
        raise ValueError(f"existence prior must be in (0, 1), got {prior}")
    r = np.clip(np.asarray(W, dtype=float), POOL_CLIP, 1.0 - POOL_CLIP)
    lo = float(logit(prior))
    return expit(lo + np.bincount(group, weights=logit(r) - lo, minlength=n_groups))


def hybrid_fuse(
    densities: Sequence[GaussianMixture],
    weights: Sequence[float],
    reduce: Reduce | None = None,
    gate: float = HYBRID_GATE,
) -> GaussianMixture:
    """Arithmetic average for how many targets, geometric average for where they are.

    The hybrid of Li, Fan, Herrero & Corchado 2019 (Inf. Fusion 51, §5: "GA for localisation,
    AA for cardinality"): the inputs' components are grouped by target (the sweep of
    :func:`tracking.reduction.sweep_labels` on the union, association gate ``gate``); a group's
    weight is the AA ``sum_i omega_i W_gi`` of every input's mass in it, so an input that missed
    or pruned the target lowers it by ``omega_i W`` instead of zeroing it (GCI's product); its
    Gaussian is the covariance intersection (GCI of one Gaussian each, seed 000 eq. 15-16) of the
    inputs present, each first moment-matched within the group:
    ``Y_g = sum_i omega~_gi P_gi^-1``, ``m_g = Y_g^-1 sum_i omega~_gi P_gi^-1 m_gi``,
    ``omega~_gi = omega_i / sum_(present) omega``. Then ``reduce``.
    """
    densities, weights = check_weights(densities, weights)
    d = densities[0].dim
    used = [(D, w) for D, w in zip(densities, weights, strict=True) if w > 0.0 and len(D)]
    if not used:
        return GaussianMixture.empty(d)
    n = len(used)
    omegas = np.array([w for _, w in used])
    own_w = np.concatenate([D.weights for D, _ in used])
    src = np.repeat(np.arange(n), [len(D) for D, _ in used])
    union = GaussianMixture.trusted(  # the AA (inputs are validated mixtures: no checks)
        own_w * omegas[src], np.concatenate([D.means for D, _ in used]),
        np.concatenate([D.covs for D, _ in used]))
    # the union's inverses, shared by the sweep and (exactly symmetric covariances, the usual
    # case: symmetrise is then the identity) the cells of one component
    Pu = union.covs
    Yu = inv_spd(Pu)
    shared = bool((Pu == Pu.swapaxes(1, 2)).all())
    labels = sweep_labels(union, gate, inv=Yu)
    G = int(labels.max()) + 1
    key = labels * n + src  # (group, input) cell of each component
    order = np.argsort(key, kind="stable")
    key_s = key[order]
    starts = np.flatnonzero(np.concatenate(([True], key_s[1:] != key_s[:-1])))
    cells = key_s[starts]  # the occupied cells
    w, m, P = own_w[order], union.means[order], union.covs[order]
    Y = None
    if len(cells) == len(w) and (w > 0).all():
        # one component per cell (the common case): its moment match is itself, exactly
        W, mean, cov = w, m, P
        if shared:
            Y = Yu[order]
    else:
        cnt = np.diff(np.append(starts, len(w)))
        cell_of = np.repeat(np.arange(len(cells)), cnt)
        W = np.add.reduceat(w, starts)
        with np.errstate(divide="ignore", invalid="ignore"):  # a zero-mass cell: plain mean
            wn = np.where(W[cell_of] > 0, w / W[cell_of], 1.0 / cnt[cell_of])
        mean = np.add.reduceat(wn[:, None] * m, starts)  # moment match per cell
        diff = m - mean[cell_of]
        cov = np.add.reduceat(wn[:, None, None] * (P + diff[:, :, None] * diff[:, None, :]),
                              starts)
    g, i = np.divmod(cells, n)
    if Y is None:
        Y = inv_spd(symmetrise(cov))  # (cells, d, d)
    present_om = np.zeros((G, n))
    present_om[g, i] = omegas[i]
    om_t = (present_om / present_om.sum(axis=1, keepdims=True))[g, i]  # omega~ per cell
    gstarts = np.flatnonzero(np.concatenate(([True], g[1:] != g[:-1])))  # cells are sorted by group
    Ysum = np.add.reduceat(om_t[:, None, None] * Y, gstarts)  # (G, d, d)
    hsum = np.add.reduceat(om_t[:, None] * c_einsum("cij,cj->ci", Y, mean), gstarts)
    Pf = inv_spd(Ysum)  # exactly symmetric already (inv_spd symmetrises)
    mf = c_einsum("gij,gj->gi", Pf, hsum)
    wf = np.bincount(g, weights=omegas[i] * W, minlength=G)
    fused = GaussianMixture.trusted(wf, mf, Pf)
    return reduce(fused) if reduce is not None else fused


def metropolis_weights(adjacency: np.ndarray) -> np.ndarray:
    """Metropolis weights ``omega_ij = 1/(1 + max(deg_i, deg_j))`` on edges, ``omega_ii = 1 - sum``.

    ``adjacency (n, n)`` symmetric boolean without self-loops; returns a doubly stochastic
    ``(n, n)`` matrix (Battistelli et al. 2013, the consensus of seed 000 ref. [13]).
    """
    A = np.asarray(adjacency, dtype=bool)
    if A.ndim != 2 or A.shape[0] != A.shape[1] or not np.array_equal(A, A.T):
        raise ValueError("adjacency must be a symmetric square matrix")
    A = A & ~np.eye(len(A), dtype=bool)
    deg = A.sum(axis=1)
    W = np.where(A, 1.0 / (1.0 + np.maximum(deg[:, None], deg[None, :])), 0.0)
    W[np.diag_indices_from(W)] = 1.0 - W.sum(axis=1)
    return W


def optimal_omega(Di: GaussianMixture, Dj: GaussianMixture, criterion: str = "det") -> float:
    """The ``omega`` in [0, 1] chosen per fusion (§3, our reading).

    ``"det"``: minimise the determinant of the fused (normalised, moment-matched) covariance.
    ``"chernoff"``: minimise the mass of ``p_i^(1-omega) p_j^omega`` of the normalised inputs
    (the Chernoff point).
    """
    if len(Di) == 0 or len(Dj) == 0:
        return 0.5
    pi, pj = Di.normalised(), Dj.normalised()

    def cost(omega: float) -> float:
        fused = gci_pair(pi, pj, omega)
        if fused.mass <= 0 or not np.isfinite(fused.mass):
            return np.inf
        if criterion == "det":
            _, cov = fused.moments()
            return float(np.linalg.slogdet(cov)[1])
        if criterion == "chernoff":
            return fused.mass
        raise ValueError(f"unknown omega criterion {criterion!r}; expected 'det' or 'chernoff'")

    res = minimize_scalar(cost, bounds=(1e-3, 1 - 1e-3), method="bounded",
                          options={"xatol": 1e-3})
    return float(res.x)


def gci_fuse_optimised(
    densities: Sequence[GaussianMixture],
    criterion: str = "det",
    reduce: Reduce | None = None,
    cardinality: str = "emd",
) -> GaussianMixture:
    """Sequential GCI where each step's ``omega`` is chosen by :func:`optimal_omega`."""
    densities = list(densities)
    if not densities:
        raise ValueError("need at least one density to fuse")
    acc = densities[0]
    for D in densities[1:]:
        acc = gci_combine(acc, D, optimal_omega(acc, D, criterion), cardinality)
        if reduce is not None:
            acc = reduce(acc)
    return acc
