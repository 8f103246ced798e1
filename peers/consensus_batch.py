"""The consensus side of a host's fusion batch (:mod:`peers.batching`).

With a :class:`~peers.batching.FusionBatch` set on a :class:`peers.consensus.Consensus`, a
round that is ready is queued there as a :class:`~peers.batching.FusionJob` instead of fused
at once. :class:`BatchedRounds` holds what that adds to a consensus: forcing a scan's
remaining rounds through the batch at its deadline, settling a queued round on the spot when
its result is needed now, cancelling it, and going on once the batch has fused it.
"""

from __future__ import annotations

from sensornet.peers.batching import FusionJob
from sensornet.peers.consensus_types import ScanState
from sensornet.peers.contracts import FusionInput
from sensornet.tracking.mixture import GaussianMixture


class BatchedRounds:
    """The batch half of :class:`peers.consensus.Consensus` (mixed into it).

    It uses the consensus's ``batch``, ``batchable``, ``_scan`` (the
    :class:`~peers.consensus_types.ScanState` being fused), ``stats``, ``fuser``, ``trust``,
    ``_completed`` and its round steps ``_fuse_round``, ``_fused``, ``_failed``,
    ``_advance`` and ``_trusted``.
    """

    def close(self, now: float) -> bool:
        """With a batch: the current scan's remaining rounds go through it, forced (its
        deadline passed, or a newer scan waits), counted as
        :meth:`~peers.consensus.Consensus.finish` counts; False
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

    def cancel_pending(self) -> None:
        """Forget the round waiting in the batch (its scan is gone, or the peer stopped)."""
        st = self._scan
        if st is not None and st.pending is not None:
            st.pending.settled = True
            st.pending = None

    def _settle(self, st: ScanState, now: float) -> list:
        """The round waiting in the batch, fused now (its result is needed at once)."""
        job = st.pending
        if job is None:
            return []
        job.settled, st.pending = True, None
        if job.trust is not None:  # its trust test first, on its own
            try:
                weights = self.trust.weigh(*job.trust[0])
            except Exception as exc:  # noqa: BLE001 - as the batch scores it
                weights = exc
            exc = self.tested(job, weights)
            if exc is not None:
                return self._failed(st, exc)
        try:
            fused = self.fuser.fuse(job.input)
        except Exception as exc:
            return self._failed(st, exc)
        return self._fused(st, fused, job.senders, now)

    def tested(self, job: FusionJob, weights: list[float] | BaseException
               ) -> BaseException | None:
        """A queued round's trust test done (``weights``: what its
        :meth:`~peers.trust.Trust.weigh` gave, or raised): the job's inputs, senders and
        weights as :meth:`~peers.consensus.Consensus._fuse_round` makes them after the test.
        Returns the exception, if the test raised (the round then failed)."""
        call, inputs = job.trust
        job.trust = None
        if isinstance(weights, BaseException):
            return weights
        st = job.state
        inputs, job.senders, weights = self._trusted(call, inputs, weights)
        job.input = st.inputs = FusionInput(st.k, st.round, st.current, inputs, weights, st.z)
        if st.round == 0:
            st.first_inputs = st.inputs
        return None

    def complete(self, job: FusionJob, fused: GaussianMixture | None,
                 exc: Exception | None, now: float, labelled=None, masses=None) -> None:
        """The batch fused ``job`` (``fused``, or raised ``exc``): finish its round and go on
        as ``_advance`` would (a forced scan: its remaining rounds, queued again). The
        messages wait for :meth:`take_completed`. ``labelled``: the round's labels, computed
        with other jobs' (:meth:`waiting`, peers.labelling_batch), else None; ``masses``: its
        tracks' input masses likewise (peers.tracks_batch), else None."""
        st = job.state
        job.settled = True
        if st.pending is not job or self._scan is not st:
            return  # settled or cancelled meanwhile
        st.pending = None
        out = self._failed(st, exc) if exc is not None else self._fused(st, fused,
                                                                         job.senders, now,
                                                                         labelled, masses)
        if job.forced:
            while not st.done and st.pending is None:
                out += self._fuse_round(st, now, forced=True)
        else:
            out += self._advance(now)
        self._completed.extend(out)

    def waiting(self, job: FusionJob) -> bool:
        """Whether :meth:`complete` would finish ``job`` (not settled or cancelled since)."""
        st = job.state
        return not job.settled and st.pending is job and self._scan is st

    def take_completed(self) -> list:
        """The messages of the rounds the batch completed since the last call."""
        out, self._completed = self._completed, []
        return out
