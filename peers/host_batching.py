"""The batched part of a peer host's loop (:class:`peers.host.PeerHost`): the co-hosted
peers' local steps computed together before their steps, a batched peer's step held to one
scan, and the consensus rounds that became ready in a pass fused together at its end
(:mod:`peers.batching`)."""

from __future__ import annotations

import itertools
import os
import time
from collections import deque

from sensornet.peers.admission import peek
from sensornet.peers.batching import prepare_local_steps
from sensornet.peers.inbound import Delivered
from sensornet.peers.runtime import BATCH, PeerRuntime


def gather_ms(text: str | None) -> float:
    """``SENSORNET_HOST_GATHER_MS`` read: unset or empty is 0; anything but a finite number
    of ms in [0, 1000] a one-line error, not a host that waits forever or never."""
    try:
        ms = float(text or 0.0)
    except ValueError:
        ms = float("nan")
    if not 0.0 <= ms <= 1000.0:
        raise ValueError(f"SENSORNET_HOST_GATHER_MS must be a number of ms in [0, 1000], "
                         f"got {text!r}")
    return ms


GATHER_MS = gather_ms(os.environ.get("SENSORNET_HOST_GATHER_MS"))
"""How long the rounds that became ready wait for more before the host fuses them, ms
(``SENSORNET_HOST_GATHER_MS``; 0, the default: at the end of every pass, as before). A
host's stacked trust tests, fusions and labels cost mostly per call, so a pass that holds
12 rounds costs each peer more than one of 25 (:meth:`HostBatching._fuse_gathered`); opt-in
until measured as processes (docs/security.md)."""


class HostBatching:
    """What :class:`~peers.host.PeerHost` does with its batch; it uses the host's ``peers``,
    ``_backlog``, ``_batched``, ``_slot``, ``_active``, ``batch``, ``_stop``, ``_end`` and
    ``counts``."""

    def _prepare_scans(self, due: list[tuple[float, int]]) -> None:
        """The local steps of the scans this pass's steps will handle (a batched peer's first
        scan within its step's reach), computed together (:func:`peers.batching.
        prepare_local_steps`: one stacked GM-PHD step); each peer's step then takes its own
        result, or computes it if the step it makes is another. The stacked computation's CPU
        is split evenly between the peers it served (their "scan" CPU, where the step was)."""
        scans = []
        for _, i in due:
            if i not in self._batched:
                continue
            item = next((item for _, item in itertools.islice(self._backlog[i], BATCH)
                         if item[0] == "msg" and "/scan/" in item[1]), None)
            if item is not None:  # the route its transport parsed: not parsed again
                key = item.route if type(item) is Delivered else item[1]
                scans.append((self.peers[i].core, key, item[2]))
        if len(scans) < 2:
            return
        t0 = time.thread_time()
        cores = prepare_local_steps(scans)
        if cores:
            self.counts["step_batches"] += 1
            self.counts["steps_prepared"] += len(cores)
        served = cores or [c for c, _, _ in scans]  # none prepared: the guesses' cost
        share = (time.thread_time() - t0) * 1e3 / len(served)
        for core in served:
            cpu = self.peers[self._slot[id(core.consensus)]].telemetry.cpu_ms
            cpu["scan"] = cpu.get("scan", 0.0) + share

    @staticmethod
    def _one_scan(rt: PeerRuntime, entries: list, mine: deque) -> list:
        """A batched peer's step holds at most one scan: the scans far behind are skipped
        first (:meth:`PeerRuntime._catch_up`, as its step would), then what follows a second
        scan goes back to the front of its backlog, so that scan finds its predecessor's
        rounds fused through the batch (:meth:`_close_rounds`), not one by one inside it."""
        items = [item for _, item in entries]
        kept = rt._catch_up(items)
        if len(kept) < len(items):
            ids = {id(item) for item in kept}
            for tag, key, payload in (item for item in items if id(item) not in ids):
                if tag == "msg":
                    rt.core.admission.taken(key, len(payload))  # out of the inbox
            entries = [e for e in entries if id(e[1]) in ids]
        scans = [n for n, (_, (tag, key, _)) in enumerate(entries)
                 if tag == "msg" and "/scan/" in key]
        if len(scans) > 1:
            mine.extendleft(reversed(entries[scans[1]:]))
            entries = entries[:scans[1]]
        return entries

    def _close_rounds(self, due: list[tuple[float, int]]) -> bool:
        """A peer still fusing a scan with a newer scan in its backlog would fuse that scan's
        remaining rounds one by one when the newer scan comes (:meth:`Consensus.finish`, on
        a host behind): instead it takes what came before the newer scan, then its remaining
        rounds go to the batch, fused with the other peers' at once (:meth:`_fuse`) before
        the newer scan is handled. True if any did."""
        closed = False
        for _, i in due:
            rt, mine = self.peers[i], self._backlog[i]
            c = rt.core.consensus
            if i not in self._batched or not c.busy():
                continue
            j = next((n for n, (_, item) in enumerate(mine)
                      if item[0] == "msg" and "/scan/" in item[1]), None)
            if j is None or j >= BATCH or (peek(mine[j][1][2]) or ("", -1))[1] <= c.last_k:
                continue  # no newer scan within this step's reach
            if j:
                rt.step([mine.popleft()[1] for _ in range(j)], lambda: False)
                if rt._stop:
                    self._end(i)
                    continue
            closed = c.close(time.time()) or closed
        return closed

    _gather_from: float | None = None
    """When the oldest round waiting for :data:`GATHER_MS` was first seen (monotonic s)."""

    def _fuse_gathered(self) -> None:
        """The end of a pass: :meth:`_fuse`, or (:data:`GATHER_MS`) nothing yet while the
        rounds waiting are fewer than the batched peers still running, none forced by its
        deadline, the host not stopping and the first of them has waited less than
        :data:`GATHER_MS` (the loop comes back by then: :meth:`_gather_left`)."""
        batch = self.batch
        if batch is None or not batch.jobs:
            self._gather_from = None
            return
        if GATHER_MS > 0 and not self._stop:
            mono = time.monotonic()
            if self._gather_from is None:
                self._gather_from = mono
            jobs = [j for j in batch.jobs if not j.settled]
            peers = sum(1 for i in self._active if i in self._batched)  # still running
            if (jobs and len(jobs) < peers and not any(j.forced for j in jobs)
                    and (mono - self._gather_from) * 1e3 < GATHER_MS):
                return
        self._gather_from = None
        self._fuse()

    def _gather_left(self, mono: float) -> float | None:
        """Seconds until the rounds gathering (:meth:`_fuse_gathered`) are fused anyway,
        None if none are."""
        if self._gather_from is None:
            return None
        return max(0.0, self._gather_from + GATHER_MS / 1e3 - mono)

    def _fuse(self) -> None:
        """The rounds that became ready in this pass, fused together; each peer then
        publishes and records what its completed rounds give (its next round's estimate,
        its tracks), as its own step would have. The stacked computation's CPU is split
        evenly between the peers it served (their "estimate" CPU, where fusing was)."""
        batch = self.batch
        while batch is not None and batch.jobs and not self._stop:
            t0 = time.thread_time()
            jobs = len(batch.jobs)
            done = batch.run(time.time())
            self.counts["fusion_batches"] += 1
            self.counts["fusions_batched"] += jobs
            share = (time.thread_time() - t0) * 1e3 / max(1, len(done))
            for c in done:
                i = self._slot[id(c)]
                rt = self.peers[i]
                rt.telemetry.cpu_ms["estimate"] = rt.telemetry.cpu_ms.get("estimate", 0.0) + share
                if i not in self._active:
                    continue
                try:
                    rt._carry_out("estimate", rt.core.completed, time.time())
                except Exception as exc:  # as in PeerRuntime.step: not the host's end
                    rt._internal_error(exc)
                if rt._stop:
                    self._end(i)
