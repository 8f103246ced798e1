"""A peer host: several sans-I/O peers in one process, over one Zenoh session.

Each hosted peer is a :class:`peers.runtime.PeerRuntime` as in a process of its own (its name,
liveliness token, neighbours, link faults, summary, log lines, Rerun stream), except that
its transport declares on the host's one session and puts what arrives on the host's one
queue, tagged with the peer. An estimate from one peer to a co-hosted neighbour is handed
over in the process (:data:`HANDOFF`): the encoded bytes the publisher put on Zenoh go
straight to the neighbour's :meth:`peers.transport.Transport.deliver`, so they pass the same
admission (per sender) and the same link-fault layer (:class:`peers.faults.HoldQueue`) as a
remote one, without Zenoh's local routing, a callback thread or a copy; remote neighbours get
the one Zenoh put (Zenoh sends it once to each remote host, whose session fans it out). These
paths in, and the world's scan bundles, are in :mod:`peers.host_delivery`.

One loop thread does every peer's work: at each wake-up it moves what has arrived to the
peers' own backlogs, then gives each peer with due work (a message waiting, a held message or
a core deadline due) one step of at most :data:`peers.runtime.BATCH` messages, earliest due
first; a peer with a long backlog or a slow step thus delays the others by one bounded step,
not by its whole backlog. The consensus rounds that became ready in the pass are then fused
together (:mod:`peers.batching`, :data:`BATCH_FUSIONS`; a batched peer's step holds at most
one scan, see :meth:`PeerHost._one_scan`). Commands on standard input (one per line):
``kill PEER [SCAN]`` stops that peer as if its process had been killed (``sensornet run
--fault kill:PEER@K``).
"""

from __future__ import annotations

import gc
import os
import queue
import signal
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import TextIO

from sensornet.peers.admission import TokenBucket
from sensornet.peers.batching import FusionBatch
from sensornet.peers.core import PeerCore
from sensornet.peers.host_batching import HostBatching
from sensornet.peers.host_delivery import HostDelivery
from sensornet.peers.host_parts import (  # SharedDecode: re-exported (benchmarks)
    BacklogInbox,
    QueueInbox,
    SharedDecode,
    rt_line,
)
from sensornet.peers.idle_gc import IdleCollector
from sensornet.peers.observer import PENDING_MAX, HostReports
from sensornet.peers.runtime import BATCH, PeerRuntime, RuntimeOptions
from sensornet.peers.scoring import ScoreBatch
from sensornet.peers.session import open_session
from sensornet.peers.telemetry import SharedCpu
from sensornet.peers.transport import callback, settle

HANDOFF = os.environ.get("SENSORNET_HOST_HANDOFF", "direct") != "zenoh"
"""Hand estimates between co-hosted peers over in-process (default) or through the host's
Zenoh session (``SENSORNET_HOST_HANDOFF=zenoh``: to compare, ``bench_network.py --handoff``).
"""
BATCH_FUSIONS = os.environ.get("SENSORNET_HOST_BATCH", "1") != "0"
"""Fuse the consensus rounds that become ready in one pass of the loop together, at its end
(:mod:`peers.batching`; default), and score the peers' estimates together
(:class:`peers.scoring.ScoreBatch`), or each at once (``SENSORNET_HOST_BATCH=0``: to compare,
``bench_network.py --batch``). A peer that records its inputs for replay fuses at once."""
BATCH_STEPS = os.environ.get("SENSORNET_HOST_BATCH", "1") not in ("0", "fusions")
"""With :data:`BATCH_FUSIONS`, also compute the local steps of the scans a pass will handle
together (:meth:`PeerHost._prepare_scans`; default), or each in its peer's step
(``SENSORNET_HOST_BATCH=fusions``: to compare, ``bench_network.py --batch fusions``)."""

YOUNG_GC = 10_000
"""The host's generation-0 collection threshold (CPython's 700): a host of many peers
allocates many short-lived containers a scan, most dead before a larger threshold is
reached. On the 50-peer GM-PHD twin (``bench_trust_cost.py --filter gmphd --young 10000``)
collections took 0.045-0.058 -> 0.012-0.013 ms a peer-scan (262 -> 8 a run), the whole run
within the noise (0.955 x and 0.993 x in two runs of 4 pairs); a 200-scan run's RSS peaked
at 149 MiB either way (full collections: still :mod:`peers.idle_gc`'s)."""

CONTROL = -1
"""The slot of the host's own items on its queue (commands, a signal's wake-up)."""


class PeerHost(HostDelivery, HostBatching):
    """Runs several peers in one process until every one has stopped (or SIGINT/SIGTERM).

    ``session_args``: ``(listen, connect, config_file, lease_ms, gossip)`` of the host's one
    session (each peer's ``RuntimeOptions`` connection fields are not used)."""

    batch: FusionBatch | None = None
    """The peers' consensus fusions of one pass, fused together (:data:`BATCH_FUSIONS`)."""
    _batched: frozenset[int] = frozenset()
    """The peers whose fusions go through :attr:`batch`."""

    def __init__(self, name: str, peers: list[tuple[PeerCore, RuntimeOptions]],
                 session_args: tuple, say: Callable[[str], None] | None = None) -> None:
        if not peers:
            raise ValueError("a host needs at least one peer")
        if any(o.security is not None for _, o in peers):
            raise ValueError("a host has one Zenoh session, so one TLS identity: run secure "
                             "peers one per process")
        self.name = name
        self.session_args = session_args
        self.say = say or (lambda line: print(line, flush=True))
        self.q: queue.Queue = queue.Queue()
        self.cpu = SharedCpu()
        self.peers = [PeerRuntime(core, o, inbox=QueueInbox(self.q, i), shared_cpu=self.cpu)
                      for i, (core, o) in enumerate(peers)]
        self.counts = {"wakes": 0, "fusion_batches": 0, "fusions_batched": 0,
                       "step_batches": 0, "steps_prepared": 0}
        """The host loop's work so far (every hosted peer's summary shows it under ``host``):
        wake-ups, passes that fused rounds together and the rounds fused so, stacked local
        steps and the steps they prepared."""
        self.reports = HostReports()
        """The peers' telemetry for live views, one bundle a pass (:meth:`_report`)."""
        for rt in self.peers:
            self.reports.add(rt.observer)
        info = {"name": name, "peers": [rt.name for rt in self.peers], "loop": self.counts}
        for rt in self.peers:
            rt.host = info
        self.by_name = {rt.name: i for i, rt in enumerate(self.peers)}
        if HANDOFF:
            self._wire_handoff()
            self.decode = SharedDecode()
            for rt in self.peers:
                rt.core.decode = self.decode
        self.batch: FusionBatch | None = None
        if BATCH_FUSIONS and len(self.peers) > 1:
            self.batch = FusionBatch()
            for rt in self.peers:
                if rt.o.record is None:  # replay fuses each round at once: record that way
                    rt.core.consensus.batch = self.batch
            self._batched = frozenset(i for i, rt in enumerate(self.peers)
                                      if rt.core.consensus.batch is not None
                                      and rt.core.consensus.batchable)
        self._slot = {id(rt.core.consensus): i for i, rt in enumerate(self.peers)}
        self.scores: ScoreBatch | None = None
        """The peers' OSPA scores of a pass, computed together at its end."""
        if BATCH_FUSIONS and len(self.peers) > 1:
            self.scores = ScoreBatch()
            for rt in self.peers:
                rt.core.scorer.batch = self.scores
        self._scorer_slot = {id(rt.core.scorer): i for i, rt in enumerate(self.peers)}
        self.session = None
        self.stop_reason = ""
        self._stop = False
        self._active: list[int] = []
        self._remote = self._share_remote()
        self._by_sensor = {rt.core.cfg.sensor: i for i, rt in enumerate(self.peers)}
        self.bundles = {"received": 0, "rejected": 0, "unknown_sensor": 0, "why": {}}
        """Scan bundles this host received and refused (see :meth:`_unbundle`)."""
        info["bundles"] = self.bundles
        interval = min(rt.core.cfg.interval for rt in self.peers)
        n = len(self.peers)  # an honest world: one bundle a scan, one a sensor at the most
        self._bundle_rate = TokenBucket(4.0 * n / interval, 8.0 * n)
        """Bundles taken before unpacking: what the hosted sensors' own scan messages were
        allowed (peers.admission: 4 a scan interval on average, bursts of 8)."""
        self._bundle_lock = threading.Lock()
        self.gc = IdleCollector()
        self.gc_counts: dict = self.gc.counts()
        """Full collections taken between scans (:mod:`peers.idle_gc`), in the summaries."""
        info["gc"] = self.gc_counts
        self._remote_subs: list = []
        self._backlog: list[deque] = [deque() for _ in self.peers]
        self._inboxes = [BacklogInbox(b) for b in self._backlog]

    # -- life cycle -------------------------------------------------------------------------
    def _signal(self, signum, frame) -> None:
        self.stop_reason = signal.Signals(signum).name
        self._stop = True
        self.q.put((CONTROL, ("stop", "", b"")))

    def command(self, line: str) -> None:
        """A command line from standard input (:meth:`read_commands`), to the loop."""
        self.q.put((CONTROL, ("cmd", line.strip(), b"")))

    def read_commands(self, stream: TextIO) -> threading.Thread:
        """Read commands from ``stream`` (standard input) in a daemon thread, until its end."""
        def read() -> None:
            try:
                for line in stream:
                    if line.strip():
                        self.command(line)
            except (OSError, ValueError):
                pass

        t = threading.Thread(target=read, name=f"{self.name}-commands", daemon=True)
        t.start()
        return t

    def run(self) -> int:
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, self._signal)
        self.session = open_session(*self.session_args)
        opened: list[int] = []
        try:
            if self.session_args[1]:  # endpoints to connect to: let the links come up first
                settle(self.session)
            keys = self.peers[0].transport.keys
            self._remote_subs.append(self.session.declare_subscriber(  # the world's bundles
                keys.scans(self.name), callback(self._unbundle)))
            self.reports.open(self.session, keys.telemetries(self.name))
            for key, subs in self._remote.items():  # before any peer says it is ready
                self._remote_subs.append(self.session.declare_subscriber(
                    key, callback(lambda sample, subs=subs: self._fan_out(subs, sample))))
            for i, rt in enumerate(self.peers):
                rt.open(session=self.session)  # DuplicatePeer before this peer writes a file
                opened.append(i)
                self._active.append(i)  # from now on, what arrives for it is delivered
            try:
                self._loop()
            finally:
                for i in list(self._active):  # SIGTERM, or a bug in the loop: finish them all
                    self._end(i)
        finally:
            self.reports.close()
            for sub in self._remote_subs:
                try:
                    sub.undeclare()
                except Exception:
                    pass
            for i in opened:
                try:
                    self.peers[i].close()  # idempotent: already closed when it ended
                except Exception:
                    pass
            self.session.close()
        return 0

    def _end(self, i: int) -> None:
        """Peer ``i`` stopped (its core said so, or idle): fuse what is pending, write its
        files, undeclare its part of the session."""
        rt = self.peers[i]
        if self.stop_reason and not rt.stop_reason:
            rt.stop_reason = self.stop_reason
        try:
            rt._finish()
            self.reports.send()  # its last reports (the others' complete ones with them)
        finally:
            with self.cpu.aside():  # after its last fusion: not the others' CPU per scan
                rt.close()
                self._active.remove(i)
                self._backlog[i].clear()
                self.say(rt_line(rt))

    def kill(self, name: str, at_scan: int | None = None) -> bool:
        """Stop peer ``name`` as if killed (no last fusion); False if it is not running."""
        i = self.by_name.get(name)
        if i is None or i not in self._active:
            return False
        rt = self.peers[i]
        self._active.remove(i)
        self._backlog[i].clear()
        rt.core.consensus.cancel_pending()  # killed: its last round is not fused
        rt.kill(at_scan if at_scan is not None else rt.core.consensus.last_k)
        self.say(f"host {self.name}: killed peer {name} at scan {rt.killed_at}")
        return True

    def _control(self, item: tuple) -> None:
        tag, line, _ = item
        if tag != "cmd":
            return
        words = line.split()
        if len(words) in (2, 3) and words[0] == "kill" and (len(words) == 2
                                                          or words[2].isdigit()):
            if not self.kill(words[1], int(words[2]) if len(words) == 3 else None):
                self.say(f"host {self.name}: no running peer {words[1]!r} to kill")
        else:
            self.say(f"host {self.name}: unknown command {line!r} (kill PEER [SCAN])")

    # -- the loop ---------------------------------------------------------------------------
    def _loop(self) -> None:
        gc.collect()  # as PeerRuntime._loop: the start-up heap out of the collector's view
        gc.freeze()
        saved = gc.get_threshold()
        gc.set_threshold(YOUNG_GC, *saved[1:])  # fewer young collections (YOUNG_GC)
        self.gc.start()  # full collections between scans (peers.idle_gc)
        try:
            self._run_loop()
        finally:
            self.gc.stop()
            gc.set_threshold(*saved)

    def _run_loop(self) -> None:
        self.cpu.start()
        for rt in self.peers:
            rt.telemetry.start_cpu()
        q, backlog = self.q, self._backlog
        idle_check = 0.0
        interval = min(rt.core.cfg.interval for rt in self.peers)
        scan_at = time.monotonic()  # the last scan's arrival: the next comes an interval on
        while self._active and not self._stop:
            wall, mono = time.time(), time.monotonic()
            busy = any(backlog[i] for i in self._active)
            wait = 0.0 if busy else 0.25
            wakes = {}  # each peer's next wake (monotonic); nothing changes them until _work
            for i in self._active:
                w = self.peers[i].next_wake(wall, mono)
                if w is not None:
                    wait = min(wait, w)
                    wakes[i] = mono + w
            left = self._gather_left(mono)  # rounds gathering: fused by then
            if left is not None:
                wait = min(wait, left)
            gap = 0.0 if busy or not q.empty() or any(  # between scans, not between rounds
                self.peers[i].core.consensus.busy() for i in self._active) else min(
                wait, scan_at + interval - mono)
            if self.gc.idle(gap * 1e3):
                self.gc_counts.update(self.gc.counts())
                continue  # time has passed: look again
            try:
                first = q.get(timeout=max(0.0, wait))
            except queue.Empty:
                first = None
            arrived = [first] if first is not None else []
            limit = BATCH * len(self._active)  # bounded: the loop comes back to deadlines
            while arrived and len(arrived) < limit and not q.empty():
                arrived.append(q.get_nowait())
            now = time.time()
            for slot, item in arrived:
                if slot == CONTROL:
                    self._control(item)
                elif slot in self._active:
                    backlog[slot].append((now, item))
                    if item[0] == "msg" and "/scan/" in item[1]:
                        scan_at = time.monotonic()
            self.counts["wakes"] += 1
            self._work(time.time(), time.monotonic(), wakes)
            self._fuse_gathered()
            self._score()
            self._report()
            if time.monotonic() >= idle_check:  # idle timeouts are seconds: look 4 times a second
                idle_check = time.monotonic() + 0.25
                for i in [i for i in self._active if self.peers[i].idle_expired()]:
                    self._end(i)

    def _report(self) -> None:
        """The peers' complete telemetry reports, in one bundle, once no peer of the host has
        work waiting (never in the burst of a scan that sets its peers' latency; a host never
        idle sends them once a peer holds :data:`peers.observer.PENDING_MAX`); each peer's
        packing on its own CPU, the put split evenly between them ("telemetry" CPU)."""
        if not any(self.peers[i].observer.enabled for i in self._active):  # watched/recorded
            return
        busy = any(self._backlog[i] for i in self._active)
        crowded = busy and any(self.peers[i].observer.pending >= PENDING_MAX
                               for i in self._active)
        if busy and not crowded:
            return
        flushing = [self.peers[i] for i in self._active
                    if self.peers[i].observer.wants_flush or crowded]
        if not flushing:
            return
        for rt in flushing:
            t0 = time.thread_time()
            rt.observer.flush(idle=crowded or not rt.core.consensus.busy(), host=True)
            rt.telemetry.cpu_ms["telemetry"] += (time.thread_time() - t0) * 1e3
        t0 = time.thread_time()
        self.reports.send()
        share = (time.thread_time() - t0) * 1e3 / len(flushing)
        for rt in flushing:
            rt.telemetry.cpu_ms["telemetry"] += share

    def _score(self) -> None:
        """The pass's scores, computed together; their CPU split evenly between the peers
        served (their "tick" CPU, where scoring was)."""
        if self.scores is None or not self.scores.items:
            return
        t0 = time.thread_time()
        served = self.scores.flush()
        share = (time.thread_time() - t0) * 1e3 / max(1, len(served))
        for sc in served:
            cpu = self.peers[self._scorer_slot[id(sc)]].telemetry.cpu_ms
            cpu["tick"] = cpu.get("tick", 0.0) + share

    def _work(self, wall: float, mono: float, wakes: dict[int, float] | None = None) -> None:
        """One step for each peer with due work, the earliest due first (``wakes``: each
        peer's next wake on the monotonic clock, if the caller has them)."""
        due = []
        for i in self._active:
            if wakes is None:
                d = self.peers[i].next_wake(wall, mono)
            else:
                d = wakes[i] - mono if i in wakes else None
            first = self._backlog[i][0][0] if self._backlog[i] else None
            if d is not None and d <= 0:
                due.append((wall + d if first is None else min(first, wall + d), i))
            elif first is not None:
                due.append((first, i))
        due.sort()
        if self.batch is not None and self._close_rounds(due):
            self._fuse()
        if self.batch is not None and BATCH_STEPS:
            self._prepare_scans(due)
        for _, i in due:
            if self._stop:
                return
            if i not in self._active:  # ended in _close_rounds
                continue
            rt, mine = self.peers[i], self._backlog[i]
            entries = [mine.popleft() for _ in range(min(BATCH, len(mine)))]
            if i in self._batched:
                entries = self._one_scan(rt, entries, mine)
            rt.step([item for _, item in entries], lambda mine=mine: not mine)
            if rt._stop:
                self._end(i)
