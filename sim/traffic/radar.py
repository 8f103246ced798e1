"""Sensors that scan recorded traffic as real ones do (issue 34, item 2): rotating radars, each
on its own clock, and ADS-B receivers.

**Rotating radar.** Rotation ``k`` starts at ``phase + k * period`` (seconds since 1970) with the
beam pointing north and turning clockwise, so an aircraft at compass azimuth ``a`` (from the
site, clockwise from north) is illuminated at ``phase + (k + a / 360) * period``: that is its
plot's time. The time is found by fixed-point iteration from mid-rotation (the aircraft moves
while the beam turns; three steps put a 250 m/s aircraft at 20 km within 0.1 ms of the beam,
each step shrinking the error by the ratio of its angular rate to the beam's); an aircraft
absent from the truth at mid-rotation or at its beam time is not seen in that rotation. The
rotation's plots are delivered together at its end, ``phase + (k + 1) * period`` (the scan
time); ``sweep=False`` makes them all at the scan time instead (a snapshot radar).

Detection: ``Pd(r) = pd_max * Pfa ** (1 / (1 + SNR(r)))`` (Swerling I target in a
square-law detector, Skolnik, Introduction to Radar Systems, 3rd ed., §2.8) with
``SNR(r) = SNR50 * (r50 / r) ** 4`` (the radar equation) and ``SNR50`` chosen so that the
Swerling factor is 1/2 at ``r50``; zero beyond ``max_range_m``. ``r`` is the slant range.
Measurements are ``[ground range, bearing]`` with Gaussian noise (``sigma_r`` metres,
``sigma_b_deg`` degrees): ground range is the horizontal distance in the common ENU frame (a
secondary radar's slant range projected with the aircraft's Mode C altitude, as the 2-D
trackers of ``tracking.models`` expect) and the bearing is ``atan2(north, east)`` in radians,
the convention of ``tracking.models.RangeBearing``. Plots are also given in ENU x-y. The
radar is taken as perfectly registered to the common frame (its own north differs from the
frame's by the meridian convergence, under 0.5 degree within 80 km of Paris, not simulated).
Clutter: a Poisson number (mean ``clutter_per_scan``) of false plots per rotation, uniform
in area over the coverage disc, each at its beam time.

**ADS-B receiver.** Every ``period_s`` (its own phase) each aircraft present within
``max_range_m`` (slant) is reported with probability ``1 - p_drop`` (independent dropouts) at
its position plus Gaussian noise ``sigma_m`` per horizontal axis, with its ``icao24``.

Every random draw comes from the ``numpy.random.Generator`` passed in. Truth comes from
:class:`sensornet.sim.traffic.opensky.Trajectories`.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np
from sensornet.sim.traffic.opensky import LocalFrame, Trajectories
from sensornet.tracking.models import LinearPosition, RangeBearing, wrap_angle

TWO_PI = 2.0 * math.pi


def _default_phase(name: str, period: float) -> float:
    """A stable phase in ``[0, period)`` from the sensor's name, so no two default in step."""
    return (zlib.crc32(name.encode()) / 2**32) * period


def _site_enu(frame: LocalFrame, lat: float, lon: float, alt_m: float) -> np.ndarray:
    return frame.to_enu(lat, lon, alt_m)


@dataclass(frozen=True)
class RadarScan:
    """One rotation's plots (``m`` of them)."""

    radar: str
    t: float
    """Scan time: the rotation's end (seconds since 1970 UTC)."""
    t_meas: np.ndarray
    """(m,) when each plot was made (the beam crossing; = ``t`` with ``sweep=False``)."""
    z_rb: np.ndarray
    """(m, 2) ``[ground range (m), bearing atan2(dn, de) (rad)]``."""
    z_xy: np.ndarray
    """(m, 2) the plots in ENU east/north (m)."""
    R_xy: np.ndarray
    """(m, 2, 2) the covariance of ``z_xy`` (range-bearing noise through the polar Jacobian
    at the plot)."""
    truth: np.ndarray
    """(m,) icao24 of the aircraft behind each plot, ``""`` for clutter (for scoring only)."""
    site: np.ndarray
    """(2,) the radar's ENU east/north."""


@dataclass(frozen=True)
class RotatingRadar:
    """A rotating surveillance radar at a geographic site (module docstring for the model).

    Defaults are a terminal radar (4.8 s rotation, 60 NM); an en-route radar turns in about
    10-12 s and reaches 250 NM.
    """

    name: str
    lat: float
    lon: float
    alt_m: float = 0.0
    period_s: float = 4.8
    phase_s: float | None = None
    """Rotations start at ``phase_s + k * period_s``; None: a stable phase from the name."""
    max_range_m: float = 111_120.0
    pd_max: float = 0.97
    r50_m: float = 90_000.0
    pfa: float = 1e-6
    sigma_r: float = 30.0
    sigma_b_deg: float = 0.1
    clutter_per_scan: float = 2.0
    sweep: bool = True
    phase: float = field(init=False)

    def __post_init__(self):
        for name in ("period_s", "max_range_m", "r50_m", "sigma_r", "sigma_b_deg"):
            if not getattr(self, name) > 0:
                raise ValueError(f"radar {self.name!r}: {name} must be positive")
        if not (0 < self.pd_max <= 1 and 0 < self.pfa < 0.5):
            raise ValueError(f"radar {self.name!r}: pd_max must be in (0, 1], pfa in (0, 0.5)")
        if not self.clutter_per_scan >= 0:
            raise ValueError(f"radar {self.name!r}: clutter_per_scan must be >= 0")
        if not abs(self.lat) <= 90 or not abs(self.lon) <= 180:
            raise ValueError(f"radar {self.name!r}: site ({self.lat}, {self.lon}) out of range")
        phase = (_default_phase(self.name, self.period_s) if self.phase_s is None
                 else float(self.phase_s) % self.period_s)
        object.__setattr__(self, "phase", phase)

    @property
    def sigma_b(self) -> float:
        """Bearing noise in radians."""
        return math.radians(self.sigma_b_deg)

    def pd(self, r: np.ndarray) -> np.ndarray:
        """Detection probability at slant range ``r (...)`` metres (module docstring)."""
        r = np.asarray(r, dtype=float)
        snr50 = math.log(self.pfa) / math.log(0.5) - 1.0
        snr = snr50 * (self.r50_m / np.maximum(r, 1e-9)) ** 4
        p = self.pd_max * np.exp(math.log(self.pfa) / (1.0 + snr))
        return np.where(r <= self.max_range_m, p, 0.0)

    def site(self, frame: LocalFrame) -> np.ndarray:
        """(3,) the site in ENU."""
        return _site_enu(frame, self.lat, self.lon, self.alt_m)

    def measurement_model(self, frame: LocalFrame) -> RangeBearing:
        """The filters' model of this radar's ``z_rb`` in ``frame``."""
        s = self.site(frame)
        return RangeBearing(sigma_r=self.sigma_r, sigma_theta=self.sigma_b,
                            position=(float(s[0]), float(s[1])))

    def rotation_starts(self, t0: float, t1: float) -> np.ndarray:
        """(K,) start times of the rotations lying wholly in ``[t0, t1]``."""
        k0 = math.ceil((t0 - self.phase) / self.period_s - 1e-9)
        k1 = math.floor((t1 - self.phase) / self.period_s + 1e-9) - 1
        return self.phase + np.arange(k0, k1 + 1) * self.period_s

    def scan_times(self, t0: float, t1: float) -> np.ndarray:
        """(K,) scan (rotation end) times in ``[t0, t1]``."""
        return self.rotation_starts(t0, t1) + self.period_s

    def scans(self, truth: Trajectories, t0: float, t1: float,
              rng: np.random.Generator) -> list[RadarScan]:
        """Every rotation in ``[t0, t1]`` (loop over rotations, vectorised over aircraft)."""
        return [self.scan(truth, s, rng) for s in self.rotation_starts(t0, t1)]

    def _beam_time(self, start: float, de: np.ndarray, dn: np.ndarray) -> np.ndarray:
        return start + (np.arctan2(de, dn) % TWO_PI) / TWO_PI * self.period_s

    def scan(self, truth: Trajectories, start: float, rng: np.random.Generator) -> RadarScan:
        """The plots of the rotation starting at ``start`` (module docstring)."""
        site = self.site(truth.frame)
        A = len(truth.ids)
        ac = np.arange(A)
        end = start + self.period_s
        if self.sweep:
            tq = np.full(A, start + 0.5 * self.period_s)
            for _ in range(3):
                s, present = truth.evaluate(ac, tq)
                tq = np.where(present, self._beam_time(start, s[:, 0] - site[0],
                                                       s[:, 1] - site[1]), tq)
            ok = present
            s, present = truth.evaluate(ac, tq)
            present &= ok
        else:
            tq = np.full(A, end)
            s, present = truth.evaluate(ac, tq)
        d = s[present, :3] - site
        slant = np.linalg.norm(d, axis=1)
        seen = rng.random(len(d)) < self.pd(slant)
        d, ids, tq = d[seen], truth.ids[present][seen], tq[present][seen]
        r = np.hypot(d[:, 0], d[:, 1]) + rng.normal(0.0, self.sigma_r, len(d))
        b = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) + rng.normal(0.0, self.sigma_b, len(d)))
        n_c = rng.poisson(self.clutter_per_scan)
        rc = self.max_range_m * np.sqrt(rng.random(n_c))
        bc = wrap_angle(rng.uniform(-math.pi, math.pi, n_c))
        tc = (self._beam_time(start, np.cos(bc), np.sin(bc)) if self.sweep
              else np.full(n_c, end))
        z_rb = np.concatenate([np.stack([r, b], 1), np.stack([rc, bc], 1)])
        order = np.argsort(np.concatenate([tq, tc]), kind="stable")
        z_rb = z_rb[order]
        t_meas = np.concatenate([tq, tc])[order]
        truth_ids = np.concatenate([ids, np.full(n_c, "", dtype=ids.dtype)])[order]
        c, sn = np.cos(z_rb[:, 1]), np.sin(z_rb[:, 1])
        z_xy = site[:2] + z_rb[:, :1] * np.stack([c, sn], 1)
        J = np.stack([np.stack([c, -z_rb[:, 0] * sn], 1), np.stack([sn, z_rb[:, 0] * c], 1)], 1)
        R_xy = J @ np.diag([self.sigma_r**2, self.sigma_b**2]) @ J.transpose(0, 2, 1)
        return RadarScan(radar=self.name, t=float(end), t_meas=t_meas, z_rb=z_rb, z_xy=z_xy,
                         R_xy=R_xy, truth=truth_ids, site=site[:2].copy())


@dataclass(frozen=True)
class AdsbScan:
    """One period's ADS-B reports (``m`` of them)."""

    receiver: str
    t: float
    z_xy: np.ndarray
    """(m, 2) reported ENU east/north (m)."""
    ids: np.ndarray
    """(m,) icao24 (ADS-B carries the identity; also the truth)."""


@dataclass(frozen=True)
class AdsbReceiver:
    """An ADS-B ground receiver (module docstring for the model)."""

    name: str
    lat: float
    lon: float
    alt_m: float = 0.0
    period_s: float = 1.0
    phase_s: float | None = None
    max_range_m: float = 250_000.0
    p_drop: float = 0.05
    sigma_m: float = 15.0
    phase: float = field(init=False)

    def __post_init__(self):
        for name in ("period_s", "max_range_m", "sigma_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"receiver {self.name!r}: {name} must be positive")
        if not 0 <= self.p_drop < 1:
            raise ValueError(f"receiver {self.name!r}: p_drop must be in [0, 1)")
        phase = (_default_phase(self.name, self.period_s) if self.phase_s is None
                 else float(self.phase_s) % self.period_s)
        object.__setattr__(self, "phase", phase)

    def measurement_model(self, frame: LocalFrame) -> LinearPosition:
        """The filters' model of this receiver's ``z_xy``."""
        s = _site_enu(frame, self.lat, self.lon, self.alt_m)
        return LinearPosition(sigma_r=self.sigma_m, position=(float(s[0]), float(s[1])))

    def scan_times(self, t0: float, t1: float) -> np.ndarray:
        """(K,) report times in ``[t0, t1]``."""
        k0 = math.ceil((t0 - self.phase) / self.period_s - 1e-9)
        k1 = math.floor((t1 - self.phase) / self.period_s + 1e-9)
        return self.phase + np.arange(k0, k1 + 1) * self.period_s

    def scans(self, truth: Trajectories, t0: float, t1: float,
              rng: np.random.Generator) -> list[AdsbScan]:
        """Every report period in ``[t0, t1]``."""
        return [self.scan(truth, t, rng) for t in self.scan_times(t0, t1)]

    def scan(self, truth: Trajectories, t: float, rng: np.random.Generator) -> AdsbScan:
        site = _site_enu(truth.frame, self.lat, self.lon, self.alt_m)
        A = len(truth.ids)
        s, present = truth.evaluate(np.arange(A), np.full(A, t))
        inside = present.copy()
        inside[present] = np.linalg.norm(s[present, :3] - site, axis=1) <= self.max_range_m
        kept = inside & (rng.random(A) >= self.p_drop)
        z = s[kept, :2] + rng.normal(0.0, self.sigma_m, (int(kept.sum()), 2))
        return AdsbScan(receiver=self.name, t=float(t), z_xy=z, ids=truth.ids[kept])


def merged(*streams: list) -> list:
    """Scans of several sensors in time order (ties: the order of ``streams``)."""
    return sorted((s for stream in streams for s in stream), key=lambda s: s.t)
