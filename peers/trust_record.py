"""One neighbour's trust record (:class:`NeighbourTrust`) and the updates that touch only it:
the offset windows and CUSUM, registration, the repeat test, the withheld-target hold
(:class:`peers.trust.Trust` runs them per scan; design: docs/trust-calibration.md)."""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np
from sensornet.peers.trust_checks import (
    cusum_directions,
    gls_offset,
    is_repeat,
    offset_chi2,
    offset_cusum,
)
from sensornet.peers.trust_config import TrustConfig
from sensornet.tracking.mixture import GaussianMixture

STATES = ("trusted", "suspect", "quarantined")
MAX_LOG = 200
"""State changes kept for the summary (a flapping neighbour cannot grow it)."""
LOW = 0.1
"""A neighbour at or under this trust counts as detected (issue 24's target)."""


def offset_limits(cfg: TrustConfig) -> tuple[float, ...]:
    """The limits of :func:`add_offset`'s values: per window of
    :attr:`TrustConfig.bias_windows` its chi-square threshold, then (with
    :attr:`TrustConfig.bias_cusum`) the CUSUM's."""
    return (*cfg.bias_thresholds, *((cfg.bias_cusum_threshold,) if cfg.bias_cusum else ()))


def alarm_limits(cfg: TrustConfig) -> tuple[float, ...]:
    """The limits of the values in :attr:`peers.trust.Trust.history`'s last field:
    :func:`offset_limits`, then (with :attr:`TrustConfig.withhold`) the withheld-target CUSUM's."""
    return (*offset_limits(cfg), *((cfg.withhold_threshold,) if cfg.withhold else ()))


def push_window(window: deque, item, n: int) -> None:
    """Add ``item`` as the newest of ``window`` (newest first), keeping the ``n`` newest: the
    per-neighbour windows are bounded whatever a neighbour sends."""
    window.appendleft(item)
    while len(window) > n:
        window.pop()


@dataclass
class NeighbourTrust:
    """One neighbour's record."""

    score: float = 0.0
    state: str = "trusted"
    streak: int = 0
    """Scans in a row under ``suspect`` while quarantined."""
    scan_max: float = 0.0
    """Largest statistic of the scan being fused."""
    last_statistic: float = float("nan")
    last_weight: float = 1.0
    first_k: int | None = None
    """The first scan it was tested at."""
    low_k: int | None = None
    """The first scan its weight was at most :data:`LOW` (detected)."""
    last_mix: GaussianMixture | None = None
    """Its last round-0 density (the repeat test) and the scan it came at."""
    last_k: int = -1
    tested: int = -1
    """The newest scan whose estimate from this neighbour was tested
    (:attr:`TrustConfig.same_scan`)."""
    offsets: deque = field(default_factory=deque)
    """The offset test's window: per scan ``(I, y)``, ``(2, 2)`` and ``(2,)``."""
    last_offset_chi2: tuple[float, ...] = ()
    """Per window of :attr:`TrustConfig.bias_windows`: the last chi-square of the offset;
    then (:attr:`TrustConfig.bias_cusum`) the offset CUSUM's value."""
    cusum: np.ndarray | None = None
    """The offset CUSUM's charts, ``(directions,)`` (:func:`peers.trust_checks.offset_cusum`)."""
    withheld: float = 0.0
    """The withheld-target CUSUM (:attr:`TrustConfig.withhold`)."""
    registered: np.ndarray | None = None
    """The position offset ``(2,)`` subtracted from its densities (:attr:`TrustConfig.register`),
    or None."""
    rounds: int = 0
    """Rounds it was tested in."""
    holds: int = 0
    """Rounds its weight was held at 0 by the withheld-target test
    (:attr:`TrustConfig.withhold_hold`) where its score alone left it above 0."""
    repairs: int = 0
    """Rounds its repaired (:attr:`TrustConfig.repair`) or registered
    (:attr:`TrustConfig.register`) density was fused in."""
    factors: deque = field(default_factory=deque)
    """Log mass factors of its repairs' last scans (:attr:`TrustConfig.repair_window`)."""
    moves: deque = field(default_factory=deque)
    """Per scan with nothing corroborated, its ``(I, y)`` against own up to
    :attr:`TrustConfig.repair_offset_gate` apart (:meth:`peers.trust.Trust._moved`)."""
    kept_k: int | None = None
    """The last scan a repair of it kept a component."""
    repaired_k: int | None = None
    """The first scan its repaired or registered density was fused at."""
    scans_in: Counter = field(default_factory=Counter)
    """Scans spent in each state."""


def add_offset(cfg: TrustConfig, rec: NeighbourTrust, info: tuple) -> tuple[float, ...]:
    """Add this scan's ``(I, y)`` (:func:`peers.trust_checks.offset_information`) to the
    neighbour's window and return, per window of :attr:`TrustConfig.bias_windows`, the
    chi-square of its mean offset (:attr:`TrustConfig.bias`)."""
    push_window(rec.offsets, info, max(cfg.bias_windows))
    chi2 = offset_chi2(rec.offsets, cfg.bias_windows)
    if cfg.bias_cusum:
        if rec.cusum is None:
            rec.cusum = np.zeros(cfg.bias_cusum_directions)
        rec.cusum = offset_cusum(rec.cusum, info, cfg.bias_cusum_offset,
                                 cusum_directions(cfg.bias_cusum_directions))
        chi2 = (*chi2, float(rec.cusum.max()))
    rec.last_offset_chi2 = chi2
    return chi2


def update_registration(rec: NeighbourTrust, alarm: bool) -> None:
    """Registration (:attr:`TrustConfig.register`): from an offset alarm on, the
    neighbour's offset is its generalised-least-squares estimate over the window kept,
    re-estimated each scan, until its CUSUM is back at 0."""
    if not alarm and (rec.registered is None
                      or (rec.cusum is not None and float(rec.cusum.max()) <= 0.0)):
        rec.registered = None
        return
    offset = gls_offset(rec.offsets)
    if offset is not None:
        rec.registered = offset


def is_repeated(cfg: TrustConfig, rec: NeighbourTrust, k: int, mix: GaussianMixture) -> bool:
    """Whether ``mix`` (round 0 of scan ``k``) repeats, bit for bit, the non-empty density
    the neighbour sent at an earlier scan (:attr:`TrustConfig.repeat`); remembers it."""
    prev, prev_k = rec.last_mix, rec.last_k
    if k <= prev_k:
        return False
    rec.last_mix, rec.last_k = mix, k
    return is_repeat(prev, mix, cfg.repeat_weight)


def is_held(cfg: TrustConfig, rec: NeighbourTrust) -> bool:
    """Whether the neighbour's withheld-target CUSUM holds its weight at 0 this scan
    (:attr:`TrustConfig.withhold_hold`; every round of the scan, as its round-0 test
    left it)."""
    return (cfg.withhold and cfg.withhold_hold is not None
            and cfg.detection_probability is not None
            and rec.withheld > cfg.withhold_hold)
