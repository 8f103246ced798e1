"""Fusion of Gaussian-mixture intensities: GCI, AA, Metropolis weights.

Formulas and our readings: docs/algorithms.md "GCI fusion".

The GCI formula lives here, once. For two mixtures ``D_i = sum_a``, ``D_j = sum_b`` and weight
``omega`` (seed 000 eq. 14-17; Uney, Clark & Julier 2013), with ``C = omega P_a + (1-omega) P_b``:

* ``P_ab = [(1-omega) P_a^-1 + omega P_b^-1]^-1 = P_a C^-1 P_b``
* ``m_ab = P_ab [(1-omega) P_a^-1 m_a + omega P_b^-1 m_b] = m_a + omega P_a C^-1 (m_b - m_a)``
* ``w_ab = w_a^(1-omega) w_b^omega kappa(1-omega, P_a) kappa(omega, P_b)
  N(m_a - m_b; 0, P_a/(1-omega) + P_b/omega)``, and ``P_a/(1-omega) + P_b/omega =
  C / (omega (1-omega))``.

The right-hand forms (identity: ``(1-omega) P_a^-1 + omega P_b^-1 = P_a^-1 C P_b^-1``) need one
inverse per pair instead of three; with the closed-form 4x4 inverse the ``N_i x N_j`` pairs are a
single array computation.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import minimize_scalar

from tracking.gaussian import (
    LOG_2PI,
    SYM4_INDEX,
    SYM4_WORK,
    c_einsum,
    inv_det_spd,
    inv_spd,
    quad_form,
    sym4_inverse_into,
    symmetrise,
)
from tracking.mixture import GaussianMixture
from tracking.reduction import sweep_labels

Reduce = Callable[[GaussianMixture], GaussianMixture]


def log_kappa(omega: float, logdet: np.ndarray, d: int) -> np.ndarray:
    """``log kappa(omega, P)``, ``kappa = det(2 pi P / omega)^(1/2) / det(2 pi P)^(omega/2)``."""
    return 0.5 * (1.0 - omega) * (d * LOG_2PI + logdet) - 0.5 * d * np.log(omega)


def gci_pair(Di: GaussianMixture, Dj: GaussianMixture, omega: float) -> GaussianMixture:
    """GCI of two mixtures, ``D_i^(1-omega) D_j^omega``, one component per pair (a, b).

    Computed in information form: ``Y_ab = (1-omega) Y_a + omega Y_b`` (``Y = P^-1``),
    ``P_ab = Y_ab^-1``, ``m_ab = P_ab ((1-omega) Y_a m_a + omega Y_b m_b)``; the weight's
    ``C^-1 = Y_b P_ab Y_a`` and ``det C = det Y_ab det P_a det P_b`` (from ``Y_ab = Y_a C Y_b``).
    """
    if not 0.0 <= omega <= 1.0:
        raise ValueError(f"GCI weight omega must be in [0, 1], got {omega}")
    if omega == 0.0:
        return Di
    if omega == 1.0:
        return Dj
    d = Di.dim
    na, nb = len(Di), len(Dj)
    if na == 0 or nb == 0:
        return GaussianMixture.empty(d)
    if na * nb <= _SMALL_PAIRS:
        return _gci_pair_small(Di, Dj, omega)
    Ya, det_a = inv_det_spd(Di.covs)
    Yb, det_b = inv_det_spd(Dj.covs)
    ma, mb = Di.means, Dj.means
    ha = np.einsum("aij,aj->ai", Ya, ma)  # (na, d)
    hb = np.einsum("bij,bj->bi", Yb, mb)  # (nb, d)
    # u = Y_a (m_b - m_a) = Y_a m_b - h_a, v = Y_b (m_b - m_a) = h_b - Y_b m_a: two small GEMMs
    Ya_mb = (Ya.reshape(na * d, d) @ mb.T).reshape(na, d, nb)
    Yb_ma = (Yb.reshape(nb * d, d) @ ma.T).reshape(nb, d, na)
    with np.errstate(divide="ignore"):  # a zero weight gives zero-weight pairs
        log_wa = (1.0 - omega) * np.log(Di.weights)
        log_wb = omega * np.log(Dj.weights)
    n_blocks = -(-na * nb // _GCI_BLOCK)
    terms = _GCITerms(omega, ha, hb, Ya, Yb, Ya_mb, Yb_ma, log_wa, log_wb, np.log(det_a),
                      np.log(det_b), rows=-(-na // n_blocks))
    weights = np.empty((na, nb))
    if d == 4:  # entry-major slabs, (4, n) means and (16, n) covariances, returned transposed:
        # the memory layout this function always had (NumPy's reductions follow the layout)
        means, covs = np.empty((d, na, nb)), np.empty((d, d, na, nb))
    else:
        means, covs = np.empty((na, nb, d)), np.empty((na, nb, d, d))
    for a0 in range(0, na, terms.rows):
        rows = slice(a0, min(a0 + terms.rows, na))
        terms.block(rows, weights[rows], means, covs)
    if d == 4:
        means, covs = means.reshape(d, -1).T, covs.reshape(d * d, -1).T.reshape(-1, d, d)
    return GaussianMixture(weights.reshape(-1), means.reshape(na * nb, d),
                           covs.reshape(na * nb, d, d))


_SMALL_PAIRS = 24
"""Up to this many pairs :func:`gci_pair` uses plain batched LAPACK calls (:func:`_gci_pair_small`):
for the few components of level-2-pruned estimates the closed-form machinery costs more in
per-call overhead than it saves."""


def _gci_pair_small(Di: GaussianMixture, Dj: GaussianMixture, omega: float) -> GaussianMixture:
    """:func:`gci_pair` for a few pairs: the same information-form equations, ``(na, nb)``
    stacks through ``numpy.linalg`` (equal to the batched path up to round-off)."""
    d, na, nb = Di.dim, len(Di), len(Dj)
    Ya, Yb = np.linalg.inv(Di.covs), np.linalg.inv(Dj.covs)
    _, logdet_a = np.linalg.slogdet(Di.covs)
    _, logdet_b = np.linalg.slogdet(Dj.covs)
    Y = (1.0 - omega) * Ya[:, None] + omega * Yb[None, :]  # (na, nb, d, d)
    P = np.linalg.inv(Y)
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    _, logdet_y = np.linalg.slogdet(Y)
    ha = np.einsum("aij,aj->ai", Ya, Di.means)
    hb = np.einsum("bij,bj->bi", Yb, Dj.means)
    info = (1.0 - omega) * ha[:, None] + omega * hb[None, :]  # (na, nb, d)
    means = np.einsum("abij,abj->abi", P, info)
    diff = Dj.means[None, :] - Di.means[:, None]  # m_b - m_a
    u = np.einsum("aij,abj->abi", Ya, diff)  # Y_a (m_b - m_a)
    v = np.einsum("bij,abj->abi", Yb, diff)  # Y_b (m_b - m_a)
    quad = np.einsum("abi,abij,abj->ab", v, P, u)  # (m_b - m_a)' C^-1 (m_b - m_a)
    oo = omega * (1.0 - omega)
    log_det_c = logdet_y + logdet_a[:, None] + logdet_b[None, :]  # det C = det Y det Pa det Pb
    log_n = -0.5 * (oo * quad + log_det_c - d * np.log(oo) + d * LOG_2PI)
    with np.errstate(divide="ignore"):
        log_w = ((1.0 - omega) * np.log(Di.weights)[:, None] + omega * np.log(Dj.weights)[None]
                 + log_kappa(1.0 - omega, logdet_a, d)[:, None]
                 + log_kappa(omega, logdet_b, d)[None, :] + log_n)
    return GaussianMixture(np.exp(log_w).reshape(-1), means.reshape(na * nb, d),
                           P.reshape(na * nb, d, d))


_GCI_BLOCK = 8192
"""At most this many pairs per block of :func:`gci_pair` (its scratch stays a few MB)."""


class _GCITerms:
    """The per-component terms of :func:`gci_pair`, and its pairs one block of rows at a time.

    A block is the components ``a`` in ``rows`` of ``D_i`` against every ``b`` of ``D_j``. Each
    pair's numbers depend on its own inputs only, so blocking changes no result; it keeps the
    temporaries small and, for ``d = 4``, in one reused scratch array (no page faults).
    """

    def __init__(self, omega, ha, hb, Ya, Yb, Ya_mb, Yb_ma, log_wa, log_wb, log_det_a, log_det_b,
                 rows):
        d = ha.shape[1]
        self.d, self.rows = d, rows
        # one row, or one (na, nb) slab, per state entry
        self.ha_t, self.hb_t = ha.T, hb.T
        self.Ya_mb_t = Ya_mb.transpose(1, 0, 2)  # (d, na, nb)
        self.Yb_ma_t = Yb_ma.transpose(1, 2, 0)  # (d, na, nb)
        self.cha_t, self.chb_t = ((1.0 - omega) * ha).T, (omega * hb).T
        cYa, cYb = (1.0 - omega) * Ya, omega * Yb
        if d == 4:
            self.cYa10 = cYa[:, _SYM4_I, _SYM4_J].T  # (10, na): the SYM4_INDEX entries
            self.cYb10 = cYb[:, _SYM4_I, _SYM4_J].T  # (10, nb)
        else:
            self.cYa, self.cYb = cYa, cYb
        # the pair-independent parts of log w_ab
        self.log_wa, self.log_wb = log_wa, log_wb
        self.log_det_a, self.log_det_b = log_det_a, log_det_b
        self.log_kappa_a = log_kappa(1.0 - omega, log_det_a, d)
        self.log_kappa_b = log_kappa(omega, log_det_b, d)
        self.oo = omega * (1.0 - omega)
        self.log_oo, self.log_2pi = d * np.log(self.oo), d * LOG_2PI

    def block(self, rows: slice, weights: np.ndarray, means: np.ndarray,
              covs: np.ndarray) -> None:
        """Fill ``weights (r, nb)`` and the block's part of ``means``, ``covs``: for ``d = 4``
        the slabs ``(4, na, nb)``, ``(4, 4, na, nb)``, else ``(na, nb, d)``, ``(na, nb, d, d)``.
        """
        r, nb = weights.shape
        if self.d == 4:
            work = _scratch(_GCI_PLANES * r * nb).reshape(_GCI_PLANES, r, nb)
            quad, log_det_y = self._block_sym4(rows, work, means[:, rows], covs[:, :, rows])
        else:
            u = self.Ya_mb_t[:, rows] - self.ha_t[:, rows, None]  # (d, r, nb)
            v = self.hb_t[:, None, :] - self.Yb_ma_t[:, rows]
            info = self.cha_t[:, rows, None] + self.chb_t[:, None, :]
            Pab, det_y = inv_det_spd(self.cYa[rows, None] + self.cYb[None, :])  # (r, nb, d, d)
            means[rows] = np.moveaxis(np.einsum("abij,jab->iab", Pab, info), 0, -1)
            quad = np.einsum("iab,abij,jab->ab", v, Pab, u)
            covs[rows] = symmetrise(Pab)
            log_det_y = np.log(det_y)
        log_det_c = log_det_y + self.log_det_a[rows, None] + self.log_det_b[None, :]
        log_n = -0.5 * (self.oo * quad + log_det_c - self.log_oo + self.log_2pi)
        log_w = (
            self.log_wa[rows, None]
            + self.log_wb[None, :]
            + self.log_kappa_a[rows, None]
            + self.log_kappa_b[None, :]
            + log_n
        )
        np.exp(log_w, out=weights)

    def _block_sym4(self, rows: slice, W: np.ndarray, means: np.ndarray, covs: np.ndarray):
        """``d = 4``: fill ``means (4, r, nb)``, ``covs (4, 4, r, nb)``; return ``quad``,
        ``log det Y_ab``. All in the ``(r, nb)`` planes of the scratch ``W``.
        """
        mul, add = np.multiply, np.add
        Y = W[0:10]  # upper entries of Y_ab = (1-omega) Y_a + omega Y_b
        add(self.cYa10[:, rows, None], self.cYb10[:, None, :], out=Y)
        det = W[10]
        sym4_inverse_into(Y, covs, det, W[11:11 + SYM4_WORK])  # P_ab, det Y_ab
        P = covs
        log_det_y = np.log(det, out=det)
        # m_i = sum_j P_ij info_j, quad = sum_i v_i sum_j P_ij u_j (Y no longer needed)
        info, u, v = W[0:4], W[4:8], W[11:15]
        np.add(self.cha_t[:, rows, None], self.chb_t[:, None, :], out=info)
        np.subtract(self.Ya_mb_t[:, rows], self.ha_t[:, rows, None], out=u)
        np.subtract(self.hb_t[:, None, :], self.Yb_ma_t[:, rows], out=v)
        Pu, tmp, quad = W[15:19], W[19:23], W[8]
        mul(P[:, 0], info[0], out=means)
        mul(P[:, 0], u[0], out=Pu)
        for j in range(1, 4):
            mul(P[:, j], info[j], out=tmp)
            add(means, tmp, out=means)
            mul(P[:, j], u[j], out=tmp)
            add(Pu, tmp, out=Pu)
        mul(v, Pu, out=Pu)
        add(Pu[0], Pu[1], out=quad)
        add(quad, Pu[2], out=quad)
        add(quad, Pu[3], out=quad)
        return quad, log_det_y


_SYM4_I, _SYM4_J = (np.array(ix) for ix in zip(*SYM4_INDEX, strict=True))
_GCI_PLANES = 11 + SYM4_WORK
"""``(r, nb)`` planes of scratch for one ``d = 4`` block."""

_LOCAL = threading.local()


def _scratch(size: int) -> np.ndarray:
    """A float array of ``size``, reused across calls (one per thread)."""
    buf = getattr(_LOCAL, "scratch", None)
    if buf is None or buf.size < size:
        buf = _LOCAL.scratch = np.empty(size)
    return buf[:size]


CARDINALITY_RULES = ("emd", "separate")
MIN_OVERLAP = 1e-12
"""Below this ``int p_i^(1-omega) p_j^omega`` the location densities are taken as disjoint."""


def gci_combine(Di: GaussianMixture, Dj: GaussianMixture, omega: float,
                cardinality: str = "emd") -> GaussianMixture:
    """GCI of two intensities with a choice of how the fused mass (target number) is formed.

    ``"emd"``: the exponential mixture of two Poisson processes is Poisson with intensity
    ``D_i^(1-omega) D_j^omega`` (Uney, Clark & Julier 2013): exactly :func:`gci_pair`. Its mass
    is at most ``N_i^(1-omega) N_j^omega`` and drops whenever the peers' estimates of a target
    differ, so fused PHDs under-count targets.
    ``"separate"``: location densities and cardinality distributions fused separately, as in
    the consensus CPHD of Battistelli et al. 2013 (seed 000 ref. [13]): the normalised product
    ``p_i^(1-omega) p_j^omega`` scaled to the GCI of the Poisson cardinalities, whose mean is
    ``N_i^(1-omega) N_j^omega`` (our reading for PHD peers).
    """
    if cardinality == "emd":
        return gci_pair(Di, Dj, omega)
    if cardinality != "separate":
        raise ValueError(f"unknown cardinality rule {cardinality!r}; expected {CARDINALITY_RULES}")
    Ni, Nj = Di.mass, Dj.mass
    if Ni <= 0 or Nj <= 0:
        return GaussianMixture.empty(Di.dim)
    fused = gci_pair(Di.scaled(1.0 / Ni), Dj.scaled(1.0 / Nj), omega)
    c = fused.mass
    if not c > MIN_OVERLAP:  # the densities do not overlap: no common target to scale up
        return GaussianMixture.empty(Di.dim)
    return fused.scaled(Ni ** (1.0 - omega) * Nj**omega / c)


def gci_fuse(
    densities: Sequence[GaussianMixture],
    weights: Sequence[float],
    reduce: Reduce | None = None,
    normalise: bool = False,
    cardinality: str = "emd",
) -> GaussianMixture:
    """n-ary GCI ``prod_i D_i^(omega_i)`` (§3), reduced.

    While the number of component combinations ``prod_i N_i`` is at most
    :data:`NARY_MAX_COMBINATIONS` it is formed in one batched step (:func:`gci_product`) and
    reduced once; beyond, by sequential pairing, reducing after each step (the pair count
    multiplies): step ``i`` fuses the running result (weight ``s = omega_0 + ... +
    omega_(i-1)``) with the newcomer at ``omega = omega_i / (s + omega_i)``. Before any
    reduction both give the same mixture. ``normalise`` gives a unit-mass result
    (single-target densities; with one Gaussian each this is covariance intersection).
    ``cardinality``: see :func:`gci_combine`.
    """
    densities, weights = _check_weights(densities, weights)
    used = [(D, w) for D, w in zip(densities, weights, strict=True) if w > 0.0]
    if len(used) > 1 and math.prod(len(D) for D, _ in used) <= NARY_MAX_COMBINATIONS:
        acc = gci_product([D for D, _ in used], [w for _, w in used], cardinality,
                          gate=reduce is not None)
        if reduce is not None:
            acc = reduce(acc)
    else:
        acc, s = None, 0.0
        for D, w in used:
            if acc is None:
                acc, s = D, w
                continue
            acc = gci_combine(acc, D, w / (s + w), cardinality)
            s += w
            if reduce is not None:
                acc = reduce(acc)
    assert acc is not None
    if normalise and acc.mass > 0:
        acc = acc.normalised()
    return acc


NARY_MAX_COMBINATIONS = 4096
"""Up to this many component combinations :func:`gci_fuse` forms the n-ary product at once."""


def gci_product(densities: Sequence[GaussianMixture], weights: Sequence[float],
                cardinality: str = "emd", gate: bool = False) -> GaussianMixture:
    """``prod_i D_i^(omega_i)`` (``sum omega_i = 1``) in one step: a component per combination.

    The power of a mixture drops cross terms (§3; seed 000 eq. 14-17), so the product is, over
    the combinations ``c = (c_1, ..., c_n)`` of one component per density,
    ``prod_i (w_ic N_ic)^(omega_i)``: in information form ``Y = sum_i omega_i Y_ic``,
    ``P = Y^-1``, ``m = P sum_i omega_i Y_ic m_ic``, and weight ``prod_i w_ic^(omega_i)`` times
    ``int prod_i N_ic^(omega_i) = exp(-1/2 [sum_i omega_i log det P_ic + log det Y
    + sum_i omega_i (m_ic - m)' Y_ic (m_ic - m)])`` (the ``2 pi`` factors cancel as the weights
    sum to 1). Every term is taken about the combination's own points (:func:`_centred_terms`):
    no large numbers cancel, so the result stays within about ``eps * cond(P)`` of exact
    arithmetic (tested to condition number 1e12). This is what sequential :func:`gci_combine`
    steps give before any reduction (the same equations, regrouped); combinations are ordered
    with the first density's component slowest. ``cardinality``: ``"emd"`` or ``"separate"`` (see
    :func:`gci_combine`). ``gate``: leave out the combinations that two far-apart components
    make negligible (:func:`_gated_rows`; for a reduced result: a pruning reducer drops them).
    """
    if cardinality not in CARDINALITY_RULES:
        raise ValueError(f"unknown cardinality rule {cardinality!r}; expected {CARDINALITY_RULES}")
    densities = list(densities)
    omegas = np.asarray(weights, dtype=float)
    d = densities[0].dim
    if any(len(D) == 0 for D in densities):
        return GaussianMixture.empty(d)
    masses = np.array([D.mass for D in densities])
    if cardinality == "separate":
        if np.any(masses <= 0):
            return GaussianMixture.empty(d)
        densities = [D.scaled(1.0 / N) for D, N in zip(densities, masses, strict=True)]
    log_w, means, covs = _centred_terms(densities, omegas, gate)
    fused = GaussianMixture(np.exp(log_w), means, covs)
    if cardinality == "emd":
        return fused
    c = fused.mass
    if not c > MIN_OVERLAP:  # the densities do not overlap: no common target to scale up
        return GaussianMixture.empty(d)
    return fused.scaled(float(np.prod(masses ** omegas)) / c)


class _Components:
    """Per-component inputs of :func:`gci_product`, all densities' components concatenated:
    ``wY = omega_i Y_i (K, d, d)``, ``wc = omega_i (log w_i - 1/2 log det P_i) (K,)``, means
    ``(K, d)``, and ``start[i]`` (density ``i``'s first row)."""

    def __init__(self, densities: list[GaussianMixture], omegas: np.ndarray) -> None:
        self.sizes = [len(D) for D in densities]
        self.start = np.cumsum(self.sizes) - self.sizes
        Yall, det_all = inv_det_spd(np.concatenate([D.covs for D in densities]))
        om = np.repeat(omegas, self.sizes)
        with np.errstate(divide="ignore", invalid="ignore"):  # zero weights: zero-weight combos
            self.wc = om * (np.log(np.concatenate([D.weights for D in densities]))
                            - 0.5 * np.log(det_all))
        self.wY = om[:, None, None] * Yall
        self.means = np.concatenate([D.means for D in densities])
        self.densities, self.omegas = densities, omegas

    def part(self, i: int) -> slice:
        """Density ``i``'s rows."""
        return slice(self.start[i], self.start[i] + self.sizes[i])


def _centred_terms(densities: list[GaussianMixture], omegas: np.ndarray, gate: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`gci_product`'s ``log w (C,)``, means ``(C, d)`` and covariances ``(C, d, d)``.

    Combination ``c`` is computed about ``r = m_(1 c_1)``, its first density's mean: with
    ``u_i = m_ic - r``, ``m = r + delta``, ``delta = P sum_i omega_i Y_ic u_i``, and the
    quadratic term from the residuals ``e_i = m_ic - m = u_i - delta`` themselves. That term
    is the minimum over ``x`` of ``sum_i omega_i (m_ic - x)' Y_ic (m_ic - x)``, so a round-off
    error in ``m`` changes it only to second order. (The information form
    ``sum_i omega_i m_ic' Y_ic m_ic - h' m`` subtracts numbers of size ``|m - ref|^2 / lambda_min
    (P)``: relative weight errors up to 7e-3 at condition number 1e6, overflow at 1e9.)
    Up to :data:`_SMALL_COMBINATIONS` combinations are gathered into flat arrays (fewest NumPy
    calls); more are summed on the ``(*sizes)`` grid by broadcasting (least memory traffic), or
    with ``gate`` only those :func:`_gated_rows` keeps, gathered, when what it leaves out carries
    at most :data:`_GATE_TOLERANCE` of the kept mass.
    """
    comps = _Components(densities, omegas)
    if math.prod(comps.sizes) <= _SMALL_COMBINATIONS:
        return _centred_gathered(comps)
    if gate:
        gated = _gated_rows(comps)
        if gated is not None:
            rows, left_out = gated
            terms = _centred_gathered(comps, rows)
            if left_out <= _GATE_TOLERANCE * np.exp(terms[0]).sum():
                return terms  # else what was left out might matter: form every combination
    return _centred_on_grid(comps)


_SMALL_COMBINATIONS = 64
"""Up to this many combinations :func:`_centred_terms` gathers per-combination arrays (the
level-2-pruned inputs of a peer's fusion are usually this few)."""


_GATE = 2.0 * math.log(1e20)
"""Pair term above which :func:`_gated_rows` leaves a combination out (its weight is then at
most ``1e-20`` times the largest product of its components' weights)."""

_GATE_TOLERANCE = 1e-14
"""Largest share of the fused mass the combinations left out may carry (else: all of them)."""


def _gated_rows(comps: _Components) -> tuple[np.ndarray, float] | None:
    """The combinations worth forming, as ``(n, C_kept)`` component rows, and a bound on the
    mass of those left out; None if none is kept.

    A combination's quadratic term is ``min_x sum_i omega_i |m_ic - x|^2_(Y_ic)``, at least the
    same minimum over two of its components, its first density's ``a`` and density ``i``'s
    ``b``: ``(m_a - m_b)' (P_a / omega_1 + P_b / omega_i)^-1 (m_a - m_b)``; and its determinant
    factor is at most 1 (log det is concave), so its weight is at most ``prod_i w_ic^(omega_i)
    exp(-pair / 2)``. Combinations with a pair term above :data:`_GATE` are left out, densities
    added one at a time (a PHD's components for different targets never combine).
    """
    sizes, start, n = comps.sizes, comps.start, len(comps.sizes)
    om = np.repeat(comps.omegas, sizes)
    S = np.concatenate([D.covs for D in comps.densities]) / om[:, None, None]  # P / omega
    first = comps.part(0)
    # pair terms of each first-density component with every other component: (N_1, K)
    diff = comps.means[None, :, :] - comps.means[first, None, :]
    pair = quad_form(diff, inv_spd(S[first, None] + S[None, :]))
    rows = np.arange(sizes[0])[:, None] + start[0]  # (M, i) kept partial combinations
    for i in range(1, n):
        new = np.arange(sizes[i]) + start[i]
        mi, ni = np.nonzero(pair[rows[:, 0]][:, new] <= _GATE)
        rows = np.concatenate([rows[mi], new[ni, None]], axis=1)
    if not len(rows):
        return None
    log_wmax = sum(o * math.log(D.weights.max()) if D.weights.max() > 0 else -math.inf
                   for D, o in zip(comps.densities, comps.omegas, strict=True))
    dropped = math.prod(sizes) - len(rows)
    return rows.T, dropped * math.exp(min(700.0, log_wmax - 0.5 * _GATE))


def _centred_gathered(comps: _Components, idx: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_centred_terms` with every density's term gathered to ``(n, C, ...)``, over all
    combinations or the ``(n, C)`` component rows ``idx``."""
    n, sizes = len(comps.sizes), comps.sizes
    if idx is None:
        idx = np.indices(sizes).reshape(n, -1) + comps.start[:, None]  # (n, C) component rows
    wY = comps.wY[idx]  # (n, C, d, d)
    ref = comps.means[idx[0]]  # (C, d)
    u = comps.means[idx] - ref  # (n, C, d)
    g = np.einsum("ncjk,nck->cj", wY, u)
    P, det_y = inv_det_spd(wY.sum(axis=0))
    delta = np.einsum("cij,cj->ci", P, g)
    e = u - delta  # m_ic - m
    quad = np.einsum("ncj,ncjk,nck->c", e, wY, e)
    log_w = comps.wc[idx].sum(axis=0) - 0.5 * (np.log(det_y) + quad)
    return log_w, ref + delta, P


def _centred_on_grid(comps: _Components) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_centred_terms` on the ``(*sizes)`` grid, one axis per density: the sums over
    densities are built one axis at a time (the grid reaches full size at the last density),
    the quadratic terms by one batched matrix product per density."""
    sizes, d = comps.sizes, comps.means.shape[1]
    parts = [comps.part(i) for i in range(len(sizes))]
    wY, wc, ref = comps.wY, comps.wc, comps.means[parts[0]]
    U = comps.means[None, :, :] - ref[:, None, :]  # u for every (first-density, any) pair
    wYU = np.einsum("bjk,abk->abj", wY, U)  # (N_1, K, d)
    Y, log_c, g = wY[parts[0]], wc[parts[0]], np.zeros((sizes[0], d))
    for i in range(1, len(sizes)):
        part, lead = parts[i], (1,) * (i - 1)
        Y = Y[..., None, :, :] + wY[part].reshape(*lead, 1, sizes[i], d, d)
        log_c = log_c[..., None] + wc[part].reshape(*lead, 1, sizes[i])
        g = g[..., None, :] + wYU[:, part].reshape(sizes[0], *lead, sizes[i], d)
    C = math.prod(sizes)
    P, det_y = inv_det_spd(Y.reshape(C, d, d))  # exactly symmetric, as Y is
    delta = np.einsum("cij,cj->ci", P, g.reshape(C, d)).reshape(*sizes, d)
    quad = _quad_along(-delta, wY[parts[0]], 0)  # e_1 = -delta
    for i in range(1, len(sizes)):
        e = U[:, parts[i]].reshape(*_axes(sizes, 0, i), d) - delta  # m_ic - m
        quad += _quad_along(e, wY[parts[i]], i)
    log_w = log_c.reshape(C) - 0.5 * (np.log(det_y) + quad.reshape(C))
    means = (ref.reshape(*_axes(sizes, 0), d) + delta).reshape(C, d)
    return log_w, means, P


def _quad_along(e: np.ndarray, Y: np.ndarray, axis: int) -> np.ndarray:
    """``e' Y_k e`` over a grid ``e (*sizes, d)`` whose axis ``axis`` indexes ``Y (N, d, d)``,
    as one batched matrix product ``(pre, N, post, d) (1, N, d, d)`` (no copies; several times
    faster than a broadcasting einsum)."""
    shape = e.shape[:-1]
    E = e.reshape(math.prod(shape[:axis]), shape[axis], -1, e.shape[-1])
    return np.einsum("pkmj,pkmj->pkm", E @ Y, E).reshape(shape)


def _axes(sizes: list[int], *which: int) -> list[int]:
    """Broadcast shape of a per-density array over the combination grid: ``sizes[i]`` on the
    axes ``which``, 1 elsewhere."""
    return [s if i in which else 1 for i, s in enumerate(sizes)]


def aa_fuse(
    densities: Sequence[GaussianMixture],
    weights: Sequence[float],
    reduce: Reduce | None = None,
) -> GaussianMixture:
    """Arithmetic average ``sum_i omega_i D_i`` (seed 004 baseline): union, scaled, reduced."""
    densities, weights = _check_weights(densities, weights)
    fused = GaussianMixture.concatenate([D.scaled(w) for D, w in zip(densities, weights,
                                                                       strict=True)])
    return reduce(fused) if reduce is not None else fused


HYBRID_GATE = 26.0
"""Default association gate of :func:`hybrid_fuse`: ``(m_i - m_j)' P_i^-1 (m_i - m_j)``. Two
consistent estimates of one target differ by about ``2 P``, so the form is about twice a
chi-square with ``d`` degrees of freedom: 26 keeps 99 % of same-target pairs in 4-D (twice the
99 % point 13.3)."""


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
    densities, weights = _check_weights(densities, weights)
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


def _check_weights(densities, weights):
    densities, weights = list(densities), [float(w) for w in weights]
    if not densities or len(densities) != len(weights):
        raise ValueError(f"need one weight per density ({len(densities)} vs {len(weights)})")
    if any(w < 0 for w in weights) or not math.isclose(sum(weights), 1.0, rel_tol=1e-5,
                                                       abs_tol=1e-8):
        raise ValueError(f"fusion weights must be non-negative and sum to 1, got {weights}")
    return densities, weights


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

