"""The live view: a process of its own that subscribes to a network and builds its Rerun
recording from what is on the wire (issue 38; ``sensornet view NETWORK --connect EP``).

Peers log nothing to Rerun: like RViz or Foxglove on ROS 2 topics, the view only subscribes
(the world's scans and scan bundles, truth and control, and each peer's per-scan
:class:`protocol.messages.Telemetry` with its tracks, alone or in its host's bundle), never to
a key the peers publish for each other (estimates, tracks: each put there would fan out to
the view too, and the peers would pay per message for the watcher), so a network never pays
for who watches it beyond its reports, and a view
that falls behind drops or decimates its own work (counted, and said in one line), never the
peers'.

Three concerns, three modules: this one the subscription, its bounded queue and the drain and
flush loop (:class:`LiveView`) and the offline replay of MCAP recordings;
:mod:`sensornet.view_state` what each message looks like (:class:`ViewState`);
:mod:`sensornet.view_columns` the batched Rerun writer (:class:`Batcher`). Their public names
are importable from here as before.
"""

from __future__ import annotations

import hashlib
import os
import queue
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import zenoh

from sensornet.peers.recording import TOPICS as RECORDED
from sensornet.peers.recording import read as read_recording
from sensornet.peers.session import DIAL_SOON, SessionError, zenoh_config
from sensornet.protocol.codec import Rejected, encode
from sensornet.protocol.keys import ROOT, Keys
from sensornet.protocol.messages import Truth
from sensornet.view_columns import Batcher, strip_array
from sensornet.view_state import TAIL, ViewState, id_color, id_labels, later_round

__all__ = ["BEHIND", "BEHIND_S", "END_DRAIN_S", "FLUSH_MAX_S", "FLUSH_S", "FLUSH_SHARE",
           "MAP_KEEP", "QUEUE_MAX", "SERIES_EVERY", "TAIL",
           "Batcher", "LiveView", "ViewState", "cpu_seconds", "id_color", "id_labels",
           "idle_process", "later_round", "nice_process", "normal_process", "replay_recordings",
           "strip_array", "thread_policies"]

FLUSH_S = 1.0
"""Seconds of rows gathered per entity before one send (Rerun's native call behind
``send_columns``, :meth:`sensornet.view_columns.Batcher.flush`; doubled, up to
:data:`FLUSH_MAX_S`, while a flush takes more than :data:`FLUSH_SHARE` of its period)."""
FLUSH_MAX_S = 8.0
FLUSH_SHARE = 0.25
MAP_KEEP = 12
"""Newest scans of one map entity kept per flush while the view is behind (more than
:data:`BEHIND` / 4 messages waiting, or none handled with an empty queue for
:data:`BEHIND_S`): older ones are decimated (counted)."""
BEHIND_S = 2.0
"""Seconds without the view's queue once empty beyond which the view is behind (its own clock:
no sender's): at 50 peers in two hosts a scan is ~5 messages, so :data:`BEHIND` / 4 waiting
messages came only ~10 s behind, and a view in SCHED_IDLE that a busy network leaves little
CPU must catch up sooner."""
END_DRAIN_S = 10.0
"""Seconds the view spends at its end on the messages still waiting (those heard before it
stopped); what is left after is counted as dropped and said."""
SERIES_EVERY = 4
"""The health series go at the first flush, then once :data:`FLUSH_S` x this many seconds of
flush periods have passed (every 4th flush at 1 s, every 2nd at 2 s, every flush from 4 s);
the map, and a new entity's first rows, go every flush. At 50 peers ~1,500 of the view's
~1,950 entities a flush are series, each a chunk Rerun encodes (~90 us an entity with the
view's own part): held back, their rows go in fewer, longer chunks. Every flush they cost
29.1 ms of CPU a scan against 26.4 every 4 s (medians of 3, lower in each pair;
``bench_view.py --series-every 1,4 --repeats 3``, 12 s of the twin's traffic in real time
through the view's loop, flush period 2 s, load 4.4-5.8, 131992c; 22.2 against 24.0 before
it, when flushes took long enough to double the period to 4-8 s anyway)."""
PEERS_WAIT_S = 5.0
"""Seconds a run's view (``sensornet view --until-end --scenario``: it knows the peers) waits
at most for every peer's liveliness token before it subscribes to the truth
(:meth:`LiveView.open`). A peer's token here says the peer is linked to the view, so it has
the view's telemetry subscription and reports from its first scan; the run's world holds its
first scan until the truth has a subscriber (``--view-wait``). Bounded: a peer that does not
come (a view attached to a network without it) costs the view this much, once."""
QUEUE_MAX = 20_000
"""Messages waiting for the view; more are dropped on arrival (counted)."""
BEHIND = 2_000
"""Waiting messages above which estimates (the heaviest to draw) are skipped unread."""


class LiveView:
    """The view process: a Zenoh subscription on ``sensornet/<network>/**`` feeding a bounded
    queue (full: dropped, counted), drained by :meth:`run` into a :class:`ViewState`, flushed
    to Rerun every :data:`FLUSH_S` seconds."""

    def __init__(self, network: str, state_factory, rr, rec, connect: Sequence[str] = (),
                 config: str | None = None, say: Callable[[str], None] | None = None,
                 estimates: bool = False, security=None, discard: bool = False,
                 peers: Sequence[str] = ()) -> None:
        """``estimates``: hear the peers' estimates too (the local marks of peers that send
        no telemetry); by default not: the local estimate rides in each peer's telemetry,
        and every peer would send the view a copy of each of its heaviest messages (+5 %
        of the peers' CPU at seed 004). ``security``: a
        :class:`peers.security.Security` of a read-only observer (``view``) to join a secure
        network (mutual TLS; the network's access control lets it subscribe, not put).
        ``discard`` (a diagnostic): subscribe as usual but drop every message on arrival but
        the world's control (its end), counted in :attr:`discarded`: what a subscriber's mere
        presence costs the peers, without the view's drawing. ``peers``: the run's peers, whose
        liveliness tokens :meth:`open` waits for (:data:`PEERS_WAIT_S`) before it subscribes
        to the truth; none: no wait."""
        self.network = network
        self.peers = list(peers)
        self.discard = discard
        self.discarded = 0
        self.estimates = estimates
        self.connect, self.config = list(connect), config
        self.security = security
        self.state: ViewState | None = None
        if state_factory is not None:
            self.draw_into(state_factory, rr, rec)
        self.q: queue.Queue = queue.Queue(maxsize=QUEUE_MAX)
        self.dropped = 0
        self.skipped = 0
        self.drawn = 0
        """Messages drawn so far (``run``'s ``count``)."""
        self.flush_s = FLUSH_S
        self.say = say or (lambda s: print(s, file=sys.stderr, flush=True))
        self.stop = threading.Event()
        self.at_end: Callable[[], object] | None = None
        """Called once the drawing loop stops, before the last messages are drawn and the
        recording closed (``sensornet view --idle``: back to normal scheduling, so a view left
        no CPU while the network ran still writes its recording within the run's grace)."""
        self._said = (0, 0, 0)
        self._said_at = 0.0
        self._between = 0.0
        """Seconds of the flush under way spent handling messages (:meth:`waiting`)."""
        self.flushes = 0
        self._series_s = 0.0
        """Seconds of flush periods since the health series last went (:meth:`flush`)."""
        self._reported = 0
        """Peers of ``state.first_report`` said to be in the recording (:meth:`reporting`)."""
        self._empty_at = time.monotonic()
        """When the view last found its queue empty (:meth:`behind`)."""
        self.session = None

    def draw_into(self, state_factory, rr, rec) -> None:
        """Where to draw (before :meth:`run`; what arrives meanwhile waits in the queue): the
        view process subscribes first and opens its recording after (0.8 s), so it hears a
        short run from its first scan."""
        self.rr, self.rec = rr, rec
        self.batcher = Batcher(rr, rec)
        self.state = state_factory(self.batcher)

    def open(self) -> None:
        # the run starts the view before the world listens: dial it soon (DIAL_SOON)
        conf = zenoh_config((), self.connect, self.config, security=self.security,
                            retry=DIAL_SOON)
        try:
            self.session = zenoh.open(conf)
        except Exception as exc:
            raise SessionError(f"cannot open Zenoh session (connect {self.connect}): "
                               f"{exc}") from None
        k = Keys(self.network)  # each channel by name: what an observer may subscribe to
        # no tracks/<peer>: each peer's tracks come with its reports (peers.observer)
        exprs = [k.scan(), k.scans(), k.ctl(), k.telemetry(), k.telemetries(),
                 *([k.estimate()] if self.estimates else [])]
        self._subs = [self.session.declare_subscriber(e, self._on_sample) for e in exprs]
        if self.peers:
            self._await_peers(k)
        # the truth last: a run's world holds its first scan until the truth has a subscriber
        # (--view-wait), by when every peer has the view's telemetry subscription
        self._subs.append(self.session.declare_subscriber(k.truth(), self._on_sample))

    def _await_peers(self, k: Keys) -> None:
        """Until every peer of :attr:`peers` has its liveliness token here (linked to the
        view: it heard the view's subscriptions), a stop, or :data:`PEERS_WAIT_S` (then one
        line naming those missing: their first reports may not be drawn)."""
        want, seen, cond = set(self.peers), set(), threading.Condition()

        def on_live(sample) -> None:  # Zenoh's thread
            if sample.kind == zenoh.SampleKind.PUT:
                with cond:
                    seen.add(Keys.last(str(sample.key_expr)))
                    cond.notify_all()

        sub = self.session.liveliness().declare_subscriber(k.alive("*"), on_live,
                                                           history=True)
        end = time.monotonic() + PEERS_WAIT_S
        try:
            with cond:
                while not want <= seen and not self.stop.is_set():
                    left = end - time.monotonic()
                    if left <= 0:
                        self.say(f"view: peers {', '.join(sorted(want - seen))} not linked "
                                 f"within {PEERS_WAIT_S:g} s: their first reports may be "
                                 "missed")
                        break
                    cond.wait(min(left, 0.2))  # a stop (signal) is seen within 0.2 s
        finally:
            sub.undeclare()

    def _on_sample(self, sample) -> None:
        if self.discard and not str(sample.key_expr).endswith("/ctl"):
            self.discarded += 1
            return
        try:
            self.q.put_nowait((str(sample.key_expr), sample.payload.to_bytes()))
        except queue.Full:
            self.dropped += 1

    def close(self) -> None:
        for sub in getattr(self, "_subs", []):
            try:
                sub.undeclare()
            except Exception:  # the session is gone already
                pass
        if self.session is not None:
            self.session.close()
            self.session = None

    def drain(self, budget: float) -> int:
        """Handle what waits, for at most ``budget`` seconds; estimates skipped unread while
        more than :data:`BEHIND` messages wait (counted)."""
        end = time.monotonic() + budget
        n = 0
        while time.monotonic() < end:
            try:
                key, payload = self.q.get(timeout=max(0.0, min(0.05, end - time.monotonic())))
            except queue.Empty:
                self._empty_at = time.monotonic()
                break
            n += self._take(key, payload)
        return n

    def _take(self, key: str, payload: bytes) -> int:
        """Draw one message (1), or skip an estimate while behind (0, counted)."""
        if "/estimate/" in key and self.q.qsize() > BEHIND:
            self.skipped += 1
            return 0
        self.state.receive(key, payload)
        self.drawn += 1
        return 1

    def waiting(self) -> None:
        """Handle the messages waiting now, without waiting for more (between the parts of a
        flush: a long flush would hold them back, and the view would run behind by it)."""
        t0 = time.monotonic()
        for _ in range(self.q.qsize()):
            try:
                key, payload = self.q.get_nowait()
            except queue.Empty:
                break
            self._take(key, payload)
        if self.q.empty():
            self._empty_at = time.monotonic()
        self._between += time.monotonic() - t0

    def flush(self) -> None:
        """The batcher's rows to Rerun, handling what arrives meanwhile, the health series'
        when :data:`SERIES_EVERY` periods of :data:`FLUSH_S` have passed; the period doubles
        while a flush (its own part) takes more than :data:`FLUSH_SHARE` of it."""
        t0 = time.monotonic()
        self._between = 0.0
        self.batcher.map_keep = MAP_KEEP if self.behind() else None
        self.flushes += 1
        self._series_s += self.flush_s
        hold = ("scalar",)
        if self.flushes == 1 or self._series_s >= SERIES_EVERY * FLUSH_S - 1e-9:
            hold, self._series_s = (), 0.0
        heard = self._heard()  # drawn before this flush: all sent by it
        self.batcher.flush(between=self.waiting, hold=hold)
        took = time.monotonic() - t0 - self._between
        if took > FLUSH_SHARE * self.flush_s and self.flush_s < FLUSH_MAX_S:
            self.flush_s = min(FLUSH_MAX_S, 2 * self.flush_s)
        self.note()
        self.reporting(heard)  # a first report's series are new: never held

    def _heard(self) -> int:
        """Peers whose first report is drawn (0 with nothing to draw into yet)."""
        return len(getattr(self.state, "first_report", ()))

    def reporting(self, heard: int) -> None:
        """One line naming the peers whose first reports a flush has just sent to the
        recording (the first ``heard`` of ``state.first_report``): the view's own word that it
        hears and has drawn them, which a script or test can wait on (a view that starts late
        on a busy machine links after a short run's first scans, or after its end)."""
        if heard > self._reported:
            new = list(self.state.first_report.items())[self._reported:heard]
            self._reported = heard
            self.say("view: drew the first reports of "
                     + ", ".join(f"{n} (scan {k})" for n, k in new))

    def behind(self) -> bool:
        """Whether the view runs behind the network: more than :data:`BEHIND` / 4 messages
        wait, or its queue has not been empty for :data:`BEHIND_S` (a view that keeps up
        empties it every drain)."""
        return (self.q.qsize() > BEHIND // 4
                or time.monotonic() - self._empty_at > BEHIND_S)

    def note(self, final: bool = False) -> None:
        """One line when the view fell behind (at most every 5 s): what it left out."""
        now = (self.dropped, self.skipped, self.batcher.decimated)
        if now != self._said and (final or time.monotonic() - self._said_at > 5.0):
            self.say(f"view: behind the network: {now[0]} messages dropped (on arrival or "
                     f"unread at the end), "
                     f"{now[1]} estimates skipped, {now[2]} map frames decimated (the view's "
                     f"own work; the peers are not affected); flushing every {self.flush_s:g} s")
            self._said, self._said_at = now, time.monotonic()

    def run(self, duration: float | None = None, until_end: bool = False,
            grace: float = 3.0, count: int | None = None) -> None:
        """Until :attr:`stop`, ``duration`` seconds, ``count`` messages drawn, or
        (``until_end``) ``grace`` seconds after the world's end message; flushes at the end."""
        t0 = time.monotonic()
        next_flush = t0 + self.flush_s
        ended_at = None
        while not self.stop.is_set():
            now = time.monotonic()
            if duration is not None and now - t0 >= duration:
                break
            if count is not None and self.drawn >= count:
                break
            if until_end and self.state.ended:
                ended_at = ended_at or now
                if now - ended_at >= grace:
                    break
            self.drain(min(0.2, max(0.0, next_flush - now)))
            if time.monotonic() >= next_flush:
                self.flush()
                next_flush = time.monotonic() + self.flush_s
        if self.at_end is not None:
            self.at_end()
        self.drain(0.5)
        self.finish()
        heard = self._heard()
        self.batcher.flush()
        self.note(final=True)
        self.reporting(heard)

    def finish(self) -> None:
        """The messages still waiting at the end (heard before the view stopped: a view that
        ran behind has seconds of them), for at most :data:`END_DRAIN_S` seconds; the rest
        counted as dropped."""
        end = time.monotonic() + END_DRAIN_S
        while time.monotonic() < end:
            try:
                key, payload = self.q.get_nowait()
            except queue.Empty:
                return
            self._take(key, payload)
        while True:
            try:
                self.q.get_nowait()
            except queue.Empty:
                return
            self.dropped += 1


def replay_recordings(state: ViewState, paths: Sequence[Path]) -> int:
    """Rebuild the picture offline from peers' MCAP recordings (``sensornet run --record``:
    what each peer received, its own tracks, the truth it scored against and its telemetry),
    merged in time order; a message heard by several peers (a scan, the truth) is drawn once.
    A recording with telemetry (its tracks and reports, as the live view hears them: fused
    marks, events, health series) has its tracks drawn from it, as the live view does; an
    older one's from its ``tracks`` records. Returns the messages drawn. A file that is not a
    whole recording is a one-line ValueError naming it; a record of the wrong shape is
    counted in ``state.rejected``, as an undecodable message is."""
    merged = []
    for path in paths:
        try:
            meta, records = read_recording(Path(path), (*RECORDED, "truth", "telemetry"))
        except (ValueError, KeyError, TypeError) as exc:  # not MCAP, cut short, bad records
            raise ValueError(f"{path}: {exc}") from None
        peer, network = meta.get("peer", "?"), meta.get("network", "net")
        drawn_from = {"receive", "truth", "telemetry"}  # tracks within the telemetry
        if not any(topic == "telemetry" for topic, _ in records):
            drawn_from = {"receive", "truth", "tracks"}  # recorded before the telemetry was
        for topic, r in records:
            if topic in drawn_from:
                item = _drawable(topic, r, f"{ROOT}/{network}", peer)
                if item is None:
                    state.rejected += 1
                else:
                    merged.append(item)
    merged.sort(key=lambda m: m[0])
    seen: set[bytes] = set()
    drawn = 0
    for _, key, payload in merged:
        digest = hashlib.blake2b(payload, digest_size=16).digest()
        if digest in seen:
            continue
        seen.add(digest)
        state.receive(key, payload)
        drawn += 1
    return drawn


def _drawable(topic: str, r, prefix: str, peer: str) -> tuple[float, str, bytes] | None:
    """A recorded ``receive``, ``tracks``, ``truth`` or ``telemetry`` record as ``(time, key,
    message)`` for the view, or None if it has not the shape the view reads (a time, a key or
    scan, the message's bytes, or the truth's ids and states). Peers hear no truth message:
    the truth their scorer had is recorded, and goes as the world's Truth message (the same
    bytes from every peer: drawn once)."""
    if not (isinstance(r, (list, tuple)) and len(r) >= 2 and isinstance(r[0], (int, float))
            and not isinstance(r[0], bool)):
        return None
    if topic == "telemetry" and isinstance(r[1], (bytes, bytearray)):
        return float(r[0]), f"{prefix}/telemetry/{peer}", bytes(r[1])
    if len(r) < 3:
        return None
    if topic == "receive" and isinstance(r[1], str) and isinstance(r[2], (bytes, bytearray)):
        return float(r[0]), r[1], bytes(r[2])
    if topic == "tracks" and isinstance(r[2], (bytes, bytearray)):
        return float(r[0]), f"{prefix}/tracks/{peer}", bytes(r[2])
    if topic == "truth" and len(r) >= 4:
        try:
            ids = np.asarray(r[2], np.int64).reshape(-1)
            states = np.asarray(r[3], float).reshape(len(ids), -1) if len(ids) else \
                np.zeros((0, 2))  # none: the dimension was not kept, nor is it needed
            return float(r[0]), f"{prefix}/truth", encode(Truth(int(r[1]), ids, states))
        except (Rejected, ValueError, TypeError, OverflowError):  # no ids, ragged, ...
            return None
    return None


def nice_process(increment: int) -> int:
    """Lower every thread of this process's CPU priority by ``increment`` (at most to 19);
    returns the threads changed. On Linux a nice value is a thread's own (``os.nice`` lowers
    the caller's only): the view's Zenoh, callback and Rerun threads would keep competing
    with the peers at full priority. Threads started later inherit their starter's value."""
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:  # no /proc: the process's value, as the platform defines it
        os.nice(increment)
        return 1
    changed = 0
    for tid in tids:
        try:
            now = os.getpriority(os.PRIO_PROCESS, tid)
            os.setpriority(os.PRIO_PROCESS, tid, min(19, now + increment))
            changed += 1
        except OSError:  # the thread has ended meanwhile
            pass
    return changed


def idle_process(fallback_nice: int = 10, tids: Sequence[int] | None = None) -> tuple[str, int]:
    """Put every thread of this process (or the threads ``tids``) in Linux's ``SCHED_IDLE``
    class (sched(7)): it runs only on CPU time no normal thread wants, and a normal thread
    that wakes preempts it at once, where a niced thread still takes its weighted share and
    its slice first. The view's drawing then never delays a peer on the cores they share
    (issue 38); a view left no CPU falls behind alone (its queue, its decimation). Per
    thread, as :func:`nice_process` (later threads inherit their starter's class). Where not
    permitted (no ``SCHED_IDLE``, not Linux, refused): :func:`nice_process` by
    ``fallback_nice``. Returns ``("idle" or "nice", threads changed)``."""
    if not hasattr(os, "SCHED_IDLE"):
        return "nice", nice_process(fallback_nice)
    try:
        return "idle", _set_class(os.SCHED_IDLE, tids)
    except PermissionError:  # not permitted here (a container's seccomp, say): nice instead
        return "nice", nice_process(fallback_nice)


def normal_process(tids: Sequence[int] | None = None) -> int:
    """Every thread of this process back in the normal class (``SCHED_OTHER``), undoing
    :func:`idle_process` once the network no longer needs the cores (the view's end: its last
    drawing and the recording's close must not wait for CPU a busy machine never leaves).
    Returns the threads changed; threads where it is refused stay as they were."""
    if not hasattr(os, "SCHED_OTHER"):
        return 0
    try:
        return _set_class(os.SCHED_OTHER, tids)
    except PermissionError:  # not permitted: it stays idle
        return 0


def _set_class(policy: int, tids: Sequence[int] | None) -> int:
    """Each thread of ``tids`` (default: every thread of this process; without /proc this
    one, which later threads inherit from) in scheduling class ``policy``; returns the
    threads changed. A thread that ended meanwhile is skipped; any other refusal is raised
    as PermissionError (the callers' fallback)."""
    if tids is None:
        try:
            tids = [int(t) for t in os.listdir("/proc/self/task")]
        except OSError:
            tids = [0]
    changed = 0
    for tid in tids:
        try:
            os.sched_setscheduler(tid, policy, os.sched_param(0))
            changed += 1
        except ProcessLookupError:  # the thread has ended meanwhile
            pass
        except OSError as exc:
            raise PermissionError(str(exc)) from exc
    return changed


def thread_policies() -> dict[int, int]:
    """Each thread of this process and its scheduling policy (``os.SCHED_*``; Linux)."""
    out = {}
    for t in os.listdir("/proc/self/task"):
        try:
            out[int(t)] = os.sched_getscheduler(int(t))
        except ProcessLookupError:  # ended meanwhile
            pass
    return out


def cpu_seconds() -> float:
    """This process's CPU (user + system) so far."""
    t = os.times()
    return t.user + t.system
