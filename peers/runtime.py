"""The peer process: drives a sans-I/O :class:`peers.core.PeerCore` with Zenoh, clocks and files.

Nothing here decides anything about tracking or trust: the core gets every message as bytes
(``receive``), every liveliness change (``liveliness``) and the clock (``tick``), and returns
what to publish and record. The driver carries that out (:mod:`peers.transport`), measures it
(:mod:`peers.telemetry`), reports it to live views (:mod:`peers.observer`; no Rerun here),
injects the configured link faults, and writes the summary, recording and tracks, never over
an earlier run's files.
"""

from __future__ import annotations

import gc
import signal
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sensornet.peers.admission import Route, peek
from sensornet.peers.core import PeerCore, Publish, Record, Stop
from sensornet.peers.faults import FaultInjector, HoldQueue
from sensornet.peers.inbound import delivered
from sensornet.peers.observer import KINDS as OBSERVED
from sensornet.peers.observer import Observer
from sensornet.peers.recording import Recorder
from sensornet.peers.run_output import RunOutputs, output_stem
from sensornet.peers.telemetry import SharedCpu, Telemetry
from sensornet.peers.transport import Transport
from sensornet.protocol.messages import Estimate, Forward, Returns

BATCH = 64
"""At most this many queued messages are handled per wake-up before deadlines are checked."""

BACKLOG = 4
"""Scans a peer may be behind and still work off every one (see PeerRuntime._catch_up): a
transient backlog (a pause, a busy moment) costs latency, not measurements; a longer one
(the scan window is 5 ahead) means the peer cannot keep up, and it skips to the newest."""


@dataclass(frozen=True)
class RuntimeOptions:
    """Where and how one peer process runs (everything that is not the peer's logic)."""

    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    config_file: str | None = None
    lease_ms: int | None = None
    gossip: bool | str = True
    """See :func:`peers.session.zenoh_config`."""
    out_dir: Path | None = None
    run_id: str | None = None
    viewer: str | None = None
    color_index: int = 0
    idle_timeout: float = 30.0
    rerun: bool = True
    save_tracks: bool = False
    scan_period: float = 1.0
    """Simulated seconds per scan (the "sim" timeline in Rerun)."""
    faults: FaultInjector | None = field(default=None, compare=False)
    security: object = None
    """A :class:`peers.security.Security`: mutual TLS and the network's access control."""
    record: dict[str, str] | None = None
    """Record the core's inputs to ``<out_dir>/record/<stem>.mcap`` with this metadata
    (scenario text, overrides, run, ...: what ``sensornet replay`` needs to rebuild the peer)."""
    recover: bool = False
    """Estimates and scans through Zenoh's advanced publisher/subscriber (routed runs): what a
    router's outage held back is asked for again; ``recovery`` in the summary counts it."""
    ros2: int | None = None
    """Also publish the tracks as ROS 2 messages on this ROS 2 domain (:mod:`peers.ros2`;
    scenario ``network.ros2``); None: not."""


class PeerRuntime(RunOutputs):
    """Runs one peer until its core says stop, SIGINT/SIGTERM, or no input for a while."""

    def __init__(self, core: PeerCore, options: RuntimeOptions | None = None,
                 inbox=None, shared_cpu: SharedCpu | None = None) -> None:
        """``inbox``: where the transport puts what arrives (a host's tagged queue, see
        :mod:`peers.host`); by default the peer's own queue, which :meth:`run` drains.
        ``shared_cpu``: the host's CPU, which this peer shares (see :class:`SharedCpu`)."""
        self.core = core
        self.o = options or RuntimeOptions()
        self.name = core.name
        c = core.consensus
        self.transport = Transport(core.keys, core.name, core.cfg.sensor, c.o.neighbours,
                                   core.admission,
                                   (list(self.o.listen), list(self.o.connect),
                                    self.o.config_file, self.o.lease_ms, self.o.gossip),
                                   security=self.o.security, truth=core.wants_truth,
                                   recover=self.o.recover, inbox=inbox)
        self.telemetry = Telemetry(shared_cpu)
        self.observer = Observer(core, self.o.scan_period, self.telemetry)
        self.held = HoldQueue()
        self.saved_tracks: dict[int, np.ndarray] | None = {} if self.o.save_tracks else None
        self.live_events: list[tuple[str, str, float, int]] = []
        self.stem = output_stem(self.o.out_dir, self.name) if self.o.out_dir else None
        self.stop_reason = ""
        self.killed_at: int | None = None
        self.host: dict | None = None
        """A hosted peer's host: its name and peers (in the summary)."""
        self._stop = False
        self._last_input = time.monotonic()
        self.recorder = None
        self.ros2 = None

    # -- life cycle -------------------------------------------------------------------------
    def _signal(self, signum, frame) -> None:
        self.stop_reason = signal.Signals(signum).name
        self._stop = True
        self.transport.wake()

    def run(self) -> int:
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, self._signal)
        self.open()  # raises DuplicatePeer before any file is written
        try:
            try:
                self._loop()
            finally:
                self._finish()
        finally:
            self.close()
        return 0

    def open(self, session=None) -> None:
        """Open the transport (on ``session`` if given: a host's), the recorder and the sink."""
        o = self.o
        self.transport.open(session=session)
        try:
            if o.record is not None and o.out_dir is not None:
                meta = {**o.record, "peer": self.name, "network": self.core.cfg.network}
                self.recorder = Recorder(o.out_dir / "record" / f"{self.stem}.mcap", meta)
                self.recorder.attach(self.core)  # truth and the Foxglove scene too
                # and the telemetry, watched or not: the offline view's fused marks, health
                self.observer.record_put = lambda b, rec=self.recorder: rec.telemetry(
                    time.time(), b)
            # live views' telemetry (secure: the access control lets p put telemetry/p)
            self.observer.open(self.transport.session, self.core.keys)
            if o.ros2 is not None:
                from sensornet.peers.ros2 import PeerRos2  # optional dependency: rosbags
                self.ros2 = PeerRos2(self.transport.session, self.name, o.ros2,
                                     o.scan_period, o.color_index)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Undeclare everything on the transport (the token goes), the telemetry and recorder."""
        try:
            if self.ros2 is not None:
                self.ros2.close()
                self.ros2 = None
            self.observer.close()
            self.observer.record_put = None  # the recorder closes next
            self.transport.close()
        finally:
            if self.recorder is not None:
                self.recorder.close()
                self.recorder = None

    def _loop(self) -> None:
        # the start-up heap (NumPy, SciPy, Zenoh, ...) never becomes garbage: out of the
        # collector's view, a full collection no longer walks it in the middle of a scan
        gc.collect()
        gc.freeze()
        self.telemetry.start_cpu()
        q = self.transport.q
        while not self._stop:
            wake = self.next_wake(time.time(), time.monotonic())
            wait = 0.25 if wake is None else min(0.25, wake)
            try:
                item = q.get(timeout=max(0.0, wait))
            except Exception:  # queue.Empty
                item = None
            # what has queued up meanwhile is handled before the deferred work (one tick
            # and one telemetry flush per wake-up instead of per message; bounded)
            items = [item] if item is not None else []
            while items and len(items) < BATCH and not q.empty():
                items.append(q.get_nowait())
            self.step(items, q.empty)
            if self.idle_expired():
                break

    def next_wake(self, wall: float, mono: float) -> float | None:
        """Seconds from now (``wall``/``mono``: the two clocks read now) to this peer's next
        deferred work, a core deadline or a held message; None when it has none."""
        wait = None
        due = self.core.next_due()
        if due is not None:
            wait = due - wall
        held = self.held.next_due()
        if held is not None:
            wait = held - mono if wait is None else min(wait, held - mono)
        return wait

    def step(self, items: list[tuple], queue_empty) -> None:
        """One wake-up's work: ``items`` (at most :data:`BATCH`), the held messages now due,
        the core's tick and a telemetry flush (``queue_empty()``: nothing more waiting for this
        peer, so the observer may flush). A message's key is parsed once, by the transport
        (:class:`peers.inbound.Delivered`), and its payload decoded once (:meth:`_handle`)."""
        try:
            network = self.core.cfg.network
            items = [delivered(item, network) for item in items]
            self.core.admission.taken_all(  # out of the inbox (handled or skipped below)
                [(item.route, len(item[2])) for item in items if item[0] == "msg"])
            for item in self._catch_up(items):
                if self._stop:
                    break
                self._handle(item)
            for route, key, payload, msg in self.held.pop_due(time.monotonic()):
                self._feed(route, key, payload, msg)
            now = time.time()
            due = self.core.next_due()
            if self.recorder is not None and due is not None and due <= now:
                self.recorder.tick(now)  # a deadline fires: replay must tick here too
            self._carry_out("tick", self.core.tick, now)
            if self.observer.wants_flush:  # a scan's telemetry may be complete
                t0 = time.thread_time()
                self.observer.flush(idle=queue_empty() and not self.core.consensus.busy())
                self.telemetry.cpu_ms["telemetry"] += (time.thread_time() - t0) * 1e3
        except Exception as exc:  # a bug must not take the peer (and the run) down
            self._internal_error(exc)

    def idle_expired(self) -> bool:
        """No input for ``idle_timeout`` seconds: set the stop reason, say so."""
        if time.monotonic() - self._last_input > self.o.idle_timeout:
            self.stop_reason = f"no input for {self.o.idle_timeout:g} s"
            return True
        return False

    def _catch_up(self, items: list[tuple]) -> list[tuple]:
        """A peer that has fallen behind by more than :data:`BACKLOG` scans goes to the newest
        ones: a scan with its next ``BACKLOG`` successors queued too is left out (counted,
        scored as a miss), so its scan index stays with its neighbours' and their estimates
        inside its window; a shorter backlog is worked off whole. Only scans a backlog
        explains count (up to the scan window's end plus one per queued scan): forged scans
        far ahead are left to the core, which refuses them."""
        scans = [i for i, (tag, key, _) in enumerate(items)
                 if tag == "msg" and "/scan/" in key]
        if len(scans) < 2:
            return items
        top = self.core.window_for("scan")[1] + len(scans)
        ks = {i: (peek(items[i][2]) or ("", -1))[1] for i in scans}
        ks = {i: k for i, k in ks.items() if 0 <= k <= top}
        queued = set(ks.values())
        drop = {i for i, k in ks.items() if all(k + j in queued for j in range(1, BACKLOG + 1))}
        self.telemetry.scans_skipped_behind += len(drop)
        return [it for i, it in enumerate(items) if i not in drop]

    def _handle(self, item: tuple) -> None:
        tag, key, payload = item
        if tag == "stop":
            return
        if tag == "live":
            name, joined = key, bool(payload)
            self.transport.saw(name, joined)
            if name != "world" and name != self.name:
                self.live_events.append((name, "joined" if joined else "left", time.time(),
                                         self.core.consensus.last_k))
            now = time.time()
            if self.recorder is not None:
                self.recorder.liveliness(now, name, joined)
            self._carry_out("live", lambda now: self.core.liveliness(name, joined, now), now)
            return
        self._last_input = time.monotonic()
        route = item.route
        msg = None
        if route is not None and route.channel == "estimate" and self.o.faults is not None:
            msg = self.core.decoded(payload)  # one decode: the link faults' and the core's
            if self._hold(route, key, payload, msg):
                return
        self._feed(route, key, payload, msg)

    def _feed(self, route: Route | None, key: str, payload: bytes, msg=None) -> None:
        """Hand an admitted message to the core (``msg``: its payload decoded already)."""
        now = time.time()
        if self.recorder is not None:
            self.recorder.receive(now, key, payload)
        channel = route.channel if route is not None else "other"
        self._carry_out(channel, lambda now: self.core.receive_routed(route, payload, now, msg),
                        now)

    def _carry_out(self, channel: str, step, now: float) -> None:
        """Run one core step at wall time ``now``; publish and record what it returns."""
        cpu = self.telemetry.cpu_ms
        t0 = time.thread_time()
        outputs = step(now)
        t1 = time.thread_time()
        cpu[channel] = cpu.get(channel, 0.0) + (t1 - t0) * 1e3
        if not outputs:  # (most ticks): nothing to measure, publish or record
            return
        leave = time.time()
        if channel in ("scan", "estimate", "tick"):
            self.telemetry.handled(channel, now, leave, outputs)
        scan_ms = (leave - now) * 1e3 if channel == "scan" else None
        # a live view watching: the observer gathers telemetry from the records it reads
        # (their kind checked here: most are estimates', a call each cost more than the
        # check), untimed ("loop" CPU) unless the step published: a thread-CPU clock read
        # is a system call, and most steps publish nothing
        drawing = self.observer.enabled
        published = False
        for out in outputs:
            if isinstance(out, Publish):
                wall = time.time()
                self.transport.publish(out.channel, out.payload)
                if out.channel == "tracks" and self.ros2 is not None:
                    self.ros2.tracks(out.message, wall)
                published = True
                lat = self.telemetry.published(out, wall, len(out.payload))
                if out.channel == "tracks" and self.saved_tracks is not None:
                    self.saved_tracks[out.k] = out.message.states
                if out.channel == "tracks" and self.recorder is not None:
                    self.recorder.tracks(wall, out.k, out.payload)
                if drawing and out.channel == "tracks":
                    self.observer.published(out, lat)
            elif isinstance(out, Record):
                if drawing and out.kind in OBSERVED:
                    self.observer.record(out, scan_ms)
                if out.kind == "error":
                    self._report_error(out)
                if out.kind == "scan" and out.k % 1000 == 0:
                    self._flush_fault_log()  # the injector's log stays small in long runs
            elif isinstance(out, Stop):
                self.stop_reason = out.reason
                self._stop = True
        if published:
            cpu["publish"] += (time.thread_time() - t1) * 1e3

    # -- link faults (a test facility: the network's behaviour, not the peer's) -------------
    def _run_time(self, send_time: float) -> float:
        """Seconds on the run clock (scan ``k`` at ``k * interval``, as in the twin)."""
        interval = self.core.cfg.interval
        t0 = self.core.t0 if self.core.t0 is not None else (
            send_time - self.core.consensus.last_k * interval)
        return send_time - t0 + interval

    def _hold(self, route: Route, key: str, payload: bytes, msg) -> bool:
        """Injected faults on the link ``sender -> self``: hold, duplicate or drop (``msg``:
        the payload decoded, :meth:`peers.core.PeerCore.decoded`; held with the message)."""
        if not isinstance(msg, Estimate | Forward | Returns):
            return False  # a Rejected: the core counts it
        delays = self.o.faults.deliveries(msg.sender, self.name,
                                          self._run_time(msg.send_time), msg)
        transit = max(0.0, time.time() - msg.send_time)
        now = time.monotonic()
        for d in delays:
            self.held.push(now + max(0.0, d - transit), (route, key, payload, msg))
        return True

    def _report_error(self, r: Record) -> None:
        """The core caught a bug (scan ``k`` has no output): say so the first few times."""
        self._errors_reported = getattr(self, "_errors_reported", 0) + 1
        if self._errors_reported <= 5:
            print(f"peer {self.name}: internal error at scan {r.k}: {r.values['error']}: "
                  f"{r.values['message']}", file=sys.stderr, flush=True)

    def _internal_error(self, exc: Exception) -> None:
        """Count an unexpected error; print its traceback the first few times (to the log)."""
        errors = self.telemetry.internal_errors
        errors[type(exc).__name__] += 1
        if sum(errors.values()) <= 5:
            print(f"peer {self.name}: internal error {type(exc).__name__}: {exc}",
                  file=sys.stderr)
            traceback.print_exc()

    # -- the end ----------------------------------------------------------------------------
    def kill(self, at_scan: int) -> None:
        """Stop at once, as a killed process would (``kill:PEER@K`` in a host): no last fusion
        and nothing more published; the liveliness token goes; unlike a killed process it
        still writes its summary (saying so), fault log and saved tracks."""
        self.stop_reason = f"killed at scan {at_scan}"
        self.killed_at = at_scan
        self._stop = True
        with self.telemetry.after_run():
            try:
                self.close()
            finally:
                if self.o.out_dir is not None:
                    self._flush_fault_log()
                    self._save_tracks()
                    self.write_summary()
                    self._write_results()

    def _finish(self) -> None:
        """Fuse what is pending, then write the summary, tracks and fault log."""
        try:
            now = time.time()
            if self.recorder is not None:
                self.recorder.finish(now)
            self._carry_out("tick", self.core.finish, now)
        except Exception as exc:
            self._internal_error(exc)
        self.observer.flush(idle=True, force=True)
        out = self.o.out_dir
        if out is None:
            return
        with self.telemetry.after_run():  # one-off work, not the run's CPU per scan
            out.mkdir(parents=True, exist_ok=True)  # --out of a folder not made (--no-rerun)
            self._flush_fault_log()
            self._save_tracks()
            self.write_summary()
            self._write_results()
