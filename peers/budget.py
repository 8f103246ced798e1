"""What one neighbour's estimate may cost a receiver: a size budget before decoding, a
reduction after it (issue 36 items 1-2).

A member inside its message rate can still send each estimate at the codec's limit (2,000
components, 240 kB at d = 4): every step after decoding that grows faster than linearly in
the components (the trust test's divergence over all component pairs, the merge, the fusion)
would then cost the receiver hundreds of times an honest estimate. Two bounds, both sized
from the receiver's *own* settings (it publishes at most ``J`` = its reducer's
``max_components`` components, level-2 pruned at its own threshold in round 0):

- before decoding (:class:`peers.admission.Admission`, reason ``bytes``): per member, the
  bytes of its estimates are charged to a budget of ``rate_factor`` times what the receiver
  itself would send at its limit per scan (:attr:`EstimateBudget.message_bytes` per
  message), with bursts of ``burst`` scans' worth;
- after decoding (:meth:`EstimateBudget.bound`): a round-0 estimate (every peer of a network
  publishes its round 0 level-2 pruned, peers.consensus, whatever a sender declares) or one
  declared level-2 pruned (``pruning == 2``) loses the components the receiver's own level-2
  pruning would drop (``w <= W0``: an honest sender never sends them, padding is all of
  them); any estimate
  still over ``J`` components is cut to its ``2 J`` heaviest (a linear partial sort) and
  reduced with the receiver's reducer (prune, merge, cap at ``J``), so the trust tests and
  the fusion see at most ``J`` components per neighbour, as from an honest one at its limit.

An estimate within both is passed on untouched (the same object): clean runs are unchanged.
Whatever is refused or reduced is counted per member (:meth:`EstimateBudget.counts`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace

import numpy as np
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer

MESSAGE_OVERHEAD = 256
"""Bytes of an estimate besides its components (header, names, signature trailer)."""


def row_bytes(dim: int) -> int:
    """Bytes of one packed component of dimension ``dim`` on the wire (protocol.codec:
    weight, mean, upper triangle of the covariance, float64)."""
    return 8 * (1 + dim + dim * (dim + 1) // 2)


def heaviest(weights: np.ndarray, n: int) -> np.ndarray:
    """Sorted indices of the ``n`` heaviest of ``weights`` (``(m,)``), in ``O(m)``
    (``argpartition``; ties broken arbitrarily)."""
    if len(weights) <= n:
        return np.arange(len(weights))
    return np.sort(np.argpartition(-weights, n - 1)[:n])


@dataclass
class EstimateBudget:
    """A receiver's bound on one neighbour's estimate: ``max_components`` (``J``, its
    reducer's), its state ``dim``, its level-2 threshold (None: it does not prune at level 2)
    and its ``reducer`` (None: cut to the heaviest only)."""

    max_components: int
    dim: int
    level2: float | None = None
    reducer: Reducer | None = None
    reduced: Counter = field(default_factory=Counter)
    """Estimates reduced, per sender."""
    dropped: Counter = field(default_factory=Counter)
    """Components removed by the reduction, per sender."""
    largest: Counter = field(default_factory=Counter)
    """Per sender, the most components one of its estimates carried (before reduction)."""

    def __post_init__(self) -> None:
        if self.max_components < 1:
            raise ValueError(f"max_components must be at least 1, got {self.max_components}")
        if self.dim < 1:
            raise ValueError(f"dim must be at least 1, got {self.dim}")

    @classmethod
    def of(cls, estimator) -> EstimateBudget | None:
        """The budget of a local estimator that has a reducer (GM-PHD kinds), else None
        (single-target and scan-forwarding kinds send a few components or raw scans)."""
        reducer = getattr(estimator, "reducer", None)
        if not isinstance(reducer, Reducer):
            return None
        level2 = (float(estimator.level2_threshold)
                  if getattr(estimator, "level2", False) else None)
        return cls(reducer.max_components, int(estimator.dim), level2, reducer)

    @property
    def message_bytes(self) -> int:
        """Bytes of an estimate of ``max_components`` components: the most this receiver
        would itself send in one message (the unit of the byte budget)."""
        return self.max_components * row_bytes(self.dim) + MESSAGE_OVERHEAD

    def bound(self, sender: str, mix: GaussianMixture, pruning: int,
              rnd: int = 0) -> GaussianMixture:
        """``mix`` as the trust tests and the fusion may see it (module docstring): the same
        object if nothing needs cutting, else the reduced mixture (counted for ``sender``);
        ``pruning`` and ``rnd``: the estimate's declared pruning level and its round.
        Linear in ``len(mix)`` up to the reducer's work on ``2 J`` components."""
        n = len(mix)
        self.largest[sender] = max(self.largest[sender], n)
        out = mix
        if (pruning == 2 or rnd == 0) and self.level2 is not None and n:
            keep = mix.weights > self.level2
            if not keep.all():
                out = mix.select(keep)
        J = self.max_components
        if len(out) > J:
            out = out.select(heaviest(out.weights, 2 * J))
            out = self.reducer(out) if self.reducer is not None else out
            if len(out) > J:
                out = out.select(heaviest(out.weights, J))
        if out is not mix:
            self.reduced[sender] += 1
            self.dropped[sender] += n - len(out)
        return out

    def bound_estimate(self, msg):
        """An :class:`~protocol.messages.Estimate` with its mixture bounded (:meth:`bound`);
        the message itself when nothing was cut."""
        mix = self.bound(msg.sender, msg.mixture, msg.pruning, msg.round)
        return msg if mix is msg.mixture else replace(msg, mixture=mix)

    def counts(self) -> dict:
        """Per sender: estimates reduced, components removed, the largest estimate seen."""
        return {"reduced": dict(self.reduced), "components_dropped": dict(self.dropped),
                "largest": dict(self.largest)}


__all__ = ["MESSAGE_OVERHEAD", "EstimateBudget", "heaviest", "row_bytes"]
