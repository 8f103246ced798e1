"""Wire message types: plain dataclasses of the things peers, the world and tools exchange.

Times: ``k`` is the scan index (simulated time ``k T``); ``send_time`` is the sender's wall
clock (``time.time()``) at publication, for latency and age measurements.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from sensornet.tracking.mixture import GaussianMixture


@dataclass(frozen=True)
class Scan:
    """One sensor's measurements at scan ``k``: ``z (m, 2)``."""

    sensor: str
    k: int
    z: np.ndarray
    seq: int = 0
    send_time: float = 0.0
    ages: np.ndarray | None = None
    """``(m,)`` how long before the scan's time each plot was made (s, the scenario's clock,
    in ``[0, scan_period)``): a rotating radar's plots at their own times (issue 34); None:
    every plot at the scan's time (protocol 1, byte for byte as always)."""


@dataclass(frozen=True)
class Estimate:
    """A peer's Gaussian-mixture estimate at scan ``k`` and consensus round ``round``."""

    sender: str
    k: int
    mixture: GaussianMixture
    round: int = 0
    seq: int = 0
    send_time: float = 0.0
    pruning: int = 1
    """Pruning level applied before publishing: 1 (filter reduction only) or 2 (``w > W0``)."""
    kind: str = "posterior"
    """``"posterior"`` or ``"prediction"`` (single-target particle fusion needs both)."""
    labels: np.ndarray | None = None
    """``(n, 3)`` int64 component labels ``(origin, birth_scan, index)`` of a labelled
    estimator (tracking.labels), one per mixture row; None: unlabelled (protocol 1)."""
    label_masks: np.ndarray | None = None
    """``(n, W)`` int64 holder-mask words 1 and up of the labels' rows (peers.label_support:
    word 0 rides in the origin column; these name peers 40 and beyond), with ``labels``
    only; None: none (protocol 2 or 1, byte for byte as before)."""


@dataclass(frozen=True)
class Tracks:
    """A peer's extracted (fused) target states at scan ``k``: ``states (n, d)``, with optional
    identities and uncertainty (None: not sent; a protocol-1 message never has them).

    ids:       (n, 3) int64 track labels ``(origin, birth_scan, index)`` (tracking.labels).
    covs:      (n, d, d) state covariances (symmetric positive definite).
    existence: (n,) probabilities in [0, 1] (a PHD weight clipped to 1, an LMB ``r``).
    status:    (n,) int8, :data:`TENTATIVE` or :data:`CONFIRMED`.
    """

    sender: str
    k: int
    states: np.ndarray
    seq: int = 0
    send_time: float = 0.0
    ids: np.ndarray | None = None
    covs: np.ndarray | None = None
    existence: np.ndarray | None = None
    status: np.ndarray | None = None

    TENTATIVE: ClassVar[int] = 0
    CONFIRMED: ClassVar[int] = 1

    @property
    def labelled(self) -> bool:
        """Whether any optional field is set (the codec then writes protocol 2)."""
        return not (self.ids is None and self.covs is None and self.existence is None
                    and self.status is None)


@dataclass(frozen=True)
class Truth:
    """True target states at scan ``k`` (from the world): ``ids (n,)``, ``states (n, d)``."""

    k: int
    ids: np.ndarray
    states: np.ndarray
    send_time: float = 0.0


@dataclass(frozen=True)
class Control:
    """Run control: ``command`` is ``"start"``, ``"stop"`` or ``"end"``, with parameters."""

    command: str
    run_id: str = ""
    params: dict[str, str | int | float | bool] = field(default_factory=dict)
    send_time: float = 0.0


@dataclass(frozen=True)
class ScanSet:
    """Scans of one scan index by origin sensor (seed 004's flooding payload):
    ``scans[origin]`` is that sensor's ``(m, 2)`` measurements, in its own measurement space."""

    scans: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.scans)

    @property
    def points(self) -> int:
        """Measurements over all entries."""
        return sum(len(z) for z in self.scans.values())

    def tuples(self) -> int:
        """The seed's cost unit: 2 per 2-D measurement (docs/seed004.md)."""
        return 2 * self.points


@dataclass(frozen=True)
class Forward:
    """Flooding iteration ``round + 1`` of scan ``k``: the scans ``sender`` forwards (its own
    in iteration 1, then only those it had not forwarded before)."""

    sender: str
    k: int
    scans: ScanSet
    round: int = 0
    seq: int = 0
    send_time: float = 0.0
    kind: ClassVar[str] = "posterior"
    """The consensus slot it fills (flooding has one kind)."""


@dataclass(frozen=True)
class Returns:
    """Measurement sharing (seed 003): the returns ``z (m, 2)`` of ``sender``'s own scan ``k``
    that it shares for every peer's sequential update (the sensor is the sender's; its noise
    comes from the scenario). 16 bytes a return on the wire, where the same return as a
    component of a 6-D state's mixture took 224."""

    sender: str
    k: int
    z: np.ndarray
    round: int = 0
    seq: int = 0
    send_time: float = 0.0
    kind: ClassVar[str] = "returns"
    """The consensus slot it fills."""


@dataclass(frozen=True)
class Telemetry:
    """A peer's compact report of scan ``k`` for live views (``sensornet view``), never an
    input of a filter: what the Rerun health tabs show (counts, timings, component numbers,
    trust state) and a few marks no other message carries.

    values:  named scalars, ``"components/fused"`` -> 12.0 (the view plots
             ``metrics/components/<sender>/fused``; ``"age"``: ``metrics/age/<sender>``).
    events:  text lines (a neighbour joined, a trust state changed).
    points:  named ``(m, 2)`` map points (a sample of particles).
    mixture: the fused Gaussian mixture (the heaviest components), or None.
    """

    sender: str
    k: int
    values: Mapping[str, float] = field(default_factory=dict)
    events: tuple[str, ...] = ()
    points: Mapping[str, np.ndarray] = field(default_factory=dict)
    mixture: GaussianMixture | None = None
    send_time: float = 0.0


Message = Scan | Estimate | Tracks | Truth | Control | Forward | Returns | Telemetry
