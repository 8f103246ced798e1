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

import sys
from collections import deque
from pathlib import Path

import numpy as np

if not __package__:  # run as a script: this checkout's code, not the installed one
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sensornet.peers.trust_config import TrustConfig
from sensornet.tracking import divergence
from sensornet.tracking.divergence import cs_from_log_overlaps
from sensornet.tracking.gaussian import inv_det_spd, log_gaussian
from sensornet.tracking.mixture import GaussianMixture


def log_overlaps(mixtures: list[GaussianMixture]) -> np.ndarray:
    """:func:`tracking.divergence.log_overlaps` before it made each unordered pair once (every
    ordered pair's term, then block log-sum-exps; its blocked path is the module's own)."""
    n = len(mixtures)
    sizes = np.array([len(D) for D in mixtures], dtype=int)
    L = np.full((n, n), -np.inf)
    C = int(sizes.sum())
    if C == 0:
        return L
    w = np.concatenate([D.weights for D in mixtures if len(D)])
    m = np.concatenate([D.means for D in mixtures if len(D)])
    P = np.concatenate([D.covs for D in mixtures if len(D)])
    with np.errstate(divide="ignore"):
        lw = np.log(w)
    present = np.flatnonzero(sizes)
    starts = np.r_[0, np.cumsum(sizes[present])[:-1]]
    if C * C <= divergence.BLOCK_PAIRS:
        inv, det = inv_det_spd(P[:, None] + P[None, :])
        G = lw[:, None] + lw[None, :] + log_gaussian(m[:, None] - m[None, :], inv, det)
        blk = np.repeat(np.arange(len(present)), sizes[present])  # block of each component
        top = np.maximum.reduceat(np.maximum.reduceat(G, starts, axis=0), starts, axis=1)
        safe = np.where(np.isfinite(top), top, 0.0)
        S = np.add.reduceat(np.add.reduceat(np.exp(G - safe[blk][:, blk]), starts, axis=0),
                            starts, axis=1)
        with np.errstate(divide="ignore"):
            L[np.ix_(present, present)] = np.where(np.isfinite(top), safe + np.log(S),
                                                   -np.inf)
        return L
    L[np.ix_(present, present)] = divergence._blocked(
        lw, m, P, starts, max(1, divergence.BLOCK_PAIRS // C))
    return L


def neighbour_statistics(cfg: TrustConfig, own: GaussianMixture,
                         inputs: dict[str, GaussianMixture], weights: dict[str, float],
                         quarantined: set[str], pos: tuple[int, int] = (0, 2)
                         ) -> dict[str, float]:
    """``T_j`` of every neighbour in ``inputs`` against ``own`` and the leave-one-out
    average of the other trusted inputs (weights ``weights``, own's under ``""``; the
    neighbours in ``quarantined`` are left out of every reference; ``pos``: the position
    entries of the state, for :func:`unmatched_weights`)."""
    names = sorted(inputs)
    mixes = [own] + [inputs[s] for s in names]
    L = log_overlaps(mixes)
    L0 = shape_overlaps(cfg, mixes)
    mass = np.array([D.mass for D in mixes])
    tm = np.array([target_mass(D, cfg.repeat_weight) for D in mixes])
    trusted = np.array([1.0] + [0.0 if s in quarantined else 1.0 for s in names])
    w = np.array([weights.get("", 1.0)] + [weights.get(s, 0.0) for s in names]) * trusted
    U = None
    if cfg.majority and cfg.unmatched and cfg.detection_probability is not None:
        U, _ = unmatched_weights(mixes, list(pos), cfg.repeat_weight, cfg.bias_gate,
                                 cfg.gate_chi2)
    pair = pair_tests(cfg, L, mass, tm, U, L0) if cfg.majority else None
    out = {}
    for j, s in enumerate(names, start=1):
        t_own = divergence_test(cfg, L[j, j], L[j, 0], L[0, 0], mass[j], mass[0], tm[j], tm[0],
                                shape=_cs(L0, j, L0[j, 0], L0[0, 0]) if L0 is not None else 0.0)
        wo = w.copy()
        wo[j] = 0.0
        if wo.sum() > 0 and np.count_nonzero(wo) > 1:  # the others besides own
            wo = wo / wo.sum()
            t_loo = divergence_test(cfg, L[j, j], *_loo(L, j, wo), mass[j], float(wo @ mass),
                                    tm[j], float(wo @ tm),
                                    shape=_cs(L0, j, *_loo(L0, j, wo)) if L0 is not None
                                    else 0.0)
            out[s] = min(t_own, t_loo)
        else:
            out[s] = t_own
        others = np.flatnonzero(wo > 0) if pair is not None else ()
        if len(others) >= 3:  # own and at least two other trusted neighbours
            sub = pair[np.ix_(others, others)][np.triu_indices(len(others), 1)]
            base = float(np.median(pair[j, others])) if cfg.median_test else out[s]
            out[s] = max(0.0, base - float(np.median(sub)))
    return out


def pair_tests(cfg: TrustConfig, L: np.ndarray, mass: np.ndarray,
               targets: np.ndarray | None = None,
               unmatched: np.ndarray | None = None,
               shape: np.ndarray | None = None) -> np.ndarray:
    """The test between every two inputs (``(n, n)``; the majority's own spread) from their
    log overlaps ``L`` (``(n, n)``), masses ``mass`` (``(n,)``), target masses
    ``targets`` (``(n,)``, :func:`target_mass`; None: no missed-detection bound),
    unmatched target weights ``unmatched`` (``(n, n)``, :func:`unmatched_weights`; None:
    not used) and the log overlaps of the inputs centred (``(n, n)``,
    :func:`shape_overlaps`; None: the divergence as it is)."""
    cs = _cs_matrix(L)
    if shape is not None:  # the location part (TrustConfig.location_only)
        cs = np.maximum(cs - np.nan_to_num(_cs_matrix(shape), nan=0.0, posinf=0.0), 0.0)
    a, b = mass[:, None], mass[None, :]
    card = cfg.kappa * (a - b) ** 2 / (b + 1.0)
    card = np.minimum(card, card.T)  # symmetric: the smaller of the two directions
    ea, eb = a <= 1e-9, b <= 1e-9
    cs = np.where(np.isfinite(cs), cs, cfg.cap)
    one = cfg.empty_penalty * np.minimum(1.0, np.maximum(a, b))
    where = np.where(ea & eb, 0.0, np.where(ea | eb, one, cs))
    if unmatched is not None:
        where = np.maximum(where, cfg.unmatched_cost * (unmatched + unmatched.T))
    if targets is not None:
        where = np.minimum(where, miss_cost(cfg, targets[:, None], targets[None, :]))
    P = np.minimum(where + card, cfg.cap)
    np.fill_diagonal(P, 0.0)
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
    w = np.concatenate([D.weights[m] for D, m in zip(mixes, sel, strict=True)])
    X = np.concatenate([D.means[m][:, pos] for D, m in zip(mixes, sel, strict=True)])
    P = (np.concatenate([D.covs[m][:, pos][:, :, pos] for D, m in zip(mixes, sel, strict=True)])
         if chi2 is not None else np.zeros((len(owner), 2, 2)))
    G = np.zeros((len(owner), n))
    G[np.arange(len(owner)), owner] = 1.0  # (C, n): which input a component is of
    close = near(X, P, X, P, gate, chi2)  # (C, C)
    hit = (close.astype(float) @ G) > 0  # (C, n)
    U = G.T @ (w[:, None] * ~hit)  # (n, n)
    return U, (hit, w, owner)


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
          chi2: float | None = None) -> np.ndarray:
    """Whether position differences ``d (..., 2)`` between estimates with position
    covariances ``Pa``, ``Pb`` (``(..., 2, 2)``, broadcast) are one target: within ``gate``
    metres, or (``chi2`` not None) within the chi-square gate ``d' S^-1 d <= chi2`` of their
    own uncertainty, ``S = 2 P`` with ``P`` the pair's covariance of smaller determinant.

    Why both: estimates whose position sd is hundreds of metres (real traffic: plots of
    170-270 m, radars that sweep a target once in 5 ticks) are honestly hundreds of metres
    apart, where a fixed metric gate pairs 9 % of them (the chi-square gate at 99.9 %: 90 %;
    on seed 000 94-95 % of honest pairs are within either); the smaller covariance, so
    that a neighbour cannot widen the gate by claiming a wide one (an honest pair's
    ``P_a + P_b`` gates the same share on both scenarios: training run 9000)."""
    close = np.einsum("...i,...i->...", d, d) <= gate * gate
    if chi2 is None or close.size == 0:
        return close
    smaller = (np.linalg.det(Pa) <= np.linalg.det(Pb))[..., None, None]
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
    """``T = W + kappa (N_j - N_R)^2 / (N_R + 1)``, capped at :attr:`TrustConfig.cap`, from
    the log overlaps of a density ``D_j`` and a reference ``R`` and their masses. ``W``,
    where the targets are: ``D_CS(D_j, R)`` less ``shape`` (the divergence of the two
    centred, :func:`shape_overlaps`; at least 0), :attr:`TrustConfig.empty_penalty` when one
    side is empty, at least ``unmatched_cost`` times the ``unmatched`` target weight on
    both sides (:func:`unmatched_weights`) and at most :func:`miss_cost` of their target
    masses ``t_j``, ``t_r`` (each when given)."""
    card = cfg.kappa * (n_j - n_r) ** 2 / (n_r + 1.0)
    if n_j <= 1e-9 and n_r <= 1e-9:
        where = 0.0
    elif n_j <= 1e-9 or n_r <= 1e-9:  # one side empty: where cannot be compared
        where = cfg.empty_penalty * min(1.0, max(n_j, n_r))
    else:
        where = float(cs_from_log_overlaps(np.float64(l_jr), np.float64(l_jj),
                                           np.float64(l_rr)))
        if not np.isfinite(where):
            where = cfg.cap
        elif np.isfinite(shape):
            where = max(0.0, where - shape)
    if unmatched is not None:
        where = max(where, cfg.unmatched_cost * float(unmatched))
    if t_j is not None and t_r is not None:
        where = min(where, float(miss_cost(cfg, t_j, t_r)))
    return min(cfg.cap, where + card)


def is_repeat(prev: GaussianMixture | None, mix: GaussianMixture, min_weight: float) -> bool:
    """Whether ``mix`` repeats, bit for bit, the earlier density ``prev`` (another object,
    non-empty, its heaviest component at least ``min_weight``: :attr:`TrustConfig.repeat`)."""
    return (prev is not None and prev is not mix and len(mix) > 0 and len(mix) == len(prev)
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


def cusum_directions(n: int) -> np.ndarray:
    """``(n, 2)`` unit vectors at angles ``2 pi m / n`` (the charts of :func:`offset_cusum`)."""
    a = 2.0 * np.pi * np.arange(n) / n
    return np.stack([np.cos(a), np.sin(a)], axis=1)


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


def offset_information(ref: GaussianMixture, mix: GaussianMixture, pos: list[int],
                       min_weight: float, gate: float, chi2: float | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Information ``I = sum S_i^-1`` (``(2, 2)``) and ``y = sum S_i^-1 d_i`` (``(2,)``) of the
    position differences ``d_i = m_i - r_(i)`` between each component of ``mix`` of weight at
    least ``min_weight`` and the nearest such component of ``ref`` if within the gate
    (:func:`near`: ``gate`` metres, or the ``chi2`` gate of their covariances; ``S_i``: the
    sum of the two position covariances): the generalised-least-squares estimate of a
    common offset is ``I^-1 y``, its chi-square ``y' I^-1 y``."""
    zero = (np.zeros((2, 2)), np.zeros(2))
    if len(ref) == 0 or len(mix) == 0:
        return zero
    a = mix.weights >= min_weight
    b = ref.weights >= min_weight
    if not a.any() or not b.any():
        return zero
    ix = np.ix_(pos, pos)
    ma, mb = mix.means[a][:, pos], ref.means[b][:, pos]  # (n, 2), (m, 2)
    Pa = mix.covs[a][:, ix[0], ix[1]]  # (n, 2, 2)
    Pb = ref.covs[b][:, ix[0], ix[1]]  # (m, 2, 2)
    diff = ma[:, None, :] - mb[None, :, :]  # (n, m, 2)
    dist = np.linalg.norm(diff, axis=2)
    nearest = np.argmin(dist, axis=1)
    rows = np.arange(len(ma))
    ok = gated(diff[rows, nearest], Pa, Pb[nearest], gate, chi2)
    if not ok.any():
        return zero
    d = diff[rows, nearest][ok]  # (p, 2)
    S = Pa[ok] + Pb[nearest[ok]]  # (p, 2, 2)
    Si = np.linalg.inv(S)
    return Si.sum(axis=0), np.einsum("pij,pj->i", Si, d)


def relative_offsets(infos: dict[str, tuple[np.ndarray, np.ndarray]],
                     among: list[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each of ``among``'s scan offsets against own made relative to the others':
    ``y_j = I_j (b_j - med_h b_h)`` with ``b = I^-1 y`` and the coordinate-wise median over
    the other neighbours of ``among`` with an offset (at least two; else ``y_j`` is kept).
    Own's estimation error is in every neighbour's offset against own (an honest own that
    re-acquires a target 70 m off moves them all); the median of the others' takes it out,
    and a biased neighbour's offset is its own (W-MSR's premise: the others are mostly
    honest). ``infos``: per neighbour ``(I, y)``, ``(2, 2)`` and ``(2,)``."""
    names = [s for s in among if np.linalg.det(infos[s][0]) > 1e-12]
    if len(names) < 3:
        return infos
    b = np.linalg.solve(np.array([infos[s][0] for s in names]),
                        np.array([infos[s][1] for s in names])[..., None])[..., 0]  # (n, 2)
    n = len(names)
    others = np.array([[h for h in range(n) if h != i] for i in range(n)])  # (n, n-1)
    med = np.median(b[others], axis=1)  # (n, 2): each one's leave-one-out median
    info = np.array([infos[s][0] for s in names])  # (n, 2, 2)
    y = np.einsum("nij,nj->ni", info, b - med)
    out = dict(infos)
    out.update({s: (infos[s][0], y[i]) for i, s in enumerate(names)})
    return out


def shape_overlaps(cfg: TrustConfig, mixes: list[GaussianMixture]) -> np.ndarray | None:
    """With :attr:`TrustConfig.location_only`: the log overlaps (``(n, n)``,
    :func:`tracking.divergence.log_overlaps`) of ``mixes`` with every component moved to
    the origin, whose divergence is the part of ``D_CS`` that does not depend on where the
    components are (for two Gaussians exactly ``1/2 log(|P_a + P_b| / (2^d |P_a P_b|^1/2))``,
    so the rest is ``1/2`` the squared Mahalanobis distance of the means in ``P_a + P_b``);
    None without it."""
    if not cfg.location_only:
        return None
    return log_overlaps([GaussianMixture(D.weights, np.zeros_like(D.means), D.covs)
                         for D in mixes])


def _cs_matrix(L: np.ndarray) -> np.ndarray:
    """``D_CS`` between every two inputs from their log overlaps ``L`` (``(n, n)``)."""
    d = np.diag(L)
    return np.asarray(cs_from_log_overlaps(L, np.broadcast_to(d[:, None], L.shape),
                                           np.broadcast_to(d[None, :], L.shape)))


def _cs(L0: np.ndarray, j: int, l_jr: float, l_rr: float) -> float:
    """``D_CS`` of input ``j`` and a reference from the centred log overlaps ``L0``
    (``log int D_j R``: ``l_jr``, ``log int R^2``: ``l_rr``), 0 where it is not finite (the
    ``shape`` of :func:`divergence_test`)."""
    v = float(cs_from_log_overlaps(np.float64(l_jr), np.float64(L0[j, j]), np.float64(l_rr)))
    return v if np.isfinite(v) else 0.0


def _loo(L: np.ndarray, j: int, wo: np.ndarray) -> tuple[float, float]:
    """``log int D_j R`` and ``log int R^2`` of the leave-one-out average ``R`` of the
    inputs with weights ``wo`` (``(n,)``, 0 at ``j``) from the log overlaps ``L``."""
    lw = _log(wo)
    return _lse(L[j] + lw), _lse((L + lw[:, None] + lw[None, :]).ravel())


def _log(w: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.log(w)


def _lse(x: np.ndarray) -> float:
    top = np.max(x)
    if not np.isfinite(top):
        return -np.inf
    return float(top + np.log(np.exp(x - top).sum()))


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
    :func:`target_mass`."""
    a = np.log(alternative) - np.log1p(-detection_probability)
    b = np.log1p(-alternative) - np.log(detection_probability)
    d = np.maximum(0.0, U - U.T)  # [r, j]: r's target weight j lacks, net of j's own extras
    m = np.maximum(0.0, targets[:, None] - U)  # [r, j]: r's target weight j shows too
    L = np.minimum(a * d, cap) + b * m  # [r, j]
    out = over_references(L, refs)
    out[0] = 0.0
    return np.nan_to_num(out, nan=0.0)


def over_references(values: np.ndarray, refs: np.ndarray) -> np.ndarray:
    """Per input ``j`` (``(n,)``): ``values[r, j]`` (``(n, n)``) over its references
    ``r`` (``refs[j, r]``): the median with three or more (W-MSR's majority), else the
    smallest (no majority to outvote a reference that lies itself); NaN with none. The
    rule of :func:`withheld_increments` and :func:`whole_losses`."""
    refs = np.asarray(refs, bool)
    count = refs.sum(axis=1)
    V = np.where(refs.T, values, np.inf)  # [r, j], non-references last when sorted
    V.sort(axis=0)
    cols = np.arange(len(count))
    lo, hi = np.maximum(count - 1, 0) // 2, count // 2  # the median's two middle entries
    med = 0.5 * (V[lo, cols] + V[hi, cols]) if len(count) else np.zeros(0)
    out = np.where(count >= 3, med, V[0] if len(count) else np.zeros(0))
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
