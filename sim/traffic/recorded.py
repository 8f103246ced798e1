"""The ``"recorded"`` truth model: recorded aircraft as the truth and rotating radars scanning
them, delivered on the network's common fusion clock (issue 34).

**Clock.** The run's time origin ``t_0`` is ``traffic.start``; tick ``k`` (1-based) is at
``t_k = t_0 + k T``, ``T = scenario.scan_period``, the fusion clock every peer steps on.

**Truth at tick k**: the aircraft present at ``t_k`` (``sim.traffic.opensky``: interpolated
between reports, absent over gaps longer than ``traffic.max_gap``), as ``[px, vx, py, vy]`` in
the local east-north frame about ``traffic.centre`` (the horizontal part of ENU), each with the
id ``int(icao24, 16)`` (the transponder address, stable over the run).

**Scans at tick k.** Each sensor is a :class:`sim.traffic.radar.RotatingRadar` on its own
``rotation_period`` and ``phase``; a plot is made when the beam crosses the aircraft, and the
sensor's scan at tick ``k`` holds the plots whose beam-crossing time falls in
``(t_(k-1), t_k]`` (:func:`assign_ticks`: every plot in exactly one tick), as x-y (kind
``"linear"``) or as range and bearing from the site (kind ``"range-bearing"``). A sensor
without ``rotation_period`` is a snapshot of every aircraft at ``t_k``.

**Time alignment (accepted error).** A plot is treated as made at ``t_k``, though it was made
up to one tick earlier: the aircraft has moved on by ``v (t_k - t_plot)``, up to ``v T``
(500 m for 250 m/s and ``T = 2 s``) and ``v T / 2`` on average, along its track. Without the
aircraft's velocity the world cannot move the plot (that would be using the truth), so the
tick is kept short and the filters' noise covers it: measured by :func:`alignment_errors`
(tests/test_traffic_scenario.py) and in docs/real-traffic.md. With ``lmb.time_slice`` the world
sends each plot's age with its scan (:func:`recorded_ages`, the Scan message's ``ages``), and
LMB peers take the plots at their own times instead (:mod:`peers.lmb_own_times`).

**Filters' view of a radar** (``sim.world.build.sensor_params``): in a tick of ``T`` the beam
sweeps ``T / rotation_period`` of the circle, so the per-tick detection probability is
``detection_probability x min(1, T / rotation_period)`` and clutter per tick is
``clutter_rate x min(1, T / rotation_period)`` over the coverage disc. The GM-PHD with
measurement-driven birth knows better (``sim.world.birth.Beam``): a component's ``Pd`` in
tick ``k`` is the radar's range curve inside the sector the beam swept in that tick and 0
outside, so an aircraft the beam did not pass is not counted as missed (on the Paris window
this halved the local filters' cardinality bias and took the fused OSPA from 412 to 313 m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from sensornet.sim.scenario import Scenario, ScenarioError, SensorSpec
from sensornet.sim.traffic.excerpt import EXCERPT
from sensornet.sim.traffic.opensky import (
    LocalFrame,
    Trajectories,
    TruthGrid,
    default_frame,
    load_states,
    select,
    to_epoch,
    trajectories,
)
from sensornet.sim.traffic.radar import RadarScan, RotatingRadar
from sensornet.sim.truths import TruthModel
from sensornet.sim.world import Truth, sensor_rng
from sensornet.sim.world.birth import R50_FRACTION, rotation_phase


@dataclass(frozen=True)
class RecordedWorld:
    """The traffic of a scenario: the trajectories, the tick clock and the radars."""

    trajectories: Trajectories
    t0: float
    """The time origin (seconds since 1970 UTC): tick ``k`` is at ``t0 + k T``."""
    times: np.ndarray
    """(K,) tick times ``t_1 .. t_K``."""
    grid: TruthGrid
    """The aircraft at the tick times."""
    radars: tuple[RotatingRadar, ...]
    """One per sensor, in the scenario's order."""

    @property
    def frame(self) -> LocalFrame:
        return self.trajectories.frame


def traffic_file(scn: Scenario) -> Path:
    """The scenario's state-vector file (``traffic.file``, else the shipped excerpt)."""
    spec = scn.traffic
    return Path(spec.file) if spec is not None and spec.file else EXCERPT


@lru_cache(maxsize=8)
def _trajectories(path: str, start, end, centre, radius, max_gap, airborne_only):
    states = load_states(path)
    first, last = float(states.t.min()), float(states.t.max())
    t0 = first + start if isinstance(start, float) else (
        to_epoch(start, "traffic.start") if start is not None else first)
    t1 = first + end if isinstance(end, float) else (
        to_epoch(end, "traffic.end") if end is not None else last)
    sel = select(states, start=t0 - max_gap, end=t1, centre=centre,
                 radius_m=radius, airborne_only=airborne_only)
    frame = LocalFrame(*centre, 0.0) if centre is not None else default_frame(sel)
    return trajectories(sel, frame, max_gap_s=max_gap), t0, t1


def radar_of(scn: Scenario, spec: SensorSpec, frame: LocalFrame, t0: float) -> RotatingRadar:
    """Sensor ``spec`` as a rotating radar (a snapshot at each tick without a rotation)."""
    if spec.site is not None:
        lat, lon = spec.site
    else:
        lat, lon, _ = frame.to_geodetic(np.array([*spec.position, 0.0]))
    T = scn.scan_period
    sweep = spec.rotation_period is not None
    period = spec.rotation_period if sweep else T
    phase = t0 + (rotation_phase(spec) if sweep else 0.0)
    rng_max = spec.max_range if spec.max_range is not None else math.inf
    return RotatingRadar(
        name=spec.name, lat=float(lat), lon=float(lon), period_s=period, phase_s=phase,
        max_range_m=rng_max, pd_max=max(spec.detection_probability, 1e-12),
        r50_m=R50_FRACTION * rng_max, sigma_r=max(spec.sigma_r, 1e-9),
        sigma_b_deg=max(spec.sigma_theta_deg or 0.0, 1e-9),
        clutter_per_scan=spec.clutter_rate, sweep=sweep)


@lru_cache(maxsize=4)
def recorded_world(scn: Scenario) -> RecordedWorld:
    """The scenario's traffic, tick clock and radars (cached: every peer of a twin asks)."""
    t = scn.traffic
    if t is None:
        raise ScenarioError(f"{scn.name}: truth 'recorded' needs a [traffic] table")
    path = traffic_file(scn)
    try:
        traj, t0, t1 = _trajectories(str(path), t.start, t.end, t.centre, t.radius, t.max_gap,
                                     t.airborne_only)
    except ScenarioError:
        raise
    except ValueError as e:  # the loader's one line (file and field): the user's to fix
        raise ScenarioError(f"{scn.name}: [traffic] {e}") from None
    K, T = scn.num_scans, scn.scan_period
    if t0 + K * T > t1 + 1e-6:
        raise ScenarioError(
            f"{scn.name}: scenario.num_scans = {K} ticks of {T:g} s run {K * T:g} s past "
            f"traffic.start, beyond the reports read ({t1 - t0:.0f} s; traffic.end or the "
            f"file's last report)")
    times = t0 + T * np.arange(1, K + 1)
    radars = tuple(radar_of(scn, s, traj.frame, t0) for s in scn.sensors)
    return RecordedWorld(trajectories=traj, t0=t0, times=times, grid=traj.grid(times),
                         radars=radars)


def truth_ids(icao: np.ndarray) -> np.ndarray:
    """``(n,)`` int64 ids of icao24 addresses (``int(icao24, 16)``: stable, unique)."""
    return np.array([int(a, 16) for a in icao], dtype=np.int64)


def recorded_truth(scn: Scenario, rng: np.random.Generator | None = None) -> Truth:
    """The aircraft at each tick (module docstring); no random draw."""
    grid = recorded_world(scn).grid
    states, ids = [], []
    for k in range(len(grid.times)):
        icao, x = grid.planar(k)
        states.append(np.ascontiguousarray(x))
        ids.append(truth_ids(icao))
    return Truth(states=states, ids=ids)


def assign_ticks(t_meas: np.ndarray, t0: float, T: float) -> np.ndarray:
    """``(m,)`` the tick ``k`` whose interval ``(t0 + (k-1) T, t0 + k T]`` holds each plot
    time ``t_meas (m,)``."""
    # a snapshot's plot time and its tick's time are computed apart: within 1e-9 T is "at"
    return np.ceil((np.asarray(t_meas, float) - t0) / T - 1e-9).astype(np.int64)


def radar_rotations(scn: Scenario, run: int) -> list[list[RadarScan]]:
    """Every sensor's rotations overlapping ``(t_0, t_K]`` (its own stream,
    :func:`sim.world.sensor_rng`)."""
    w = recorded_world(scn)
    out = []
    for spec, radar in zip(scn.sensors, w.radars, strict=True):
        rng = sensor_rng(scn, run, spec.name)
        out.append(radar.scans(w.trajectories, w.t0 - radar.period_s,
                               float(w.times[-1]) + radar.period_s, rng))
    return out


@dataclass(frozen=True)
class TickPlots:
    """One sensor's plots over the run, each with its tick (``m`` plots in time order)."""

    tick: np.ndarray
    """(m,) 1-based tick."""
    t_meas: np.ndarray
    """(m,) beam-crossing time."""
    z: np.ndarray
    """(m, 2) the measurement in the sensor's kind (x-y or range-bearing)."""
    z_xy: np.ndarray
    """(m, 2) the plot in the local frame."""
    truth: np.ndarray
    """(m,) icao24 behind the plot, ``""`` for clutter."""


def tick_plots(scn: Scenario, run: int) -> list[TickPlots]:
    """Each sensor's plots in ``(t_0, t_K]`` with their ticks."""
    w = recorded_world(scn)
    T, K = scn.scan_period, scn.num_scans
    out = []
    for spec, rotations in zip(scn.sensors, radar_rotations(scn, run), strict=True):
        if rotations:
            t, z_rb, z_xy, truth = (np.concatenate([getattr(r, f) for r in rotations])
                                    for f in ("t_meas", "z_rb", "z_xy", "truth"))
        else:
            t, z_rb, z_xy, truth = np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2)), \
                np.zeros(0, str)
        k = assign_ticks(t, w.t0, T)
        keep = (k >= 1) & (k <= K)
        z = z_xy if spec.kind == "linear" else z_rb
        out.append(TickPlots(tick=k[keep], t_meas=t[keep], z=z[keep].reshape(-1, 2),
                             z_xy=z_xy[keep].reshape(-1, 2), truth=truth[keep]))
    return out


def _per_tick(p: TickPlots, rows: np.ndarray, K: int) -> list[np.ndarray]:
    """``rows`` (one per plot of ``p``) split by tick: ``out[k-1]`` in the plots' order."""
    order = np.argsort(p.tick, kind="stable")
    bounds = np.searchsorted(p.tick[order], np.arange(1, K + 2))
    rows = rows[order]
    return [rows[bounds[k]:bounds[k + 1]] for k in range(K)]


def recorded_run(scn: Scenario, run: int) -> tuple[Truth, list[list[np.ndarray]]]:
    """Truth and every sensor's scan per tick: ``scans[s][k-1]`` is ``(m, 2)``."""
    K = scn.num_scans
    scans = [_per_tick(p, p.z, K) for p in tick_plots(scn, run)]
    return recorded_truth(scn), scans


def recorded_ages(scn: Scenario, run: int) -> list[list[np.ndarray]]:
    """``ages[s][k-1]`` ``(m,)``: how long before ``t_k`` each plot of :func:`recorded_run`'s
    ``scans[s][k-1]`` was made (s, in ``[0, T)``): its beam crossing's time, which the world
    sends with the scan for peers that take plots at their own times (``lmb.time_slice``)."""
    w, K, T = recorded_world(scn), scn.num_scans, scn.scan_period
    return [_per_tick(p, p.tick * T - (p.t_meas - w.t0), K) for p in tick_plots(scn, run)]


def alignment_errors(scn: Scenario, run: int = 0) -> np.ndarray:
    """``(m,)`` for every aircraft plot of the run, how far the aircraft is at its tick's time
    from where it was at the plot's time (m): the error of treating the plot as made at
    ``t_k`` (module docstring); NaN where the aircraft is absent at ``t_k``."""
    w = recorded_world(scn)
    index = {a: i for i, a in enumerate(w.trajectories.ids)}
    out = []
    for p in tick_plots(scn, run):
        real = p.truth != ""
        a = np.array([index[x] for x in p.truth[real]], dtype=np.intp)
        at_plot, _ = w.trajectories.evaluate(a, p.t_meas[real])
        at_tick, _ = w.trajectories.evaluate(a, w.t0 + p.tick[real] * scn.scan_period)
        out.append(np.linalg.norm(at_tick[:, :2] - at_plot[:, :2], axis=1))
    return np.concatenate(out) if out else np.zeros(0)


RECORDED = TruthModel("recorded", "recorded aircraft ([traffic]) under rotating radars on their "
                                  "own clocks, fused on the common tick", recorded_truth,
                      run=recorded_run, ages=recorded_ages)
