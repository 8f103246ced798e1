"""An LMB peer's plots taken at their own times within the tick (issue 34, ``lmb.time_slice``).

A rotating radar's scan at tick ``k`` holds the plots its beam made in ``(t_(k-1), t_k]``
(``t_k = k T``); taking them all as made at ``t_k`` costs 161 m rms on the Paris traffic
(docs/real-traffic.md). With their ages (the scan message's ``ages``) the peer cuts the tick
into slices of ``slice_s`` and takes each slice's plots at the slice's midpoint, as the
asynchronous centralised reference does for one radar
(``sim.studies.traffic.asynchronous.AsyncLmb``; Bar-Shalom, Willett & Tian 2011, ch. 9,
sequential updating): per slice, empty ones too (the beam swept the sector and saw nothing),
predict over the elapsed time (:class:`tracking.elapsed.ElapsedMotion`, ``Ps^(dt / T)``), correct
with the slice's plots, the ``Pd`` of the sector the beam swept in the slice (soft edges:
the range curve times the probability that the track's azimuth is in the sector,
``sim.world.birth.sector_share``) and the clutter intensity inside that sector; then predict
to ``t_k``, where the peer publishes and fuses as before. A track's confirmation counts once
per tick, at ``t_k``.

The births of a slice's plots enter at the next slice's prediction (the last slice's at
``t_k``), labelled ``(origin, k, j * SLICE_LABEL_BASE + i)`` for the ``j``-th prediction of the
tick (``j = 0``: births queued by a step at the tick, labelled as the tick filter labels
them), so labels stay unique within the tick. Births labelled alike at every peer
(``network.birth_ids = "shared"``: ``(shared, k, cell)`` of the plot) keep that label unless a
track of the tick already holds it (two plots in one cell in one tick), which then takes an
own label, as :func:`tracking.label_keys.shared_births` does within one scan.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from sensornet.tracking.elapsed import ElapsedMotion, slice_of, slices_per_tick
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import keys_isin, label_keys
from sensornet.tracking.lmb import LmbFilter, LmbState, check_scan
from sensornet.tracking.lmb_sets import LabelledBernoulliSet

SLICE_LABEL_BASE = 1 << 24
"""Label index offset per prediction within a tick (below ``peers.labelling.FRESH_BASE``,
``1 << 32``: births stay births)."""


@dataclass(frozen=True)
class OwnTimes:
    """How a peer takes its plots at their own times (module docstring)."""

    slice_s: float
    """Slice length (s); divides :attr:`T`."""
    T: float
    """The tick (s): tick ``k`` is at ``k T`` from the run's origin."""
    motion: ElapsedMotion
    survival_probability: float
    """Per tick ``T``; ``Ps^(dt / T)`` over ``dt``."""
    clutter_intensity: float
    """Inside the sector the beam sweeps (``> 0``)."""
    sector_pd: Callable[[float, float, np.ndarray, np.ndarray], np.ndarray] | None = None
    """``(start, end, means (n, 4), covs (n, 4, 4)) -> (n,)`` Pd over the sector swept in
    ``(start, end]`` (``sim.world.birth.Beam.sector``, soft edges); None: :attr:`fixed_pd`
    everywhere."""
    fixed_pd: float = 1.0

    def __post_init__(self) -> None:
        slices_per_tick(self.T, self.slice_s)
        if not self.clutter_intensity > 0:
            raise ValueError(f"OwnTimes.clutter_intensity must be > 0, got "
                             f"{self.clutter_intensity!r}")
        if not 0.0 < self.fixed_pd <= 1.0:
            raise ValueError(f"OwnTimes.fixed_pd must be in (0, 1], got {self.fixed_pd!r}")

    @property
    def n(self) -> int:
        """Slices per tick."""
        return slices_per_tick(self.T, self.slice_s)


def slice_index(ages: np.ndarray, k: int, own: OwnTimes) -> np.ndarray:
    """``(m,)`` the slice ``0 .. n-1`` of tick ``k`` of each plot of ages ``ages (m,)``
    (:func:`tracking.elapsed.slice_of` on ``k T - age``, the rule of the centralised
    reference); ValueError if an age is outside ``[0, T]``."""
    ages = np.asarray(ages, float).reshape(-1)
    if len(ages) and not (np.isfinite(ages).all() and ages.min() >= -1e-6
                          and ages.max() <= own.T + 1e-6):
        raise ValueError(f"plot ages must be in [0, {own.T:g}] s (the tick), got "
                         f"{ages.min():g}..{ages.max():g}")
    j = slice_of(k * own.T - ages, own.slice_s) - 1 - (k - 1) * own.n
    return np.clip(j, 0, own.n - 1)


def _predict(f: LmbFilter, state: LmbState, k: int, dt: float, j: int,
             own: OwnTimes) -> LmbState:
    """``state`` over ``dt`` seconds (the pending births enter), births labelled for the
    ``j``-th prediction of tick ``k``; ``state.k`` becomes ``k``."""
    f.motion = own.motion.at(max(dt, 0.0))
    f.survival_probability = own.survival_probability ** (max(dt, 0.0) / own.T)
    n0 = len(state.tracks)
    pred = f.predict(LmbState(state.tracks, state.hits, k - 1, state.pending), k)
    if j == 0 or len(pred.tracks) == n0:
        return pred
    t = pred.tracks
    labels = t.labels.copy()
    born = labels[n0:]  # a view: (origin, k, i) own, (shared, k, cell) alike at every peer
    if f.shared_origin is not None:  # a cell a track of this tick already holds: own label
        taken = born[:, 0] == f.shared_origin
        taken &= keys_isin(label_keys(born), label_keys(labels[:n0]))
        born[taken, 0] = f.origin
        born[taken, 2] = np.flatnonzero(taken)
    own = born[:, 0] == f.origin
    born[own, 2] += j * SLICE_LABEL_BASE
    return LmbState(LabelledBernoulliSet.trusted(labels, t.existence, t.weights, t.means,
                                                 t.covs, t.owner), pred.hits, k, pred.pending)


def step_at_own_times(filt: LmbFilter, state: LmbState, z: np.ndarray, ages: np.ndarray,
                      k: int, own: OwnTimes) -> LmbState:
    """The tracks after tick ``k``'s plots ``z (m, dz)`` of ages ``ages (m,)`` (s before
    ``k T``), taken slice by slice at their own times, predicted to ``k T`` (module
    docstring). ``filt`` is not changed (a copy is stepped; it shares the Gibbs stream)."""
    z = check_scan(z, filt.sensor.model.dim)
    if len(np.asarray(ages).reshape(-1)) != len(z):
        raise ValueError(f"{len(np.asarray(ages).reshape(-1))} plot ages for {len(z)} plots")
    if k <= state.k:
        raise ValueError(f"cannot step from tick {state.k} to tick {k}")
    f = copy.copy(filt)
    n, s = own.n, own.slice_s
    which = slice_index(ages, k, own)
    order = np.argsort(which, kind="stable")
    bounds = np.searchsorted(which[order], np.arange(n + 1))
    z = z[order]
    t = (k - 1) * own.T if state.k < 0 else state.k * own.T  # the state's time
    model = filt.sensor.model
    for j in range(n):
        a = ((k - 1) * n + j) * s  # the slice (a, a + s], taken at its midpoint
        mid = a + s / 2
        pred = _predict(f, state, k, mid - t, j, own)
        t = mid
        tr = pred.tracks
        top = tr.heaviest()
        pd = (np.full(len(top), own.fixed_pd) if own.sector_pd is None
              else own.sector_pd(a, a + s, tr.means[top], tr.covs[top]))
        f.sensor = SensorParams(model, pd, own.clutter_intensity)
        st = f.correct(pred, z[bounds[j]:bounds[j + 1]])
        rows = keys_isin(label_keys(tr.labels), label_keys(st.tracks.labels))
        state = LmbState(st.tracks, pred.hits[rows], k, st.pending)  # hits: once, at t_k
    state = _predict(f, state, k, k * own.T - t, n, own)
    hits = state.hits + (state.tracks.existence >= f.confirm_existence)
    return LmbState(state.tracks, hits.astype(np.int64), k, state.pending)


__all__ = ["SLICE_LABEL_BASE", "OwnTimes", "slice_index", "step_at_own_times"]
