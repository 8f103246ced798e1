"""Consensus over a peer's neighbours: one class for any local estimator and fuser.

Per scan ``k`` (docs/algorithms.md "GCI fusion", "NALE"): the local estimator steps and its round-0
estimate goes out; then ``L`` consensus rounds; round ``l`` fuses the peer's current density with
the neighbours' round-``(l-1)`` densities (round 0 through the NALE buffer, so late estimates are
predicted to ``k``). A round runs as soon as every live neighbour's inputs are in, or at the
deadline with whatever arrived. After round ``L`` the tracks go out.

Inputs here are decoded, already validated messages (:class:`peers.core.PeerCore` checks keys,
senders, dimensions, scan windows and rates first); outputs are messages to publish.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from sensornet.peers.batching import FusionBatch, FusionJob
from sensornet.peers.contracts import (
    EstimatorHooks,
    Fuser,
    FuserHooks,
    FusionInput,
    LocalEstimator,
    metropolis_weights,
)
from sensornet.peers.fusers import NoFuser
from sensornet.peers.trust import Trust, TrustConfig
from sensornet.protocol.messages import Estimate, Forward, Returns, ScanSet, Tracks
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.nale import NaleBuffer


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

    def __post_init__(self) -> None:
        if self.rounds < 1:
            raise ValueError("consensus rounds must be at least 1")
        if self.name in self.neighbours:
            raise ValueError("a peer cannot be its own neighbour")


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
class _ScanState:
    k: int
    z: np.ndarray
    round: int = 0
    current: GaussianMixture | None = None
    local: GaussianMixture | None = None
    done: bool = False
    pending: FusionJob | None = None
    """The round waiting in a host's :class:`~peers.batching.FusionBatch` (its inputs taken)."""


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


class Consensus:
    """Drives a :class:`LocalEstimator` and a :class:`Fuser` through the rounds of each scan."""

    def __init__(self, options: ConsensusOptions, estimator: LocalEstimator,
                 fuser: Fuser) -> None:
        self.o = options
        self.estimator = estimator
        self.fuser = fuser
        self.hooks = EstimatorHooks.of(estimator)
        """The estimator's optional hooks (:class:`peers.contracts.EstimatorHooks`)."""
        self.fuser_hooks = FuserHooks.of(fuser)
        """The fuser's optional hooks (:class:`peers.contracts.FuserHooks`)."""
        self.fusing = bool(options.neighbours) and not isinstance(fuser, NoFuser)
        self.rounds = min(options.rounds, fuser.max_rounds)
        self.kinds = tuple(estimator.kinds) if self.fusing else ()
        self.nale = NaleBuffer(max_age=options.max_age, policy=options.policy)
        self.alive: set[str] = set(options.neighbours)
        self._deg = dict(options.degrees)
        self._inbox: dict[tuple[int, int, str], dict[str, GaussianMixture]] = {}
        self._scan: _ScanState | None = None
        self._seq = 0
        self.last_k = 0
        self.stats = ConsensusStats()
        self.errors: Counter = Counter()
        """Unexpected exceptions in the estimator or fuser, by type (each scored a miss)."""
        self.records: list[dict] = []
        self.last_local: GaussianMixture | None = None
        self.last_fused: GaussianMixture | None = None
        self.trust = (Trust(options.trust, options.neighbours,
                            tuple(getattr(estimator, "position_index", (0, 2))))
                      if self.fusing and options.trust is not None and options.trust.enabled
                      else None)
        self.batch: FusionBatch | None = None
        """A host's batch: ready rounds wait there to be fused with the other peers'
        (:mod:`peers.batching`); None: each round fused when it is ready."""
        self.batchable = (self.fusing and self.fuser_hooks.fuse_many is not None
                          and self.fuser_hooks.batch_key is not None
                          and not options.round_deadlines)
        self._completed: list = []  # messages of rounds the batch completed, not yet taken

    # -- inputs -----------------------------------------------------------------------------
    def busy(self) -> bool:
        """Whether the current scan's fusion is still to come."""
        return self._scan is not None and not self._scan.done

    def on_scan(self, k: int, z: np.ndarray, steps: int, now: float) -> list:
        """Local step with scan ``k`` (``steps`` scans after the previous one); round-0
        estimates out; fuse at once if nothing is awaited."""
        out: list = []
        if self.busy():
            out += self.finish(now)
        self.last_k = k
        try:
            local = self.estimator.step(steps, z)
        except Exception as exc:  # a bug must not stop the scans: no output, scored a miss
            self._error(k, exc)
            self._scan = None
            return out
        self.last_local = local.density
        self.stats.scans += 1
        self._scan = _ScanState(k, z, 0, local.published["posterior"], local.density)
        self._record(k, "local", **local.info)
        if self.fusing:
            for kind in self.kinds:
                out.append(self._estimate(k, 0, local.published[kind], now, kind))
        out += self._advance(now)
        self._drop_old(k)
        return out

    def on_estimate(self, est: Estimate, now: float) -> list:
        """Store a neighbour's estimate (round-0 posteriors through NALE); fuse if complete."""
        self.stats.estimates_in += 1
        payload = (est.scans if isinstance(est, Forward) else est.z if isinstance(est, Returns)
                   else est.mixture)
        st, late = self._scan, self.fuser_hooks.late
        if late is not None and st is not None and (
                est.k < st.k or (est.k == st.k and (st.done or est.round < st.round))):
            late(est.sender, payload, est.k)  # after its round: the fuser's hook decides
            return []
        if est.round == 0 and est.kind == "posterior":
            self.nale.offer(est.sender, est.k, payload)
        if self._scan is not None and est.k < self._scan.k and est.round > 0:
            self.stats.old_round_estimates += 1
            return []
        self._inbox.setdefault((est.k, est.round, est.kind), {})[est.sender] = payload
        return self._advance(now)

    def on_deadline(self, k: int, now: float) -> list:
        """The fusion deadline of scan ``k``: run the remaining rounds with what arrived."""
        st = self._scan
        if st is None or st.k != k or st.done:
            return []
        if self.close(now):  # the remaining rounds through the batch
            return []
        if self.o.round_deadlines:  # this round's deadline: run it, then what is complete
            self.stats.deadline_fusions += 1
            return self._fuse_round(self._scan, now) + self._advance(now)
        return self.finish(now)

    def close(self, now: float) -> bool:
        """With a batch: the current scan's remaining rounds go through it, forced (its
        deadline passed, or a newer scan waits), counted as :meth:`finish` counts; False
        (nothing done) without a batch or a scan being fused."""
        st = self._scan
        if self.batch is None or not self.batchable or st is None or st.done:
            return False
        if st.pending is not None:
            if not st.pending.forced:
                st.pending.forced = True
                self.stats.deadline_fusions += 1
            return True
        self.stats.deadline_fusions += 1
        self._fuse_round(st, now, forced=True)
        return True

    def forced(self) -> bool:
        """Whether the scan's remaining rounds go through the batch already, its deadline
        passed (no deadline left to fire for it)."""
        st = self._scan
        return st is not None and st.pending is not None and st.pending.forced

    def round_of(self, k: int) -> int | None:
        """Rounds of scan ``k`` already run (None: not the scan being fused, or done)."""
        st = self._scan
        return st.round if st is not None and st.k == k and not st.done else None

    def finish(self, now: float) -> list:
        """Run the current scan's remaining rounds now (deadline, next scan, or end of run)."""
        out: list = []
        st = self._scan
        if st is not None and not st.done:
            if st.pending is None or not st.pending.forced:  # a forced one counted already
                self.stats.deadline_fusions += 1
            out += self._settle(st, now)
            while not st.done:
                out += self._fuse_round(st, now, now_only=True)
        return out

    def peer_left(self, name: str) -> bool:
        """A neighbour went away: stop waiting for it and forget its stored estimate."""
        if name not in self.alive:
            return False
        self.alive.discard(name)
        self.nale.forget(name)
        return True

    def resume(self, now: float) -> list:
        """Run the rounds that are now complete (e.g. they waited only for a peer that left)."""
        return self._advance(now)

    def peer_joined(self, name: str) -> bool:
        if name in self.o.neighbours and name not in self.alive:
            self.alive.add(name)
            return True
        return False

    def reset_window(self) -> None:
        """Forget every stored estimate (the scan numbering restarted)."""
        self._inbox.clear()
        for name in list(self.nale.stored):
            self.nale.forget(name)
        self.cancel_pending()
        self._scan = None

    def cancel_pending(self) -> None:
        """Forget the round waiting in the batch (its scan is gone, or the peer stopped)."""
        st = self._scan
        if st is not None and st.pending is not None:
            st.pending.settled = True
            st.pending = None

    # -- rounds -----------------------------------------------------------------------------
    def _inputs(self, k: int, rnd: int) -> dict[str, dict[str, GaussianMixture]]:
        got: dict[str, dict[str, GaussianMixture]] = {}
        if rnd == 0:
            for s, mix in self.nale.collect(k, self.estimator.predict).items():
                got[s] = {"posterior": mix}
        for kind in self.kinds:
            for s, mix in self._inbox.get((k, rnd, kind), {}).items():
                got.setdefault(s, {}).setdefault(kind, mix)
        return {s: v for s, v in got.items() if all(kd in v for kd in self.kinds)}

    def _ready(self, k: int, rnd: int) -> bool:
        if not self.fusing:
            return True
        return all(n in self._inbox.get((k, rnd, kind), {})
                   for n in self.alive for kind in self.kinds)

    def _advance(self, now: float) -> list:
        out: list = []
        st = self._scan
        while (st is not None and not st.done and st.pending is None
               and self._ready(st.k, st.round)):
            out += self._fuse_round(st, now)
        return out

    def _fuse_round(self, st: _ScanState, now: float, forced: bool = False,
                    now_only: bool = False) -> list:
        """Consensus round ``st.round + 1`` of scan ``st.k``: fused now, or (with a batch,
        unless ``now_only``) queued there as a job, ``forced`` if the scan's deadline passed
        (then its remaining rounds follow it through the batch)."""
        if not self.fusing:
            st.done = True
            return self._tracks(st.k, st.local, now)
        inputs = self._inputs(st.k, st.round)
        senders = sorted(inputs)
        weights = metropolis_weights(self.o.name, senders, self._deg,
                                     uniform=self.o.omega == "uniform")
        if self.trust is not None and senders and isinstance(st.current, GaussianMixture):
            inputs, senders, weights = self._trusted(st, inputs, senders, weights)
        inp = FusionInput(st.k, st.round, st.current, inputs, weights, st.z)
        if self.batch is not None and self.batchable and not now_only:
            st.pending = FusionJob(self, st, inp, senders, forced)
            self.batch.add(st.pending)
            return []
        try:
            fused = self.fuser.fuse(inp)
        except Exception as exc:  # a bug must not stop the peer: no tracks, scored a miss
            return self._failed(st, exc)
        return self._fused(st, fused, senders, now)

    def _failed(self, st: _ScanState, exc: Exception) -> list:
        self._error(st.k, exc)
        st.done = True
        return []

    def _settle(self, st: _ScanState, now: float) -> list:
        """The round waiting in the batch, fused now (its result is needed at once)."""
        job = st.pending
        if job is None:
            return []
        job.settled, st.pending = True, None
        try:
            fused = self.fuser.fuse(job.input)
        except Exception as exc:
            return self._failed(st, exc)
        return self._fused(st, fused, job.senders, now)

    def complete(self, job: FusionJob, fused: GaussianMixture | None,
                 exc: Exception | None, now: float) -> None:
        """The batch fused ``job`` (``fused``, or raised ``exc``): finish its round and go on
        as :meth:`_advance` would (a forced scan: its remaining rounds, queued again). The
        messages wait for :meth:`take_completed`."""
        st = job.state
        job.settled = True
        if st.pending is not job or self._scan is not st:
            return  # settled or cancelled meanwhile
        st.pending = None
        out = self._failed(st, exc) if exc is not None else self._fused(st, fused,
                                                                         job.senders, now)
        if job.forced:
            while not st.done and st.pending is None:
                out += self._fuse_round(st, now, forced=True)
        else:
            out += self._advance(now)
        self._completed.extend(out)

    def take_completed(self) -> list:
        """The messages of the rounds the batch completed since the last call."""
        out, self._completed = self._completed, []
        return out

    def _fused(self, st: _ScanState, fused: GaussianMixture, senders: list[str],
               now: float) -> list:
        """The rest of a round once fused: counts, records, the next round's estimate or
        the tracks."""
        self.stats.fusions += 1
        self.stats.fused_inputs += len(senders)
        for s in senders:
            self.stats.last_fused_from[s] = st.k
        ages = self.nale.ages(st.k) if st.round == 0 else {}
        st.round += 1
        st.current = fused
        self.last_fused = fused
        self._record(st.k, "fusion", round=st.round, n_inputs=len(senders), n_fused=len(fused),
                     ages={s: ages.get(s, 0) for s in senders})
        if st.round < self.rounds:
            outgoing = self.fuser_hooks.outgoing  # e.g. only the scans not sent before
            return [self._estimate(st.k, st.round,
                                   fused if outgoing is None else outgoing(fused), now,
                                   "posterior")]
        st.done = True
        if self.o.feedback:
            self.estimator.adopt(fused)
        return self._tracks(st.k, fused, now)

    def _trusted(self, st: _ScanState, inputs: dict, senders: list[str], weights: list[float]):
        """The round's inputs and weights after the trust test: a neighbour's weight scaled by
        its trust (the rest to own); a neighbour at weight 0 is left out (fusers that do not
        use the weights, e.g. the single-target rules, must not see it)."""
        mixes = {s: inputs[s]["posterior"] for s in senders}
        if not all(isinstance(m, GaussianMixture) for m in mixes.values()):
            return inputs, senders, weights  # raw scans: not densities
        weights = self.trust.weigh(st.k, st.round, st.current, mixes, list(weights),
                                   drop_suspects=self.fuser_hooks.product)
        self.records.extend(self.trust.drain_records())
        kept = [i for i, w in enumerate(weights[1:]) if w > 0.0]
        if len(kept) == len(senders):
            return inputs, senders, weights
        senders = [senders[i] for i in kept]
        return ({s: inputs[s] for s in senders}, senders,
                [weights[0]] + [weights[1 + i] for i in kept])

    # -- outputs ----------------------------------------------------------------------------
    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _estimate(self, k: int, rnd: int, mix: GaussianMixture, now: float,
                  kind: str) -> Estimate:
        self.stats.estimates_out += 1
        tuples = payload_tuples(mix)
        self.stats.tuples_out += tuples
        self.stats.tuples_to_neighbours += tuples * len(self.alive)
        if isinstance(mix, ScanSet):
            return Forward(self.o.name, k, mix, round=rnd, seq=self._next_seq(), send_time=now)
        if isinstance(mix, np.ndarray):
            return Returns(self.o.name, k, mix, round=rnd, seq=self._next_seq(), send_time=now)
        return Estimate(self.o.name, k, mix, round=rnd, seq=self._next_seq(),
                        send_time=now, pruning=2 if rnd == 0 else 1, kind=kind)

    def _tracks(self, k: int, fused: GaussianMixture, now: float) -> list:
        states = self.estimator.extract(fused)
        self.stats.tracks_out += 1
        return [Tracks(self.o.name, k, states, seq=self._next_seq(), send_time=now)]

    def _error(self, k: int, exc: Exception) -> None:
        self.errors[type(exc).__name__] += 1
        self._record(k, "error", error=type(exc).__name__, message=str(exc)[:300])

    def _record(self, k: int, kind: str, **values) -> None:
        self.records.append({"k": k, "kind": kind, **values})

    def drain_records(self) -> list[dict]:
        out, self.records = self.records, []
        return out

    def _drop_old(self, k: int) -> None:
        """Bound memory: forget inbox entries of scans before ``k``."""
        for key in [key for key in self._inbox if key[0] < k]:
            del self._inbox[key]
