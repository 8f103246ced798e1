"""What goes into and out of the sans-I/O peer (:class:`peers.core.PeerCore`).

:class:`CoreConfig` is one peer's clock and bounds; :class:`Publish`, :class:`Record` and
:class:`Stop` are the outputs its entry points return for a driver to carry out.
"""

from __future__ import annotations

from dataclasses import dataclass

from sensornet.protocol.codec import DEFAULT_LIMITS, Limits
from sensornet.protocol.messages import Estimate, Forward, Returns, Tracks


@dataclass(frozen=True)
class Publish:
    """Put ``payload`` on this peer's ``channel`` key (``"estimate"`` or ``"tracks"``)."""

    channel: str
    k: int
    payload: bytes
    message: Estimate | Forward | Returns | Tracks


@dataclass(frozen=True)
class Record:
    """Something to log or measure (Rerun, latency breakdown); ``values`` are plain data."""

    kind: str
    k: int
    values: dict


@dataclass(frozen=True)
class Stop:
    """The run is over for this peer."""

    reason: str


Output = Publish | Record | Stop


WORLD_GRACE_SCANS = 8
WORLD_GRACE_MIN = 3.0


@dataclass(frozen=True)
class CoreConfig:
    """Clock and bounds of one peer (the filter and fusion settings live in its parts)."""

    name: str
    sensor: str
    network: str
    interval: float = 1.0
    """Seconds between scans on the driver's clock."""
    deadline: float = 0.5
    """Fusion deadline after a scan arrives, as a fraction of ``interval``."""
    horizon: int = 5
    """Scans ahead of the newest accepted scan that a message may be stamped with."""
    quiet: float = 3.0
    """Intervals without an accepted scan after which a scan outside the horizon is taken as
    a new start of the scan numbering (a late join, a restarted world)."""
    last_scan: int | None = None
    """The run's last scan index (the scenario's ``num_scans``), or None if open-ended. A scan
    stamped after it is refused as ``future`` even after a quiet spell: a restarted world
    numbers within the run, so such a scan is forged (in plain mode anyone can put one) and,
    followed as a new numbering, would leave the peer refusing every real scan as stale."""
    rate_factor: float = 4.0
    """Messages per sender allowed per scan, as a multiple of what an honest one sends."""
    world_grace: float | None = None
    """Seconds a peer waits for the world's liveliness token to come back before the run is
    over for it (0: at once; None: :meth:`grace`'s default). A router restart, a peer frozen
    past the lease or a partition from the world takes the token away for a while: the world
    back within the grace is an outage (``world_outages``), not the end. A world that sent
    ``ctl`` "end" first has ended the run: its leaving stops the peer at once, grace or not."""
    limits: Limits = DEFAULT_LIMITS

    def grace(self) -> float:
        """:attr:`world_grace`, by default :data:`WORLD_GRACE_SCANS` scan intervals and at
        least :data:`WORLD_GRACE_MIN` seconds (a frozen peer relinks after Zenoh's connect
        retry, about a second, whatever the scan rate)."""
        if self.world_grace is not None:
            return self.world_grace
        return max(WORLD_GRACE_SCANS * self.interval, WORLD_GRACE_MIN)
