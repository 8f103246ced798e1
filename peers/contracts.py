"""The two small parts a peer is built from: a local estimator and a fuser.

In the spirit of Stone Soup's Predictor / Updater / Reducer split, but on arrays: a
:class:`LocalEstimator` turns this peer's own scans into a density it publishes; a
:class:`Fuser` combines that density with the neighbours' into the fused density the peer's
tracks come from. :class:`peers.consensus.Consensus` drives any pair of them (consensus rounds,
out-of-sequence buffer, deadlines), and :class:`peers.core.PeerCore` puts bytes, bounds and
counters around it. A new estimator plugs in by implementing these methods; nothing else in
the peer changes (docs/architecture.md has a ten-line example).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Protocol, runtime_checkable

import numpy as np
from sensornet.tracking.mixture import GaussianMixture


@dataclass(frozen=True)
class LocalOutput:
    """What one local step produced."""

    density: GaussianMixture
    """The estimator's full local density after the scan (for display)."""
    published: Mapping[str, GaussianMixture]
    """What neighbours receive, by estimate kind (``"posterior"``, ``"prediction"``, ...);
    ``published["posterior"]`` is also this peer's own input to the first consensus round."""
    info: Mapping[str, float] = field(default_factory=dict)
    """Numbers for the records (e.g. components before pruning)."""
    labels: Mapping[str, np.ndarray] | None = None
    """A labelled estimator's ``(n, 3)`` int64 labels of each published density's rows, by
    kind (tracking.labels); None: unlabelled."""
    density_labels: np.ndarray | None = None
    """The labels of :attr:`density`'s rows (its local tracks' ids), or None."""


@runtime_checkable
class LocalEstimator(Protocol):
    """A local filter fed with this peer's own scans."""

    dim: int
    """State dimension of every density it publishes (and accepts from neighbours)."""
    kinds: tuple[str, ...]
    """Estimate kinds it publishes per scan (first is ``"posterior"``)."""
    position_index: tuple[int, int]
    """Columns of (x, y) in the state (for scoring and display)."""

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        """Predict ``steps`` scans ahead (>= 1) and update with the scan ``z (m, 2)``."""
        ...

    def predict(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        """Predict a (neighbour's) density ``steps`` scans ahead (out-of-sequence estimates)."""
        ...

    def extract(self, mix: GaussianMixture) -> np.ndarray:
        """Target state estimates ``(n, dim)`` from a (fused) density."""
        ...

    def adopt(self, fused: GaussianMixture) -> None:
        """Use a fused density as the next scan's prior (feedback); may do nothing."""
        ...


@dataclass(frozen=True)
class FusionInput:
    """One consensus round's inputs, as the fuser sees them."""

    k: int
    """Scan index."""
    round: int
    """0 for the first round (local densities), l for round l + 1."""
    own: GaussianMixture
    """This peer's density entering the round (its published posterior in round 0)."""
    neighbours: Mapping[str, Mapping[str, GaussianMixture]]
    """Per neighbour present, its densities by kind."""
    weights: Sequence[float]
    """Fusion weights for ``[own, *sorted(neighbours)]`` (sum 1)."""
    z: np.ndarray
    """This peer's own scan ``(m, 2)`` (fusers that re-run a filter need it)."""


@runtime_checkable
class Fuser(Protocol):
    """Combines this peer's density with its neighbours' (GCI, AA, particle ratio, none)."""

    kinds: tuple[str, ...]
    """Estimate kinds needed from each neighbour before a round can run."""
    max_rounds: int
    """Consensus rounds it supports per scan (1 for the single-target fusers)."""

    def fuse(self, inp: FusionInput) -> GaussianMixture:
        """The fused density of one round (never raises on well-formed, compatible inputs)."""
        ...


def _nothing(*_args: Any) -> None:
    return None


class _Hooks:
    """Optional hooks of a part, each declared below with its default, read off the part once
    when a peer is built: the core, the consensus and the observer then call them without
    probing the part (a part declares a hook by having an attribute of its name)."""

    @classmethod
    def of(cls, part: object):
        return cls(**{f.name: getattr(part, f.name) for f in fields(cls)
                      if getattr(part, f.name, None) is not None})


@dataclass(frozen=True)
class EstimatorHooks(_Hooks):
    """What a :class:`LocalEstimator` may add to its four methods."""

    payload: str = "mixture"
    """What it exchanges: ``"mixture"`` (:class:`~protocol.messages.Estimate`) or ``"scans"``
    (raw scans in :class:`~protocol.messages.Forward` messages)."""
    plane: Callable[[Any], np.ndarray] | None = None
    """The points ``(n, 2)`` of a scans payload, to draw it (``payload = "scans"``)."""
    particles: Callable[[], np.ndarray | None] = _nothing
    """A sample of its particle cloud ``(n, 2)`` to draw, or None."""
    partition_view: Callable[[], tuple[np.ndarray, np.ndarray] | None] = _nothing
    """The last scan's measurement cells ``(points, labels)`` to draw, or None."""
    pda_view: Callable[[], dict | None] = _nothing
    """The last update's gates, weighted returns and detector state to draw, or None."""
    model_names: tuple[str, ...] = ()
    """Names of its motion models (labels of :attr:`FuserHooks.model_probabilities`)."""
    # -- identities (a labelled estimator: peers.labelling) ---------------------------------
    origin: int | None = None
    """Its label origin (not None: it labels its components, and its output carries the
    labels in :attr:`LocalOutput.labels`; the consensus then labels the fused density)."""
    begin_scan: Callable[[int], None] = _nothing
    """Told the scan index of the next step (births are stamped with it)."""
    plot_ages: Callable[[np.ndarray | None], None] = _nothing
    """Told the ages ``(m,)`` of the next step's plots (s before the scan's time, the scan
    message's ``ages``; None: all at the scan's time), to take them at their own times."""
    extract_tracks: Callable[..., Any] | None = None
    """``(mix, labels, confirmation) -> tracking.labels.ExtractedTracks``: ``extract``'s
    states with their ids, covariances, existence and status."""
    relabel: Callable[[Any], None] = _nothing
    """Takes a :class:`tracking.labels.LabelMatch` (own label -> the network's winner)."""
    fresh_stamps: Callable[[], np.ndarray | None] = _nothing
    """The labels ``(b, 3)`` its last step stamped at their first publication (the fusion
    moves an uncorroborated one a scan later: :func:`peers.labelling.corroborated`)."""
    adopt_labels: Callable[[np.ndarray], None] = _nothing
    """The labels of the fused density ``adopt`` just took (feedback)."""
    point_tracks: Any = None
    """A :class:`peers.point_ids.PointIds` (a kind without labels, ``origin`` None): ids for
    its extracted points by frame-to-frame association, filled into its published tracks and
    results by the core."""


@dataclass(frozen=True)
class FuserHooks(_Hooks):
    """What a :class:`Fuser` may add to ``fuse``."""

    late: Callable[[str, Any, int], None] | None = None
    """Takes a neighbour's payload that came after its round (else it is dropped as late)."""
    outgoing: Callable[[Any], Any] | None = None
    """What of a fused payload the next round sends (else all of it)."""
    model_probabilities: Callable[[], np.ndarray] | None = None
    """The fused model probabilities (to plot), if it fuses a model mixture."""
    product: bool = False
    """Whether it is a product rule (GCI): any weight above 0 of an input lets that input veto
    a target, so the trust test drops a suspect neighbour instead of down-weighting it."""
    fuse_many: Callable[[Sequence[FusionInput]], list[GaussianMixture]] | None = None
    """``[fuse(i) for i in inputs]`` computed together, for inputs of fusers with the same
    :attr:`batch_key` (a host's co-hosted peers: :mod:`peers.batching`); the same results
    to round-off."""
    batch_key: object = None
    """Fusers whose ``batch_key`` is equal (hashable, not None) compute the same rule with
    the same settings, so one's ``fuse_many`` may fuse the others' inputs."""


def metropolis_weights(own: str, senders: Sequence[str], degrees: Mapping[str, int],
                       uniform: bool = False) -> list[float]:
    """Fusion weights for ``[own, *senders]``: Metropolis on the graph degrees (seed 000 §3).

    A neighbour whose input is missing simply has no term; its weight stays with this peer
    (``omega_ii = 1 - sum_j omega_ij`` over the neighbours present).
    """
    n = len(senders) + 1
    if uniform:
        return [1.0 / n] * n
    di = degrees.get(own, len(senders))
    w = [1.0 / (1.0 + max(di, degrees.get(s, di))) for s in senders]
    return [1.0 - sum(w), *w]
