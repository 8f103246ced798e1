"""A GM-PHD peer's plots taken at their own times within the tick (issue 34,
``filter.time_slice``).

The GM-PHD counterpart of :mod:`peers.lmb_own_times` (whose :class:`OwnTimes` and
:func:`slice_index` it uses): a rotating radar's scan at tick ``k`` holds the plots its beam
made in ``(t_(k-1), t_k]``; with their ages the peer cuts the tick into slices of ``slice_s``
and, slice by slice (empty ones too), predicts over the elapsed time
(:class:`tracking.elapsed.ElapsedMotion`, ``Ps^(dt / T)``; the pending births move with the
survivors), corrects with the slice's plots at the ``Pd`` of the sector the beam swept in the
slice (soft edges) and the clutter inside that sector, reduces, and applies Panta's duplicate
rule, as the asynchronous centralised reference's GM-PHD does for one radar
(``sim.studies.traffic.asynchronous.AsyncGmphd``; Bar-Shalom, Willett & Tian 2011, ch. 9). The
mixture is then predicted to ``t_k``, where the peer publishes and fuses as before; a sensor
without a beam (no ``sector_pd``) takes its scan in one batch at ``t_k``.

The filter is the peer's measurement-birth GM-PHD (``sim.world.birth.MeasurementBirthGMPHD``:
``correct_parents`` judges the plots no heavy component explains and queues their births in
``pending``), stepped on a copy whose sensor carries the slice's ``Pd`` vector. A slice's
births enter at the next slice's prediction; the last slice's are moved to ``t_k`` and stay
``pending`` (outside the published mixture, so a fusion's feedback keeps them, as the tick
filter's) until the next tick's first prediction, where they are predicted with the survivors:
the same numbers as the reference, whose births enter its mixture at ``t_k``.

Labels (Panta, Clark & Vo 2009 tags): survivors keep theirs through every slice; births of the
``j``-th prediction of tick ``k`` are ``(birth_origin, k, j * SLICE_LABEL_BASE + i)`` (``j = 0``:
the births queued before the tick, labelled as the tick filter labels them) and the duplicate
rule's splits of slice ``j`` ``(origin, k, j * SLICE_LABEL_BASE + b_j + i)`` after its ``b_j``
births, so labels stay unique within the tick. The tick's label bookkeeping (publication
stamps, re-identification, moving stamps) then runs once at ``t_k`` on the result, as after a
tick step.
"""

from __future__ import annotations

import copy

import numpy as np
from sensornet.peers.lmb_own_times import SLICE_LABEL_BASE, OwnTimes, slice_index
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.gmphd import predict as gm_predict
from sensornet.tracking.label_keys import new_labels
from sensornet.tracking.labels import LabelledMixture, split_duplicates
from sensornet.tracking.mixture import GaussianMixture

WIDE_SD = 10_000.0
"""Metres of position sd (either axis) above which a component is dropped before a slice's
correction. Measurement births never detected again (clutter, or beyond a radar's range where
``Pd`` is 0) coast with the birth's velocity sd for minutes, 50-120 km wide at weights 1e-4 to
0.05; Vo & Ma's merge test uses the lighter member's covariance, so such a component merged into
an aircraft's track tens of km away, made it 14-17 km wide, and the widened track then merged a
second aircraft's track (weight 1.7, two aircraft's labels on one component): the training
hour's fused identity switches at the plots' own times (docs/real-traffic.md)."""


def check_filter(filt) -> None:
    """ValueError unless ``filt`` is a one-sensor measurement-birth GM-PHD (its births come
    from the plots, ``correct_parents`` and ``pending``): fixed birth components would enter at
    every slice."""
    if not (hasattr(filt, "correct_parents") and hasattr(filt, "pending")
            and len(filt.sensors) == 1):
        raise ValueError("plots at their own times need a one-sensor GM-PHD with measurement "
                         "births (birth.model 'measurements')")


def drop_wide(mix: GaussianMixture, labels: np.ndarray | None, wide_sd: float
              ) -> tuple[GaussianMixture, np.ndarray | None]:
    """``mix`` (and its ``labels``) without the components whose position sd on either axis
    exceeds ``wide_sd`` m (:data:`WIDE_SD`)."""
    P = mix.covs
    keep = np.maximum(P[:, 0, 0], P[:, 2, 2]) <= wide_sd * wide_sd
    if keep.all():
        return mix, labels
    return mix.select(keep), None if labels is None else labels[keep]


def _moved(births: GaussianMixture | None, own: OwnTimes, dt: float) -> GaussianMixture | None:
    """``births`` over ``dt`` seconds, all of them (they enter: no survival), or None."""
    if births is None or not len(births):
        return None
    return gm_predict(births, own.motion.at(dt), 1.0, None, 1)


def step_at_own_times(filt, mix: GaussianMixture, labels: np.ndarray | None, z: np.ndarray,
                      ages: np.ndarray, t_prev: float, k: int, own: OwnTimes,
                      origin: int | None = None, birth_origin: int | None = None,
                      wide_sd: float | None = WIDE_SD
                      ) -> tuple[GaussianMixture, np.ndarray | None]:
    """The mixture (and its labels, None if ``labels`` is None) after tick ``k``'s plots
    ``z (m, dz)`` of ages ``ages (m,)`` (s before ``k T``), taken slice by slice at their own
    times from ``mix`` at ``t_prev`` s, predicted to ``k T`` (module docstring). ``filt``'s
    ``pending`` becomes the last slice's births at ``k T`` and its scan ``k``; nothing else of
    it changes (a copy is stepped)."""
    check_filter(filt)
    model = filt.sensors[0].model
    z = np.asarray(z, float).reshape(-1, model.dim)
    ages = np.asarray(ages, float).reshape(-1)
    if len(ages) != len(z):
        raise ValueError(f"{len(ages)} plot ages for {len(z)} plots")
    T, s = own.T, own.slice_s
    if t_prev > k * T + 1e-9:
        raise ValueError(f"cannot step from {t_prev:g} s back to tick {k} ({k * T:g} s)")
    if own.sector_pd is None:  # no beam: the scan at the tick, in one batch
        n, which = 1, np.zeros(len(z), dtype=np.int64)
        slices = [((k - 1) * T, k * T, k * T)]
    else:
        n, which = own.n, slice_index(ages, k, own)
        slices = [(a, a + s, a + s / 2) for a in ((k - 1) * n + np.arange(n)) * s]
    order = np.argsort(which, kind="stable")
    bounds = np.searchsorted(which[order], np.arange(n + 1))
    z = z[order]
    f = copy.copy(filt)
    f.beams = None  # the slice's Pd goes in the sensor
    births, t = filt.pending, t_prev  # queued before the tick: at the state's time
    lab = labels
    for j, (a, b, mid) in enumerate(slices):
        dt = max(mid - t, 0.0)
        nb = 0 if births is None else len(births)
        enter = None
        if j == 0 and nb:  # they entered at t_prev: predicted with the survivors
            mix = GaussianMixture.trusted(np.concatenate((mix.weights, births.weights)),
                                          np.concatenate((mix.means, births.means)),
                                          np.concatenate((mix.covs, births.covs)))
        elif nb:  # the previous slice's births, at its midpoint: they enter now
            enter = _moved(births, own, dt)
        mix = gm_predict(mix, own.motion.at(dt), own.survival_probability ** (dt / T), enter, 1)
        t = mid
        start = j * SLICE_LABEL_BASE
        if lab is not None and nb:
            lab = np.concatenate((lab, new_labels(birth_origin, k, nb, start)))
        if wide_sd is not None:
            mix, lab = drop_wide(mix, lab, wide_sd)
        pd = (np.full(len(mix), own.fixed_pd) if own.sector_pd is None
              else own.sector_pd(a, b, mix.means, mix.covs))
        f.sensors = [SensorParams(model, pd, own.clutter_intensity)]
        f.pending = None
        mix, par = f.correct_parents(mix, [z[bounds[j]:bounds[j + 1]]])
        births = f.pending
        if lab is not None:
            lab = split_duplicates(LabelledMixture(mix, lab[par]), f.extraction_threshold,
                                   origin, k, start + nb).labels
    dt = max(k * T - t, 0.0)
    mix = gm_predict(mix, own.motion.at(dt), own.survival_probability ** (dt / T), None, 1)
    filt.pending = _moved(births, own, dt)
    filt.k = k
    return mix, lab


__all__ = ["WIDE_SD", "check_filter", "drop_wide", "step_at_own_times"]
