"""What a peer process measures about itself: latency and where it goes, compute, memory, bytes.

The sans-I/O core has no clock of its own; the driver stamps its outputs and records with wall
time here. Per scan ``k`` (milliseconds): ``transit`` (world sent the scan -> it arrived),
``local`` (arrived -> local estimate out), ``fusion_wait`` (local estimate out -> tracks out),
split into ``neighbours`` (-> last neighbour estimate in) and ``fusing`` (-> tracks out); and the
scan-to-track ``latency`` (world sent the scan -> tracks out).
"""

from __future__ import annotations

import os
import resource
import statistics
import time
from collections import Counter, deque
from collections.abc import Iterator
from contextlib import contextmanager

from sensornet.peers.core import Publish, Record

BREAKDOWN = ("transit", "local", "fusion_wait", "neighbours", "fusing")
_KEEP = 4096  # samples kept per series (memory stays flat in long runs)
_BY_SCAN_MAX = 500_000  # per-scan latencies kept for the results table (peers.scan_results)
_SCANS_KEPT = 10  # per-scan stamps older than this many scans are dropped


def current_rss_mb() -> float:
    """This process's resident memory now (MB), from /proc (0 where there is none)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return 0.0


def percentile(sorted_values, q: float) -> float | None:
    """The sample at index ``floor(q n)`` of ``n`` sorted samples (no interpolation)."""
    v = sorted_values
    return v[min(len(v) - 1, int(q * len(v)))] if len(v) else None


def _median(v) -> float | None:
    return statistics.median(v) if v else None


class SharedCpu:
    """The CPU of one process that several peers share (a :class:`peers.host.PeerHost`).

    Each peer's own steps (its core, publishing, telemetry) are measured as in a process of its
    own; what the peers share is split evenly between them: the rest of the host loop's thread
    ("loop") and every other thread ("transport": Zenoh's threads and the callbacks), so the
    hosted peers' ``cpu_s_running`` add up to the process's. Read from the loop's thread."""

    def __init__(self) -> None:
        self.peers: list[Telemetry] = []
        self.start()

    def start(self) -> None:
        self._cpu0, self._thread0 = time.process_time(), time.thread_time()
        self._aside_main = self._aside_total = 0.0
        self._open: tuple[float, float] | None = None

    @contextmanager
    def aside(self) -> Iterator[None]:
        """CPU spent inside is not the run's: a peer writing its files after its last scan
        (one-off work, not a cost per scan; the other peers' shares must not carry it)."""
        if self._open is not None:  # nested: the outer one sets it all aside
            yield
            return
        self._open = (time.thread_time(), time.process_time())
        try:
            yield
        finally:
            t0, c0 = self._open
            self._open = None
            self._aside_main += time.thread_time() - t0
            self._aside_total += time.process_time() - c0

    def shares(self) -> tuple[float, float]:
        """One peer's share (ms) of the loop's own work and of the other threads'."""
        thread, process = time.thread_time(), time.process_time()
        if self._open is not None:  # read from inside aside(): stop the clocks at its start
            thread, process = self._open
        main = (thread - self._thread0 - self._aside_main) * 1e3
        total = (process - self._cpu0 - self._aside_total) * 1e3
        own = sum(sum(t.cpu_ms.values()) for t in self.peers)
        n = max(1, len(self.peers))
        return max(0.0, main - own) / n, max(0.0, total - main) / n


class Telemetry:
    """Counters and timings of one peer process (or of one peer in a shared process)."""

    def __init__(self, shared: SharedCpu | None = None) -> None:
        self.shared = shared
        if shared is not None:
            shared.peers.append(self)
        self.sent: Counter = Counter()
        self.sent_bytes: Counter = Counter()
        self.latency_ms: deque = deque(maxlen=_KEEP)
        self.latency_by_scan: dict[int, float] = {}
        """Scan -> published fused tracks (ms) for every scan (the per-scan results table)."""
        self.breakdown = {n: deque(maxlen=_KEEP) for n in BREAKDOWN}
        self.compute_ms = {"filter": 0.0, "fusion": 0.0}
        self.per_scan_ms: deque = deque(maxlen=_KEEP)
        self.ages: deque = deque(maxlen=_KEEP)
        self.rss_samples: list[tuple[int, float]] = []
        self.internal_errors: Counter = Counter()
        self.scans_skipped_behind = 0  # scans left out to catch up (see PeerRuntime._catch_up)
        self.cpu_ms: dict[str, float] = {"publish": 0.0, "telemetry": 0.0}
        """Main-thread CPU (ms) by what it did: core steps by channel, publishing, telemetry
        (the observer's per-scan report for live views; peers log nothing to Rerun)."""
        self._thread0 = time.thread_time()
        self._scan_sent: dict[int, float] = {}
        self._local_done: dict[int, float] = {}
        self._last_in: dict[int, float] = {}
        self._cpu0 = time.process_time()

    def handled(self, channel: str, entry: float, leave: float, outputs: list) -> None:
        """One input handled between wall times ``entry`` and ``leave``."""
        ms = (leave - entry) * 1e3
        self.compute_ms["filter" if channel == "scan" else "fusion"] += ms
        for o in outputs:
            if not isinstance(o, Record):
                continue
            if o.kind == "scan":
                self._scan_sent[o.k] = o.values["send_time"]
                self.breakdown["transit"].append((entry - o.values["send_time"]) * 1e3)
                self.breakdown["local"].append(ms)
                self._local_done[o.k] = leave
                self.per_scan_ms.append(ms)
                if o.k == 1 or o.k % 1000 == 0:
                    self.rss_samples.append((o.k, current_rss_mb()))
                    self.rss_samples = self.rss_samples[-100:]
            elif o.kind == "estimate":
                self._last_in[o.k] = entry
            elif o.kind == "fusion" and o.values.get("round", 1) <= 1:
                # ages are measured in a scan's first round (later rounds' records say 0)
                self.ages.extend(o.values.get("ages", {}).values())

    def published(self, out: Publish, wall: float, nbytes: int) -> float | None:
        """An output went on the wire at ``wall``; the scan-to-track latency (ms) for tracks."""
        self.sent[out.channel] += 1
        self.sent_bytes[out.channel] += nbytes
        if out.channel != "tracks":
            return None
        k = out.k
        local = self._local_done.pop(k, None)
        if local is not None:
            self.breakdown["fusion_wait"].append((wall - local) * 1e3)
            last = self._last_in.pop(k, None)
            if last is not None and last > local:  # waited for a neighbour, then fused
                self.breakdown["neighbours"].append((last - local) * 1e3)
                self.breakdown["fusing"].append((wall - last) * 1e3)
        sent = self._scan_sent.pop(k, None)
        for d in (self._scan_sent, self._local_done, self._last_in):
            for old in [kk for kk in d if kk < k - _SCANS_KEPT]:
                del d[old]
        if sent is None:
            return None
        lat = (wall - sent) * 1e3
        self.latency_ms.append(lat)
        if len(self.latency_by_scan) < _BY_SCAN_MAX:
            self.latency_by_scan[k] = lat
        return lat

    def start_cpu(self) -> None:
        """CPU from here on is the run's (start-up, imports and session set-up excluded)."""
        self._cpu0, self._thread0 = time.process_time(), time.thread_time()
        self._frozen = None
        self.cpu_ms = dict.fromkeys(self.cpu_ms, 0.0)

    _frozen: tuple[float, float] | None = None

    @contextmanager
    def after_run(self) -> Iterator[None]:
        """The run is over (last fusion done): what follows (writing the summary, results,
        tracks and fault log) is one-off work, not CPU per scan. A peer of its own process
        stops its clocks here; a hosted peer's work inside is set aside from the host's shared
        CPU (:meth:`SharedCpu.aside`), so no peer's share carries another's file writing."""
        if self.shared is not None:
            with self.shared.aside():
                yield
            return
        if self._frozen is None:
            self._frozen = (time.process_time(), time.thread_time())
        yield

    def _clocks(self) -> tuple[float, float]:
        """(process, thread) CPU seconds now, or when the run ended (:meth:`after_run`)."""
        return self._frozen or (time.process_time(), time.thread_time())

    def cpu_breakdown(self) -> dict[str, float]:
        """Process CPU (ms) since :meth:`start_cpu`, split: the main thread's core steps by channel,
        publishing, telemetry and the rest of its loop ("loop": queue, liveliness, telemetry), and
        every other thread ("transport": Zenoh's threads and the callbacks that admit messages).
        A core step includes decoding what it received and encoding what it publishes."""
        out = {k: round(v, 3) for k, v in self.cpu_ms.items()}
        if self.shared is not None:  # a hosted peer: its own steps, its share of the rest
            loop, transport = self.shared.shares()
            out["loop"], out["transport"] = round(loop, 3), round(transport, 3)
            return out
        process, thread = self._clocks()
        main = (thread - self._thread0) * 1e3
        total = (process - self._cpu0) * 1e3
        out["loop"] = round(max(0.0, main - sum(self.cpu_ms.values())), 3)
        out["transport"] = round(max(0.0, total - main), 3)
        return out

    def cpu_s_running(self) -> float:
        """Process CPU (s) since :meth:`start_cpu`; a hosted peer's: its part of it."""
        if self.shared is not None:
            return sum(self.cpu_breakdown().values()) / 1e3
        return self._clocks()[0] - self._cpu0

    def summary(self, last_k: int) -> dict:
        lat = sorted(self.latency_ms)
        return {
            "messages_sent": sum(self.sent.values()),
            "bytes_sent": sum(self.sent_bytes.values()),
            "estimates_sent": self.sent["estimate"],
            "estimate_bytes_sent": self.sent_bytes["estimate"],
            "latency_ms_median": statistics.median(lat) if lat else None,
            "latency_ms_p99": percentile(lat, 0.99),
            "latency_ms_samples": [round(x, 4) for x in self.latency_ms],
            "compute_ms": dict(self.compute_ms),
            "latency_breakdown_ms_median": {n: _median(v) for n, v in self.breakdown.items()},
            "mean_estimate_age": statistics.fmean(self.ages) if self.ages else None,
            "driver_errors": dict(self.internal_errors),
            "scans_skipped_behind": self.scans_skipped_behind,
            "rss_mb_samples": [*self.rss_samples, (last_k, current_rss_mb())],
            "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "cpu_s": time.process_time(),
            "cpu_s_running": self.cpu_s_running(),
            "cpu_ms_breakdown": self.cpu_breakdown(),
            "pid": os.getpid(),
        }
