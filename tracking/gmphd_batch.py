"""Many GM-PHD local steps (predict, update, level-1 reduction) as one stacked array computation.

A peer host steps the local filters of many peers at one instant (every peer's scan ``k``
arrives together). Each step is a few components times a few measurements, so one costs the
~50 NumPy calls' overhead of :func:`tracking.gmphd.predict`, :func:`tracking.gmphd.update`
and the :class:`~tracking.reduction.Reducer`, not arithmetic. Here ``P`` steps are laid side
by side: every component of every problem in one stack (its problem's id beside it), every
(measurement, component) pair of every problem in one flat array (Vo & Ma 2006, Table I,
steps 3-4, the same equations as :func:`tracking.gmphd.update`), the reductions through
:func:`tracking.fusion_batch.reduce_many`. Problems never mix: a pair lies inside one problem
and the PHD denominator ``kappa + Pd sum_l w_l q_l(z)`` sums over its own components only, so
problem ``p``'s result is ``filt.correct(filt.predict(mix, steps), [z])`` for it alone (equal
to round-off; ``tests/test_gmphd_batch.py`` checks it on random mixtures and scans).

Stacked together: filters with one linear sensor that picks state entries
(``MeasurementModel.selected``), the same motion model, survival probability, reducer (no ISE
re-fit), gate and step count. ``Pd``, clutter intensity, ``R`` and the birth intensity may
differ per problem. Anything else goes through the filter's own ``correct(predict(...))``.
Arrays: ``N`` components of all problems ``(N,)``, ``(N, d)``, ``(N, d, d)``; ``T`` pairs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sensornet.tracking.fusion_batch import reduce_many
from sensornet.tracking.gaussian import c_einsum, inv_det_spd
from sensornet.tracking.gmphd import (
    _LOG_2PI,
    GMPHDFilter,
    _inv_det_2x2,
    _selected_columns,
    update_parents,
)
from sensornet.tracking.mixture import GaussianMixture


def batch_key(filt: GMPHDFilter, steps: int) -> tuple | None:
    """What must be equal for two steps to be stacked together; None: not stackable."""
    if (len(filt.sensors) != 1 or steps < 1 or filt.reducer.refit
            or not getattr(filt, "stackable", True)):  # a filter with its own step
        return None
    model = filt.sensors[0].model
    if model.selected is None:
        return None
    return (type(model), tuple(model.selected), model.dim, filt.motion,
            filt.survival_probability, filt.reducer, filt.gate, int(steps))


def step_many(filters: Sequence[GMPHDFilter], mixes: Sequence[GaussianMixture],
              steps: Sequence[int], scans: Sequence[np.ndarray], parents: bool = False) -> list:
    """``[f.correct(f.predict(mix, s), [z]) for f, mix, s, z in ...]``, stacked where the
    filters allow it (:func:`batch_key`), each problem on its own otherwise.

    ``parents``: each problem's ``(posterior, parents)`` instead, ``parents (k,)`` for each
    posterior component the index into the predicted mixture ``f.predict(mix, s)`` (survivors
    in order, then the births) of the component it descends from (the heaviest member of its
    merge group): the same numbers, and what tag propagation (tracking.labels) needs."""
    out: list = [None] * len(filters)
    groups: dict[tuple, list[int]] = {}
    for p, (f, s) in enumerate(zip(filters, steps, strict=True)):
        key = batch_key(f, s)
        if key is None:
            out[p] = _one(f, mixes[p], s, scans[p], parents)
        else:
            groups.setdefault(key, []).append(p)
    for ps in groups.values():
        if len(ps) == 1:
            p = ps[0]
            out[p] = _one(filters[p], mixes[p], steps[p], scans[p], parents)
            continue
        res = _step_stacked([filters[p] for p in ps], [mixes[p] for p in ps], steps[ps[0]],
                            [scans[p] for p in ps], parents)
        for p, r in zip(ps, res, strict=True):
            out[p] = r
    return out


def correct_parents(filt: GMPHDFilter, predicted: GaussianMixture,
                    scans: Sequence[np.ndarray]) -> tuple[GaussianMixture, np.ndarray]:
    """``filt.correct(predicted, scans)`` (the same numbers) and each posterior component's
    parent index into ``predicted`` (:func:`tracking.gmphd.update_parents`, then
    :meth:`~tracking.reduction.Reducer.with_sources`, composed over the sensors)."""
    own = getattr(filt, "correct_parents", None)
    if own is not None:  # a filter that does more in its correction (sim.world.birth)
        return own(predicted, scans)
    if len(scans) != len(filt.sensors):
        raise ValueError(f"expected {len(filt.sensors)} scans, got {len(scans)}")
    mix, par = predicted, np.arange(len(predicted))
    for sensor, scan in zip(filt.sensors, scans, strict=True):
        mix, det = update_parents(mix, scan, sensor, filt.gate, filt.reducer.prune_threshold)
        par = np.concatenate((par, par[det]))
        mix, src = filt.reducer.with_sources(mix)
        par = par[src]
    return mix, par


def _one(f: GMPHDFilter, mix: GaussianMixture, steps: int, z: np.ndarray, parents: bool):
    if parents:
        return correct_parents(f, f.predict(mix, steps), [z])
    return f.correct(f.predict(mix, steps), [z])


def _segments(starts: np.ndarray, lens: np.ndarray) -> np.ndarray:
    """Indices ``starts[0] .. starts[0] + lens[0] - 1, starts[1] ..`` as one array."""
    total = int(lens.sum())
    if total == 0:
        return np.zeros(0, dtype=np.intp)
    before = np.cumsum(lens) - lens
    return np.repeat(starts - before, lens) + np.arange(total)


def _interleave(a_lens: np.ndarray, b_lens: np.ndarray) -> np.ndarray:
    """Index into ``concat(A, B)`` (``A`` of blocks ``a_lens``, ``B`` of ``b_lens``) giving
    ``A_0, B_0, A_1, B_1, ..``: each problem's own block of A, then its block of B."""
    a_start = np.cumsum(a_lens) - a_lens
    b_start = a_lens.sum() + np.cumsum(b_lens) - b_lens
    starts = np.stack((a_start, b_start), axis=1).ravel()
    lens = np.stack((a_lens, b_lens), axis=1).ravel()
    return _segments(starts, lens)


@dataclass(frozen=True)
class _Stack:
    """Every problem's predicted components side by side: ``w (N,)``, ``mean (N, d)``,
    ``P (N, d, d)``, ``n_lens (P,)`` components per problem, ``prob (N,)`` each one's problem."""

    w: np.ndarray
    mean: np.ndarray
    P: np.ndarray
    n_lens: np.ndarray
    prob: np.ndarray


def _step_stacked(filters: list[GMPHDFilter], mixes: list[GaussianMixture], steps: int,
                  scans: list[np.ndarray], parents: bool = False) -> list:
    """Predict, update and reduce every problem together (see the module docstring)."""
    f0, n_prob = filters[0], len(filters)
    st = _predict_stacked(filters, mixes, steps)
    missed_w, det_w, det_m, det_P, det_lens, det_par = _update_stacked(filters, st, scans)
    n_lens = st.n_lens
    idx = _interleave(n_lens, det_lens)
    w_all = np.concatenate((missed_w, det_w))[idx]
    m_all = np.concatenate((st.mean, det_m))[idx]
    P_all = np.concatenate((st.P, det_P))[idx]
    prob_all = np.repeat(np.arange(n_prob), n_lens + det_lens)
    if not parents:
        return reduce_many(f0.reducer, w_all, m_all, P_all, prob_all, n_prob)
    # each pre-reduction row's parent in its problem's predicted mixture: the missed terms
    # are the predicted components in order, the detection terms their pairs' components
    own = np.arange(len(st.w)) - np.repeat(np.cumsum(n_lens) - n_lens, n_lens)
    par_all = np.concatenate((own, det_par))[idx]
    starts = np.cumsum(n_lens + det_lens) - (n_lens + det_lens)
    return [(mix, par_all[starts[p] + src]) for p, (mix, src) in enumerate(
        reduce_many(f0.reducer, w_all, m_all, P_all, prob_all, n_prob, sources=True))]


def _predict_stacked(filters: list[GMPHDFilter], mixes: list[GaussianMixture],
                     steps: int) -> _Stack:
    """:func:`tracking.gmphd.predict` of every problem: survivors, then each one's births."""
    f0 = filters[0]
    F, Q = f0.motion.transition(steps)
    ps_pow = f0.survival_probability**steps
    w = np.concatenate([m.weights for m in mixes]) * ps_pow
    mean = np.concatenate([m.means for m in mixes]) @ F.T
    P = F @ np.concatenate([m.covs for m in mixes]) @ F.T + Q
    births = [f.birth if f.birth is not None else GaussianMixture.empty(f0.motion.dim)
              for f in filters]
    b_lens = np.array([len(b) for b in births])
    s_lens = np.array([len(m) for m in mixes])
    if b_lens.any():
        idx = _interleave(s_lens, b_lens)
        w = np.concatenate((w, *[b.weights for b in births]))[idx]
        mean = np.concatenate((mean, *[b.means for b in births]))[idx]
        P = np.concatenate((P, *[b.covs for b in births]))[idx]
    n_lens = s_lens + b_lens  # components per problem after the prediction
    return _Stack(w, mean, P, n_lens, np.repeat(np.arange(len(filters)), n_lens))


def _update_stacked(filters: list[GMPHDFilter], st: _Stack, scans: list[np.ndarray]) -> tuple:
    """:func:`tracking.gmphd.update` of every problem over its own (z, j) pairs:
    ``(missed_w (N,), det_w (K,), det_m (K, d), det_P (K, d, d), det_lens (P,), det_par (K,))``,
    the detection terms problem by problem, ``det_par`` their components' index in it."""
    n_prob, dim = len(filters), filters[0].sensors[0].model.dim
    Pd = np.array([f.sensors[0].detection_probability for f in filters])
    kappa = np.array([f.sensors[0].clutter_intensity for f in filters])
    R = np.stack([f.sensors[0].model.R for f in filters])  # (P, dim, dim)
    Z = [np.asarray(z, dtype=float).reshape(-1, dim) for z in scans]
    m_lens = np.array([len(z) for z in Z])
    scan = np.concatenate(Z) if len(Z) else np.zeros((0, dim))
    missed_w = st.w * (1.0 - Pd[st.prob])
    pair_lens = m_lens * st.n_lens
    if int(pair_lens.sum()) == 0:
        return (missed_w, st.w[:0], st.mean[:0], st.P[:0], np.zeros(n_prob, dtype=np.intp),
                np.zeros(0, dtype=np.intp))
    return (missed_w, *_detections(filters[0], st, R, Pd, kappa, scan, m_lens, pair_lens))


def _detections(f0: GMPHDFilter, st: _Stack, R: np.ndarray, Pd: np.ndarray, kappa: np.ndarray,
                scan: np.ndarray, m_lens: np.ndarray, pair_lens: np.ndarray) -> tuple:
    """The detection terms of every (problem, z, j) pair (Vo & Ma 2006, Table I, step 4):
    ``(det_w, det_m, det_P, det_lens, det_par)`` of the pairs kept (weight over the prune
    threshold), problem by problem; ``R (P, dim, dim)``, ``Pd``/``kappa (P,)``, ``scan (M, dim)``
    every problem's measurements, ``m_lens``/``pair_lens (P,)`` their counts and pairs."""
    model, n_prob, n_lens = f0.sensors[0].model, len(m_lens), st.n_lens
    dim, n_pairs, w, mean, P = model.dim, int(pair_lens.sum()), st.w, st.mean, st.P
    cols = _selected_columns(model)
    zhat = mean[:, cols]  # (N, dim)
    PHt = P[:, :, cols]  # (N, d, dim)
    S = PHt[:, cols, :] + R[st.prob]  # (N, dim, dim)
    S_inv, S_det = (_inv_det_2x2(S) if dim == 2 else inv_det_spd(S))
    K = PHt @ S_inv  # (N, d, dim)
    P_upd = P - K @ PHt.swapaxes(1, 2)
    P_upd = P_upd + P_upd.swapaxes(1, 2)
    P_upd *= 0.5
    # the pairs, problem by problem, measurement-major (update's (m, n) array row by row)
    pp = np.repeat(np.arange(n_prob), pair_lens)  # (T,)
    local = np.arange(n_pairs) - np.repeat(np.cumsum(pair_lens) - pair_lens, pair_lens)
    n_of = n_lens[pp]
    j_local = local % n_of
    zi = (np.cumsum(m_lens) - m_lens)[pp] + local // n_of  # into scan
    ji = (np.cumsum(n_lens) - n_lens)[pp] + j_local  # into the components
    nu = model.residual(scan[zi], zhat[ji])  # (T, dim)
    d2 = c_einsum("...i,...ij,...j->...", nu, S_inv[ji], nu)  # (T,)
    num = d2 + np.log(S_det)[ji]
    num += dim * _LOG_2PI
    num *= -0.5
    np.exp(num, out=num)
    num *= Pd[pp] * w[ji]
    if f0.gate is not None:
        num = np.where(d2 <= f0.gate, num, 0.0)
    first = j_local == 0  # each (problem, z) row starts here
    row = np.cumsum(first) - 1  # (T,): the row of each pair
    denom = np.add.reduceat(num, np.flatnonzero(first))
    denom += kappa[pp[first]]
    num /= denom[row]
    min_weight = f0.reducer.prune_threshold
    keep = num > min_weight if min_weight > 0 else num >= 0
    kj = ji[keep]
    det_m = mean[kj] + c_einsum("kij,kj->ki", K[kj], nu[keep])
    return (num[keep], det_m, P_upd[kj], np.bincount(pp[keep], minlength=n_prob),
            j_local[keep])


__all__ = ["batch_key", "correct_parents", "step_many"]
