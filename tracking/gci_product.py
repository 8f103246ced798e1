"""The n-ary GCI product ``prod_i D_i^(omega_i)`` in one batched step (one component per
combination of one component from each density), and the cardinality rules GCI takes.

The pairwise formula and the sequential n-ary fusion are :mod:`tracking.fusion`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from sensornet.tracking.gaussian import (
    c_einsum,
    inv_det_spd,
    inv_spd,
    quad_form,
)
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import merge_stacked

CARDINALITY_RULES = ("emd", "separate")
_sum, _max, _all = np.add.reduce, np.maximum.reduce, np.logical_and.reduce
"""What ``x.sum()``, ``x.max()``, ``x.all()`` call, without their Python wrappers (~1 us a call
in the small steps of :func:`gci_step`; the same numbers)."""
MIN_OVERLAP = 1e-12
"""Below this ``int p_i^(1-omega) p_j^omega`` the location densities are taken as disjoint."""


def gci_product(densities: Sequence[GaussianMixture], weights: Sequence[float],
                cardinality: str = "emd", gate: bool = False,
                inverses: Sequence[Inverse | None] | None = None,
                limit: int | None = None) -> GaussianMixture:
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
    ``inverses``: per density, its ``(P^-1, det P)`` if the caller has it (:func:`inverses`:
    the same numbers), else None. ``limit``: most combinations formed (default
    :data:`MAX_COMBINATIONS`); beyond, a ValueError naming the count instead of arrays that
    may not fit in memory (the gate keeps them all when the components overlap).
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
    limit = MAX_COMBINATIONS if limit is None else limit
    log_w, means, covs = _centred_terms(_Components(densities, omegas, inverses), gate, limit)
    fused = GaussianMixture.trusted(np.exp(log_w), means, covs)
    if cardinality == "emd":
        return fused
    c = fused.mass
    if not c > MIN_OVERLAP:  # the densities do not overlap: no common target to scale up
        return GaussianMixture.empty(d)
    return fused.scaled(float(np.prod(masses ** omegas)) / c)


MAX_COMBINATIONS = 1 << 18
"""Most combinations :func:`gci_product` forms by default (262,144: at ``d = 4`` each
``(C, d, d)`` array is 34 MB, and several are live at once). :func:`tracking.fusion.gci_fuse`
calls it with at most ``NARY_MAX_COMBINATIONS`` (4096) and fuses larger products in steps."""


def _too_many(what: str, sizes: list[int], limit: int) -> ValueError:
    """The one-line error of :func:`gci_product` beyond ``limit`` combinations."""
    return ValueError(f"gci_product: {what} (densities of {sizes} components), more than the "
                      f"limit {limit:,}; reduce the densities or fuse them in steps "
                      f"(tracking.fusion.gci_fuse with a reducer)")


Inverse = tuple[np.ndarray, np.ndarray]
"""A density's ``(P^-1 (N, d, d), det P (N,))``, as :func:`inverses` gives them."""


def inverses(densities: Sequence[GaussianMixture]) -> list[Inverse]:
    """Each density's :data:`Inverse`, in one batched call (per matrix the numbers
    :class:`_Components` computes itself): for a caller that uses a density in several
    products (the newcomers of :func:`tracking.fusion.gci_fuse`'s sequential steps)."""
    if not densities:
        return []
    Y, det = inv_det_spd(np.concatenate([D.covs for D in densities]))
    out, start = [], 0
    for D in densities:  # views, by slices (np.split's Python costs ~40 us for 8 densities)
        end = start + len(D)
        out.append((Y[start:end], det[start:end]))
        start = end
    return out


def gci_step(acc: GaussianMixture, new: GaussianMixture, omega: float, cardinality: str,
             new_inverse: Inverse) -> GaussianMixture:
    """``gci_product([acc, new], [1 - omega, omega], cardinality, gate=True)`` (``0 < omega <
    1``) with the fewest NumPy calls: one step of :func:`tracking.fusion.gci_fuse`'s sequential
    fusion, whose reducer prunes what the gate leaves out. ``new_inverse``: ``new``'s
    :data:`Inverse`.

    The gate is the marginal bound of :func:`_gated_rows` alone: pair ``(a, b)`` is left out
    when ``max_k (m_a - m_b)_k^2 / (P_a,kk / (1-omega) + P_b,kk / omega) > _GATE`` (a lower
    bound of its pair term), so its weight is below ``1e-20 w_a^(1-omega) w_b^omega``; if all
    of them together could carry more than :data:`_GATE_TOLERANCE` of the kept mass, every
    pair is formed. The kept pairs go through the same formula (:func:`_centred_rows`), in the
    same order (``acc``'s component slowest). Issue 33: the 8 steps of own + 8 neighbours of
    10 tracks form about 11 of each step's 110 pairs, with two small LAPACK calls each.
    """
    if cardinality not in CARDINALITY_RULES:
        raise ValueError(f"unknown cardinality rule {cardinality!r}; expected {CARDINALITY_RULES}")
    na, nb = len(acc), len(new)
    if na == 0 or nb == 0:
        return GaussianMixture.empty(acc.dim)
    wa, wb, oa = acc.weights, new.weights, 1.0 - omega
    if cardinality == "separate":
        Na, Nb = float(_sum(wa)), float(_sum(wb))
        if Na <= 0 or Nb <= 0:
            return GaussianMixture.empty(acc.dim)
        wa, wb = wa / Na, wb / Nb
    diag_a = np.diagonal(acc.covs, axis1=1, axis2=2) / oa
    diag_b = np.diagonal(new.covs, axis1=1, axis2=2) / omega
    diff = new.means[None, :, :] - acc.means[:, None, :]  # (na, nb, d): u of the pairs
    bound = _max(np.square(diff) / (diag_a[:, None] + diag_b[None]), axis=-1)
    ia, ib = np.nonzero(bound <= _GATE)
    Ya, det_a = inv_det_spd(acc.covs)
    Yb, det_b = new_inverse
    with np.errstate(divide="ignore", invalid="ignore"):  # zero weights: zero-weight pairs
        wc = np.concatenate((oa * (np.log(wa) - 0.5 * np.log(det_a)),
                             omega * (np.log(wb) - 0.5 * np.log(det_b))))
        log_wmax = oa * np.log(_max(wa)) + omega * np.log(_max(wb))
    wY = np.concatenate((oa * Ya, omega * Yb))
    log_w, means, covs = _centred_rows(wY, wc, np.concatenate((acc.means, new.means)),
                                       np.array((ia, ib + na)))
    weights = np.exp(log_w)
    left_out = (na * nb - len(ia)) * math.exp(min(700.0, log_wmax - 0.5 * _GATE))
    if not left_out <= _GATE_TOLERANCE * _sum(weights):  # might matter: every pair
        return gci_product([acc, new], [oa, omega], cardinality,  # (as gci_combine forms)
                           inverses=[None, new_inverse], limit=na * nb)
    if cardinality == "separate":
        c = _sum(weights)
        if not c > MIN_OVERLAP:  # the densities do not overlap: no common target to scale up
            return GaussianMixture.empty(acc.dim)
        weights *= Na**oa * Nb**omega / c
    return GaussianMixture.trusted(weights, means, covs)


def gci_product_gated(densities: Sequence[GaussianMixture], weights: Sequence[float],
                      cardinality: str = "emd", limit: int = 4096,
                      premerge: tuple[float, str] | None = None) -> GaussianMixture | None:
    """``gci_product(densities, weights, cardinality, gate=True)`` for many densities at once,
    or None when that is not cheap: more than ``limit`` combinations kept, or the gate cannot
    certify what it leaves out (the caller then fuses in steps). Issue 33: own + 8 neighbours
    of 10 tracks.

    The gate is :func:`_gated_rows`' lower bound alone, about the density of the largest
    omega (``r``; the tightest): a combination is left out when one of its components is, on
    some coordinate ``k``, farther from its component ``a`` of ``r`` than
    ``(m_a - m_b)_k^2 / (P_a,kk / omega_r + P_b,kk / omega_i) > gate`` (a lower bound of
    the pair term, so its weight is below ``exp(-gate / 2)`` times its components' weight
    product; no inverse is formed for the gate). ``gate`` is :data:`_GATE`, widened for many
    combinations to ``_GATE + 2 log(prod N_i / 4096)``, so the bound on all that is left out
    (their count times that) stays ``4096e-20`` of the largest weight product. The kept
    combinations are counted per component of ``r`` before any is formed, then enumerated in
    mixed radix, all densities in one array call instead of a loop over them, and put in
    :func:`gci_product`'s order (the first density's component slowest); their numbers are
    :func:`_centred_rows`'. ``separate`` normalises through the log weights. 11^9
    combinations of ``bench_lmb``: about 26 kept (tests/test_gci_at_once.py).

    ``premerge = (U, rule)``: first merge each density's close components, density ``i`` by
    ``rule`` at ``U / omega_i`` (:func:`tracking.reduction.merge_stacked`, all densities in one
    call): the merge test applied to the powered components ``N(m, P)^omega ~ N(m, P/omega)``,
    which the product's ``(sum_j w_j N_j)^omega ~ sum_j w_j^omega N_j^omega`` (Battistelli et
    al. 2013; Wang et al. 2017) needs well apart; close rows powered apart over-count a track
    (issue 33: bench_lmb's split tracks, tests/test_gci_at_once.py).
    """
    if cardinality not in CARDINALITY_RULES:
        raise ValueError(f"unknown cardinality rule {cardinality!r}; expected {CARDINALITY_RULES}")
    densities = list(densities)
    omegas = np.asarray(weights, dtype=float)
    if len(densities) != len(omegas) or not densities:
        raise ValueError(f"gci_product_gated: need one weight per density ({len(densities)} "
                         f"vs {len(omegas)})")
    d = densities[0].dim
    if len(densities) == 1:  # prod of one: the density itself (separate: N p = D)
        return densities[0]
    ref = int(np.argmax(omegas))  # the gate's reference density: the heaviest omega gates most
    if ref:
        perm = [ref, *range(ref), *range(ref + 1, len(densities))]
        densities, omegas = [densities[i] for i in perm], omegas[perm]
    sizes = [len(D) for D in densities]
    if min(sizes) == 0:
        return GaussianMixture.empty(d)
    w_all = np.concatenate([D.weights for D in densities])
    means = np.concatenate([D.means for D in densities])
    covs = np.concatenate([D.covs for D in densities])
    if premerge is not None:
        w_all, means, covs, merged = merge_stacked(w_all, means, covs, np.array(sizes),
                                                   premerge[0] / omegas, premerge[1])
        sizes = merged.tolist()
    start = np.cumsum(sizes) - sizes
    om = np.repeat(omegas, sizes)
    log_mass = None
    if cardinality == "separate":
        masses = np.add.reduceat(w_all, start)
        if not _all(masses > 0):
            return GaussianMixture.empty(d)
        log_mass = np.log(masses)
    with np.errstate(divide="ignore", invalid="ignore"):  # zero weights: zero-weight combos
        log_w_in = np.log(w_all)
        if log_mass is not None:
            log_w_in = log_w_in - np.repeat(log_mass, sizes)
        log_wmax = float(omegas @ np.maximum.reduceat(log_w_in, start))
    total = math.prod(sizes)  # an int, maybe beyond a float: only its log is taken
    gate = _GATE + 2.0 * max(0.0, math.log(total) - math.log(_GATE_COUNT))
    # the marginal bound of each component of r (first now) against every later component, in
    # coordinate-major (d, K) rows: the max over coordinates is then elementwise (4x faster)
    n1 = sizes[0]
    mT = np.ascontiguousarray(means.T)
    Sd = np.ascontiguousarray(np.diagonal(covs, axis1=1, axis2=2).T) / om  # P_kk / omega
    bound = _max(np.square(mT[:, None, n1:] - mT[:, :n1, None])
                 / (Sd[:, :n1, None] + Sd[:, None, n1:]), axis=0)  # (N_1, K - N_1)
    near = bound <= gate
    counts = np.add.reduceat(near, start[1:] - n1, axis=1, dtype=np.intp)  # (N_1, n - 1)
    if _sum(np.prod(counts, axis=1, dtype=float)) > limit:
        return None
    per = np.prod(counts, axis=1)  # kept combinations per first-density component
    kept = int(_sum(per))
    if kept == 0:
        return None
    a = np.repeat(np.arange(n1), per)  # (C,): combination c's first component
    local = np.arange(kept) - np.repeat(np.cumsum(per) - per, per)
    # mixed radix, last density fastest: digit j = (local // prod counts[j+1:]) % counts[j]
    stride = np.ones_like(counts)
    stride[:, :-1] = np.cumprod(counts[:, :0:-1], axis=1)[:, ::-1]
    digit = (local[:, None] // stride[a]) % counts[a]  # (C, n - 1)
    flat = counts.reshape(-1)
    first = (np.cumsum(flat) - flat).reshape(counts.shape)  # a's first kept one of density j
    cols = np.nonzero(near)[1]  # kept later components, by (a, column): by density per a
    rows = np.concatenate((a[None], (cols[first[a] + digit] + n1).T))  # (n, C)
    if ref:  # back to the densities' own order, the first one's component slowest
        rows = np.concatenate((rows[1:ref + 1], rows[:1], rows[ref + 1:]))
        rows = rows[:, np.lexsort(rows[::-1])]
    Y, det = inv_det_spd(covs)  # only now: a product not formed at once costs no inverse
    with np.errstate(divide="ignore", invalid="ignore"):
        wc = om * (log_w_in - 0.5 * np.log(det))
    log_w, m, P = _centred_rows(om[:, None, None] * Y, wc, means, rows)
    w = np.exp(log_w)
    c = _sum(w)
    left_out = (math.exp(min(700.0, math.log(total - kept) + log_wmax - 0.5 * gate))
                if total > kept else 0.0)
    if not left_out <= _GATE_TOLERANCE * c:  # what was left out might matter (or no mass)
        return None
    if log_mass is not None:
        if not c > MIN_OVERLAP:  # the densities do not overlap: no common target to scale up
            return GaussianMixture.empty(d)
        w *= math.exp(float(omegas @ log_mass)) / c
    return GaussianMixture.trusted(w, m, P)


_GATE_COUNT = 4096
"""Up to this many combinations :func:`gci_product_gated` gates at :data:`_GATE`; beyond, at
``_GATE + 2 log(count / _GATE_COUNT)`` (the same bound on what is left out)."""


class _Components:
    """Per-component inputs of :func:`gci_product`, all densities' components concatenated:
    ``wY = omega_i Y_i (K, d, d)``, ``wc = omega_i (log w_i - 1/2 log det P_i) (K,)``, means
    ``(K, d)``, and ``start[i]`` (density ``i``'s first row). ``given``: the densities'
    :data:`Inverse` where known (a scaled density has its unscaled one's), else None."""

    def __init__(self, densities: list[GaussianMixture], omegas: np.ndarray,
                 given: Sequence[Inverse | None] | None = None) -> None:
        self.sizes = [len(D) for D in densities]
        self.start = np.cumsum(self.sizes) - self.sizes
        given = [None] * len(densities) if given is None else list(given)
        missing = [i for i, g in enumerate(given) if g is None]
        for i, inv in zip(missing, inverses([densities[i] for i in missing]), strict=True):
            given[i] = inv
        Yall = np.concatenate([Y for Y, _ in given])
        det_all = np.concatenate([det for _, det in given])
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


def _centred_terms(comps: _Components, gate: bool = False, limit: int = MAX_COMBINATIONS
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
    at most :data:`_GATE_TOLERANCE` of the kept mass. More than ``limit`` combinations to form
    (all of them, or those the gate keeps): a ValueError (:func:`gci_product`).
    """
    total = math.prod(comps.sizes)
    if total <= _SMALL_COMBINATIONS:
        return _centred_gathered(comps)
    if gate:
        gated = _gated_rows(comps, limit)
        if gated is not None:
            rows, left_out = gated
            terms = _centred_gathered(comps, rows)
            if left_out <= _GATE_TOLERANCE * np.exp(terms[0]).sum():
                return terms  # else what was left out might matter: form every combination
    if total > limit:
        raise _too_many(f"{total:,} combinations to form", comps.sizes, limit)
    return _centred_on_grid(comps)


_SMALL_COMBINATIONS = 64
"""Up to this many combinations :func:`_centred_terms` gathers per-combination arrays (the
level-2-pruned inputs of a peer's fusion are usually this few)."""


_GATE = 2.0 * math.log(1e20)
"""Pair term above which :func:`_gated_rows` leaves a combination out (its weight is then at
most ``1e-20`` times the largest product of its components' weights)."""

_GATE_TOLERANCE = 1e-14
"""Largest share of the fused mass the combinations left out may carry (else: all of them)."""


def _gated_rows(comps: _Components, limit: int = MAX_COMBINATIONS
                ) -> tuple[np.ndarray, float] | None:
    """The combinations worth forming, as ``(n, C_kept)`` component rows, and a bound on the
    mass of those left out; None if none is kept.

    A combination's quadratic term is ``min_x sum_i omega_i |m_ic - x|^2_(Y_ic)``, at least the
    same minimum over two of its components, its first density's ``a`` and density ``i``'s
    ``b``: ``(m_a - m_b)' (P_a / omega_1 + P_b / omega_i)^-1 (m_a - m_b)``; and its determinant
    factor is at most 1 (log det is concave), so its weight is at most ``prod_i w_ic^(omega_i)
    exp(-pair / 2)``. Combinations with a pair term above :data:`_GATE` are left out, densities
    added one at a time (a PHD's components for different targets never combine). The pair
    term is formed only where a cheap lower bound, one coordinate's marginal ``x' S^-1 x >=
    x_k^2 / S_kk`` (widened by 1e-6, far above round-off), is within the gate: far-apart
    targets' pairs cost no inverse (the same rows as forming every pair term, but for a pair
    term within round-off of the gate).
    """
    sizes, start, n = comps.sizes, comps.start, len(comps.sizes)
    om = np.repeat(comps.omegas, sizes)
    S = np.concatenate([D.covs for D in comps.densities]) / om[:, None, None]  # P / omega
    n1 = sizes[0]
    # pair terms of each first-density component with every later component: (N_1, K - N_1)
    diff = comps.means[None, n1:, :] - comps.means[:n1, None, :]
    Sd = np.diagonal(S, axis1=1, axis2=2)
    bound = (np.square(diff) / (Sd[:n1, None] + Sd[None, n1:])).max(axis=-1, initial=0.0)
    fi, kj = np.nonzero(bound <= _GATE * (1.0 + 1e-6))
    pair = np.full(bound.shape, np.inf)
    pair[fi, kj] = quad_form(diff[fi, kj], inv_spd(S[fi] + S[n1 + kj]))
    rows = np.arange(n1)[:, None] + start[0]  # (M, i) kept partial combinations
    for i in range(1, n):
        new = np.arange(sizes[i]) + start[i]
        mi, ni = np.nonzero(pair[rows[:, 0]][:, new - n1] <= _GATE)
        if len(mi) > limit:  # checked before the rows are gathered
            kept = f"the gate keeps {len(mi):,} combinations of the first {i + 1} densities"
            raise _too_many(kept, sizes, limit)
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
    return _centred_rows(comps.wY, comps.wc, comps.means, idx)


def _centred_rows(wY: np.ndarray, wc: np.ndarray, means: np.ndarray, idx: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The GCI formula of :func:`_centred_terms` for the combinations ``idx (n, C)`` (rows of
    the component arrays ``wY (K, d, d)``, ``wc (K,)``, ``means (K, d)``; see
    :class:`_Components`). Returns ``log w (C,)``, means ``(C, d)``, covs ``(C, d, d)``."""
    wY = wY[idx]  # (n, C, d, d)
    ref = means[idx[0]]  # (C, d)
    u = means[idx] - ref  # (n, C, d)
    g = c_einsum("ncjk,nck->cj", wY, u)
    P, det_y = inv_det_spd(_sum(wY, axis=0))
    delta = c_einsum("cij,cj->ci", P, g)
    e = u - delta  # m_ic - m
    quad = c_einsum("ncj,ncjk,nck->c", e, wY, e)
    log_w = _sum(wc[idx], axis=0) - 0.5 * (np.log(det_y) + quad)
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
