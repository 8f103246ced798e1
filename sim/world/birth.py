"""Measurement-driven birth for the GM-PHD (``birth.model = "measurements"``): targets may
appear anywhere (recorded traffic), so births are placed at the previous scan's plots that no
existing component explains, as in the adaptive birth of Ristic, Clark, Vo & Vo, "Adaptive
target birth intensity for PHD and CPHD filters" (IEEE T-AES 48(2), 2012), simplified: a plot
is unexplained when its squared Mahalanobis distance (in x-y, plot and component covariances
added) to every predicted component heavier than :data:`HEAVY` exceeds the gate, and each such
plot gives one component of a fixed weight, zero-velocity mean at the plot, the plot's
position covariance and ``birth_speed^2`` per velocity axis. The births enter at the next
prediction (so a target's first plot never updates its own birth).

With ``beams`` (rotating radars of recorded traffic, :class:`Beam`), each component's ``Pd``
in a scan is the radar's range curve inside the sector the beam swept in that scan and 0
outside it (the update takes a ``(n,)`` ``Pd``), instead of the sensor's one number.

The filter keeps the births of its last correction (``pending``): one filter per peer, stepped
by ``correct(predict(...))`` or ``tracking.gmphd_batch.correct_parents`` (which calls
:meth:`MeasurementBirthGMPHD.correct_parents`); a peer host never stacks its steps.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import ndtr
from sensornet.tracking.gmphd import GMPHDFilter, predict, update_parents
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import RangeBearing

R50_FRACTION = 0.8
"""A radar's ``Pd`` is half its ``detection_probability`` at this fraction of ``max_range``."""
HEAVY = 0.1
"""Components lighter than this do not explain a plot away."""


@dataclass(frozen=True)
class Beam:
    """A rotating radar seen by the filter (``sim.traffic.recorded``): in the scan interval
    ``(t_(k-1), t_k]`` (``t_k = k T`` from the run's origin) its beam sweeps the compass
    azimuths from ``((t_(k-1) - phase) / period) 360`` degrees on for ``T / period`` of a turn,
    and only aircraft there can be detected, with ``Pd(r)`` falling with range as the world's
    (``sim.traffic.radar.RotatingRadar.pd`` on the horizontal range)."""

    period: float
    phase: float
    T: float
    site: tuple[float, float]
    pd: object
    """``(n,) ranges -> (n,) Pd`` (the radar's curve)."""
    margin_deg: float = 1.0
    """Sector edges widened by this (an aircraft crossing the edge between scans)."""

    def detection(self, k: int, means: np.ndarray) -> np.ndarray:
        """``(n,)`` Pd of components ``means (n, 4)`` in scan ``k``."""
        dx, dy = means[:, 0] - self.site[0], means[:, 2] - self.site[1]
        az = np.degrees(np.arctan2(dx, dy)) % 360.0
        start = (((k - 1) * self.T - self.phase) / self.period % 1.0) * 360.0
        swept = min(1.0, self.T / self.period) * 360.0
        off = (az - start + self.margin_deg) % 360.0
        inside = off <= swept + 2 * self.margin_deg
        return np.where(inside, self.pd(np.hypot(dx, dy)), 0.0)

    def sector(self, start: float, end: float, means: np.ndarray,
               covs: np.ndarray | None = None) -> np.ndarray:
        """``(n,)`` Pd of components ``means (n, 4)`` over the sector swept in ``(start,
        end]`` (seconds after the run's origin): :meth:`detection` on a one-interval clock (a
        slice of a tick, for plots taken at their own times). With ``covs (n, 4, 4)``: soft
        edges, the range curve times the probability that the component's azimuth lies in
        the sector (:func:`sector_share`), so a track whose aircraft may be just across an
        edge is not charged a full miss in one slice and denied its plot in the next."""
        if covs is None:
            return replace(self, phase=self.phase - start, T=end - start).detection(1, means)
        dx, dy = means[:, 0] - self.site[0], means[:, 2] - self.site[1]
        first = ((start - self.phase) / self.period % 1.0) * 360.0
        swept = min(1.0, (end - start) / self.period) * 360.0
        share = sector_share(dx, dy, covs[:, [0, 2]][:, :, [0, 2]], first, swept,
                             self.margin_deg)
        return share * self.pd(np.hypot(dx, dy))


def sector_share(dx: np.ndarray, dy: np.ndarray, P: np.ndarray, first: float, swept: float,
                 floor_deg: float) -> np.ndarray:
    """``(n,)`` the probability that a target at ``(dx, dy) (n,)`` from a radar (position
    covariance ``P (n, 2, 2)``) lies in the compass sector ``[first, first + swept]``
    (degrees): its azimuth linearised, ``sd^2 = g^T P g`` with ``g = (dy, -dx) / r^2`` (plus
    ``floor_deg^2``, the edge's own blur), integrated over the sector by the normal CDF, the
    nearer way round (Pd(x) integrated against the Gaussian, as Vo & Ma 2006 Sec. III-D do
    for a state-dependent Pd)."""
    r2 = np.maximum(dx * dx + dy * dy, 1.0)
    g = np.stack([dy, -dx], axis=1) / r2[:, None]  # (n, 2) d(azimuth)/d(x, y), radians
    var = np.einsum("ni,nij,nj->n", g, P, g)
    sd = np.sqrt(np.degrees(np.sqrt(var)) ** 2 + floor_deg**2)
    d = (np.degrees(np.arctan2(dx, dy)) - first + 180.0) % 360.0 - 180.0  # from the start
    inside = ndtr((swept - d) / sd) - ndtr(-d / sd)
    other = d - np.where(d >= 0, 360.0, -360.0)  # the same azimuth the other way round
    return np.maximum(inside, ndtr((swept - other) / sd) - ndtr(-other / sd))


def plots_xy(model, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plots ``z (m, 2)`` of ``model`` as x-y ``(m, 2)`` with covariances ``(m, 2, 2)``
    (range-bearing: the polar Jacobian at the plot, ``J R J^T``)."""
    z = np.asarray(z, float).reshape(-1, 2)
    if not isinstance(model, RangeBearing):  # a linear model measures [px, py]
        return z, np.broadcast_to(model.R, (len(z), 2, 2)).copy()
    r, b = z[:, 0], z[:, 1]
    c, s = np.cos(b), np.sin(b)
    xy = np.asarray(model.position, float) + r[:, None] * np.stack([c, s], 1)
    J = np.stack([np.stack([c, -r * s], 1), np.stack([s, r * c], 1)], 1)  # (m, 2, 2)
    return xy, J @ model.R @ J.transpose(0, 2, 1)


def unexplained(mix: GaussianMixture, xy: np.ndarray, R_xy: np.ndarray,
                gate: float) -> np.ndarray:
    """``(m,)`` True for plots ``xy (m, 2)`` (covariances ``R_xy (m, 2, 2)``) farther than
    ``gate`` (squared Mahalanobis, x-y) from every component of ``mix`` heavier than
    :data:`HEAVY`: one (m, n) array computation."""
    heavy = mix.weights > HEAVY
    if not heavy.any() or len(xy) == 0:
        return np.ones(len(xy), bool)
    pos = mix.means[heavy][:, [0, 2]]  # (n, 2)
    P = mix.covs[heavy][:, [0, 2]][:, :, [0, 2]]  # (n, 2, 2)
    S = P[None] + R_xy[:, None]  # (m, n, 2, 2)
    nu = xy[:, None, :] - pos[None]  # (m, n, 2)
    a, b, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
    det = a * d - b * b
    d2 = (d * nu[..., 0] ** 2 - 2 * b * nu[..., 0] * nu[..., 1] + a * nu[..., 1] ** 2) / det
    return (d2 > gate).all(axis=1)


def birth_components(xy: np.ndarray, R_xy: np.ndarray, weight: float,
                     speed: float) -> GaussianMixture:
    """One component per plot: weight ``weight``, mean ``[x, 0, y, 0]``, position covariance
    ``R_xy``, velocity variance ``speed^2`` per axis (independent)."""
    m = len(xy)
    means = np.zeros((m, 4))
    means[:, [0, 2]] = xy
    covs = np.zeros((m, 4, 4))
    covs[:, [0, 0, 2, 2], [0, 2, 0, 2]] = R_xy.reshape(m, 4)
    covs[:, 1, 1] = covs[:, 3, 3] = speed * speed
    return GaussianMixture(np.full(m, weight), means, covs)


def rotation_phase(spec) -> float:
    """A rotating sensor's phase from the run's origin: ``phase``, else a stable one from its
    name (``sim.traffic.radar``'s default), so no two default in step."""
    if spec.phase is not None:
        return float(spec.phase) % spec.rotation_period
    # heavy optional dependency: pyarrow (sim.traffic reads recorded traffic; a run without
    # rotating radars, most of them, starts 45 ms of CPU sooner without it)
    from sensornet.sim.traffic.radar import _default_phase
    return _default_phase(spec.name, spec.rotation_period)


def radar_pd(spec, r50_fraction: float = R50_FRACTION):
    """The ``Pd(range)`` curve of sensor ``spec`` (:class:`sim.traffic.radar.RotatingRadar`:
    ``detection_probability`` at short range, half of it at ``r50_fraction * max_range``,
    0 beyond ``max_range``)."""
    r_max = spec.max_range if spec.max_range is not None else math.inf
    # heavy optional dependency: pyarrow (through sim.traffic, as in rotation_phase)
    from sensornet.sim.traffic.radar import RotatingRadar
    return RotatingRadar(spec.name, 0.0, 0.0, pd_max=max(spec.detection_probability, 1e-12),
                         max_range_m=r_max, r50_m=r50_fraction * r_max).pd


def beam_of(scn, spec) -> Beam | None:
    """Sensor ``spec``'s :class:`Beam` in scenario ``scn`` (None without a rotation)."""
    if spec.rotation_period is None:
        return None
    return Beam(period=spec.rotation_period, phase=rotation_phase(spec), T=scn.scan_period,
                site=tuple(spec.position), pd=radar_pd(spec))


@dataclass
class MeasurementBirthGMPHD(GMPHDFilter):
    """A GM-PHD filter whose births are the last scan's unexplained plots (module docstring).

    ``birth`` holds the births the last prediction added (so a labelled estimator counts them,
    ``len(filter.birth)``); a correction puts its scan's births in :attr:`pending`, and the
    next prediction of at least one step makes them ``birth``."""

    birth_weight: float = 0.05
    """Weight of each birth component."""
    birth_speed: float = 200.0
    """Velocity standard deviation per axis of a birth (m/s)."""
    birth_gate: float = 13.8
    """Squared Mahalanobis distance beyond which a plot is unexplained."""
    pending: GaussianMixture | None = field(default=None, repr=False)
    """The births of the last correction, at its time (they enter at the next prediction)."""
    beams: tuple[Beam | None, ...] | None = None
    """Per sensor, its :class:`Beam` (Pd per component and scan) or None (the sensor's
    fixed ``Pd``)."""
    k: int = 0
    """The scan of the last correction (the sum of the predictions' steps)."""
    _steps: int = field(default=0, repr=False)
    stackable = False
    """A peer host never stacks its steps (``tracking.gmphd_batch.batch_key``): the births
    come from :meth:`correct_parents`."""

    def predict(self, mix: GaussianMixture, steps: int = 1) -> GaussianMixture:
        if steps >= 1 and self.pending is not None:
            self.birth, self.pending = self.pending, None
        self._steps = steps  # a step is predict then correct: its scan is k + steps
        return predict(mix, self.motion, self.survival_probability, self.birth, steps)

    def correct(self, mix: GaussianMixture, scans: Sequence[np.ndarray]) -> GaussianMixture:
        return self.correct_parents(mix, scans)[0]

    def correct_parents(self, mix: GaussianMixture, scans: Sequence[np.ndarray]
                        ) -> tuple[GaussianMixture, np.ndarray]:
        """:meth:`correct` and each posterior component's parent in ``mix`` (as
        ``tracking.gmphd_batch.correct_parents``); the scan's unexplained plots (each judged
        against the mixture before its sensor's update) become :attr:`pending`."""
        if len(scans) != len(self.sensors):
            raise ValueError(f"expected {len(self.sensors)} scans, got {len(scans)}")
        births_xy, births_R = [], []
        par = np.arange(len(mix))
        self.k += self._steps
        self._steps = 0
        beams = self.beams or (None,) * len(self.sensors)
        for sensor, scan, beam in zip(self.sensors, scans, beams, strict=True):
            if beam is not None:
                sensor = replace(sensor, detection_probability=beam.detection(self.k,
                                                                              mix.means))
            xy, R_xy = plots_xy(sensor.model, scan)
            new = unexplained(mix, xy, R_xy, self.birth_gate)
            births_xy.append(xy[new])
            births_R.append(R_xy[new])
            mix, det = update_parents(mix, scan, sensor, self.gate, self.reducer.prune_threshold)
            par = np.concatenate((par, par[det]))
            mix, src = self.reducer.with_sources(mix)
            par = par[src]
        self.pending = birth_components(np.concatenate(births_xy).reshape(-1, 2),
                                        np.concatenate(births_R).reshape(-1, 2, 2),
                                        self.birth_weight, self.birth_speed)
        return mix, par
