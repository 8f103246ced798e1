"""What one neighbour's estimate may cost a receiver: a size budget before decoding, a
reduction after it (issue 36 items 1-2).

A member inside its message rate can still send each estimate at the codec's limit (2,000
components, 240 kB at d = 4): every step after decoding that grows faster than linearly in
the components (the trust test's divergence over all component pairs, the merge, the fusion)
would then cost the receiver hundreds of times an honest estimate. Two bounds, both sized
from the receiver's *own* settings (it publishes at most ``J`` = its reducer's
``max_components`` components, level-2 pruned at its own threshold in round 0):

- before decoding (:class:`peers.admission.Admission`, reason ``bytes``): per member, the
  bytes of its estimates are charged to a budget of, per scan and estimate it may send, one
  estimate at the codec's component limit plus ``rate_factor`` times what the receiver
  itself would send at its own (:meth:`EstimateBudget.slot_bytes`), with bursts of
  ``burst`` scans' worth: a member that sends one estimate per scan at the codec's limit is
  let through (and reduced), one that sends its whole message rate at that size is held to
  about one and a fifth a scan (measured: refusing the padded estimate of a member that sends
  one a scan, the budget at ``rate_factor`` times ``J`` alone, left its neighbours fusing at
  the deadline on half the scans and their fused OSPA 37 % worse, where reducing it costs them
  nothing measurable: ``benchmarks/bench_padding.py``);
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
from sensornet.protocol.codec import DEFAULT_LIMITS
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer

MESSAGE_OVERHEAD = 256
"""Bytes of an estimate besides its components (header, names, signature trailer)."""


_FEW = 32
"""Up to this many components, whether level-2 pruning keeps them all is found in Python."""


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
    codec_components: int = DEFAULT_LIMITS.max_components
    """The most components the receiver's codec decodes in one estimate."""
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
    def of(cls, estimator, codec_components: int = DEFAULT_LIMITS.max_components
           ) -> EstimateBudget | None:
        """The budget of a local estimator that has a reducer (GM-PHD kinds), else None
        (single-target and scan-forwarding kinds send a few components or raw scans);
        ``codec_components``: the receiver's codec limit (``Limits.max_components``)."""
        reducer = getattr(estimator, "reducer", None)
        if not isinstance(reducer, Reducer):
            return None
        level2 = (float(estimator.level2_threshold)
                  if getattr(estimator, "level2", False) else None)
        return cls(reducer.max_components, int(estimator.dim), level2, reducer,
                   codec_components)

    @property
    def message_bytes(self) -> int:
        """Bytes of an estimate of ``max_components`` components: the most this receiver
        would itself send in one message (the unit of the byte budget)."""
        return self.max_components * row_bytes(self.dim) + MESSAGE_OVERHEAD

    def slot_bytes(self, factor: float) -> int:
        """Bytes a member may send per scan for each estimate it may send, on average: one
        at the codec's limit plus ``factor`` times :attr:`message_bytes` (the unit of
        :class:`peers.admission.Admission`'s byte budget)."""
        codec = self.codec_components * row_bytes(self.dim) + MESSAGE_OVERHEAD
        return int(codec + factor * self.message_bytes)

    def bound(self, sender: str, mix: GaussianMixture, pruning: int,
              rnd: int = 0) -> GaussianMixture:
        """``mix`` as the trust tests and the fusion may see it (module docstring): the same
        object if nothing needs cutting, else the reduced mixture (counted for ``sender``);
        ``pruning`` and ``rnd``: the estimate's declared pruning level and its round.
        Linear in ``len(mix)`` up to the reducer's work on ``2 J`` components."""
        return self._bound(sender, mix, pruning, rnd)[0]

    def _bound(self, sender: str, mix: GaussianMixture, pruning: int,
               rnd: int) -> tuple[GaussianMixture, np.ndarray | None]:
        """:meth:`bound`, and the rows of ``mix`` kept (``(m,)``) when the result is a
        selection of them (None when merged; all of them, unmade, when nothing was cut:
        the result is ``mix`` itself, every honest estimate)."""
        w = mix.weights
        n = w.shape[0]
        if self.largest.get(sender, -1) < n:  # max(largest[sender], n), as a Counter keeps it
            self.largest[sender] = n
        out, rows = mix, None
        if (pruning == 2 or rnd == 0) and self.level2 is not None and n and (
                # whether an estimate's few weights are all above W0 (an honest one's
                # are) in Python: no NumPy call for the usual answer (NaN is not above)
                n > _FEW or not all(map(float(self.level2).__lt__, w.tolist()))):
            keep = w > self.level2
            if not keep.all():
                rows = np.flatnonzero(keep)
                out = mix.select(rows)
        J = self.max_components
        if len(out) > J:
            if rows is None:
                rows = np.arange(n)
            top = heaviest(out.weights, 2 * J)
            out, rows = out.select(top), rows[top]
            if self.reducer is not None:
                out, rows = self.reducer(out), None
            if len(out) > J:
                top = heaviest(out.weights, J)
                out, rows = out.select(top), None if rows is None else rows[top]
        if out is not mix:
            self.reduced[sender] += 1
            self.dropped[sender] += n - len(out)
        return out, rows

    def bound_estimate(self, msg):
        """An :class:`~protocol.messages.Estimate` with its mixture bounded (:meth:`bound`):
        the message itself when nothing was cut; labels (protocol 2) kept for the rows kept,
        dropped where components were merged."""
        mix, rows = self._bound(msg.sender, msg.mixture, msg.pruning, msg.round)
        if mix is msg.mixture:
            return msg
        labels = getattr(msg, "labels", None)
        if labels is None:
            return replace(msg, mixture=mix)
        if rows is None or len(labels) != len(msg.mixture):
            return replace(msg, mixture=mix, labels=None, label_masks=None)
        masks = getattr(msg, "label_masks", None)
        return replace(msg, mixture=mix, labels=labels[rows],
                       label_masks=None if masks is None else masks[rows])

    def counts(self) -> dict:
        """Per sender: estimates reduced, components removed, the largest estimate seen."""
        return {"reduced": dict(self.reduced), "components_dropped": dict(self.dropped),
                "largest": dict(self.largest)}


__all__ = ["MESSAGE_OVERHEAD", "EstimateBudget", "heaviest", "row_bytes"]
