"""The peer process: a thin Zenoh + Rerun runtime around :class:`peers.logic.PeerLogic`.

Zenoh callbacks only put raw payloads on a queue (calling Zenoh from a callback can deadlock,
and a slow callback holds up receiving); the main thread decodes, validates and feeds the
state machine, publishes what it returns, fires fusion deadlines, and logs to Rerun.
A bad message is counted by reason and dropped; nothing a neighbour sends stops the peer.
"""

from __future__ import annotations

import gc
import json
import os
import queue
import resource
import signal
import statistics
import sys
import time
import traceback
from collections import Counter, deque
from dataclasses import asdict
from pathlib import Path

import numpy as np
import zenoh

from peers.faults import FaultInjector, HoldQueue
from peers.logic import PeerLogic
from peers.rerun_sink import RerunSink, color_of, position_columns
from peers.session import open_session
from protocol.codec import Rejected, decode, encode
from protocol.keys import Keys
from protocol.messages import Control, Estimate, Scan, Tracks, Truth


def current_rss_mb() -> float:
    """This process's resident memory now (MB), from /proc (0 where there is none)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return 0.0


class PeerRuntime:
    """Runs one peer until the world says the run ended, or SIGINT/SIGTERM."""

    def __init__(self, logic: PeerLogic, network: str, interval: float, deadline: float,
                 listen=(), connect=(), config_file: str | None = None,
                 lease_ms: int | None = None, out_dir: Path | None = None,
                 run_id: str | None = None, viewer: str | None = None, color_index: int = 0,
                 idle_timeout: float = 30.0, rerun: bool = True,
                 faults: FaultInjector | None = None, save_tracks: bool = False,
                 gossip: bool = True, scan_period: float = 1.0) -> None:
        self.logic = logic
        self.name = logic.o.name
        self.keys = Keys(network)
        self.interval = interval
        self.scan_period = scan_period  # simulated seconds per scan (the "sim" timeline)
        self.deadline_frac = deadline
        self.session_args = (list(listen), list(connect), config_file, lease_ms, gossip)
        self.out_dir = out_dir
        self.run_id = run_id or network
        self.viewer = viewer
        self.color = color_of(color_index)
        self.idle_timeout = idle_timeout
        self.faults = faults
        self.saved_tracks: dict[int, np.ndarray] | None = {} if save_tracks else None
        self.held = HoldQueue()
        self.t0: float | None = None  # wall time of the run's start (the world's Control)
        self.rerun = rerun
        self.q: queue.Queue = queue.Queue()
        self.sink = RerunSink()
        self.rejected: Counter = Counter()
        self.errors: Counter = Counter()
        self.rss_samples: list[tuple[int, float]] = []
        """Resident memory (MB) after scan 1 and every 1000th scan (leak checks)."""
        self.seen_alive: set[str] = set()
        self._session = None
        self._ready_token = None
        self.live_events: list[tuple[str, str, float, int]] = []
        """Liveliness changes seen: (peer, "joined"/"left", wall time, last scan)."""
        self.sent = Counter()
        self.sent_bytes = Counter()
        self.received = Counter()
        self.received_bytes = Counter()
        self.latency_ms: deque = deque(maxlen=4096)
        self.compute_ms = {"filter": 0.0, "fusion": 0.0}
        self.ages: deque = deque(maxlen=4096)
        self.deadlines: dict[int, float] = {}
        self.scan_sent: dict[int, float] = {}
        # latency breakdown per scan (wall seconds): scan received, local estimate out, and the
        # last neighbour estimate of the scan received
        self.stage: dict[int, tuple[float, float]] = {}
        self.last_arrival: dict[int, float] = {}
        self.breakdown: dict[str, deque] = {
            n: deque(maxlen=4096)
            for n in ("transit", "local", "fusion_wait", "neighbours", "fusing")}
        self.tails: deque = deque(maxlen=20)
        self._deferred: list = []  # Rerun logging postponed off the critical path
        self.stop_reason = ""
        self._stop = False
        self._last_input = time.monotonic()

    # -- zenoh plumbing ---------------------------------------------------------------------
    def _put(self, tag: str):
        def callback(sample) -> None:
            self.q.put((tag, str(sample.key_expr), sample.payload.to_bytes()))
        return callback

    def _live(self, sample) -> None:
        self.q.put(("live", str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT))

    def _signal(self, signum, frame) -> None:
        self.stop_reason = signal.Signals(signum).name
        self._stop = True
        self.q.put(("stop", "", b""))

    def _publish(self, messages: list, now_wall: float) -> None:
        for msg in messages:
            data = encode(msg)
            if isinstance(msg, Estimate):
                self.est_pub.put(data)
                kind = "estimate"
            elif isinstance(msg, Tracks):
                self.tracks_pub.put(data)
                kind = "tracks"
                self._on_tracks(msg, now_wall)
            else:
                continue
            self.sent[kind] += 1
            self.sent_bytes[kind] += len(data)

    # -- main loop --------------------------------------------------------------------------
    def run(self) -> int:
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, self._signal)
        if self.out_dir is not None and self.rerun or self.viewer:
            rrd = self.out_dir / "rerun" / f"peer-{self.name}.rrd" if self.out_dir else None
            self.sink.open(self.run_id, rrd if self.rerun else None, self.viewer)
        session = open_session(*self.session_args)
        try:
            # BLOCK: nothing is dropped under load; express: no batching delay
            block = zenoh.CongestionControl.BLOCK
            self.est_pub = session.declare_publisher(
                self.keys.estimate(self.name), congestion_control=block, express=True)
            self.tracks_pub = session.declare_publisher(
                self.keys.tracks(self.name), congestion_control=block, express=True)
            subs = [
                session.declare_subscriber(self.keys.scan(self.logic.o.sensor), self._put("scan")),
                # only the neighbours' estimates: routing does the filtering, not decoding
                *(session.declare_subscriber(self.keys.estimate(n), self._put("estimate"))
                  for n in self.logic.o.neighbours),
                session.declare_subscriber(self.keys.truth(), self._put("truth")),
                session.declare_subscriber(self.keys.ctl(), self._put("ctl")),
                session.liveliness().declare_subscriber(self.keys.alive("*"), self._live,
                                                        history=True),
            ]
            token = session.liveliness().declare_token(self.keys.alive(self.name))
            self._session = session
            self._check_ready()
            try:
                profile_dir = os.environ.get("SENSORNET_PROFILE")
                if profile_dir:  # cProfile of the main loop, for finding hot spots
                    import cProfile

                    prof = cProfile.Profile(time.process_time)  # CPU time, not wall
                    prof.runctx("self._loop()", globals(), {"self": self})
                    prof.dump_stats(str(Path(profile_dir) / f"peer-{self.name}.prof"))
                else:
                    self._loop()
            finally:
                self._finish()
                token.undeclare()
                if self._ready_token is not None:
                    self._ready_token.undeclare()
                for s in subs:
                    s.undeclare()
        finally:
            session.close()
            self.sink.close()
        return 0

    def _loop(self) -> None:
        self._cpu_at_start = time.process_time()
        # the start-up heap (NumPy, SciPy, Zenoh, ...) never becomes garbage: moved out of the
        # collector's view, a full collection no longer walks it in the middle of a scan
        gc.collect()
        gc.freeze()
        while not self._stop:
            now = time.monotonic()
            due = min(self.deadlines.values(), default=now + 0.25)
            held_due = self.held.next_due()
            if held_due is not None:
                due = min(due, held_due)
            try:
                item = self.q.get(timeout=max(0.0, min(due - now, 0.25)))
            except queue.Empty:
                item = None
            try:
                if item is not None:
                    self._handle(*item)
                self._release_held()
                self._fire_deadlines()
                self._drain_records()
                self._flush_deferred()
            except Exception as exc:  # a bug must not take the peer (and the run) down
                self._internal_error(exc)
            if time.monotonic() - self._last_input > self.idle_timeout:
                self.stop_reason = f"no input for {self.idle_timeout:g} s"
                break

    def _handle(self, tag: str, key: str, payload) -> None:
        if tag == "stop":
            return
        wall = time.time()
        if tag == "live":
            peer = Keys.last(key)
            if peer == self.name:
                return
            if payload:
                self.seen_alive.add(peer)
                self._check_ready()
            what = "joined" if payload else "left"
            self.sink.text(f"peers/{self.name}/events", f"{peer} {what}")
            if peer != "world":
                self.live_events.append((peer, what, wall, self.logic.last_k))
            if payload:
                self.logic.on_peer_joined(peer, wall)
            else:
                self.logic.on_peer_left(peer)
            return
        if tag == "estimate" and Keys.last(key) == self.name:
            return  # our own publication
        self._last_input = time.monotonic()
        self.received[tag] += 1
        self.received_bytes[tag] += len(payload)
        try:
            msg = decode(payload)
        except Rejected as exc:
            self.rejected[exc.reason] += 1
            self.sink.scalar(f"metrics/rejected/{self.name}", sum(self.rejected.values()))
            return
        expected = {"scan": Scan, "estimate": Estimate, "truth": Truth, "ctl": Control}[tag]
        if not isinstance(msg, expected):
            self.rejected["wrong-key"] += 1
            return
        if isinstance(msg, Estimate) and msg.sender != Keys.last(key):
            self.rejected["spoofed"] += 1
            return
        t0 = time.perf_counter()
        if isinstance(msg, Scan):
            self.scan_sent[msg.k] = msg.send_time
            self.breakdown["transit"].append((wall - msg.send_time) * 1e3)
            self.sink.time(msg.k, msg.k * self.scan_period)
            out = self.logic.on_scan(msg, wall)
            self.compute_ms["filter"] += (time.perf_counter() - t0) * 1e3
            self.deadlines[msg.k] = time.monotonic() + self.deadline_frac * self.interval
            local_done = time.time()
            self.stage[msg.k] = (wall, local_done)
            self.breakdown["local"].append((local_done - wall) * 1e3)
            self._publish(out, local_done)
            self.logic.score_local()
            if msg.k == 1 or msg.k % 1000 == 0:
                self.rss_samples.append((msg.k, current_rss_mb()))
                self._flush_fault_log()
            self._log_local(msg.k)
        elif isinstance(msg, Estimate):
            if self.faults is not None and self._hold(msg, wall):
                return
            self._deliver(msg, wall)
        elif isinstance(msg, Truth):
            self.logic.on_truth(msg.k, msg.states)
        elif isinstance(msg, Control) and msg.command == "start":
            self.t0 = msg.send_time
        elif isinstance(msg, Control) and msg.command == "end":
            self.stop_reason = "end of run"
            self._stop = True

    def _flush_fault_log(self) -> None:
        """Move the injected-fault records to ``faults-into-<peer>.csv`` (memory stays flat)."""
        if self.faults is not None and self.out_dir is not None:
            self.faults.write_log(self.out_dir / f"faults-into-{self.name}.csv", append=True)

    def _check_ready(self) -> None:
        """Declare the ``ready`` token once every neighbour has been seen alive.

        The world starts the run when all peers are ready, so no peer misses its neighbours'
        first estimates while links are still being set up (matters with ``--no-gossip``).
        """
        if self._ready_token is None and self._session is not None and set(
                self.logic.o.neighbours) <= self.seen_alive:
            self._ready_token = self._session.liveliness().declare_token(
                self.keys.ready(self.name))

    def _run_time(self, wall: float) -> float:
        """Seconds on the run clock (scan ``k`` at ``k * interval``, as in the twin)."""
        t0 = self.t0 if self.t0 is not None else wall - self.logic.last_k * self.interval
        return wall - t0 + self.interval

    def _hold(self, msg: Estimate, wall: float) -> bool:
        """Injected link faults on the link ``sender -> self``: hold, duplicate or drop."""
        delays = self.faults.deliveries(msg.sender, self.name, self._run_time(msg.send_time),
                                        msg)
        transit = max(0.0, wall - msg.send_time)
        now = time.monotonic()
        for d in delays:
            self.held.push(now + max(0.0, d - transit), msg)
        return True

    def _release_held(self) -> None:
        for msg in self.held.pop_due(time.monotonic()):
            self._deliver(msg, time.time())

    def _deliver(self, msg: Estimate, wall: float) -> None:
        """Hand a neighbour estimate to the logic (on arrival, or when an injected delay ends)
        and publish what it returns; ``wall`` is when the logic got it (latency breakdown)."""
        self.last_arrival[msg.k] = wall
        t0 = time.perf_counter()
        out = self.logic.on_estimate(msg, wall)
        self.compute_ms["fusion"] += (time.perf_counter() - t0) * 1e3
        self._publish(out, time.time())

    def _internal_error(self, exc: Exception) -> None:
        """Count an unexpected error; print its traceback the first few times (to the log)."""
        name = type(exc).__name__
        self.errors[name] += 1
        if sum(self.errors.values()) <= 5:
            print(f"peer {self.name}: internal error {name}: {exc}", file=sys.stderr)
            traceback.print_exc()
        if self.logic._scan is not None:  # do not retry the scan that failed
            self.logic._scan.done = True

    def _fire_deadlines(self) -> None:
        now = time.monotonic()
        for k in [k for k, t in self.deadlines.items() if t <= now]:
            del self.deadlines[k]
            t0 = time.perf_counter()
            out = self.logic.on_deadline(k, time.time())
            self.compute_ms["fusion"] += (time.perf_counter() - t0) * 1e3
            self._publish(out, time.time())

    def _finish(self) -> None:
        """Fuse what is pending, then write the summary (also on SIGINT/SIGTERM)."""
        if self.stop_reason == "end of run":  # handle what already arrived, then stop
            while True:
                try:
                    item = self.q.get_nowait()
                except queue.Empty:
                    break
                try:
                    self._handle(*item)
                except Exception as exc:
                    self._internal_error(exc)
            self._release_held()
        self._flush_fault_log()
        if self.saved_tracks is not None and self.out_dir is not None:
            np.savez(self.out_dir / f"tracks-{self.name}.npz",
                     **{f"k{k}": v for k, v in self.saved_tracks.items()})
        for k in sorted(self.deadlines):
            self._publish(self.logic.on_deadline(k, time.time()), time.time())
        self.deadlines.clear()
        self._drain_records()
        self._flush_deferred(force=True)
        self.write_summary()

    # -- records, Rerun, summary ------------------------------------------------------------
    def _on_tracks(self, msg: Tracks, now_wall: float) -> None:
        if self.saved_tracks is not None:
            self.saved_tracks[msg.k] = msg.states
        sent = self.scan_sent.pop(msg.k, None)
        stage = self.stage.pop(msg.k, None)
        if stage is not None:
            self.breakdown["fusion_wait"].append((now_wall - stage[1]) * 1e3)
            last = self.last_arrival.pop(msg.k, None)
            if last is not None and last > stage[1]:  # waited for a neighbour, then fused
                self.breakdown["neighbours"].append((last - stage[1]) * 1e3)
                self.breakdown["fusing"].append((now_wall - last) * 1e3)
        for old in [k for k in self.last_arrival if k < msg.k - 10]:
            del self.last_arrival[old]
        for old in [k for k in self.stage if k < msg.k - 10]:
            del self.stage[old]
        if sent:
            lat = (now_wall - sent) * 1e3
            self.latency_ms.append(lat)
            self.sink.scalar(f"metrics/latency_ms/{self.name}", lat)
        for old in [k for k in self.scan_sent if k < msg.k - 10]:
            del self.scan_sent[old]
        self.sink.time(msg.k, msg.k * self.scan_period)
        xy = (msg.states[:, position_columns(msg.states.shape[1])] if len(msg.states)
              else np.zeros((0, 2)))
        self.sink.points(f"peers/{self.name}/tracks", xy, self.color, radius=5.0)
        self.tails.append(xy)
        if self.sink.enabled:
            self.sink.points(f"peers/{self.name}/tail", np.concatenate(list(self.tails)),
                             self.color, radius=1.5)
        self.sink.scalar(f"metrics/cardinality/{self.name}/fused", len(msg.states))

    def _log_local(self, k: int) -> None:
        """Log the local estimate of scan ``k`` to Rerun, later: see :meth:`_flush_deferred`."""
        if not self.sink.enabled:
            return
        mix = self.logic.mix
        particles = getattr(self.logic, "particles", lambda: None)()
        filter_total = self.compute_ms["filter"]

        def log() -> None:
            self.sink.time(k, k * self.scan_period)
            self.sink.mixture(f"peers/{self.name}/local", mix, self.color)
            if particles is not None:  # IMM-PF peers: the particle cloud
                self.sink.points(f"peers/{self.name}/particles", particles, self.color,
                                 radius=1.0)
            self.sink.scalar(f"metrics/compute_ms/{self.name}/filter_total", filter_total)

        self._deferred.append(log)

    def _flush_deferred(self, force: bool = False) -> None:
        """Run the deferred Rerun logging once the scan's tracks are out and nothing waits.

        Drawing the local mixture (ellipses) right after publishing it took CPU from the
        neighbours' filter steps on a shared machine, in the very burst that sets the
        scan-to-track latency; the recording is the same, only written a few ms later.
        """
        if not self._deferred or not (force or len(self._deferred) > 10 or (
                self.q.empty() and not self.logic.busy())):
            return
        pending, self._deferred = self._deferred, []
        for log in pending:
            log()

    def _drain_records(self) -> None:
        for r in self.logic.drain_records():
            kind = r["kind"]
            if kind == "fusion":
                for age in r["ages"].values():
                    self.ages.append(age)
                if self.sink.enabled:
                    self.sink.time(r["k"], r["k"] * self.scan_period)
                    self.sink.scalar(f"metrics/components/{self.name}/fused", r["n_fused"])
                    if r["ages"]:
                        self.sink.scalar(f"metrics/age/{self.name}", max(r["ages"].values()))
                    c = self.logic.nale.counts
                    for what in ("late", "redundant", "too_old", "dropped_late"):
                        self.sink.scalar(f"metrics/out_of_sequence/{self.name}/{what}",
                                         getattr(c, what))
                    fused = self.logic.current_fused()
                    if fused is not None:
                        self.sink.mixture(f"peers/{self.name}/fused", fused, self.color)
            elif kind == "local" and self.sink.enabled:
                self.sink.scalar(f"metrics/components/{self.name}/before_level2",
                                 r["n_components"])
                self.sink.scalar(f"metrics/components/{self.name}/after_level2",
                                 r["n_published"])
            elif kind == "models" and self.sink.enabled:
                self.sink.time(r["k"], r["k"] * self.scan_period)
                for model, p in r.items():
                    if model not in ("k", "kind"):
                        self.sink.scalar(f"metrics/model_probability/{self.name}/{model}", p)
            elif kind == "ospa" and self.sink.enabled:
                self.sink.time(r["k"], r["k"] * self.scan_period)
                self.sink.scalar(f"metrics/ospa/{self.name}/{r['which']}", r["value"])

    def summary(self) -> dict:
        lat = sorted(self.latency_ms)
        stats = asdict(self.logic.stats)
        return {
            "peer": self.name,
            "stop_reason": self.stop_reason,
            "scans": self.logic.stats.scans,
            "mean_ospa_local": self.logic.mean_ospa("local"),
            "mean_ospa_fused": self.logic.mean_ospa("fused"),
            "messages_sent": sum(self.sent.values()),
            "bytes_sent": sum(self.sent_bytes.values()),
            "messages_received": sum(self.received.values()),
            "bytes_received": sum(self.received_bytes.values()),
            "received_by_kind": dict(self.received),
            "rejected": dict(self.rejected),
            "rejected_total": sum(self.rejected.values()),
            "internal_errors": dict(self.errors),
            "peer_events": self.live_events[-1000:],
            "rss_mb_samples": self.rss_samples[-100:] + [(self.logic.last_k, current_rss_mb())],
            "injected_faults": self.faults.counts() if self.faults is not None else {},
            "mean_estimate_age": statistics.fmean(self.ages) if self.ages else None,
            "latency_ms_median": statistics.median(lat) if lat else None,
            "latency_ms_p99": lat[min(len(lat) - 1, int(0.99 * len(lat)))] if lat else None,
            "compute_ms": self.compute_ms,
            "latency_breakdown_ms_median": {
                n: statistics.median(v) if v else None for n, v in self.breakdown.items()},
            "nale": asdict(self.logic.nale.counts),
            "stats": stats,
            "estimate_bytes_sent": self.sent_bytes["estimate"],
            "estimates_sent": self.sent["estimate"],
            "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "cpu_s": time.process_time(),
            "cpu_s_running": time.process_time() - getattr(self, "_cpu_at_start", 0.0),
            "pid": os.getpid(),
        }

    def write_summary(self) -> None:
        if self.out_dir is None:
            return
        path = self.out_dir / f"peer-{self.name}.json"
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.summary(), indent=2, default=float))
        tmp.replace(path)
