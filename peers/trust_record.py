"""One neighbour's trust record (:class:`NeighbourTrust`) and the updates that touch only it:
the offset windows and CUSUM, registration, the repeat test, the withheld-target hold
(:class:`peers.trust.Trust` runs them per scan; design: docs/trust-calibration.md)."""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Generator
from dataclasses import dataclass, field

import numpy as np
from sensornet.peers.trust_checks import (
    cusum_directions,
    gls_offset,
    gls_trend,
    is_repeat,
    offset_chi2,
    offset_cusum,
    run_alone,
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
    stacked: tuple | None = None
    """:attr:`offsets` as arrays and the entry they are newest of (:func:`stacked_window`)."""
    last_offset_chi2: tuple[float, ...] = ()
    """Per window of :attr:`TrustConfig.bias_windows`: the last chi-square of the offset;
    then (:attr:`TrustConfig.bias_cusum`) the offset CUSUM's value."""
    cusum: np.ndarray | None = None
    """The offset CUSUM's charts, ``(directions,)`` (:func:`peers.trust_checks.offset_cusum`)."""
    withheld: float = 0.0
    """The withheld-target CUSUM (:attr:`TrustConfig.withhold`)."""
    registered: np.ndarray | None = None
    """The position offset ``(2,)`` subtracted from its densities (:attr:`TrustConfig.register`),
    or None: at scan :attr:`registered_k`, growing by :attr:`registered_rate` per scan."""
    registered_rate: np.ndarray | None = None
    """The registered offset's rate ``(2,)`` m/scan (:attr:`TrustConfig.register_drift`)."""
    registered_k: int = 0
    """The scan :attr:`registered` is the offset at."""
    drift_window: deque = field(default_factory=deque)
    """Per tested scan ``(I, y)`` of its offset, the last :attr:`TrustConfig.register_window`
    (what :attr:`TrustConfig.register_drift` fits)."""
    residuals: deque = field(default_factory=deque)
    """Per tested scan, ``(I, y)`` of what is left after the registered offset
    (:attr:`TrustConfig.readmit_offset`; the raw offsets when none is registered)."""
    moved: np.ndarray | None = None
    """The last offset ``(2,)`` a repair subtracted (:meth:`peers.trust.Trust._moved`)."""
    raw_offset: np.ndarray | None = None
    """Its last tested scan's offset ``I^-1 y`` ``(2,)`` (None: nothing matched), kept
    where :attr:`peers.trust.Trust.trace` is on (the trace's alone)."""
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
    if cfg.register and cfg.register_drift:
        push_window(rec.drift_window, info, cfg.register_window)
    chi2 = offset_chi2(rec.offsets, cfg.bias_windows)
    if cfg.bias_cusum:
        if rec.cusum is None:
            rec.cusum = np.zeros(cfg.bias_cusum_directions)
        rec.cusum = offset_cusum(rec.cusum, info, cfg.bias_cusum_offset,
                                 cusum_directions(cfg.bias_cusum_directions))
        chi2 = (*chi2, float(rec.cusum.max()))
    rec.last_offset_chi2 = chi2
    return chi2


def add_offsets(cfg: TrustConfig, recs: list[NeighbourTrust], infos: list[tuple]
                ) -> list[tuple[float, ...]]:
    """:func:`add_offset` of several neighbours at once, the same windows and numbers (their
    chi-squares in one batch, :func:`peers.trust_checks.offset_chi2_many`)."""
    return run_alone(add_offsets_steps(cfg, recs, infos))


def add_offsets_steps(cfg: TrustConfig, recs: list[NeighbourTrust], infos: list[tuple]
                      ) -> Generator:
    """:func:`add_offsets` as requests (``"chi2"``, ``"cusums"``:
    :func:`peers.trust_checks.run_alone`), so that a host computes its peers' at once."""
    for rec, info in zip(recs, infos, strict=True):
        push_window(rec.offsets, info, max(cfg.bias_windows))
        if cfg.register and cfg.register_drift:
            push_window(rec.drift_window, info, cfg.register_window)
    out = yield ("chi2", [stacked_window(rec) for rec in recs], cfg.bias_windows)
    if cfg.bias_cusum and recs:  # every chart in one batch (offset_cusums)
        m = cfg.bias_cusum_directions
        G = yield ("cusums", np.array([np.zeros(m) if rec.cusum is None else rec.cusum
                                       for rec in recs]), list(infos), cfg.bias_cusum_offset,
                   cusum_directions(m))
        tops = G.max(axis=1).tolist()  # every chart's at once (float(g.max()) each)
        for i, (rec, g) in enumerate(zip(recs, G, strict=True)):
            rec.cusum = g
            out[i] = (*out[i], tops[i])
    for rec, chi2 in zip(recs, out, strict=True):
        rec.last_offset_chi2 = chi2
    return out


def stacked_window(rec: NeighbourTrust) -> tuple[np.ndarray, np.ndarray]:
    """The offset test's window (:attr:`NeighbourTrust.offsets`) as arrays, newest first:
    ``I`` (``(n, 2, 2)``) and ``y`` (``(n, 2)``), the same values. The window just pushed
    to is the one before with its newest scan in front, so it is made from the arrays kept
    of that one (:attr:`NeighbourTrust.stacked`: their newest entry is the window's
    second), or anew where they are not (another push came between)."""
    w = rec.offsets
    kept = rec.stacked
    if kept is not None and len(w) >= 2 and kept[2] is w[1]:
        n = len(w)  # the newest in front of the kept ones (np.concatenate's values)
        I, y = np.empty((n, 2, 2)), np.empty((n, 2))
        I[0], y[0] = w[0]
        I[1:], y[1:] = kept[0][:n - 1], kept[1][:n - 1]
    else:
        I, y = np.array([i for i, _ in w]), np.array([v for _, v in w])
    rec.stacked = (I, y, w[0])
    return I, y


def update_registration(rec: NeighbourTrust, alarm: bool, k: int = 0,
                        drift: bool = False, drift_chi2: float = 0.0) -> None:
    """Registration (:attr:`TrustConfig.register`): from an offset alarm on, the
    neighbour's offset is its generalised-least-squares estimate over the window kept,
    re-estimated each scan (``k``), until its CUSUM is back at 0. ``drift``
    (:attr:`TrustConfig.register_drift`): the offset and its rate at ``k``
    (:func:`peers.trust_checks.gls_trend`) where the rate's chi-square is above
    ``drift_chi2``, else the window's mean."""
    if not alarm and (rec.registered is None
                      or (rec.cusum is not None and float(rec.cusum.max()) <= 0.0)):
        rec.registered, rec.registered_rate = None, None
        return
    fit = gls_trend(rec.drift_window or rec.offsets) if drift else None
    if fit is not None and fit[2] > drift_chi2:
        rec.registered, rec.registered_rate, _ = fit
        rec.registered_k = k
        return
    offset = gls_offset(rec.offsets)
    if offset is not None:
        rec.registered, rec.registered_rate, rec.registered_k = offset, None, k


def registered_at(rec: NeighbourTrust, k: int) -> np.ndarray | None:
    """The neighbour's registered offset ``(2,)`` predicted to scan ``k`` (None: none)."""
    if rec.registered is None:
        return None
    if rec.registered_rate is None:
        return rec.registered
    return rec.registered + rec.registered_rate * (k - rec.registered_k)


def residual_passes(cfg: TrustConfig, rec: NeighbourTrust) -> bool:
    """Whether the neighbour's residual offset (:attr:`NeighbourTrust.residuals`) is under
    every window's threshold of :attr:`TrustConfig.bias_thresholds` (true with no
    window yet: nothing to hold it out on)."""
    if not rec.residuals:
        return True
    chi2 = offset_chi2(rec.residuals, cfg.bias_windows)
    return all(c <= t for c, t in zip(chi2, cfg.bias_thresholds, strict=True))


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
