"""Consensus over a peer's neighbours: one class for any local estimator and fuser.

Per scan ``k`` (docs/algorithms.md "GCI fusion", "NALE"): the local estimator steps and its round-0
estimate goes out; then ``L`` consensus rounds; round ``l`` fuses the peer's current density with
the neighbours' round-``(l-1)`` densities (round 0 through the NALE buffer, so late estimates are
predicted to ``k``). A round runs as soon as every live neighbour's inputs are in, or at the
deadline with whatever arrived. After round ``L`` the tracks go out.

Inputs here are decoded, already validated messages (:class:`peers.core.PeerCore` checks keys,
senders, dimensions, scan windows and rates first); outputs are messages to publish.

The options, counters and per-scan state are in :mod:`peers.consensus_types`, the rounds'
passage through a host's fusion batch in :mod:`peers.consensus_batch`.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from sensornet.peers.batching import FusionBatch, FusionJob
from sensornet.peers.consensus_batch import BatchedRounds
from sensornet.peers.consensus_types import (
    ConsensusOptions,
    ConsensusStats,
    ScanState,
    payload_tuples,
)
from sensornet.peers.contracts import (
    EstimatorHooks,
    Fuser,
    FuserHooks,
    FusionInput,
    LocalEstimator,
    metropolis_weights,
)
from sensornet.peers.fusers import NoFuser
from sensornet.peers.label_support import LabelSupport, decode, peer_bit
from sensornet.peers.labelling import FusedLabels, copy_keepers
from sensornet.peers.labelling_batch import LabelProblem
from sensornet.peers.tracks_batch import rows_support
from sensornet.peers.trust import Trust
from sensornet.protocol.messages import Estimate, Forward, Returns, ScanSet, Tracks
from sensornet.tracking.fusion_rules import aa_label_density
from sensornet.tracking.held_ids import HeldIds, ReportedIds
from sensornet.tracking.label_keys import label_keys
from sensornet.tracking.label_twins import StampTwins
from sensornet.tracking.labels import Confirmation, ExtractedTracks, LabelledMixture
from sensornet.tracking.mature_existence import MatureExistence
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.nale import NaleBuffer
from sensornet.tracking.own_scan import own_scan_ratio, own_scan_weights
from sensornet.tracking.stamp_blocks import block_ids
from sensornet.tracking.support import (
    SupportRule,
    input_mass,
    input_support,
    pooled_weights,
    revisit_weights,
)


class Consensus(BatchedRounds):
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
        self._scan: ScanState | None = None
        self._seq = 0
        self.last_k = 0
        self.stats = ConsensusStats()
        self.errors: Counter = Counter()
        """Unexpected exceptions in the estimator or fuser, by type (each scored a miss)."""
        self._unstepped = 0
        """Scans whose local step raised, of an estimator whose step is all or nothing
        (``atomic_parts``: peers.step_atomic): the next step covers them too, as after a gap."""
        self._atomic = callable(getattr(estimator, "atomic_parts", None))
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
        # -- identities (peers.labelling): a labelled estimator's labels through the rounds
        self.labelled = self.hooks.origin is not None
        """Whether the estimator labels its components (its tracks then carry ids)."""
        self.last_local_labels: np.ndarray | None = None
        self.last_fused_labels: np.ndarray | None = None
        self.confirm_local = Confirmation(options.confirm_scans, settle=options.confirm_settle)
        self.confirm_fused = Confirmation(options.confirm_scans, settle=options.confirm_settle)
        """Confirmation of the local and the fused tracks' labels (tracking.labels)."""
        self._in_labels: dict[tuple[int, int, str, str], tuple[object, np.ndarray]] = {}
        """(k, round, kind, sender) -> (payload, its labels) of labelled estimates."""
        self._nale_labels: dict[str, tuple[object, np.ndarray]] = {}
        """sender -> (the NALE buffer's stored payload, its labels)."""
        self._fresh = 0  # fresh labels this peer's fusions created (their index offsets)
        self.label_support = (LabelSupport(peer_bit(self.hooks.origin),
                                           dict(options.label_reach) or None, self.rounds)
                              if self.labelled and options.label_support else None)
        """Holder masks of shared labels (peers.label_support): same-scan ties by support;
        a neighbour's masks cut to what it can vouch for (``label_reach``)."""
        self.support = (SupportRule(options.support_inputs, options.support_scans)
                        if self.fusing and options.support_inputs != 0 else None)
        """Which extracted fused tracks are reported (tracking.support); None: all."""
        self.mature = (MatureExistence(options.existence_mature, options.existence_young,
                                       options.existence_absent)
                       if self.fusing and options.existence_mature > 0 else None)
        """Mature fused tracks' existence for extraction (tracking.mature_existence)."""
        self.twins = (StampTwins(options.stamp_twins, options.stamp_twins)
                      if self.fusing and self.labelled and options.stamp_twins > 0 else None)
        """Young fused rows held back while a moved stamp's first may come (label_twins)."""
        self.held = (HeldIds(options.label_hold, options.existence_young)
                     if self.fusing and self.labelled and options.label_hold > 0 else None)
        """Young reported rows take an id reported just before beside them (held_ids)."""
        self._reported = label_keys(np.zeros((0, 3), dtype=np.int64))
        """Sorted keys of the fused tracks reported last scan (``existence_keep``,
        ``label_keep``)."""
        self.kept_ids = (ReportedIds(options.label_keep_scans) if self.fusing and self.labelled
                         and options.label_keep and options.label_keep_scans > 0 else None)
        """Ids reported in the last ``label_keep_scans`` scans, kept too (held_ids)."""

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
            self.hooks.begin_scan(k)
            local = self.estimator.step(steps + self._unstepped, z)
        except Exception as exc:  # a bug must not stop the scans: no output, scored a miss
            self._error(k, exc)
            self._scan = None
            self._unstepped += steps if self._atomic else 0
            return out
        self._unstepped = 0
        self.last_local = local.density
        self.stats.scans += 1
        self._scan = ScanState(k, z, 0, local.published["posterior"], local.density)
        labels = local.labels if self.labelled and local.labels is not None else {}
        if self.labelled:
            self._scan.labels = labels.get("posterior")
            if self.label_support is not None and self._scan.labels is not None:
                self.label_support.prune(k)
                self.label_support.own(self._scan.labels, k)
            self._scan.local_labels = self.last_local_labels = local.density_labels
            if local.density_labels is not None:
                self.confirm_local.observe(LabelledMixture(local.density, local.density_labels),
                                           k)
        self._record(k, "local", **local.info)
        if self.fusing:
            for kind in self.kinds:
                out.append(self._estimate(k, 0, local.published[kind], now, kind,
                                          labels.get(kind)))
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
        labels = getattr(est, "labels", None)
        if labels is not None and self.label_support is not None:  # the masks off the wire
            extra = getattr(est, "label_masks", None)  # words 1.. (more than 39 peers)
            if extra is not None and len(extra) != len(labels):
                extra = None  # rows cut or padded on the way: word 0 alone
            labels, masks = decode(labels, extra)  # a label older than any publication vouched:
            labels, masks = self.label_support.checked(  # re-stamped to this scan
                est.sender, labels, masks, est.k, est.round)
            self.label_support.heard(est.sender, labels, masks, est.k, est.round)
        if labels is not None and (not self.labelled or len(labels) != len(payload)):
            labels = None  # not ours to use, or a receiver's bound cut its rows
        if est.round == 0 and est.kind == "posterior":
            if self.nale.offer(est.sender, est.k, payload):
                if labels is not None:
                    self._nale_labels[est.sender] = (payload, labels)
                else:
                    self._nale_labels.pop(est.sender, None)
        if self._scan is not None and est.k < self._scan.k and est.round > 0:
            self.stats.old_round_estimates += 1
            return []
        self._inbox.setdefault((est.k, est.round, est.kind), {})[est.sender] = payload
        if labels is not None:
            self._in_labels[(est.k, est.round, est.kind, est.sender)] = (payload, labels)
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
        self._nale_labels.pop(name, None)
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
        self._in_labels.clear()
        self._nale_labels.clear()
        for name in list(self.nale.stored):
            self.nale.forget(name)
        self.cancel_pending()
        self._scan = None
        self._unstepped = 0

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
        for kind in self.kinds:  # every live neighbour's estimate of each kind in (a
            box = self._inbox.get((k, rnd, kind))  # set compare, not a generator per call)
            if not (box.keys() >= self.alive if box is not None else not self.alive):
                return False
        return True

    def _advance(self, now: float) -> list:
        out: list = []
        st = self._scan
        while (st is not None and not st.done and st.pending is None
               and self._ready(st.k, st.round)):
            out += self._fuse_round(st, now)
        return out

    def _fuse_round(self, st: ScanState, now: float, forced: bool = False,
                    now_only: bool = False) -> list:
        """Consensus round ``st.round + 1`` of scan ``st.k``: fused now, or (with a batch,
        unless ``now_only``) queued there as a job, ``forced`` if the scan's deadline passed
        (then its remaining rounds follow it through the batch)."""
        if not self.fusing:
            st.done = True
            return self._tracks(st.k, st.local, now, st.local_labels)
        inputs = self._inputs(st.k, st.round)
        senders = sorted(inputs)
        weights = metropolis_weights(self.o.name, senders, self._deg,
                                     uniform=self.o.omega == "uniform")
        call = (self._trust_call(st, inputs, senders, weights)
                if self.trust is not None and isinstance(st.current, GaussianMixture) else None)
        if call is not None and self.batch is not None and self.batchable and not now_only:
            st.pending = FusionJob(self, st, None, senders, forced, trust=(call, inputs))
            self.batch.add(st.pending)  # tested with the batch's (peers.trust_batch)
            return []
        if call is not None:
            inputs, senders, weights = self._trusted(call, inputs, self.trust.weigh(*call))
        inp = FusionInput(st.k, st.round, st.current, inputs, weights, st.z)
        st.inputs = inp
        if st.round == 0:
            st.first_inputs = inp
        if self.batch is not None and self.batchable and not now_only:
            st.pending = FusionJob(self, st, inp, senders, forced)
            self.batch.add(st.pending)
            return []
        try:
            fused = self.fuser.fuse(inp)
        except Exception as exc:  # a bug must not stop the peer: no tracks, scored a miss
            return self._failed(st, exc)
        return self._fused(st, fused, senders, now)

    def _failed(self, st: ScanState, exc: Exception) -> list:
        self._error(st.k, exc)
        st.done = True
        return []

    def _fused(self, st: ScanState, fused: GaussianMixture, senders: list[str],
               now: float, labelled: FusedLabels | None = None,
               masses: tuple | None = None) -> list:
        """The rest of a round once fused: counts, records, the next round's estimate or
        the tracks. ``labelled``: the round's labels computed already (with other peers':
        :meth:`label_problem`, peers.labelling_batch), else computed here; ``masses``: the
        input masses of its tracks likewise (:meth:`tracks_problem`, peers.tracks_batch)."""
        self.stats.fusions += 1
        self.stats.fused_inputs += len(senders)
        for s in senders:
            self.stats.last_fused_from[s] = st.k
        ages = self.nale.ages(st.k) if st.round == 0 else {}
        labelling = self._label(st, fused, labelled) if self.labelled else None
        st.round += 1
        st.current = fused
        st.labels = None if labelling is None else labelling.labels
        self.last_fused = fused
        self.last_fused_labels = st.labels
        self._record(st.k, "fusion", round=st.round, n_inputs=len(senders), n_fused=len(fused),
                     ages={s: ages.get(s, 0) for s in senders})
        if st.round < self.rounds:
            outgoing = self.fuser_hooks.outgoing  # e.g. only the scans not sent before
            return [self._estimate(st.k, st.round,
                                   fused if outgoing is None else outgoing(fused), now,
                                   "posterior", st.labels if outgoing is None else None)]
        st.done = True
        if self.o.feedback:
            self.estimator.adopt(fused)
            if st.labels is not None:
                self.hooks.adopt_labels(st.labels)
        if labelling is not None and (not self.o.feedback or getattr(  # an LMB that keeps its
                self.estimator, "relabel_on_feedback", False)):  # tracks (lmb.adopt_states)
            self.hooks.relabel(labelling.own)  # the winners of our own labels, kept locally
        return self._tracks(st.k, fused, now, st.labels, st.first_inputs,
                            None if labelling is None else labelling.copies, masses)

    def _label(self, st: ScanState, fused, done: FusedLabels | None = None):
        """The labels of a round's fused density (peers.labelling.label_fused of
        :meth:`label_problem`; ``done``: computed already). None if ``fused`` is no
        mixture."""
        if done is None:
            problem = self.label_problem(st, fused)
            if problem is None:
                return None
            done = problem.alone()
        self._fresh += done.fresh
        return done

    def label_problem(self, st: ScanState, fused) -> LabelProblem | None:
        """The arguments of the round's :func:`peers.labelling.label_fused`, from the
        round's labelled inputs: the own density's, then each neighbour's whose estimate
        carried labels for the very payload fused (round 0: the one the NALE buffer holds,
        maybe predicted: its labels fit its first rows). None if ``fused`` is no mixture."""
        if not isinstance(fused, GaussianMixture):
            return None
        inp = st.inputs
        pairs = [(st.current, st.labels)] if isinstance(st.current, GaussianMixture) else []
        if inp is not None:
            for s in sorted(inp.neighbours):
                mix = inp.neighbours[s].get("posterior")
                held = (self._nale_labels.get(s) if st.round == 0
                        else self._in_labels.get((st.k, st.round, "posterior", s)))
                if not isinstance(mix, GaussianMixture) or held is None:
                    continue
                payload, labels = held
                stored = self.nale.stored.get(s) if st.round == 0 else None
                if st.round == 0 and (stored is None or stored[1] is not payload):
                    continue
                if st.round > 0 and mix is not payload:
                    continue
                if len(labels) <= len(mix):
                    pairs.append((mix, labels))
        own_first = bool(pairs) and pairs[0][0] is st.current
        bump = self.hooks.fresh_stamps() if st.round == 0 and own_first else None
        # an AA fuser keeps each input's copy of a target (peers.fusers.AaFuser.copies)
        return LabelProblem(fused, pairs, self.hooks.origin, st.k, self._fresh, bump=bump,
                            copies=bool(getattr(self.fuser, "copies", False)),
                            support=self.label_support, fallback=self.o.label_fallback,
                            keep=(None if not self.o.label_keep else self._reported
                                  if self.kept_ids is None  # label_keep_scans: held_ids
                                  else self.kept_ids.union(st.k, self._reported)),
                            settle=self.o.confirm_settle)

    def tracks_problem(self, st: ScanState, fused) -> tuple | None:
        """``(fused means, the scan's first-round input mixtures)`` if completing this round with
        ``fused`` extracts tracks by the input masses (:meth:`_tracks`: the last round of a
        labelled scan, with ``existence_prior`` or the support rule), else None."""
        if (st.round + 1 < self.rounds or not self.labelled or not self.fusing
                or self.hooks.extract_tracks is None or not isinstance(fused, GaussianMixture)
                or not len(fused) or (self.support is None and self.o.existence_prior <= 0)):
            return None
        mixes = self._input_mixtures(st.first_inputs)
        return None if mixes is None else (fused.means, mixes)

    def _trust_call(self, st: ScanState, inputs: dict, senders: list[str],
                    weights: list[float]) -> tuple | None:
        """The arguments of the round's :meth:`Trust.weigh` (None: raw scans, not
        densities, are fused)."""
        mixes = {s: inputs[s]["posterior"] for s in senders}
        if not all(isinstance(m, GaussianMixture) for m in mixes.values()):
            return None
        late = None
        if st.round == 0:  # made at an earlier scan, predicted forward: as received
            late = {s: self.nale.stored[s] for s in senders
                    if s in self.nale.stored and self.nale.stored[s][0] < st.k}
        return (st.k, st.round, st.current, mixes, list(weights), self.fuser_hooks.product,
                late)

    def _trusted(self, call: tuple, inputs: dict, weights: list[float]):
        """The round's inputs, senders and weights after the trust test (``call``:
        :meth:`_trust_call`'s, ``weights``: what :meth:`Trust.weigh` gave): a neighbour's
        weight scaled by its trust (the rest to own); a neighbour at weight 0 is left out
        (fusers that do not use the weights, e.g. the single-target rules, must not see
        it)."""
        mixes = call[3]
        senders = sorted(mixes)
        self.records.extend(self.trust.drain_records())
        if self.trust.cfg.register or self.trust.cfg.repair:  # repaired / registered
            inputs = {s: {**inputs[s], "posterior": self.trust.fused_input(s, mixes[s])}
                      if s in mixes else inputs[s] for s in inputs}
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
                  kind: str, labels: np.ndarray | None = None) -> Estimate:
        self.stats.estimates_out += 1
        tuples = payload_tuples(mix)
        self.stats.tuples_out += tuples
        self.stats.tuples_to_neighbours += tuples * len(self.alive)
        if isinstance(mix, ScanSet):
            return Forward(self.o.name, k, mix, round=rnd, seq=self._next_seq(), send_time=now)
        if isinstance(mix, np.ndarray):
            return Returns(self.o.name, k, mix, round=rnd, seq=self._next_seq(), send_time=now)
        extra = None
        if labels is not None and self.label_support is not None:  # the masks on the wire
            if rnd > 0:  # a later round's fresh own labels: published by us at their scan
                self.label_support.sent(labels, k)
            labels, extra = self.label_support.encode(labels)
        return Estimate(self.o.name, k, mix, round=rnd, seq=self._next_seq(),
                        send_time=now, pruning=2 if rnd == 0 else 1, kind=kind,
                        labels=labels if self.labelled else None,
                        label_masks=extra if self.labelled else None)

    def _tracks(self, k: int, fused: GaussianMixture, now: float,
                labels: np.ndarray | None = None, inputs: FusionInput | None = None,
                copies: np.ndarray | None = None, masses: tuple | None = None) -> list:
        """The published tracks of scan ``k``: states only, or (labelled) a Tracks message
        with ids, covariances, existence and confirmation status (protocol 2). Fused tracks
        (``inputs``: the scan's first round's, own and neighbours' own scans: independent
        evidence, as the pooled existence assumes; a later round's inputs are fused densities
        that all hold one peer's young clutter track, which with 2 rounds was pooled as a
        confirmation by each, issue 33) by the extraction rules of tracking.support when on:
        young tracks' pooled existence (``existence_prior``; not of an AA fusion's
        ``copies``, peers.labelling.copy_rows), then :attr:`support`; an AA fuser's ``label_state``
        first sums each label's copies' existence (tracking.fusion_rules.aa_label_density, Li
        2022's per-label AA), so a target three inputs hold at 0.9 is not three rows at 0.3, each
        under the existence test (issue 33). ``masses``: ``(input
        masses, supports of the rows, the fused means they are of)`` computed with other peers'
        (peers.tracks_batch.masses_many), else computed here."""
        if masses is not None and masses[2] is not fused.means:
            masses = None
        self.stats.tracks_out += 1
        if labels is None or self.hooks.extract_tracks is None:
            states = self.estimator.extract(fused)
            return [Tracks(self.o.name, k, states, seq=self._next_seq(), send_time=now)]
        self.confirm_fused.observe(LabelledMixture(fused, labels), k)
        mixes = self._input_mixtures(inputs)
        cap = None  # a mature track every input just missed (tracking.mature_existence)
        if self.mature is not None and mixes is not None:
            cap = self.mature.caps(fused.weights, labels, k, input_mass(fused.means, mixes)
                                   if masses is None else masses[0])
        state, moments = getattr(self.fuser, "label_state", None), None
        if state is not None and copies is not None and copies.any():  # AA copies per label
            w, *moments = aa_label_density(fused.weights, fused.means, fused.covs,  # after the
                                           copy_keepers(fused, copies), state)  # cap's prior
            fused = GaussianMixture.trusted(w, fused.means, fused.covs)  # means: masses' rows
        if self.o.existence_prior > 0 and mixes is not None and len(fused):
            keep = (np.isin(label_keys(labels), self._reported) if self.o.existence_keep
                    else None)
            mass = input_mass(fused.means, mixes) if masses is None else masses[0]
            w0 = fused.weights
            fused = GaussianMixture.trusted(  # for extraction only
                pooled_weights(fused, labels, k, mass, self.o.existence_prior,
                               self.o.existence_young, skip=copies, keep=keep),
                fused.means, fused.covs)
            if self.o.existence_own and self._scan is not None and self._scan.k == k:
                ratio = own_scan_ratio(fused.means, fused.covs, self._scan.z,
                                       *self.o.existence_own)
                fused = GaussianMixture.trusted(  # the own scan, where its tracks hold none
                    own_scan_weights(fused.weights, w0, labels, k, mass[:, 0],
                                     self.o.existence_young, ratio), fused.means, fused.covs)
        if self.o.existence_revisit and mixes is not None and len(fused):
            spans = dict(self.o.existence_revisit)
            names = [self.o.name, *sorted(inputs.neighbours)]
            fused = GaussianMixture.trusted(  # for extraction only
                revisit_weights(fused.weights, labels, k, input_mass(fused.means, mixes)
                                if masses is None else masses[0], list(inputs.weights),
                                [spans.get(n, 0.0) for n in names]),
                fused.means, fused.covs)
        if cap is not None and len(fused):
            fused = GaussianMixture.trusted(np.minimum(fused.weights, cap), fused.means,
                                            fused.covs)
        if moments is not None:  # the labels' states (aa_label_density), for extraction
            fused = GaussianMixture.trusted(fused.weights, *moments)
        t = self.hooks.extract_tracks(fused, labels, self.confirm_fused)
        if self.support is not None and mixes is not None:
            held = None if masses is None else rows_support(masses[1], masses[2], t.states)
            if held is None:
                held = input_support(t.states, mixes)
            keep = self.support.keep(t.ids, held, len(mixes))
            if not keep.all():
                t = ExtractedTracks(t.states[keep], t.ids[keep], t.covs[keep],
                                    t.existence[keep], t.status[keep])
        if self.twins is not None:  # a moved stamp's row, while its first may still come
            keep = ~self.twins.held(k, t.ids, t.states, t.covs, labels, fused.weights,
                                    fused.means, fused.covs)
            if not keep.all():
                t = ExtractedTracks(t.states[keep], t.ids[keep], t.covs[keep],
                                    t.existence[keep], t.status[keep])
        if self.held is not None:  # a young label does not replace an id just reported
            t = ExtractedTracks(t.states, self.held.ids(k, t.ids, t.states, t.covs, labels,
                                                        fused.means, fused.covs),
                                t.covs, t.existence, t.status)
        if self.o.existence_keep or self.o.label_keep:
            self._reported = np.unique(label_keys(t.ids))
        if self.kept_ids is not None:
            self.kept_ids.remember(k, t.ids)
        ids = block_ids(t.ids, self.o.id_blocks) if self.o.id_blocks else t.ids  # stamp_blocks
        return [Tracks(self.o.name, k, t.states, seq=self._next_seq(), send_time=now,
                       ids=ids, covs=t.covs, existence=t.existence, status=t.status)]

    def _input_mixtures(self, inputs: FusionInput | None) -> list[GaussianMixture] | None:
        """The inputs' mixtures (own density, then each neighbour's posterior) of ``inputs``
        (the scan's first round's, :meth:`_tracks`) if the extraction rules need them and all
        are mixtures, else None."""
        if inputs is None or (self.support is None and self.o.existence_prior <= 0
                              and self.mature is None and not self.o.existence_revisit):
            return None
        mixes = [inputs.own, *(inputs.neighbours[s].get("posterior")
                               for s in sorted(inputs.neighbours))]
        return mixes if all(isinstance(m, GaussianMixture) for m in mixes) else None

    def local_tracks(self):
        """The last local density's tracks (tracking.labels.ExtractedTracks, with ids and
        status), or None if unlabelled."""
        if (self.last_local is None or self.last_local_labels is None
                or self.hooks.extract_tracks is None):
            return None
        return self.hooks.extract_tracks(self.last_local, self.last_local_labels,
                                         self.confirm_local)

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
        for key in [key for key in self._in_labels if key[0] < k]:
            del self._in_labels[key]
