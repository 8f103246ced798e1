"""The per-neighbour tests of :mod:`peers.trust`: divergence, median, repeat and offset.

Each function scores one scan's densities and keeps no state; :class:`peers.trust.Trust`
turns their statistics into scores, states and weights over time (the tests, their
references and their calibration: docs/trust-calibration.md).

- :func:`neighbour_statistics`: ``T_j`` of every neighbour, the smaller of its divergence
  tests against own and the leave-one-out average, or (W-MSR-style majority) its median test
  against the other inputs less their own median test (:func:`pair_tests`,
  :func:`divergence_test`).
- :func:`miss_cost`: the evidence needed to explain a whole disagreement by missed
  detections (or births seen a scan apart), which bounds every divergence test.
- :func:`is_repeat`: a non-empty density repeated bit for bit (a stuck sensor or a replay).
- :func:`offset_information` and :func:`offset_chi2`: the generalised-least-squares offset
  of a biased sensor over windows of scans; :func:`offset_cusum`: Page's CUSUM of its
  log-likelihood ratio against a 30 m-class bias, over all scans.
- :func:`withheld_increments`: one scan's log-likelihood ratio that a neighbour withholds
  the targets its references show (Page's CUSUM of it: :attr:`TrustConfig.withhold`).
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Generator

import numpy as np
from sensornet.peers.trust_config import TrustConfig
from sensornet.tracking.divergence import cs_from_log_overlaps, log_overlaps
from sensornet.tracking.mixture import GaussianMixture


def neighbour_statistics(cfg: TrustConfig, own: GaussianMixture,
                         inputs: dict[str, GaussianMixture], weights: dict[str, float],
                         quarantined: set[str], pos: tuple[int, int] = (0, 2),
                         keep: dict | None = None) -> dict[str, float]:
    """:func:`neighbour_statistics_steps` run on its own (:func:`run_alone`)."""
    return run_alone(neighbour_statistics_steps(cfg, own, inputs, weights, quarantined, pos,
                                                keep))


def run_alone(steps: Generator):
    """The value of a trust computation written as a generator of requests (``*_steps``:
    each yields ``(op, *args)`` and is sent its result), every request computed on its own
    (:data:`ALONE`); :func:`peers.trust_batch.run_together` computes several generators'
    requests of one kind at once, the same numbers."""
    try:
        request = next(steps)
        while True:
            request = steps.send(ALONE[request[0]](*request[1:]))
    except StopIteration as stop:
        return stop.value


def neighbour_statistics_steps(cfg: TrustConfig, own: GaussianMixture,
                               inputs: dict[str, GaussianMixture], weights: dict[str, float],
                               quarantined: set[str], pos: tuple[int, int] = (0, 2),
                               keep: dict | None = None) -> Generator:
    """``T_j`` of every neighbour in ``inputs`` against ``own`` and the leave-one-out
    average of the other trusted inputs (weights ``weights``, own's under ``""``; the
    neighbours in ``quarantined`` are left out of every reference; ``pos``: the position
    entries of the state, for :func:`unmatched_weights`). ``keep``: a dict given gets
    ``"unmatched"``: ``(mixes, U)``, the inputs ``[own, *sorted(inputs)]`` and their
    :func:`unmatched_weights`, and ``"targets"``: their :func:`target_mass` (``(n,)``),
    where they were made (the withheld-target test of the same round takes them instead of
    making them again)."""
    names = sorted(inputs)
    mixes = [own] + [inputs[s] for s in names]
    L = yield ("overlaps", mixes)
    L0 = (yield ("overlaps", centred(mixes))) if cfg.location_only else None
    masses, targets = yield ("masses", mixes, cfg.repeat_weight)
    mass, tm = np.array(masses), np.array(targets)
    trusted = np.array([1.0] + [0.0 if s in quarantined else 1.0 for s in names])
    w = np.array([weights.get("", 1.0)] + [weights.get(s, 0.0) for s in names]) * trusted
    U = None
    if cfg.majority and cfg.unmatched and cfg.detection_probability is not None:
        U = yield ("unmatched", mixes, list(pos), cfg.repeat_weight, cfg.bias_gate,
                   cfg.gate_chi2)
        if keep is not None:
            keep["unmatched"] = (mixes, U)
            keep["targets"] = tm
    values = yield ("tests", cfg, L, L0, mass, tm, U, w)
    return dict(zip(names, values, strict=True))


def neighbour_tests(cfg: TrustConfig, L: np.ndarray, L0: np.ndarray | None, mass: np.ndarray,
                    tm: np.ndarray, U: np.ndarray | None, w: np.ndarray) -> list[float]:
    """The statistics of :func:`neighbour_statistics` (per input ``1..n-1``, ``(n-1)``
    floats) from its inputs' log overlaps ``L`` (``(n, n)``; ``L0``: centred, or None),
    masses ``mass``, target masses ``tm`` (``(n,)``), unmatched weights ``U`` (``(n, n)``
    or None) and reference weights ``w`` (``(n,)``, 0 where left out of the references):
    one peer's :func:`neighbour_tests_many`, its divergence tests on floats (the same
    formula, :func:`divergence_test`, without the arrays' per-call overhead: a peer alone)."""
    L, mass, tm, w = L[None], mass[None], tm[None], w[None]
    L0 = None if L0 is None else L0[None]
    refs = _references(L, L0, mass, tm, w)
    if refs is None:
        return []
    has, cross, square, ref_mass, ref_tm, shape = (v[0].tolist() if isinstance(v, np.ndarray)
                                                   else v for v in refs)
    Ls, ms, ts = L[0].tolist(), mass[0].tolist(), tm[0].tolist()
    own = own_tests(cfg, L[0], None if L0 is None else L0[0], ms, ts)
    value = []
    for i, t_own in enumerate(own):
        j = i + 1
        if has[i]:
            t_loo = divergence_test(cfg, Ls[j][j], cross[i], square[i], ms[j], ref_mass[i],
                                    ts[j], ref_tm[i], shape=shape[i] if L0 is not None else 0.0)
            t_own = t_loo if t_loo < t_own else t_own  # min(t_own, t_loo)
        value.append(t_own)
    if not cfg.majority:
        return value
    return _majority(cfg, L, L0, mass, tm, None if U is None else U[None], w,
                     np.array([value]))[0].tolist()


def neighbour_tests_many(cfg: TrustConfig, L: np.ndarray, L0: np.ndarray | None,
                         mass: np.ndarray, tm: np.ndarray, U: np.ndarray | None,
                         w: np.ndarray) -> np.ndarray:
    """:func:`neighbour_tests` of ``g`` peers' rounds of as many inputs at once (``L``,
    ``L0``, ``U`` ``(g, n, n)``; ``mass``, ``tm``, ``w`` ``(g, n)``): ``(g, n - 1)``. Per
    neighbour ``j`` the smaller of its :func:`divergence_tests` against own and against
    the leave-one-out average of the other references (where there is one,
    :func:`_references`); with :attr:`TrustConfig.majority`, :func:`_majority`. Every
    (peer, neighbour) at once (a peer host's: :mod:`peers.trust_batch`)."""
    refs = _references(L, L0, mass, tm, w)
    if refs is None:
        return np.zeros((len(w), 0))
    has, cross, square, ref_mass, ref_tm, shape = refs
    # the tests against own (own_tests_many's) and against the leave-one-out references in
    # one elementwise computation, stacked on a first axis: the same numbers, half the calls
    j = _after_first(w.shape[1])
    g, J = cross.shape

    def two(own: np.ndarray, loo: np.ndarray) -> np.ndarray:
        out = np.empty((2, g, J))
        out[0] = own
        out[1] = loo
        return out

    if L0 is not None:
        shape = two(_cs_arrays(L0[:, j, 0], L0[:, j, j], L0[:, :1, 0], finite=True), shape)
    t = divergence_tests(cfg, L[:, j, j], two(L[:, j, 0], cross), two(L[:, :1, 0], square),
                         mass[:, j], two(mass[:, :1], ref_mass), tm[:, j], two(tm[:, :1], ref_tm),
                         shape=shape)
    value, t_loo = t[0], t[1]
    value = np.where(has & (t_loo < value), t_loo, value)  # min(t_own, t_loo)
    return _majority(cfg, L, L0, mass, tm, U, w, value) if cfg.majority else value


def _references(L: np.ndarray, L0: np.ndarray | None, mass: np.ndarray, tm: np.ndarray,
                w: np.ndarray) -> tuple | None:
    """Each neighbour's leave-one-out reference (the other inputs of weight ``w`` but own
    alone, renormalised): whether it has one (``has``), ``log int D_j R`` and ``log int
    R^2``, its mass and target mass, and (``L0`` given) the centred divergence, each
    ``(g, n - 1)`` (0.0 for no ``L0``); None with no neighbour."""
    g, n = w.shape
    J = n - 1
    if J == 0:
        return None
    W = np.where(_leave_out(n), w[:, None, :], 0.0)  # (g, J, n): row i leaves out input i + 1
    tot = W.sum(axis=2)
    has = (tot > 0) & ((W != 0).sum(axis=2) > 1)  # the others besides own (count_nonzero)
    W = W / np.where(has, tot, 1.0)[..., None]
    LW = _log(W)
    cross, square = _loo_stacked(L, LW)
    ref_mass = np.matmul(W[:, :, None, :], np.repeat(mass[:, None, :, None], J, axis=1))
    ref_tm = np.matmul(W[:, :, None, :], np.repeat(tm[:, None, :, None], J, axis=1))
    shape = 0.0
    if L0 is not None:
        j = np.arange(1, J + 1)
        c0, s0 = _loo_stacked(L0, LW)
        shape = _cs_arrays(c0, L0[:, j, j], s0, finite=True)
    return has, cross, square, ref_mass[..., 0, 0], ref_tm[..., 0, 0], shape


def _majority(cfg: TrustConfig, L: np.ndarray, L0: np.ndarray | None, mass: np.ndarray,
              tm: np.ndarray, U: np.ndarray | None, w: np.ndarray, value: np.ndarray
              ) -> np.ndarray:
    """:attr:`TrustConfig.majority` over the statistics ``value`` (``(g, n - 1)``): where own
    and at least two other references are, each neighbour's median pair test against them
    (:attr:`TrustConfig.median_test`; else its statistic) less the median of theirs among
    themselves (:func:`pair_tests`), at least 0."""
    n = w.shape[1]
    j = _after_first(n)
    pair = pair_tests(cfg, L, mass, tm, U, L0)  # (g, n, n)
    others = (w > 0)[:, None, :] & _leave_out(n)  # (g, J, n): w > 0 but j
    count = others.sum(axis=2)
    rows, cols = triu_indices(n)
    sub = _medians(pair[:, rows, cols][:, None, :], others[:, :, rows] & others[:, :, cols])
    base = _medians(pair[:, j, :], others) if cfg.median_test else value
    x = base - sub
    return np.where(count >= 3, np.where(x > 0.0, x, 0.0), value)  # max(0, base - sub)


def own_tests_many(cfg: TrustConfig, L: np.ndarray, L0: np.ndarray | None, mass: np.ndarray,
                   tm: np.ndarray) -> np.ndarray:
    """Each input ``j >= 1``'s :func:`divergence_tests` against own (input 0) alone, of
    ``g`` peers' rounds at once (``L``, ``L0`` ``(g, n, n)``; ``mass``, ``tm`` ``(g, n)``):
    ``(g, n - 1)``; the first test of :func:`neighbour_tests_many`, and what
    :attr:`TrustConfig.test_once`'s guard and a late estimate's test take."""
    j = np.arange(1, L.shape[-1])
    shape = (_cs_arrays(L0[:, j, 0], L0[:, j, j], L0[:, :1, 0], finite=True)
             if L0 is not None else 0.0)
    return divergence_tests(cfg, L[:, j, j], L[:, j, 0], L[:, :1, 0], mass[:, j], mass[:, :1],
                            tm[:, j], tm[:, :1], shape=shape)


def own_tests(cfg: TrustConfig, L: np.ndarray, L0: np.ndarray | None, mass: list[float],
              tm: list[float]) -> list[float]:
    """One peer's :func:`own_tests_many` (``L``, ``L0`` ``(n, n)``), element by element on
    floats: the same formula (:func:`divergence_test`), without the arrays' per-call
    overhead (a peer alone, or a host's round settled on the spot)."""
    return [divergence_test(cfg, L[j, j], L[j, 0], L[0, 0], mass[j], mass[0], tm[j], tm[0],
                            shape=0.0 if L0 is None else _cs_of(_Floats, L0[j, 0], L0[j, j],
                                                                 L0[0, 0], True))
            for j in range(1, len(mass))]


def _medians(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per row of ``mask`` (``(..., m)`` bool; ``values`` broadcast to it): the median of
    the values it marks, as :func:`median_small` (the middle of the sorted values, or
    ``(a + b) / 2.0`` of the two middle ones); NaN where it marks none."""
    V = np.sort(np.where(mask, values, np.inf), axis=-1)  # the marked first, in order
    c = mask.sum(axis=-1)[..., None]
    h = c // 2
    m = V.shape[-1]
    flat, at = V.reshape(-1), _row_starts(V.size // m if m else 0, m).reshape(c.shape)
    hi = flat[at + np.minimum(h, m - 1)]  # np.take_along_axis's, without its Python setup
    lo = flat[at + np.maximum(h - 1, 0)]
    with np.errstate(invalid="ignore"):
        med = np.where(c % 2 == 1, hi, (lo + hi) / 2.0)
    return np.where(c > 0, med, np.nan)[..., 0]


@functools.lru_cache(maxsize=256)
def _row_starts(rows: int, m: int) -> np.ndarray:
    """``m * arange(rows)`` (read-only, made once per shape): where each row of ``m`` starts
    in a flattened ``(rows, m)`` array (:func:`_medians`' picks)."""
    out = np.arange(rows, dtype=np.intp) * m
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=64)
def _leave_out(n: int) -> np.ndarray:
    """``(n - 1, n)`` bool (read-only, made once per ``n``): row ``i`` all but input
    ``i + 1`` (each neighbour's leave-one-out row)."""
    out = np.ones((n - 1, n), bool)
    out[np.arange(n - 1), np.arange(1, n)] = False
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=64)
def _after_first(n: int) -> np.ndarray:
    """``np.arange(1, n)`` (read-only, made once per ``n``): the neighbours' indices."""
    out = np.arange(1, n)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=64)
def triu_indices(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n, 1)``, made once per ``n`` (read-only arrays): the pairs of the
    majority's references, asked for per neighbour and round."""
    rows, cols = np.triu_indices(n, 1)
    rows.flags.writeable = False
    cols.flags.writeable = False
    return rows, cols


def median_small(values: np.ndarray) -> float:
    """``float(np.median(values))`` of a short 1-d array without NaN, to the bit: the middle
    of the sorted values, or half the sum of the two middle ones (as ``np.median``'s mean of
    two: ``(a + b) / 2``), without ``np.median``'s per-call overhead (tens of microseconds,
    called per neighbour and round). NaN when empty, as ``np.median``."""
    v = sorted(values.tolist())
    n = len(v)
    if n == 0:
        return float("nan")
    h = n // 2
    return v[h] if n % 2 else (v[h - 1] + v[h]) / 2.0


def pair_tests(cfg: TrustConfig, L: np.ndarray, mass: np.ndarray,
               targets: np.ndarray | None = None,
               unmatched: np.ndarray | None = None,
               shape: np.ndarray | None = None) -> np.ndarray:
    """The test between every two inputs (``(n, n)``; the majority's own spread) from their
    log overlaps ``L`` (``(n, n)``), masses ``mass`` (``(n,)``), target masses
    ``targets`` (``(n,)``, :func:`target_mass`; None: no missed-detection bound),
    unmatched target weights ``unmatched`` (``(n, n)``, :func:`unmatched_weights`; None:
    not used) and the log overlaps of the inputs centred (``(n, n)``,
    :func:`centred`; None: the divergence as it is). Stacks too (``(..., n, n)``,
    ``(..., n)``: several peers' at once, elementwise, so the same numbers)."""
    cs = _cs_matrix(L)
    if shape is not None:  # the location part (TrustConfig.location_only)
        cs = np.maximum(cs - np.nan_to_num(_cs_matrix(shape), nan=0.0, posinf=0.0), 0.0)
    a, b = mass[..., :, None], mass[..., None, :]
    card = cfg.kappa * (a - b) ** 2 / (b + 1.0)
    card = np.minimum(card, np.swapaxes(card, -1, -2))  # the smaller of the two directions
    ea, eb = a <= 1e-9, b <= 1e-9
    cs = np.where(np.isfinite(cs), cs, cfg.cap)
    one = cfg.empty_penalty * np.minimum(1.0, np.maximum(a, b))
    where = np.where(ea & eb, 0.0, np.where(ea | eb, one, cs))
    if unmatched is not None:
        where = np.maximum(where, cfg.unmatched_cost * (unmatched
                                                         + np.swapaxes(unmatched, -1, -2)))
    if targets is not None:
        where = np.minimum(where, miss_cost(cfg, targets[..., :, None], targets[..., None, :]))
    P = np.minimum(where + card, cfg.cap)
    n = P.shape[-1]
    P[..., np.arange(n), np.arange(n)] = 0.0
    return P


def unmatched_weights(mixes: list[GaussianMixture], pos: list[int], min_weight: float,
                      gate: float, chi2: float | None = None
                      ) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """``U`` (``(n, n)``): ``U[a, b]`` the summed weight of the target components of
    ``mixes[a]`` (weight at least ``min_weight``) with no target component of ``mixes[b]``
    within the gate (:func:`near`: ``gate`` metres, or the ``chi2`` gate of their
    covariances): the targets ``a`` shows that ``b`` does not (a birth or a miss on one
    side, or a phantom). Also ``(near, w, owner)``: per target component (``C`` in all)
    whether each input has one within the gate (``(C, n)``), its weight and its input."""
    n = len(mixes)
    sel = [D.weights >= min_weight if len(D) else np.zeros(0, bool) for D in mixes]
    owner = np.concatenate([np.full(int(m.sum()), i) for i, m in enumerate(sel)])
    if len(owner) == 0:
        return np.zeros((n, n)), (np.zeros((0, n), bool), np.zeros(0), owner)
    full = [D for D in mixes if len(D)]  # selected once from all components together
    keep = np.concatenate([m for m in sel if len(m)])
    w = np.concatenate([D.weights for D in full])[keep]
    X = np.concatenate([D.means for D in full])[keep][:, pos]
    P = (position_block(np.concatenate([D.covs for D in full])[keep], pos)
         if chi2 is not None else np.zeros((len(owner), 2, 2)))
    G = np.zeros((len(owner), n))
    G[np.arange(len(owner)), owner] = 1.0  # (C, n): which input a component is of
    close = near(X, P, X, P, gate, chi2)  # (C, C)
    hit = (close.astype(float) @ G) > 0  # (C, n)
    counts = np.bincount(owner, minlength=n)
    U = np.zeros((n, n))
    U[counts > 0] = unmatched_sums(w, hit, counts[counts > 0].tolist())
    return U, (hit, w, owner)


def unmatched_sums(w: np.ndarray, hit: np.ndarray, counts: list[int]) -> np.ndarray:
    """The rows of :func:`unmatched_weights`' ``U`` of the inputs with target components:
    per input (``counts`` consecutive components, weights ``w``), the summed weight of its
    components without a target of input ``b`` within the gate (``hit`` ``(C, n)``), in
    component order (:func:`segment_sums`; ``G.T @ (w * ~hit)`` gives these numbers to the
    bit on NumPy 2.4, tests/test_trust_exact.py). Several peers' inputs at once, the same
    numbers (:mod:`peers.trust_batch`)."""
    return segment_sums(w[:, None] * ~hit, counts)


def target_mass(mix: GaussianMixture, min_weight: float) -> float:
    """The summed weight of the components of ``mix`` of weight at least ``min_weight``
    (the targets a level-2 pruned density shows)."""
    if len(mix) == 0:
        return 0.0
    w = mix.weights
    return float(w[w >= min_weight].sum())


def near(Xa: np.ndarray, Pa: np.ndarray, Xb: np.ndarray, Pb: np.ndarray, gate: float,
         chi2: float | None = None) -> np.ndarray:
    """``(na, nb)`` bool: which pairs of positions ``Xa (na, 2)``, ``Xb (nb, 2)`` (position
    covariances ``Pa (na, 2, 2)``, ``Pb (nb, 2, 2)``) are within the gate
    (:func:`gated`)."""
    return gated(Xa[:, None, :] - Xb[None, :, :], Pa[:, None], Pb[None, :], gate, chi2)


def gated(d: np.ndarray, Pa: np.ndarray, Pb: np.ndarray, gate: float,
          chi2: float | None = None, det_a: np.ndarray | None = None,
          det_b: np.ndarray | None = None) -> np.ndarray:
    """Whether position differences ``d (..., 2)`` between estimates with position
    covariances ``Pa``, ``Pb`` (``(..., 2, 2)``, broadcast) are one target: within ``gate``
    metres, or (``chi2`` not None) within the chi-square gate ``d' S^-1 d <= chi2`` of their
    own uncertainty, ``S = 2 P`` with ``P`` the pair's covariance of smaller determinant.

    Why both: estimates whose position sd is hundreds of metres (real traffic: plots of
    170-270 m, radars that sweep a target once in 5 ticks) are honestly hundreds of metres
    apart, where a fixed metric gate pairs 9 % of them (the chi-square gate at 99.9 %: 90 %;
    on seed 000 94-95 % of honest pairs are within either); the smaller covariance, so
    that a neighbour cannot widen the gate by claiming a wide one (an honest pair's
    ``P_a + P_b`` gates the same share on both scenarios: training run 9000).

    ``det_a``, ``det_b``: ``np.linalg.det`` of ``Pa``, ``Pb`` where the caller has them
    (per component, gathered per pair: the same numbers, without a determinant per pair)."""
    close = np.einsum("...i,...i->...", d, d) <= gate * gate
    if chi2 is None or close.size == 0:
        return close
    smaller = ((np.linalg.det(Pa) if det_a is None else det_a)
               <= (np.linalg.det(Pb) if det_b is None else det_b))[..., None, None]
    S = 2.0 * np.where(smaller, Pa, Pb)  # (..., 2, 2)
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    x, y = d[..., 0], d[..., 1]
    quad = S[..., 1, 1] * x * x - (S[..., 0, 1] + S[..., 1, 0]) * x * y + S[..., 0, 0] * y * y
    with np.errstate(invalid="ignore", divide="ignore"):
        inside = (det > 0) & (quad <= chi2 * det)  # d' S^-1 d <= chi2, S singular: never
    return close | inside


def miss_cost(cfg: TrustConfig, m_j, m_r):
    """``-log(1 - Pd) (m_j + m_r)``: the evidence (nats) that two densities with target
    masses ``m_j`` and ``m_r`` disagree entirely because each missed the other's targets.

    An honest peer misses a target with probability ``1 - Pd`` per scan, after which its
    level-2 pruned posterior lacks it (its weight falls to about ``(1 - Pd) w``, under the
    publishing threshold), and a target born a scan apart is the same to the peer that has
    not confirmed it; a density that lacks a target has likelihood ratio ``1 / (1 - Pd)``
    lying against honest, so the log-likelihood ratio of the whole disagreement is at most
    this sum (the smaller of it and the divergence test is the statistic: a disagreement
    that misses explain costs no more than they do). Inf when
    :attr:`TrustConfig.detection_probability` is None. Broadcasts."""
    if cfg.detection_probability is None:
        return np.inf * np.ones(np.broadcast(m_j, m_r).shape)
    return -np.log1p(-cfg.detection_probability) * (np.asarray(m_j) + np.asarray(m_r))


def divergence_test(cfg: TrustConfig, l_jj: float, l_jr: float, l_rr: float, n_j: float,
                    n_r: float, t_j: float | None = None, t_r: float | None = None,
                    unmatched: float | None = None, shape: float = 0.0) -> float:
    """:func:`divergence_tests` of one density and reference, on Python floats (the same
    formula, :func:`_divergence`, without NumPy's per-call overhead: a peer alone)."""
    return _divergence(_Floats, cfg, l_jj, l_jr, l_rr, n_j, n_r, t_j, t_r, unmatched, shape)


def divergence_tests(cfg: TrustConfig, l_jj, l_jr, l_rr, n_j, n_r, t_j=None, t_r=None,
                     unmatched=None, shape=0.0) -> np.ndarray:
    """``T = W + kappa (N_j - N_R)^2 / (N_R + 1)``, capped at :attr:`TrustConfig.cap`, from
    the log overlaps of a density ``D_j`` and a reference ``R`` and their masses. ``W``,
    where the targets are: ``D_CS(D_j, R)`` less ``shape`` (the divergence of the two
    centred, :func:`centred`; at least 0), :attr:`TrustConfig.empty_penalty` when one
    side is empty, at least ``unmatched_cost`` times the ``unmatched`` target weight on
    both sides (:func:`unmatched_weights`) and at most :func:`miss_cost` of their target
    masses ``t_j``, ``t_r`` (each when given). Elementwise over arrays (broadcast): every
    (peer, neighbour) of a host at once; :func:`divergence_test` the same formula on floats
    (:func:`_divergence`, to the bit: tests/test_trust_batch.py)."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):  # as floats: silent
        return _divergence(_Arrays, cfg, l_jj, l_jr, l_rr, n_j, n_r, t_j, t_r, unmatched,
                           shape)


class _Floats:
    """:func:`_divergence`'s operations on Python floats."""

    num = float
    isfinite = math.isfinite

    def sel(c, a, b):  # noqa: N805 - a namespace of functions, never instantiated
        return a if c else b

    def square(x):  # noqa: N805
        return x ** 2


class _Arrays:
    """:func:`_divergence`'s operations elementwise on arrays: the same results as
    :class:`_Floats`' per element (``np.where`` for the conditional; C's ``pow`` for the
    square as Python's ``** 2``, which differs from ``x * x`` in the last bit for some
    ``x``: NumPy squares where the exponent is a scalar, so it is given as an array)."""

    isfinite = np.isfinite
    sel = np.where

    def num(v):  # noqa: N805
        return np.asarray(v, float)

    def square(x):  # noqa: N805
        return np.power(x, np.full(np.shape(x), 2.0))


def _divergence(xp, cfg: TrustConfig, l_jj, l_jr, l_rr, n_j, n_r, t_j, t_r, unmatched,
                shape):
    """The divergence test (:func:`divergence_tests`) with the operations ``xp``
    (:class:`_Floats` or :class:`_Arrays`): the one formula of both. ``sel(c, a, b)``
    keeps Python's ``min`` / ``max`` choices (the first argument on ties and NaN)."""
    n_j, n_r = xp.num(n_j), xp.num(n_r)
    card = cfg.kappa * xp.square(n_j - n_r) / (n_r + 1.0)
    ej, er = n_j <= 1e-9, n_r <= 1e-9
    big = xp.sel(n_r > n_j, n_r, n_j)  # max(n_j, n_r)
    one = cfg.empty_penalty * xp.sel(big < 1.0, big, 1.0)  # one side empty: min(1, big)
    cs, shape = _cs_of(xp, l_jr, l_jj, l_rr), xp.num(shape)
    x = cs - shape
    where = xp.sel(xp.isfinite(cs), xp.sel(xp.isfinite(shape), xp.sel(x > 0.0, x, 0.0), cs),
                   cfg.cap)
    where = xp.sel(ej & er, 0.0, xp.sel(ej | er, one, where))
    if unmatched is not None:
        u = cfg.unmatched_cost * xp.num(unmatched)
        where = xp.sel(u > where, u, where)  # max(where, u)
    if t_j is not None and t_r is not None and cfg.detection_probability is not None:
        m = xp.num(_miss_rate(cfg.detection_probability) * (xp.num(t_j) + xp.num(t_r)))
        where = xp.sel(m < where, m, where)  # min(where, miss_cost)
    x = where + card
    return xp.sel(x < cfg.cap, x, cfg.cap)  # min(cap, x)


@functools.lru_cache(maxsize=16)
def _miss_rate(detection_probability: float) -> np.float64:
    """``-log(1 - Pd)`` (:func:`miss_cost` per unit of target mass), made once per ``Pd``."""
    return -np.log1p(-detection_probability)


def is_repeat(prev: GaussianMixture | None, mix: GaussianMixture, min_weight: float) -> bool:
    """Whether ``mix`` repeats, bit for bit, the earlier density ``prev`` (another object,
    non-empty, its heaviest component at least ``min_weight``: :attr:`TrustConfig.repeat`).
    A first weight that differs (or is NaN) answers at once: the arrays then differ."""
    return (prev is not None and prev is not mix and len(mix) > 0 and len(mix) == len(prev)
            and float(mix.weights[0]) == float(prev.weights[0])
            and float(mix.weights.max()) >= min_weight
            and np.array_equal(mix.weights, prev.weights)
            and np.array_equal(mix.means, prev.means) and np.array_equal(mix.covs, prev.covs))


def offset_chi2(offsets: deque, windows: tuple[int, ...]) -> tuple[float, ...]:
    """Per window of ``windows`` scans: the chi-square ``y' I^-1 y`` of the mean offset over
    the newest scans of ``offsets`` (per scan ``(I, y)``, ``(2, 2)`` and ``(2,)``, newest
    first: :func:`offset_information`); 0 where ``I`` is singular."""
    info = np.cumsum([i for i, _ in offsets], axis=0)  # (n, 2, 2): newest first
    y = np.cumsum([v for _, v in offsets], axis=0)  # (n, 2)
    last = np.minimum(np.array(windows), len(offsets)) - 1
    info, y = info[last], y[last]
    ok = np.linalg.det(info) > 1e-12
    chi2 = np.zeros(len(last))
    if ok.any():
        b = np.linalg.solve(info[ok], y[ok][..., None])[..., 0]  # (w, 2): mean offsets
        chi2[ok] = np.einsum("wi,wi->w", y[ok], b)
    return tuple(float(c) for c in chi2)


def offset_chi2_many(offsets: list[deque], windows: tuple[int, ...]
                     ) -> list[tuple[float, ...]]:
    """:func:`offset_chi2` of several neighbours' offsets (each non-empty), the same
    numbers: every window stacked at once (:func:`offset_chi2_stacked`)."""
    return offset_chi2_stacked([(np.array([i for i, _ in w]), np.array([v for _, v in w]))
                                for w in offsets], windows)


def offset_chi2_stacked(stacks: list[tuple[np.ndarray, np.ndarray]], windows: tuple[int, ...]
                        ) -> list[tuple[float, ...]]:
    """:func:`offset_chi2_many` of windows given as arrays (per neighbour ``(I, y)``,
    ``(n, 2, 2)`` and ``(n, 2)``, newest first, ``n >= 1``: :func:`peers.trust_record.
    stacked_window`), the same numbers: the shorter ones padded at their old end with zeros
    no window reaches, their running sums along the scans, the determinants and solves of
    all of them in one batch (one round's neighbours, per scan)."""
    if not stacks:
        return []
    lengths = [len(i) for i, _ in stacks]
    top = max(lengths)
    if all(n == top for n in lengths):  # np.array: np.stack's values, less setup
        I = np.array([i for i, _ in stacks])  # (r, top, 2, 2): newest first
        Y = np.array([v for _, v in stacks])  # (r, top, 2)
    else:
        I, Y = np.zeros((len(stacks), top, 2, 2)), np.zeros((len(stacks), top, 2))
        for k, (i, v) in enumerate(stacks):
            I[k, :len(i)] = i
            Y[k, :len(v)] = v
    I = I.cumsum(axis=1)
    Y = Y.cumsum(axis=1)
    cols = (np.minimum(np.array(lengths)[:, None], windows) - 1).ravel()  # (r w,)
    rows = np.arange(len(stacks)).repeat(len(windows))
    info, y = I[rows, cols], Y[rows, cols]  # (r w, 2, 2), (r w, 2)
    ok = np.linalg.det(info) > 1e-12
    chi2 = np.zeros(len(info))
    if ok.any():
        b = np.linalg.solve(info[ok], y[ok][..., None])[..., 0]  # mean offsets
        chi2[ok] = np.einsum("wi,wi->w", y[ok], b)
    values = chi2.reshape(len(stacks), len(windows)).tolist()
    return [tuple(v) for v in values]


def gls_offset(window) -> np.ndarray | None:
    """The generalised-least-squares offset ``I^-1 y`` (``(2,)``) of the per-scan
    ``(I, y)`` in ``window`` (:func:`offset_information`), summed; None when they do not
    determine it (``det I`` at most 1e-12)."""
    if not window:
        return None
    I = np.sum([i for i, _ in window], axis=0)
    if np.linalg.det(I) <= 1e-12:
        return None
    return np.linalg.solve(I, np.sum([v for _, v in window], axis=0))


def gls_offsets(infos: list[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray | None]:
    """:func:`gls_offset` of each single scan's ``(I, y)`` of ``infos`` (``gls_offset([info])``
    per neighbour), the same numbers: the determinants and solves in one batch."""
    if not infos:
        return []
    I = np.array([i for i, _ in infos])  # (n, 2, 2)
    ok = np.linalg.det(I) > 1e-12
    out: list[np.ndarray | None] = [None] * len(infos)
    if ok.any():
        y = np.array([v for _, v in infos])[ok]  # (p, 2)
        for i, b in zip(np.flatnonzero(ok), np.linalg.solve(I[ok], y[..., None])[..., 0],
                        strict=True):
            out[i] = b
    return out


def gls_trend(window) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The generalised-least-squares offset and its rate, ``(a, b)`` (``(2,)`` each), and
    the rate's chi-square ``b' C_b^-1 b`` (``C_b`` its covariance: 2 degrees of freedom for
    independent scans), of the
    per-scan ``(I, y)`` in ``window`` (newest first, one scan apart: the newest at ``t = 0``,
    the one before at ``t = -1``, ...) under ``d_t = a + b t``: a drifting offset is where
    ``a`` says now and ``b`` a scan later, where a constant one's mean runs half a window
    behind. The normal equations ``[[sum I, sum t I], [sum t I, sum t^2 I]] [a; b] = [sum y;
    sum t y]``; None when they do not determine both (fewer than two scans with an
    offset: condition number above 1e12)."""
    if len(window) < 2:
        return None
    t = -np.arange(len(window), dtype=float)
    I = np.array([i for i, _ in window])  # (n, 2, 2)
    y = np.array([v for _, v in window])  # (n, 2)
    m = np.array([[1.0, 0.0], [0.0, 0.0]]), np.array([[0.0, 1.0], [1.0, 0.0]]), np.array(
        [[0.0, 0.0], [0.0, 1.0]])
    A = (np.kron(m[0], I.sum(0)) + np.kron(m[1], np.einsum("n,nij->ij", t, I))
         + np.kron(m[2], np.einsum("n,nij->ij", t * t, I)))  # (4, 4)
    if not np.isfinite(A).all() or np.linalg.cond(A) > 1e12:
        return None
    ab = np.linalg.solve(A, np.concatenate([y.sum(0), t @ y]))
    b = ab[2:]
    cov_b = np.linalg.inv(A)[2:, 2:]
    return ab[:2], b, float(b @ np.linalg.solve(cov_b, b))


@functools.lru_cache(maxsize=16)
def cusum_directions(n: int) -> np.ndarray:
    """``(n, 2)`` unit vectors at angles ``2 pi m / n`` (the charts of :func:`offset_cusum`;
    made once per ``n``, read-only: asked for per neighbour and scan)."""
    a = 2.0 * np.pi * np.arange(n) / n
    out = np.stack([np.cos(a), np.sin(a)], axis=1)
    out.flags.writeable = False
    return out


def offset_increments(info: tuple[np.ndarray, np.ndarray], offset: float,
                      directions: np.ndarray) -> np.ndarray:
    """Per direction ``u`` (``directions``, ``(m, 2)``): the log-likelihood ratio of one
    scan's offset information ``(I, y)`` (:func:`offset_information`) under a bias
    ``beta = offset u`` against none, ``beta' y - beta' I beta / 2`` (the position
    differences ``d_i ~ N(beta, S_i)``, independent: ``sum_i log N(d_i; beta, S_i) -
    log N(d_i; 0, S_i)``). ``(m,)``; 0 where ``I`` is singular (nothing matched)."""
    I, y = info
    if np.linalg.det(I) <= 1e-12:
        return np.zeros(len(directions))
    beta = offset * directions  # (m, 2)
    return beta @ y - 0.5 * np.einsum("mi,ij,mj->m", beta, I, beta)


def offset_cusum(g: np.ndarray, info: tuple[np.ndarray, np.ndarray], offset: float,
                 directions: np.ndarray) -> np.ndarray:
    """Page's CUSUM (Page 1954, "Continuous inspection schemes", Biometrika 41) of the bias
    log-likelihood ratios (:func:`offset_increments`), one chart per direction:
    ``g_k = max(0, g_(k-1) + l_k)``, ``(m,)``, which equals the largest sum of the
    increments over the windows ending at scan ``k`` (or 0): a generalised likelihood ratio
    over when the bias began. The neighbour's CUSUM is ``max(g)``
    (:attr:`TrustConfig.bias_cusum`)."""
    return np.maximum(0.0, g + offset_increments(info, offset, directions))


def offset_cusums(g: np.ndarray, infos: list[tuple[np.ndarray, np.ndarray]], offset: float,
                  directions: np.ndarray) -> np.ndarray:
    """:func:`offset_cusum` of several neighbours at once, the same numbers: their charts
    ``g (r, m)`` and scan offsets ``infos`` (``r`` of ``(I, y)``), the determinants and
    increments in one batch; ``(r, m)``."""
    if not infos:
        return np.zeros((0, len(directions)))
    I = np.array([i for i, _ in infos])  # (r, 2, 2)
    y = np.array([v for _, v in infos])  # (r, 2)
    beta = offset * directions  # (m, 2)
    lin = np.array([beta @ v for v in y])  # (r, m): per neighbour, as offset_increments
    inc = lin - 0.5 * np.einsum("mi,rij,mj->rm", beta, I, beta)
    inc[np.linalg.det(I) <= 1e-12] = 0.0  # singular: nothing matched
    return np.maximum(0.0, g + inc)


def offset_information(ref: GaussianMixture, mix: GaussianMixture, pos: list[int],
                       min_weight: float, gate: float, chi2: float | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Information ``I = sum S_i^-1`` (``(2, 2)``) and ``y = sum S_i^-1 d_i`` (``(2,)``) of the
    position differences ``d_i = m_i - r_(i)`` between each component of ``mix`` of weight at
    least ``min_weight`` and the nearest such component of ``ref`` if within the gate
    (:func:`near`: ``gate`` metres, or the ``chi2`` gate of their covariances; ``S_i``: the
    sum of the two position covariances): the generalised-least-squares estimate of a
    common offset is ``I^-1 y``, its chi-square ``y' I^-1 y``. One mixture of
    :func:`offset_information_many` (one formula)."""
    return offset_information_many(ref, [mix], pos, min_weight, gate, chi2)[0]


def offset_information_many(ref: GaussianMixture, mixes: list[GaussianMixture],
                            pos: list[int], min_weight: float, gate: float,
                            chi2: float | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`offset_information` of each of ``mixes`` against the same ``ref``, the same
    numbers to the bit: the nearest-component search, gate and inverses of every mixture's
    components done at once (one round's neighbours against own), the sums per mixture as
    :func:`offset_information` does them."""
    out = [(np.zeros((2, 2)), np.zeros(2)) for _ in mixes]
    if len(ref) == 0:
        return out
    b = ref.weights >= min_weight
    if not b.any():
        return out
    sel = [(i, M.weights >= min_weight) for i, M in enumerate(mixes) if len(M)]
    sel = [(i, a) for i, a in sel if a.any()]
    if not sel:
        return out
    ma = np.concatenate([mixes[i].means[a] for i, a in sel])[:, pos]  # (n, 2)
    Pa = position_block(np.concatenate([mixes[i].covs[a] for i, a in sel]), pos)  # (n, 2, 2)
    mb, Pb = ref.means[b][:, pos], position_block(ref.covs[b], pos)  # (m, 2), (m, 2, 2)
    diff = ma[:, None, :] - mb[None, :, :]  # (n, m, 2)
    nearest = np.argmin(np.linalg.norm(diff, axis=2), axis=1)
    d = diff[np.arange(len(ma)), nearest]
    Pn = Pb[nearest]
    ok = gated(d, Pa, Pn, gate, chi2)
    if not ok.any():
        return out
    counts = np.add.reduceat(ok, np.cumsum([0, *(int(a.sum()) for _, a in sel[:-1])]))
    for (i, _), info in zip(sel, information_sums(Pa[ok] + Pn[ok], d[ok], counts.tolist()),
                            strict=True):
        if info is not None:
            out[i] = info
    return out


def information_sums(S: np.ndarray, d: np.ndarray, counts: list[int]
                     ) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """Per segment of ``counts`` consecutive pairs (``S`` ``(p, 2, 2)``: their summed
    position covariances, ``d`` ``(p, 2)``: their differences): ``(sum S_i^-1, sum S_i^-1
    d_i)``, None for an empty segment; the sums of :func:`offset_information_many`, every
    segment at once: the inverses in one batch, the products per pair, then each segment's
    sums in order (:func:`segment_sums`; ``einsum("pij,pj->i")`` of a segment gives these
    numbers to the bit on NumPy 2.4, tests/test_trust_batch.py)."""
    if not len(S):
        return [None] * len(counts)
    Si = np.linalg.inv(S)
    v = Si[:, :, 0] * d[:, None, 0] + Si[:, :, 1] * d[:, None, 1]  # (p, 2): S_i^-1 d_i
    I, y = segment_sums(Si, counts), segment_sums(v, counts)
    return [(I[n], y[n]) if c else None for n, c in enumerate(counts)]


def segment_sums(X: np.ndarray, counts: list[int]) -> np.ndarray:
    """Per segment of ``counts`` consecutive rows of ``X`` (``(N, ...)``): the sum of its rows,
    ``(len(counts), ...)``, each ``X[segment].sum(axis=0)`` to the bit (NumPy adds the rows
    of an outer axis one after the other; the shorter segments padded with ``-0.0``, which
    added changes no number, not even a ``-0.0``); an empty segment's is ``-0.0``."""
    m, top = len(counts), max(counts, default=0)
    if m == 1 and top == len(X):
        return X.sum(axis=0)[None]
    pad = np.full((m, top, *X.shape[1:]), -0.0)
    pad[np.repeat(np.arange(m), counts), _ranks(tuple(counts))] = X
    return pad.sum(axis=1)


@functools.lru_cache(maxsize=256)
def _ranks(counts: tuple[int, ...]) -> np.ndarray:
    """Each row's place in its segment of ``counts`` (:func:`segment_sums`; read-only)."""
    c = np.asarray(counts, dtype=np.intp)
    out = np.arange(int(c.sum()), dtype=np.intp) - (c.cumsum() - c).repeat(c)
    out.flags.writeable = False
    return out


def position_block(covs: np.ndarray, pos: list[int]) -> np.ndarray:
    """The position block ``covs[:, pos][:, :, pos]`` (``(n, 2, 2)``) of covariances
    ``(n, d, d)``: a strided view where ``pos`` is increasing (the same numbers, without
    two fancy-indexing copies per call), the fancy-indexed copy otherwise."""
    i, j = pos
    if j > i:
        step = slice(i, j + 1, j - i)
        return covs[:, step, step]
    return covs[:, pos][:, :, pos]


def relative_offsets(infos: dict[str, tuple[np.ndarray, np.ndarray]],
                     among: list[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each of ``among``'s scan offsets against own made relative to the others':
    ``y_j = I_j (b_j - med_h b_h)`` with ``b = I^-1 y`` and the coordinate-wise median over
    the other neighbours of ``among`` with an offset (at least two; else ``y_j`` is kept).
    Own's estimation error is in every neighbour's offset against own (an honest own that
    re-acquires a target 70 m off moves them all); the median of the others' takes it out,
    and a biased neighbour's offset is its own (W-MSR's premise: the others are mostly
    honest). ``infos``: per neighbour ``(I, y)``, ``(2, 2)`` and ``(2,)``."""
    if len(among) < 3:
        return infos
    I = np.array([infos[s][0] for s in among])  # (m, 2, 2): the determinants in one batch
    ok = np.linalg.det(I) > 1e-12
    names = [s for s, good in zip(among, ok.tolist(), strict=True) if good]
    if len(names) < 3:
        return infos
    info = I[ok]  # (n, 2, 2)
    b = np.linalg.solve(info, np.array([infos[s][1] for s in names])[..., None])[..., 0]
    med = _loo_medians(b)  # (n, 2): each one's leave-one-out median
    y = np.einsum("nij,nj->ni", info, b - med)
    out = dict(infos)
    out.update({s: (infos[s][0], y[i]) for i, s in enumerate(names)})
    return out


def _loo_medians(b: np.ndarray) -> np.ndarray:
    """Per row ``i`` of ``b`` (``(n, k)``, ``n >= 2``): the coordinate-wise median of the
    other rows, ``(n, k)``; ``np.median(b[others], axis=1)`` to the bit (the middle of the
    sorted values, or half the sum of the two middle ones) without its per-call overhead,
    and NaN where a column holds one, as there."""
    S = np.sort(b[_others(len(b))], axis=1)  # (n, n - 1, k)
    h = (len(b) - 1) // 2
    med = S[:, h] if (len(b) - 1) % 2 else (S[:, h - 1] + S[:, h]) * 0.5
    if np.isnan(b).any():  # np.median: NaN where any of the values is
        med = np.where(np.isnan(S).any(axis=1), np.nan, med)
    return med


@functools.lru_cache(maxsize=64)
def _others(n: int) -> np.ndarray:
    """``(n, n - 1)``: row ``i`` the indices ``0..n-1`` but ``i`` (made once, read-only)."""
    out = np.array([[h for h in range(n) if h != i] for i in range(n)], dtype=np.intp)
    out.flags.writeable = False
    return out


def centred(mixes: list[GaussianMixture]) -> list[GaussianMixture]:
    """``mixes`` with every component moved to the origin: with
    :attr:`TrustConfig.location_only` their log overlaps are the ``shape`` of
    :func:`pair_tests` and :func:`divergence_tests`, whose divergence is the part of
    ``D_CS`` that does not depend on where the components are (for two Gaussians exactly
    ``1/2 log(|P_a + P_b| / (2^d |P_a P_b|^1/2))``, so the rest is ``1/2`` the squared
    Mahalanobis distance of the means in ``P_a + P_b``)."""
    return [GaussianMixture(D.weights, np.zeros_like(D.means), D.covs) for D in mixes]


def _cs_matrix(L: np.ndarray) -> np.ndarray:
    """``D_CS`` between every two inputs from their log overlaps ``L`` (``(..., n, n)``)."""
    d = np.diagonal(L, 0, -2, -1)
    return np.asarray(cs_from_log_overlaps(L, np.broadcast_to(d[..., :, None], L.shape),
                                           np.broadcast_to(d[..., None, :], L.shape)))


def _cs_arrays(lpq, lpp, lqq, finite: bool = False) -> np.ndarray:
    """:func:`_cs_scalar` elementwise (broadcast); ``finite``: 0 where it is not finite
    (the ``shape`` of :func:`divergence_tests`)."""
    with np.errstate(invalid="ignore"):
        return _cs_of(_Arrays, lpq, lpp, lqq, finite)


def _cs_scalar(lpq: float, lpp: float, lqq: float) -> float:
    """:func:`tracking.divergence.cs_from_log_overlaps` of three floats, the same operations
    in the same order (``max(-lpq + lpp / 2 + lqq / 2, 0)``, NaN where either side is empty)
    without its array overhead (``np.maximum``'s NaN kept: a NaN ``lpq`` stays NaN)."""
    return _cs_of(_Floats, lpq, lpp, lqq)


def _cs_of(xp, lpq, lpp, lqq, finite: bool = False):
    """``D_CS`` from three log overlaps with the operations ``xp`` (:func:`_divergence`'s):
    NaN where either side is empty, at least 0; ``finite``: 0 where not finite."""
    lpq, lpp, lqq = xp.num(lpq), xp.num(lpp), xp.num(lqq)
    v = -lpq + 0.5 * lpp + 0.5 * lqq
    v = xp.sel(xp.isfinite(lpp) & xp.isfinite(lqq), xp.sel(v < 0.0, 0.0, v), math.nan)
    return xp.sel(xp.isfinite(v), v, 0.0) if finite else v


def _loo_stacked(L: np.ndarray, LW: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``log int D_j R`` and ``log int R^2`` (``(g, J)`` each) of every input ``j = i + 1``
    and the leave-one-out average ``R`` of the inputs with the log weights ``LW[:, i]``
    (``(g, J, n)``, ``-inf`` at ``j``), from the log overlaps ``L`` (``(g, n, n)``): every
    peer's neighbours at once (row-wise log-sum-exps)."""
    g, J, n = LW.shape
    rows = np.arange(1, J + 1)
    cross = _lse_rows((L[:, rows] + LW).reshape(g * J, n)).reshape(g, J)
    square = _lse_rows((L[:, None] + LW[:, :, :, None] + LW[:, :, None, :]).reshape(
        g * J, n * n)).reshape(g, J)
    return cross, square


def _lse_rows(X: np.ndarray) -> np.ndarray:
    """``log sum exp`` of every row of ``X`` (``(J, m)``) from its maximum: ``(J,)``,
    ``-inf`` for a row without a finite maximum."""
    top = X.max(axis=1) if X.shape[1] else np.full(len(X), -np.inf)
    ok = np.isfinite(top)
    safe = np.where(ok, top, 0.0)
    with np.errstate(invalid="ignore", over="ignore"):
        S = np.exp(X - safe[:, None]).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, safe + np.log(S), -np.inf)


def _log(w: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.log(w)


def withheld_increments(U: np.ndarray, targets: np.ndarray, refs: np.ndarray,
                        detection_probability: float, alternative: float,
                        cap: float) -> np.ndarray:
    """Per input ``j`` (``(n,)``; 0 for own, index 0): one scan's log-likelihood ratio that
    ``j`` withholds the targets its references show (a lie such as *empty*) against an
    honest filter that missed them (:attr:`TrustConfig.withhold`).

    Against a reference ``r`` (a Bernoulli miss model per unit of target weight, Wald 1945,
    "Sequential tests of statistical hypotheses", Ann. Math. Stat. 16(2)): ``d`` of ``r``'s
    target weight has no target of ``j`` within the gate beyond what ``j`` shows unmatched
    itself (``max(0, U[r, j] - U[j, r])``: a track re-acquired elsewhere is not withheld),
    ``m = targets[r] - U[r, j]`` is matched. An honest ``j`` lacks a target at rate
    ``1 - Pd`` (a miss, or a birth a scan apart), the withholding one at rate
    ``alternative``, so ``l = min(d log(alternative / (1 - Pd)), cap) + m log((1 -
    alternative) / Pd)``. ``cap``: honest filters lose all their tracks at once (the misses
    of one scan are not independent), so one scan is no more evidence than such a loss,
    ``-log`` of its honest rate. Over the references (``refs``, ``(n, n)`` bool: ``refs[j,
    r]`` whether ``r`` is a reference of ``j``): the median with three or more (W-MSR's
    majority), else the smallest (no majority to outvote a reference that lies itself); 0
    with none. ``U`` (``(n, n)``): :func:`unmatched_weights`; ``targets`` (``(n,)``):
    :func:`target_mass`. Stacks too (``(..., n, n)``, ``(..., n)``: several peers' at once,
    the same numbers)."""
    a = np.log(alternative) - np.log1p(-detection_probability)
    b = np.log1p(-alternative) - np.log(detection_probability)
    d = np.maximum(0.0, U - np.swapaxes(U, -1, -2))  # [r, j]: r's target weight j lacks,
    m = np.maximum(0.0, targets[..., :, None] - U)  # net of j's extras; [r, j]: j shows too
    L = np.minimum(a * d, cap) + b * m  # [r, j]
    out = over_references(L, refs)
    out[..., 0] = 0.0
    return np.nan_to_num(out, nan=0.0)


def over_references(values: np.ndarray, refs: np.ndarray) -> np.ndarray:
    """Per input ``j`` (``(n,)``): ``values[r, j]`` (``(n, n)``) over its references
    ``r`` (``refs[j, r]``): the median with three or more (W-MSR's majority), else the
    smallest (no majority to outvote a reference that lies itself); NaN with none. The
    rule of :func:`withheld_increments` and :func:`whole_losses`. Stacks too
    (``(..., n, n)``)."""
    refs = np.asarray(refs, bool)
    count = refs.sum(axis=-1)
    V = np.where(np.swapaxes(refs, -1, -2), values, np.inf)  # [r, j], non-references last
    V.sort(axis=-2)
    if count.shape[-1] == 0:
        return np.zeros(count.shape)
    lo, hi = np.maximum(count - 1, 0) // 2, count // 2  # the median's two middle entries
    med = 0.5 * (np.take_along_axis(V, lo[..., None, :], -2)[..., 0, :]
                 + np.take_along_axis(V, hi[..., None, :], -2)[..., 0, :])
    out = np.where(count >= 3, med, V[..., 0, :])
    return np.where(count > 0, out, np.nan)


def whole_losses(targets: np.ndarray, refs: np.ndarray, min_weight: float) -> np.ndarray:
    """Per input ``j`` (``(n,)``): 1 where it shows no target while its references do (their
    target weight, median with three or more, else smallest, at least ``min_weight``: a
    whole loss, or *empty*), 0 where it shows some, NaN where the references show none (or
    it has none; own, index 0, NaN). What :attr:`TrustConfig.withhold_cap` was set from;
    ``targets`` and ``refs`` as in :func:`withheld_increments`."""
    n = len(targets)
    ref = over_references(np.repeat(np.asarray(targets, float)[:, None], n, axis=1), refs)
    out = np.where(ref >= min_weight, (np.asarray(targets) <= 0.0).astype(float), np.nan)
    out[:1] = np.nan  # own
    return out


ALONE = {
    "overlaps": lambda mixes: log_overlaps(mixes),
    "unmatched": lambda *args: unmatched_weights(*args)[0],
    "offsets": lambda *args: offset_information_many(*args),
    "chi2": lambda stacks, windows: offset_chi2_stacked(stacks, windows),
    "cusums": lambda *args: offset_cusums(*args),
    "tests": lambda *args: neighbour_tests(*args),
    "own_tests": lambda *args: own_tests(*args),
    "withheld": lambda *args: withheld_increments(*args),
    "relative": lambda infos, among: relative_offsets(infos, among),
    "masses": lambda mixes, min_weight: ([D.mass for D in mixes],
                                         [target_mass(D, min_weight) for D in mixes]),
}
"""How :func:`run_alone` computes each request of the trust generators: ``"overlaps"``
(:func:`tracking.divergence.log_overlaps`), ``"unmatched"`` (:func:`unmatched_weights`'
``U``), ``"offsets"`` (:func:`offset_information_many`), ``"chi2"``
(:func:`offset_chi2_stacked`), ``"cusums"`` (:func:`offset_cusums`), ``"tests"``
(:func:`neighbour_tests`), ``"withheld"`` (:func:`withheld_increments`), ``"relative"``
(:func:`relative_offsets`), ``"masses"``
(each mixture's mass and :func:`target_mass`, lists of floats); looked up when called
(a test's patch of a module's function is seen)."""
