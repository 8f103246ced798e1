"""Fusion of Gaussian-mixture intensities by GCI: pairwise, and n-ary by pairs or at once.

Formulas and our readings: docs/algorithms.md "GCI fusion". The n-ary product in one step is
:mod:`tracking.gci_product`; the other rules (AA, the hybrid, Metropolis weights, the choice of
omega) are :mod:`tracking.fusion_rules`.

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
from sensornet.tracking.gaussian import (
    LOG_2PI,
    SYM4_INDEX,
    SYM4_WORK,
    inv_det_spd,
    sym4_inverse_into,
    symmetrise,
)
from sensornet.tracking.gci_product import (
    CARDINALITY_RULES,
    MIN_OVERLAP,
    gci_product,
    gci_product_gated,
    gci_step,
    inverses,
)
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer, merge_many

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
    sequential: bool = False,
) -> GaussianMixture:
    """n-ary GCI ``prod_i D_i^(omega_i)`` (§3), reduced.

    While the number of component combinations ``prod_i N_i`` is at most
    :data:`NARY_MAX_COMBINATIONS` it is formed in one batched step (:func:`gci_product`) and
    reduced once. Beyond, with a reducer, the gated product is still formed at once and
    reduced once when the gate keeps at most that many combinations
    (:func:`gci_product_gated`; issue 33: own + 8 neighbours of 10 tracks, 11^9 combinations,
    26 kept: one product and one reduction instead of 8 of each, ~3x less CPU). With a
    reducer both products at once take the inputs pre-merged: density ``i``'s rows within the
    reducer's merge test at ``U / omega_i`` merged first (the test on the powered rows
    ``N(m, P/omega)``, which the product's powered-sum approximation needs apart; a reducer
    that is not a :class:`Reducer`: its defaults), all in one call (inputs with nothing to
    merge: the same objects, the same product to the bit); without it a track an input holds
    as two close rows was over-counted (bench inputs beyond 4096: up to +75 % of the exact
    GCI mass, pre-merged within 3.2 %, tests/test_gci_at_once.py; random cases up to 4096:
    up to 19.6x, pre-merged 1.01-1.93x and below ``prod N_i^omega_i``,
    tests/test_gci_small_premerge.py). Without a reducer: the product of the inputs as given
    (no rule to merge by; one Gaussian each, covariance intersection, merges nothing
    anyway). Otherwise, or with
    ``sequential`` (the former path, kept as a reference), by
    sequential pairing, reducing after each step (the pair count
    multiplies): step ``i`` fuses the running result (weight ``s = omega_0 + ... +
    omega_(i-1)``) with the newcomer at ``omega = omega_i / (s + omega_i)``. Before any
    reduction both give the same mixture. With a reducer a step is the two-density
    :func:`gci_product`, gated (:func:`gci_step`: the pairs of far-apart components, below
    1e-14 of the mass together, which a pruning reducer drops, are not formed; equal to
    :func:`gci_combine` then reduced, to round-off), with the newcomers' inverses computed in
    one batched call; without, :func:`gci_combine` (every pair). ``normalise`` gives a
    unit-mass result (single-target densities; with one Gaussian each this is covariance
    intersection). ``cardinality``: see :func:`gci_combine`.
    """
    densities, weights = check_weights(densities, weights)
    used = [(D, w) for D, w in zip(densities, weights, strict=True) if w > 0.0]
    acc = None
    if len(used) > 1 and not sequential:
        inputs, omegas = [D for D, _ in used], [w for _, w in used]
        small = math.prod(len(D) for D in inputs) <= NARY_MAX_COMBINATIONS
        if reduce is None:  # no reducer: the exact product of the inputs as given
            acc = gci_product(inputs, omegas, cardinality) if small else None
        else:  # one pre-merge rule for both products at once (issue 33)
            rule = reduce if isinstance(reduce, Reducer) else _DEFAULT_REDUCER
            if small:
                inputs = merge_many(inputs, rule.merge_threshold / np.array(omegas),
                                    rule.merge_rule)
                acc = gci_product(inputs, omegas, cardinality, gate=True)
            else:  # None: more kept than the bound, fuse in steps
                acc = gci_product_gated(inputs, omegas, cardinality, NARY_MAX_COMBINATIONS,
                                        premerge=(rule.merge_threshold, rule.merge_rule))
        if acc is not None and reduce is not None:
            acc = reduce(acc)
    if acc is None:
        newcomers = inverses([D for D, _ in used[1:]]) if reduce is not None else None
        acc, s = None, 0.0
        for k, (D, w) in enumerate(used):
            if acc is None:
                acc, s = D, w
                continue
            omega = w / (s + w)
            if newcomers is not None and 0.0 < omega < 1.0:
                acc = gci_step(acc, D, omega, cardinality, newcomers[k - 1])
            else:  # omega rounded to 0 or 1 is the running result or the newcomer itself
                acc = gci_combine(acc, D, omega, cardinality)
            s += w
            if reduce is not None:
                acc = reduce(acc)
    assert acc is not None
    if normalise and acc.mass > 0:
        acc = acc.normalised()
    return acc


_DEFAULT_REDUCER = Reducer()
"""The merge rule of :func:`gci_fuse`'s pre-merge when ``reduce`` is not a :class:`Reducer`."""


NARY_MAX_COMBINATIONS = 4096
"""Up to this many component combinations :func:`gci_fuse` forms the n-ary product at once."""


def check_weights(densities, weights):
    densities, weights = list(densities), [float(w) for w in weights]
    if not densities or len(densities) != len(weights):
        raise ValueError(f"need one weight per density ({len(densities)} vs {len(weights)})")
    if any(w < 0 for w in weights) or not math.isclose(sum(weights), 1.0, rel_tol=1e-5,
                                                       abs_tol=1e-8):
        raise ValueError(f"fusion weights must be non-negative and sum to 1, got {weights}")
    return densities, weights
