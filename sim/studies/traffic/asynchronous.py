"""The asynchronous centralised reference (issue 34): every radar's plots at their own times.

The tick-aligned references (:mod:`sim.studies.labelled.centralised`,
:mod:`.centralised`) take a radar's plots of ``(t_(k-1), t_k]`` as made at ``t_k``, an error
of 161 m rms on the Paris traffic (docs/real-traffic.md). Here the run is cut into slices of
``slice_s`` seconds (``T / slice_s`` an integer, so ticks are slice ends) and each radar's
plots of one slice are one batch, processed at the slice's midpoint: the filter predicts to
the batch's time and corrects with that radar alone, batches in time order (radars in the
scenario's order within a time), as an asynchronous sequential multi-sensor tracker does
(Bar-Shalom, Willett & Tian, "Tracking and Data Fusion", 2011, ch. 9, out-of-sequence-free
sequential updating). The plots are then at most ``slice_s / 2`` old or early.

Per batch the radar's ``Pd`` is :class:`sim.world.birth.Beam`'s for the slice's sector (0 for a
track whose azimuth the beam did not sweep in the slice, the range curve inside), and its
clutter intensity is the one inside the swept sector, ``clutter_rate / (pi r_max^2)``
(per rotation over the coverage disc), not the tick filters' average over the circle.

Between batches the motion is the constant-velocity model with continuous white-noise
acceleration over the elapsed time (:class:`tracking.elapsed.ElapsedMotion`; Bar-Shalom, Li &
Kirubarajan, "Estimation with Applications to Tracking and Navigation", 2001, Sec. 6.2.2).
LMB peers with ``lmb.time_slice`` take their own plots the same way
(:mod:`peers.lmb_own_times`, with soft sector edges: :attr:`AsyncLmb.soft`).

The filters are the project's: :class:`tracking.lmb.LmbFilter` (one per radar, as
:func:`sim.kinds.lmb.make_lmb_filter` builds it, sharing label origin 0) and the measurement
birth GM-PHD's pieces (:func:`tracking.gmphd.predict`, :func:`tracking.gmphd.update_parents`,
:func:`sim.world.birth.unexplained` / :func:`sim.world.birth.birth_components`, Panta's tags by
:func:`tracking.labels.split_duplicates`). Tracks are reported at every tick ``t_k`` (the
state predicted to it) as :class:`sim.studies.labelled.centralised.Extracted`; confirmation
counts a tick once, as the tick references do.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from sensornet.peers.consensus_types import ConsensusOptions
from sensornet.sim.kinds.lmb import make_lmb_filter
from sensornet.sim.kinds.own_times import sector_clutter
from sensornet.sim.scenario import Scenario
from sensornet.sim.studies.labelled.centralised import Extracted
from sensornet.sim.traffic.recorded import recorded_world, tick_plots
from sensornet.sim.world.birth import (
    Beam,
    beam_of,
    birth_components,
    plots_xy,
    unexplained,
)
from sensornet.sim.world.build import make_filter, make_reducer, sensor_params
from sensornet.tracking.elapsed import ElapsedMotion, slice_of, slices_per_tick
from sensornet.tracking.gmphd import SensorParams, update_parents
from sensornet.tracking.gmphd import predict as gmphd_predict
from sensornet.tracking.label_keys import label_keys, new_labels
from sensornet.tracking.labels import (
    Confirmation,
    LabelledMixture,
    extract_labelled,
    split_duplicates,
)
from sensornet.tracking.lmb import LmbFilter, LmbState
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer

SLICE = 0.5
"""Default slice length (s): plots at most 0.25 s from their batch's time (about 60 m at
250 m/s); chosen on the training hour (:mod:`.async_study`'s docstring)."""


@dataclass(frozen=True)
class Batch:
    """One radar's plots of one slice ``(start, end]`` (s after the run's origin), processed at
    ``t``: ``z (m, 2)`` in the radar's measurement model."""

    sensor: int
    t: float
    start: float
    end: float
    z: np.ndarray


def plot_batches(scn: Scenario, run: int, slice_s: float = SLICE) -> list[list[Batch]]:
    """Per tick ``k`` (index ``k - 1``) its batches in time order, radars in the scenario's
    order within one time: a rotating radar gives one batch per slice of ``slice_s`` (empty
    ones too: the beam swept the sector and saw nothing), at the slice's midpoint; a sensor
    without rotation one batch per tick at ``t_k`` (its snapshot)."""
    T, K = scn.scan_period, scn.num_scans
    n = slices_per_tick(T, slice_s)
    t0 = recorded_world(scn).t0
    out: list[list[Batch]] = [[] for _ in range(K)]
    for s, (spec, p) in enumerate(zip(scn.sensors, tick_plots(scn, run), strict=True)):
        if spec.rotation_period is None:
            order = np.argsort(p.tick, kind="stable")
            b = np.searchsorted(p.tick[order], np.arange(1, K + 2))
            z = p.z[order]
            for k in range(K):
                out[k].append(Batch(s, (k + 1) * T, k * T, (k + 1) * T, z[b[k]:b[k + 1]]))
            continue
        j = slice_of(p.t_meas - t0, slice_s)  # slice of each plot
        order = np.argsort(j, kind="stable")
        b = np.searchsorted(j[order], np.arange(1, K * n + 2))
        z = p.z[order]
        for i in range(K * n):
            a = i * slice_s
            out[i // n].append(Batch(s, a + slice_s / 2, a, a + slice_s, z[b[i]:b[i + 1]]))
    for bs in out:
        bs.sort(key=lambda x: (x.t, x.sensor))
    return out


def batch_pd(beam: Beam | None, fixed: float, batch: Batch, means: np.ndarray,
             covs: np.ndarray | None = None) -> np.ndarray:
    """``(n,)`` ``Pd`` of tracks at ``means (n, 4)`` in ``batch``: the beam's over the sector
    swept in ``(start, end]`` (:meth:`Beam.sector`: with ``covs (n, 4, 4)`` soft edges), else
    ``fixed``."""
    if beam is None:
        return np.full(len(means), fixed)
    return beam.sector(batch.start, batch.end, means, covs)


@dataclass
class AsyncLmb:
    """The asynchronous centralised LMB (module docstring). ``filters``: one per sensor (its
    measurement model, clutter and birth covariance), label origin 0."""

    filters: Sequence[LmbFilter]
    beams: Sequence[Beam | None]
    fixed_pd: Sequence[float]
    """Per sensor the ``Pd`` of a sensor without beam."""
    motion: ElapsedMotion
    survival_probability: float
    """Per tick ``T``; ``Ps^(dt / T)`` over ``dt``."""
    time: float = 0.0
    """Seconds after the run's origin the state refers to."""
    count: int = 0
    """Predictions so far: the ``birth_scan`` of the births' labels."""
    soft: bool = False
    """Soft sector edges (:meth:`sim.world.birth.Beam.sector` with the tracks' covariances),
    as LMB peers with ``lmb.time_slice`` take them; False: hard edges (the reference's
    published numbers)."""

    def initial(self) -> LmbState:
        self.time, self.count = 0.0, 0
        return self.filters[0].initial()

    def _predict(self, f: LmbFilter, state: LmbState, t: float) -> LmbState:
        dt = t - self.time
        if dt < -1e-9:
            raise ValueError(f"batch at {t:.3f} s is before the state's time {self.time:.3f} s")
        dt = max(dt, 0.0)
        f.motion = self.motion.at(dt)
        f.survival_probability = self.survival_probability ** (dt / self.motion.T)
        self.count += 1
        self.time = t
        return f.predict(state, self.count)

    def correct(self, state: LmbState, batch: Batch) -> LmbState:
        """Predict to the batch's time, correct with its radar alone; ``hits`` unchanged (a
        tick counts once: :meth:`tick`)."""
        f = self.filters[batch.sensor]
        pred = self._predict(f, state, batch.t)
        t = pred.tracks
        top = t.heaviest()
        pd = batch_pd(self.beams[batch.sensor], self.fixed_pd[batch.sensor], batch,
                      t.means[top], t.covs[top] if self.soft else None)
        f.sensor = SensorParams(f.sensor.model, pd, f.sensor.clutter_intensity)
        st = f.correct(pred, batch.z)
        rows = np.isin(label_keys(t.labels), label_keys(st.tracks.labels))
        return LmbState(st.tracks, pred.hits[rows], st.k, st.pending)

    def tick(self, state: LmbState, batches: Sequence[Batch], t_k: float) -> LmbState:
        """Every batch of a tick in order, then the state predicted to the tick's time ``t_k``;
        a track's hit counts once, when its ``r`` reaches the confirmation level there."""
        for b in batches:
            state = self.correct(state, b)
        f = self.filters[0]
        state = self._predict(f, state, t_k)
        hits = state.hits + (state.tracks.existence >= f.confirm_existence)
        return LmbState(state.tracks, hits.astype(np.int64), state.k, state.pending)

    def extract(self, state: LmbState) -> Extracted:
        tr = self.filters[0].extract(state)
        return Extracted(tr.states, tr.labels, tr.status)


def async_lmb(scn: Scenario, soft: bool = False) -> AsyncLmb:
    """The scenario's asynchronous centralised LMB: each sensor's LMB filter as the ``lmb``
    peer kind builds it (:func:`sim.kinds.lmb.make_lmb_filter`), with the sector's clutter
    intensity; beams from :func:`sim.world.birth.beam_of`; ``soft``: :attr:`AsyncLmb.soft`."""
    filters, beams, fixed = [], [], []
    for spec in scn.sensors:
        f = make_lmb_filter(scn, spec.name, 0)
        beam = beam_of(scn, spec)
        if beam is not None:
            f.sensor = SensorParams(f.sensor.model, f.sensor.detection_probability,
                                    sector_clutter(scn, spec.name))
        filters.append(f)
        beams.append(beam)
        fixed.append(spec.detection_probability)
    return AsyncLmb(filters, beams, fixed, ElapsedMotion(scn.scan_period, scn.sigma_w),
                    scn.survival_probability, soft=soft)


@dataclass
class AsyncGmphd:
    """The asynchronous centralised GM-PHD with tags and measurement-driven birth (module
    docstring): per batch predict (the pending births enter), correct with one radar
    (:func:`tracking.gmphd.update_parents`, the beam's ``Pd``), reduce, Panta's duplicate
    rule; confirmation once per tick."""

    sensors: Sequence[SensorParams]
    beams: Sequence[Beam | None]
    motion: ElapsedMotion
    survival_probability: float
    reducer: Reducer
    extraction_threshold: float
    extraction: str
    gate: float | None
    birth_weight: float
    birth_speed: float
    birth_gate: float
    confirmation: Confirmation
    time: float = 0.0
    count: int = 0
    pending: GaussianMixture | None = None
    soft: bool = False
    """Soft sector edges, as GM-PHD peers with ``filter.time_slice`` take them
    (:attr:`AsyncLmb.soft`); False: hard edges (the reference's published numbers)."""

    def initial(self) -> LabelledMixture:
        self.time, self.count, self.pending = 0.0, 0, None
        return LabelledMixture.empty(self.motion.dim)

    def _predict(self, lm: LabelledMixture, t: float) -> tuple[LabelledMixture, int]:
        dt = t - self.time
        if dt < -1e-9:
            raise ValueError(f"batch at {t:.3f} s is before the state's time {self.time:.3f} s")
        dt = max(dt, 0.0)
        births, self.pending = self.pending, None
        if births is not None and len(births):  # the births move with the survivors
            F, Q = self.motion.at(dt).transition(1)
            births = GaussianMixture.trusted(births.weights, births.means @ F.T,
                                             F @ births.covs @ F.T + Q)
        pred = gmphd_predict(lm.mixture, self.motion.at(dt),
                             self.survival_probability ** (dt / self.motion.T), births, 1)
        self.count += 1
        self.time = t
        nb = len(pred) - len(lm)
        return LabelledMixture(pred, np.concatenate((lm.labels, new_labels(0, self.count,
                                                                            nb)))), nb

    def correct(self, lm: LabelledMixture, batch: Batch) -> LabelledMixture:
        """Predict to the batch's time, correct with its radar (the plots no heavy component
        explains become the next prediction's births), reduce, split duplicate labels."""
        pred, nb = self._predict(lm, batch.t)
        mix = pred.mixture
        sensor = self.sensors[batch.sensor]
        beam = self.beams[batch.sensor]
        if beam is not None:
            sensor = replace(sensor, detection_probability=batch_pd(
                beam, 0.0, batch, mix.means, mix.covs if self.soft else None))
        xy, R_xy = plots_xy(sensor.model, batch.z)
        new = unexplained(mix, xy, R_xy, self.birth_gate)
        self.pending = birth_components(xy[new], R_xy[new], self.birth_weight, self.birth_speed)
        post, det = update_parents(mix, batch.z, sensor, self.gate,
                                   self.reducer.prune_threshold)
        par = np.concatenate((np.arange(len(mix)), det))
        post, src = self.reducer.with_sources(post)
        return split_duplicates(LabelledMixture(post, pred.labels[par[src]]),
                                self.extraction_threshold, 0, self.count, nb)

    def tick(self, lm: LabelledMixture, batches: Sequence[Batch], t_k: float
             ) -> LabelledMixture:
        """Every batch of a tick in order, then the mixture predicted to ``t_k`` (the last
        batch's births enter there); one confirmation count."""
        for b in batches:
            lm = self.correct(lm, b)
        lm, _ = self._predict(lm, t_k)
        self.confirmation.observe(lm)
        return lm

    def extract(self, lm: LabelledMixture) -> Extracted:
        states, labels = extract_labelled(lm, self.extraction_threshold, self.extraction)
        return Extracted(states, labels, self.confirmation.status(labels))


def async_gmphd(scn: Scenario, soft: bool = False) -> AsyncGmphd:
    """The scenario's asynchronous centralised GM-PHD (``birth.model = "measurements"``): the
    settings of :func:`sim.world.build.make_filter`, the sector's clutter intensity; ``soft``:
    :attr:`AsyncGmphd.soft`."""
    if scn.birth.model != "measurements":
        raise ValueError(f"{scn.name}: async_gmphd needs birth.model 'measurements', got "
                         f"{scn.birth.model!r}")
    f = make_filter(scn, scn.sensor_names)
    sensors, beams = [], []
    for spec in scn.sensors:
        sp, beam = sensor_params(scn, spec.name), beam_of(scn, spec)
        if beam is not None:
            sp = SensorParams(sp.model, sp.detection_probability, sector_clutter(scn, spec.name))
        else:
            sp = SensorParams(sp.model, spec.detection_probability, sp.clutter_intensity)
        sensors.append(sp)
        beams.append(beam)
    b = scn.birth
    return AsyncGmphd(sensors, beams, ElapsedMotion(scn.scan_period, scn.sigma_w),
                      scn.survival_probability, make_reducer(scn), f.extraction_threshold,
                      f.extraction, f.gate, b.measurements_weight, b.measurements_speed,
                      b.measurements_gate, Confirmation(ConsensusOptions.confirm_scans),
                      soft=soft)


def run_async(central: AsyncLmb | AsyncGmphd, batches: Sequence[Sequence[Batch]], T: float
              ) -> tuple[list[Extracted], float]:
    """Every tick's batches through ``central``: the tracks at each tick ``t_k = k T`` (index
    ``k - 1``) and the CPU seconds the filter took."""
    state = central.initial()
    out = []
    c0 = time.process_time()
    for k, bs in enumerate(batches, start=1):
        state = central.tick(state, bs, k * T)
        out.append(central.extract(state))
    return out, time.process_time() - c0


__all__ = ["SLICE", "AsyncGmphd", "AsyncLmb", "Batch", "ElapsedMotion", "async_gmphd",
           "async_lmb", "batch_pd", "plot_batches", "run_async", "sector_clutter"]
