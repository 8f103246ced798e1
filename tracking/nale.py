"""Newest-available-local-estimate (NALE) buffer for out-of-sequence estimates (seed 000 §3.2).

Per neighbour the buffer keeps only the newest estimate received, stamped with its scan index
``kappa_i``. An estimate stamped ``a <= kappa_i`` is redundant and dropped. At fusion time ``k``
each stored estimate is predicted from ``kappa_i`` to ``k`` (multi-step model plus the births
once) unless it is older than ``max_age`` scans. Two naive policies are offered for comparison
(docs/algorithms.md "NALE"): ``"drop-late"`` uses only estimates stamped exactly ``k``;
``"as-is"`` uses the newest estimate without predicting it.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field

from sensornet.tracking.mixture import GaussianMixture

POLICIES = ("nale", "drop-late", "as-is")
Predictor = Callable[[GaussianMixture, int], GaussianMixture]


@dataclass
class NaleCounts:
    """What happened to the estimates offered to a buffer."""

    accepted: int = 0
    """Estimates that became the newest for their sender."""
    redundant: int = 0
    """Estimates not newer than the stored one (dropped on arrival)."""
    late: int = 0
    """Estimates used at a fusion time later than their own stamp."""
    too_old: int = 0
    """Stored estimates skipped at fusion because they were older than ``max_age``."""
    dropped_late: int = 0
    """Stored estimates skipped by the drop-late policy."""


@dataclass
class NaleBuffer:
    """Newest estimate per neighbour, with the policy that turns it into fusion inputs."""

    max_age: int | None = None
    """Estimates more than this many scans old are not fused (``None``: no limit)."""
    policy: str = "nale"
    """``"nale"`` (default), ``"drop-late"`` or ``"as-is"``."""
    stored: dict[Hashable, tuple[int, GaussianMixture]] = field(default_factory=dict)
    counts: NaleCounts = field(default_factory=NaleCounts)

    def __post_init__(self) -> None:
        if self.policy not in POLICIES:
            raise ValueError(f"unknown out-of-sequence policy {self.policy!r}; expected {POLICIES}")

    def offer(self, sender: Hashable, k: int, estimate: GaussianMixture) -> bool:
        """Store ``estimate`` stamped ``k`` from ``sender`` if it is the newest; True if kept."""
        held = self.stored.get(sender)
        if held is not None and k <= held[0]:
            self.counts.redundant += 1
            return False
        self.stored[sender] = (int(k), estimate)
        self.counts.accepted += 1
        return True

    def forget(self, sender: Hashable) -> None:
        """Drop whatever is stored for ``sender`` (a peer that left)."""
        self.stored.pop(sender, None)

    def ages(self, k: int) -> dict[Hashable, int]:
        """Age in scans of each stored estimate at fusion time ``k``."""
        return {s: k - a for s, (a, _) in self.stored.items()}

    def collect(self, k: int, predictor: Predictor) -> dict[Hashable, GaussianMixture]:
        """The fusion inputs at scan ``k``: sender -> estimate, per the policy.

        Estimates stamped after ``k`` are kept for a later fusion and not used now.
        """
        out: dict[Hashable, GaussianMixture] = {}
        for sender, (a, est) in self.stored.items():
            age = k - a
            if age < 0:
                continue
            if self.max_age is not None and age > self.max_age:
                self.counts.too_old += 1
                continue
            if age > 0:
                if self.policy == "drop-late":
                    self.counts.dropped_late += 1
                    continue
                self.counts.late += 1
                if self.policy == "nale":
                    est = predictor(est, age)
            out[sender] = est
        return out
