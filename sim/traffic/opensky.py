"""Recorded aircraft as the truth: OpenSky state vectors loaded, filtered, placed in a local
east-north-up frame and interpolated to any time (issue 34, item 1).

Reading and checking the files (formats, fields, aliases, units, duplicates) is
:mod:`sim.traffic.opensky_files` (:func:`load_states`, re-exported here with its names); this
module selects reports (:func:`select`), places them in a frame (:class:`LocalFrame`) and
interpolates them (:func:`trajectories`, :func:`truth_at`).

Gaps: each aircraft's reports are cut into pieces wherever two consecutive reports are more
than ``max_gap_s`` apart (default 20 s: ADS-B is received about once a second, so 20 s is a
real loss of contact, not jitter). A file reporting less often (the ``traffic`` library's
samples: every 10 s) needs ``max_gap_s`` above its interval; one whose median interval is
longer than ``max_gap_s`` is refused, not read as no aircraft. An aircraft is present at time
``t`` only inside a piece of at least two reports: never extrapolated before its first report,
after its last, or across a gap. Inside a piece positions are linear in ENU between the
bracketing reports and the velocity is that segment's slope (so the truth position is the
integral of the truth velocity, and files without speed columns work the same).

A bad file or selection raises one ``ValueError`` line naming the file and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import pymap3d
from pymap3d import vincenty
from sensornet.sim.traffic.opensky_files import (
    FOOT,
    StateVectors,
    _fail,
    load_states,
    to_epoch,
)

DEFAULT_MAX_GAP_S = 20.0
"""Longest time between two reports that is still interpolated (see the module docstring)."""


@dataclass(frozen=True)
class LocalFrame:
    """A local east-north-up frame tangent to the WGS84 ellipsoid at ``(lat0, lon0, h0)``."""

    lat0: float
    lon0: float
    h0: float = 0.0

    def to_enu(self, lat, lon, h) -> np.ndarray:
        """ENU ``(..., 3)`` metres of geodetic points (degrees, metres), via ``pymap3d``."""
        e, n, u = pymap3d.geodetic2enu(np.asarray(lat, float), np.asarray(lon, float),
                                       np.asarray(h, float), self.lat0, self.lon0, self.h0)
        return np.stack(np.broadcast_arrays(e, n, u), axis=-1)

    def to_geodetic(self, enu) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Latitude, longitude (degrees) and height (metres) of ENU points ``(..., 3)``."""
        enu = np.asarray(enu, float)
        return pymap3d.enu2geodetic(enu[..., 0], enu[..., 1], enu[..., 2],
                                    self.lat0, self.lon0, self.h0)


def select(states: StateVectors, *, start: float | str | None = None,
           end: float | str | None = None,
           box: tuple[float, float, float, float] | None = None,
           centre: tuple[float, float] | None = None, radius_m: float | None = None,
           airborne_only: bool = True) -> StateVectors:
    """The reports in a time window and a region.

    ``start``/``end``: seconds since 1970 or ISO 8601 (inclusive). ``box``: ``(lat_min,
    lat_max, lon_min, lon_max)`` degrees. ``centre`` + ``radius_m``: within that geodesic
    distance (Vincenty, ``pymap3d.vincenty.vdist``) of the centre. ``airborne_only`` drops
    reports flagged on the ground. Raises ``ValueError`` if nothing is left.
    """
    keep = np.ones(len(states), bool)
    if start is not None:
        keep &= states.t >= to_epoch(start, "start")
    if end is not None:
        keep &= states.t <= to_epoch(end, "end")
    region_centre = None
    if box is not None:
        lat_min, lat_max, lon_min, lon_max = map(float, box)
        if not (lat_min < lat_max and lon_min < lon_max):
            raise ValueError(f"box: expected (lat_min, lat_max, lon_min, lon_max), got {box}")
        keep &= ((states.lat >= lat_min) & (states.lat <= lat_max)
                 & (states.lon >= lon_min) & (states.lon <= lon_max))
        region_centre = ((lat_min + lat_max) / 2, (lon_min + lon_max) / 2)
    if (centre is None) != (radius_m is None):
        raise ValueError("centre and radius_m go together")
    if centre is not None:
        if radius_m <= 0:
            raise ValueError(f"radius_m must be positive, got {radius_m}")
        idx = np.flatnonzero(keep)
        if len(idx):
            dist, _ = vincenty.vdist(centre[0], centre[1], states.lat[idx], states.lon[idx])
            keep[idx] = np.atleast_1d(dist) <= radius_m
        region_centre = (float(centre[0]), float(centre[1]))
    if airborne_only:
        keep &= ~states.onground
    if not keep.any():
        raise _fail(states.source, f"no reports left after filtering (start={start}, end={end}, "
                                   f"box={box}, centre={centre}, radius_m={radius_m}, "
                                   f"airborne_only={airborne_only})")
    return replace(states.take(keep), centre=region_centre or states.centre)


def default_frame(states: StateVectors) -> LocalFrame:
    """The frame at the centre of the selected region, else of the reports' lat/lon box, h=0."""
    if states.centre is not None:
        return LocalFrame(*states.centre, 0.0)
    return LocalFrame((states.lat.min() + states.lat.max()) / 2,
                      (states.lon.min() + states.lon.max()) / 2, 0.0)


@dataclass(frozen=True)
class TruthGrid:
    """Aircraft states at given times: ``states (T, A, 6)`` = ENU position and velocity
    ``[e, n, u, ve, vn, vu]`` (m, m/s), NaN where the aircraft is absent."""

    times: np.ndarray
    """(T,) seconds since 1970 UTC."""
    ids: np.ndarray
    """(A,) icao24 of the aircraft present at one of the times at least."""
    states: np.ndarray
    present: np.ndarray
    """(T, A) bool."""
    frame: LocalFrame

    def at(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Ids ``(n,)`` and states ``(n, 6)`` of the aircraft present at ``times[k]``."""
        m = self.present[k]
        return self.ids[m], self.states[k, m]

    def planar(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Ids ``(n,)`` and ``(n, 4)`` states ``[px, vx, py, vy]`` (tracking.models' order)."""
        ids, s = self.at(k)
        return ids, s[:, [0, 3, 1, 4]]


@dataclass(frozen=True)
class Trajectories:
    """Each aircraft's reports in one ENU frame, evaluated at any time (module docstring)."""

    frame: LocalFrame
    ids: np.ndarray
    """(A,) icao24, sorted."""
    t: np.ndarray
    """(N,) report times, sorted within each aircraft."""
    enu: np.ndarray
    """(N, 3) report positions."""
    starts: np.ndarray
    """(A + 1,) the reports of aircraft ``a`` are ``starts[a]:starts[a + 1]``."""
    max_gap_s: float = DEFAULT_MAX_GAP_S

    @property
    def span(self) -> tuple[float, float]:
        """First and last report time."""
        return float(self.t.min()), float(self.t.max())

    @cached_property
    def _gaps(self) -> np.ndarray:
        """(N,) True where segment ``k -> k + 1`` is not interpolated (gap or next aircraft)."""
        gap = np.ones(len(self.t), bool)
        gap[:-1] = np.diff(self.t) > self.max_gap_s
        gap[self.starts[1:] - 1] = True
        return gap

    @cached_property
    def _keys(self) -> tuple[float, float, np.ndarray]:
        """Origin, band width and ``(N,)`` sorted search keys: each aircraft's times live in
        their own band, so one ``searchsorted`` serves all aircraft."""
        t0 = float(self.t.min())
        width = float(self.t.max() - t0) + 2.0
        owner = np.repeat(np.arange(len(self.ids)), np.diff(self.starts))
        return t0, width, owner * width + (self.t - t0)

    def evaluate(self, aircraft: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States ``(K, 6)`` (NaN where absent) and presence ``(K,)`` of aircraft indices
        ``aircraft (K,)`` at ``times (K,)``: one vectorised search over all reports."""
        a = np.asarray(aircraft, dtype=np.intp)
        tq = np.asarray(times, dtype=float)
        out = np.full((len(a), 6), np.nan)
        n_all = len(self.t)
        if n_all < 2 or len(a) == 0:
            return out, np.zeros(len(a), bool)
        lo, hi = self.starts[a], self.starts[a + 1]
        t0, width, key = self._keys
        q = a * width + np.clip(tq - t0, -0.5, width - 1.0)
        i = np.clip(np.searchsorted(key, q, side="right") - 1, lo, np.maximum(hi - 2, lo))
        i = np.clip(i, 0, n_all - 2)
        inside = (hi - lo >= 2) & (tq >= self.t[lo]) & (tq <= self.t[np.maximum(hi - 1, lo)])
        gap = self._gaps
        back = (tq == self.t[i]) & gap[i] & (i > lo) & ~gap[np.maximum(i - 1, 0)]
        i = np.where(back, i - 1, i)
        present = inside & ~gap[i]
        dt = self.t[i + 1] - self.t[i]
        vel = (self.enu[i + 1] - self.enu[i]) / dt[:, None]
        pos = self.enu[i] + (tq - self.t[i])[:, None] * vel
        out[present] = np.concatenate([pos, vel], axis=1)[present]
        return out, present

    def grid(self, times: np.ndarray) -> TruthGrid:
        """Every aircraft at ``times (T,)``; columns are the aircraft present at least once."""
        times = np.asarray(times, dtype=float).ravel()
        A, T = len(self.ids), len(times)
        s, p = self.evaluate(np.tile(np.arange(A), T), np.repeat(times, A))
        s, p = s.reshape(T, A, 6), p.reshape(T, A)
        cols = p.any(axis=0)
        return TruthGrid(times=times, ids=self.ids[cols], states=s[:, cols], present=p[:, cols],
                         frame=self.frame)


def trajectories(states: StateVectors, frame: LocalFrame | tuple[float, ...] | None = None,
                 max_gap_s: float = DEFAULT_MAX_GAP_S, drop_stale: bool = True) -> Trajectories:
    """The reports in ENU about ``frame`` (``LocalFrame`` or ``(lat0, lon0[, h0])``; default
    :func:`default_frame`). Reports without an altitude are dropped (no 3-D position), and with
    ``drop_stale`` so is a report repeating its aircraft's previous latitude and longitude
    exactly: OpenSky repeats the last position until a new one is decoded (7 % of the airborne
    reports of the Paris file, in runs up to 311 s), a stale fix, not a stationary aircraft."""
    if not (max_gap_s > 0 and math.isfinite(max_gap_s)):
        raise ValueError(f"max_gap_s must be positive and finite, got {max_gap_s}")
    if frame is None:
        frame = default_frame(states)
    elif not isinstance(frame, LocalFrame):
        frame = LocalFrame(*map(float, frame))
    states = states.take(np.isfinite(states.alt_m))
    if len(states) == 0:
        raise _fail(states.source, "field 'altitude': no report with a position has one")
    if drop_stale:
        stale = np.zeros(len(states), bool)
        stale[1:] = ((states.icao[1:] == states.icao[:-1]) & (states.lat[1:] == states.lat[:-1])
                     & (states.lon[1:] == states.lon[:-1]))
        states = states.take(~stale)
    _check_cadence(states, float(max_gap_s))
    ids, first = np.unique(states.icao, return_index=True)  # rows are sorted by icao already
    starts = np.append(first, len(states)).astype(np.intp)
    enu = frame.to_enu(states.lat, states.lon, states.alt_m)
    return Trajectories(frame=frame, ids=ids, t=states.t, enu=enu, starts=starts,
                        max_gap_s=float(max_gap_s))


def _check_cadence(states: StateVectors, max_gap_s: float) -> None:
    """Refuse a file whose aircraft report less often than ``max_gap_s``: every consecutive
    pair would be a gap and the truth silently empty (a file resampled to one report a minute
    gave 0 aircraft at every tick with the 20 s default, which assumes ADS-B's ~1 s)."""
    same = states.icao[1:] == states.icao[:-1]
    dt = np.diff(states.t)[same]
    if len(dt) and (med := float(np.median(dt))) > max_gap_s:
        raise _fail(states.source, f"field 'timestamp': an aircraft's reports are {med:g} s "
                                   f"apart (median), more than max_gap {max_gap_s:g} s, so "
                                   f"every aircraft would be absent between them; set "
                                   f"traffic.max_gap above the file's report interval")


def truth_at(states: StateVectors, times: np.ndarray,
             frame: LocalFrame | tuple[float, ...] | None = None,
             max_gap_s: float = DEFAULT_MAX_GAP_S, drop_stale: bool = True) -> TruthGrid:
    """The aircraft at ``times (T,)`` as a dense :class:`TruthGrid` (NaN where absent)."""
    return trajectories(states, frame, max_gap_s, drop_stale).grid(times)


__all__ = ["DEFAULT_MAX_GAP_S", "FOOT", "LocalFrame", "StateVectors", "Trajectories",
           "TruthGrid", "default_frame", "load_states", "select", "to_epoch", "trajectories",
           "truth_at"]
