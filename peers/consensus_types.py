"""What :class:`peers.consensus.Consensus` is configured with and keeps per scan.

:class:`ConsensusOptions` is how one peer exchanges and fuses, :class:`ConsensusStats` the
counters of its summary (with :func:`payload_tuples`, the communication cost it counts) and
:class:`ScanState` the scan being fused (its round, current density and the round waiting in
a host's batch).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sensornet.peers.batching import FusionJob
from sensornet.peers.trust_config import TrustConfig
from sensornet.protocol.messages import ScanSet
from sensornet.tracking.mixture import GaussianMixture


@dataclass(frozen=True)
class ConsensusOptions:
    """How one peer exchanges and fuses."""

    name: str
    neighbours: tuple[str, ...] = ()
    degrees: tuple[tuple[str, int], ...] = ()
    """Degree of this peer and of each neighbour (Metropolis weights)."""
    rounds: int = 1
    """Consensus rounds ``L`` per scan."""
    omega: str = "metropolis"
    """``"metropolis"`` or ``"uniform"`` weights (optimised rules live in the fuser)."""
    max_age: int | None = 5
    """Neighbour estimates older than this many scans are not fused."""
    policy: str = "nale"
    """Out-of-sequence policy: ``"nale"``, ``"drop-late"`` or ``"as-is"``."""
    feedback: bool = False
    """Use the fused density as the local filter's prior for the next scan."""
    round_deadlines: bool = False
    """One deadline per round (the scan's deadline split evenly over the rounds) instead of
    one per scan: a round then runs with what arrived by its own deadline (scans forwarded
    in rounds)."""
    trust: TrustConfig | None = None
    """Test and weight each neighbour's density before fusing it (:mod:`peers.trust`);
    None: every neighbour fused at its consensus weight."""
    confirm_scans: int = 3
    """A track's label is confirmed once a component carrying it weighed more than the
    extraction threshold in this many scans (tracking.labels.Confirmation; labelled
    estimators only)."""
    confirm_settle: int = 0
    """...and once it is this many scans old (its birth scan that far back), so an earlier id
    of the same target on its way over the graph can no longer replace it: the peer's
    eccentricity in hops (peers.labelling.settle_scans; 0: no wait)."""
    support_inputs: int = 0
    """Report a fused track only if this many of the last round's inputs hold it, or it was
    extracted in :attr:`support_scans` consecutive scans (tracking.support.SupportRule; the
    fused density is unchanged); 0: every extracted track (the rule off); -1: more than half
    of the round's inputs, at least 2 (tracking.support.MAJORITY)."""
    support_scans: int = 2
    existence_prior: float = 0.0
    """Extraction of fused tracks: a track at most :attr:`existence_young` scans old that two
    inputs or more hold weighs at least their pooled existence with this prior
    (tracking.support.pooled_weights; the fused density is unchanged); 0: off."""
    existence_young: int = 2
    existence_mature: float = 0.0
    """Extraction of fused tracks: a track older than :attr:`existence_young` scans that two
    inputs or more hold weighs at most their existences pooled about its fused weight of the
    scan before times this survival probability (tracking.mature_existence); 0: off."""
    existence_absent: float = 0.0
    """With :attr:`existence_mature`: an input holding no mass of a mature track counts in its
    pool at this existence, the inputs' publication threshold (tracking.mature_existence
    ``absent``); 0: such inputs are left out."""
    existence_own: tuple[float, float, float] = ()
    """Extraction of fused tracks, with :attr:`existence_prior`: ``(Pd, clutter intensity per
    m^2, plot noise in m)`` of this peer's own x-y sensor; a young row the pool raised and its
    own input holds none of weighs the own scan too (tracking.own_scan); empty: off."""
    existence_keep: bool = False
    """With :attr:`existence_prior`: a fused track reported the scan before is pooled at any
    age and keeps its target against a new label beside it (tracking.support.pooled_weights
    ``keep``)."""
    existence_revisit: tuple[tuple[str, float], ...] = ()
    """Extraction of fused tracks: per input (own name and neighbours') its radar's revisit
    in scans, from the shared scenario; a young track two inputs hold weighs its AA existence
    over the inputs that could have confirmed it by its age (tracking.support.revisit_weights);
    empty: off."""
    stamp_twins: int = 0
    """Fused extraction: a row whose label is at most this many scans old is held back while
    the fused density holds, or held in the last as many scans, a label of the same origin and
    index born up to as many scans earlier at the same place (a moved stamp whose first may
    still come, tracking.label_twins); 0: off."""
    id_blocks: int = 0
    """Fused tracks' reported ids: shared labels by blocks of this many scans and cells
    (tracking.stamp_blocks); 0: the labels."""
    label_hold: int = 0
    """Fused extraction: a young reported row takes an earlier id this peer reported in the
    last this many scans whose fused row lies beside it (tracking.held_ids); 0: off."""
    label_keep_scans: int = 0
    """With :attr:`label_keep`: keep the labels reported in the last this many scans, not
    only the scan before (tracking.held_ids.ReportedIds); 0: the scan before only."""
    label_support: bool = False
    """Break a tie between shared labels of one scan by how many peers stamped each
    (peers.label_support; the masks ride on the labels' origin column); False: lowest index."""
    label_reach: tuple[tuple[str, tuple[int, ...]], ...] = ()
    """Per neighbour, the mask bits it can vouch for by hops (peers.label_support.reach_masks);
    the rest of a received mask is dropped and counted; empty: masks taken unchecked."""
    label_fallback: bool = False
    """A fused row that loses the label it won to a heavier row takes the next label it was
    paired with instead of a fresh one (peers.labelling.label_fused ``fallback``)."""
    label_keep: bool = False
    """A fused row paired with a label this peer reported the scan before does not take a
    label born :attr:`confirm_settle` scans or more before it (peers.labelling.kept_first)."""

    def __post_init__(self) -> None:
        if self.rounds < 1:
            raise ValueError("consensus rounds must be at least 1")
        if self.name in self.neighbours:
            raise ValueError("a peer cannot be its own neighbour")
        if not 0.0 <= self.existence_mature <= 1.0:
            raise ValueError(f"existence_mature must be in [0, 1], got {self.existence_mature}")
        if not 0.0 <= self.existence_absent < 1.0:
            raise ValueError(f"existence_absent must be in [0, 1), got {self.existence_absent}")
        if not 0.0 <= self.existence_prior < 1.0 or self.existence_young < 0:
            raise ValueError(f"existence_prior must be in [0, 1) and existence_young >= 0, "
                             f"got {self.existence_prior} and {self.existence_young}")
        if self.label_hold < 0:
            raise ValueError(f"label_hold must be >= 0 scans, got {self.label_hold}")
        if self.label_keep_scans < 0:
            raise ValueError(f"label_keep_scans must be >= 0 scans, got {self.label_keep_scans}")
        if self.stamp_twins < 0:
            raise ValueError(f"stamp_twins must be >= 0 scans, got {self.stamp_twins}")
        if self.support_inputs < -1 or self.support_scans < 1:
            raise ValueError(f"support_inputs must be >= -1 and support_scans >= 1, got "
                             f"{self.support_inputs} and {self.support_scans}")


@dataclass
class ConsensusStats:
    """Counters reported in the summary."""

    scans: int = 0
    estimates_in: int = 0
    estimates_out: int = 0
    tuples_out: int = 0
    """Numbers published in estimates (15 per 4-D component, 2 per 2-D measurement:
    docs/seed004.md), once per publication."""
    tuples_to_neighbours: int = 0
    """The same, once per neighbour it goes to (the seed's count: a publication reaches every
    live neighbour over its own link)."""
    old_round_estimates: int = 0
    fusions: int = 0
    fused_inputs: int = 0
    deadline_fusions: int = 0
    tracks_out: int = 0
    last_fused_from: dict[str, int] = field(default_factory=dict)


@dataclass
class ScanState:
    """The scan being fused: scan ``k``, its returns ``z`` and the rounds run so far."""

    k: int
    z: np.ndarray
    round: int = 0
    current: GaussianMixture | None = None
    local: GaussianMixture | None = None
    done: bool = False
    pending: FusionJob | None = None
    """The round waiting in a host's :class:`~peers.batching.FusionBatch` (its inputs taken)."""
    labels: np.ndarray | None = None
    """``(n, 3)`` labels of :attr:`current` (a labelled estimator's: peers.labelling)."""
    local_labels: np.ndarray | None = None
    """Labels of :attr:`local`."""
    inputs: object = None
    """The last round's :class:`~peers.contracts.FusionInput` (its labels are looked up)."""
    first_inputs: object = None
    """The first round's :class:`~peers.contracts.FusionInput`: own density and the
    neighbours' own estimates, each of its peer's scans only, so their evidence is
    independent; the fused tracks' extraction rules read these (:meth:`~peers.consensus.
    Consensus._tracks`), not a later round's fused inputs, which share it."""


def payload_tuples(payload: GaussianMixture | ScanSet | np.ndarray) -> int:
    """The seed's tuples in one published payload: a ``d``-dimensional Gaussian component
    ``1 + d + d(d+1)/2`` (15 in 4-D), a 2-D measurement 2 (docs/seed004.md); an array is
    shared returns ``(m, 2)`` (:class:`~protocol.messages.Returns`)."""
    if isinstance(payload, ScanSet):
        return payload.tuples()
    if isinstance(payload, np.ndarray):
        return payload.size
    d = payload.dim
    return len(payload) * (1 + d + d * (d + 1) // 2)
