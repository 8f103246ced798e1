"""The sans-I/O peer: bytes in, typed outputs out (in the style of h11's connection object).

``receive(key, payload, now)``, ``tick(now)``, ``liveliness(name, joined, now)`` and
``finish(now)`` return :class:`Publish`, :class:`Record` and :class:`Stop` outputs that a driver
carries out: the Zenoh runtime (``peers.runtime``) with sockets, clocks and files, the twin
(``sim.run.twin``) on a virtual clock. Everything between the bytes and the outputs lives here:
key and sender checks, decoding, every bound on what one message may cost, rejection counters
by reason code, deadlines, departures, scoring. Its configuration (:class:`CoreConfig`)
and output types are in ``peers.core_types``, its receive entry points (the one key parse and
decode) in ``peers.core_receive``, what it reports for the summary in ``peers.core_summary``.

Bounds (each rejection is counted under its reason in :meth:`snapshot`):

- ``rate``: more than a few times what an honest sender sends (``peers.admission``);
- ``wrong-key``/``spoofed``: a message of the wrong type for its key, or naming another sender;
- the codec's reasons (``malformed``, ``too-large``, ``not-psd``, ...);
- ``future``: a scan, estimate or truth more than ``horizon`` scans after the newest accepted
  scan (one message cannot move a peer's clock; see :meth:`_scan` for how a real restart of the
  scan numbering is still followed); ``stale``: before the scans still being fused;
- ``not-neighbour``, ``incompatible`` (state dimension or estimate kind this peer cannot fuse),
  ``round`` (a consensus round this peer does not run);
- ``label-mask``: an estimate whose shared labels' holder masks named peers its sender cannot
  vouch for (``peers.label_support``; those bits dropped, the estimate still fused);
  ``label-scan``: an estimate carrying a label older than any publication of it this peer
  can vouch for (``LabelSupport.refused``; the estimate fused, those rows re-stamped to its
  scan);
- ``truth-mismatch``/``truth-conflict`` (``peers.scoring``); ``ctl`` (an unknown command);
- secure mode, counted by the transport before anything is decoded (``protocol.envelope``):
  ``unauthenticated`` (no valid signature of the key's owner), ``replayed`` (a copy of a
  message already taken, or one older than it).

A ``ctl`` "end" alone never stops a peer: it stops when the world's liveliness token goes away.
"""

from __future__ import annotations

from collections import Counter, deque

import numpy as np
from sensornet.peers.admission import Admission, Route
from sensornet.peers.budget import EstimateBudget
from sensornet.peers.consensus import Consensus
from sensornet.peers.core_lifecycle import STOP_REASONS, Action, Event, Lifecycle, ScanEvent
from sensornet.peers.core_outputs import CoreOutputs
from sensornet.peers.core_receive import CoreReceive
from sensornet.peers.core_summary import core_cost, core_snapshot, cost_per_scan
from sensornet.peers.core_types import CoreConfig, Output, Publish, Record, Stop
from sensornet.peers.scoring import Scorer
from sensornet.protocol.codec import decode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import (
    Control,
    Estimate,
    Forward,
    Returns,
    Scan,
    Tracks,
    Truth,
)

END_GAP = 100_000
"""Scans a world's "end" may name after this peer's last one (misses to score: bounded)."""


class PeerCore(CoreReceive, CoreOutputs):
    """One peer's whole behaviour between bytes and outputs."""

    def __init__(self, cfg: CoreConfig, consensus: Consensus, scorer: Scorer) -> None:
        self.cfg = cfg
        self.name = cfg.name
        self.consensus = consensus
        self.estimator = consensus.estimator
        self.scorer = scorer
        self.wants_truth = scorer.truth_fn is None
        """Whether truth messages are any use to this peer: one that regenerates the truth from
        its scenario neither subscribes to them nor is fed them in the twin (a message and a
        decode per scan saved, and nothing a forger could put there reaches it)."""
        self.keys = Keys(cfg.network)
        self.decode = decode
        """Bytes -> message (a host shares one read-only decode between its peers)."""
        self._predecoded: tuple[bytes, Scan] | None = None  # (payload, msg): scan_step's
        kinds = max(1, len(consensus.kinds))
        self.budget = EstimateBudget.of(self.estimator, cfg.limits.max_components)
        """What one neighbour's estimate may cost (peers.budget): its bytes before decoding,
        its components after."""
        self.admission = Admission(cfg.network, cfg.interval, {
            "scan": 1.0, "truth": 1.0, "ctl": 0.5,
            "estimate": float(consensus.rounds * kinds)}, factor=cfg.rate_factor,
            window=self.window_for, rounds=consensus.rounds,
            kinds=consensus.kinds or ("posterior",),
            estimate_bytes=(None if self.budget is None
                            else self.budget.slot_bytes(cfg.rate_factor)))
        self.rejected: Counter = Counter()
        self.received: Counter = Counter()
        self.received_bytes: Counter = Counter()
        self.stale_scans = 0
        self.reanchored = 0
        self.first_k: int | None = None
        self.last_accept: float | None = None
        self.deadlines: dict[int, float] = {}
        self.life = Lifecycle()
        """The world's lifecycle and the scan numbering's, as explicit states
        (:mod:`peers.core_lifecycle`)."""
        self.ctl_end_early = 0
        self.t0: float | None = None
        self.departures: deque[tuple[str, str, int]] = deque(maxlen=1000)  # flapping peers
        self._pending_local: list[int] = []
        self._pending_fused: list[Tracks] = []  # published tracks, to score
        self.world_gone: float | None = None  # when the world's token went (in the grace)
        self.world_outages: list[tuple[int, float]] = []  # (last scan before, seconds)
        self.sent_bytes: Counter = Counter()
        """Bytes of every publication, by channel (what the runtime puts on the wire)."""
        self._scan_at: tuple[int, float] | None = None
        self.end_k: int | None = None  # the world's last scan, from its "end"
        self._last_scan: tuple[int, float] | None = None  # (k, world's send time) accepted
        self._cost_mark = (0, 0, 0)

    # -- the entry points (receive, receive_routed, scan_step: peers.core_receive) ---------
    def tick(self, now: float) -> list[Output]:
        """Fire due deadlines and do the deferred work (call after publishing outputs)."""
        if self.world_gone is not None and now >= self.world_gone + self.cfg.grace():
            return self._world(Event.GRACE_OVER, now)  # not back within the grace
        out: list[Output] = []
        for k in [k for k, t in self.deadlines.items() if t <= now]:
            del self.deadlines[k]
            due = self._due(k)
            if due is not None and due > now:  # its round already ran: the next round's
                self.deadlines[k] = due
                continue
            out += self._wrap(self.consensus.on_deadline(k, now))
            self._arm(k)
        self._score_deferred()
        return out + self._records()

    def completed(self, now: float) -> list[Output]:
        """What the consensus rounds a host's batch fused since the last call publish and
        record (:mod:`peers.batching`; call after :meth:`peers.batching.FusionBatch.run`)."""
        return self._wrap(self.consensus.take_completed()) + self._records()

    def liveliness(self, name: str, joined: bool, now: float) -> list[Output]:
        """A liveliness token appeared or went away (``alive/<name>``)."""
        if name == self.name:
            return []
        if name == "world":
            event = (Event.JOINED if joined  # a grace: maybe a router outage, see tick()
                     else Event.LOST if self.cfg.grace() > 0 else Event.LEFT)
            return self._world(event, now)
        c = self.consensus
        changed = c.peer_joined(name) if joined else c.peer_left(name)
        if not changed:
            return []
        what = "joined" if joined else "left"
        self.departures.append((name, what, c.last_k))
        out: list[Output] = [Record("peer", c.last_k, {"peer": name, "what": what})]
        if not joined:  # maybe the round waited only for it
            out += self._wrap(c.resume(now))
        return out

    def finish(self, now: float) -> list[Output]:
        """End of the run: fuse what is pending, score what is missing."""
        out = self._wrap(self.consensus.finish(now))
        if self.consensus.trust is not None:
            self.consensus.trust.finish()
            self.consensus.records.extend(self.consensus.trust.drain_records())
        self.deadlines.clear()
        self._score_deferred()
        last = self.consensus.last_k
        if self.end_k is not None and self.end_k > last:  # published, never handled here
            self.scorer.skipped(range(last + 1, self.end_k + 1))
            self.end_k = None
        self.scorer.finish()
        return out + self._records()

    def next_due(self) -> float | None:
        """When :meth:`tick` next has work (a deadline), or None."""
        due = min(self.deadlines.values(), default=None)
        if self.world_gone is not None:
            end = self.world_gone + self.cfg.grace()
            due = end if due is None else min(due, end)
        return due

    @property
    def world(self) -> str:
        """``"unseen"``, ``"alive"`` (an outage included) or ``"left"``."""
        return self.life.world_seen

    @property
    def end_requested(self) -> bool:
        """Whether the world's "end" came."""
        return self.life.end_requested

    def _world(self, event: Event, now: float) -> list[Output]:
        """Take the world lifecycle's transition for ``event`` and carry out its action
        (:data:`peers.core_lifecycle.WORLD_TABLE`)."""
        action = self.life.step(event)
        if action is Action.OUTAGE_START:
            self.world_gone = now
        elif action is Action.OUTAGE_END:
            self.world_outages.append((self.consensus.last_k, now - self.world_gone))
            self.world_gone = None
        elif action is Action.END_EARLY:
            self.ctl_end_early += 1  # the world is still there: wait for it to leave
        elif action in STOP_REASONS:
            self.world_gone = None
            return self.finish(now) + [Stop(STOP_REASONS[action])]
        return []

    # -- channels ---------------------------------------------------------------------------
    def _reject(self, reason: str) -> list[Output]:
        self.rejected[reason] += 1
        return [Record("rejected", self.consensus.last_k, {"reason": reason})]

    def _scan(self, route: Route, msg: Scan, now: float) -> list[Output]:
        if route.name != self.cfg.sensor:
            return self._reject("wrong-key")
        if msg.sensor != route.name:
            return self._reject("spoofed")
        c, k, h = self.consensus, msg.k, self.cfg.horizon
        if self.cfg.last_scan is not None and k > self.cfg.last_scan:
            return self._reject("future")  # past the run's end: no world sends it
        closed: list[Output] = []  # the scan a pause interrupted, fused on return
        quiet = (self.last_accept is None
                 or now - self.last_accept > self.cfg.quiet * self.cfg.interval)
        if self.first_k is not None and c.last_k < k <= c.last_k + h:
            self.life.scan(ScanEvent.NEXT)
            steps = k - c.last_k
            if steps > 1:
                self.scorer.skipped(range(c.last_k + 1, k))
        elif quiet and k != c.last_k:
            # a new start of the numbering: nothing accepted for a while (late join, restart)
            self.life.scan(ScanEvent.FIRST if self.first_k is None else ScanEvent.REANCHOR)
            if self.first_k is not None:
                self.reanchored += 1
                # the same numbering after a pause (this peer was frozen or fell behind): the
                # scan it was fusing is fused now with what it has, the scans in between had
                # no output (misses); a jump the world's clock does not explain is a new
                # numbering (the world restarted), not misses
                pause = c.last_k < k and self._same_numbering(k, msg.send_time, now)
                if pause:
                    closed = self._wrap(c.finish(now))
                c.reset_window()
                self.deadlines.clear()
                if pause:
                    self.scorer.skipped(range(c.last_k + 1, k))
            steps = k - c.last_k if k > c.last_k else 1
            self.first_k = k if self.first_k is None else self.first_k
        elif k <= c.last_k:
            self.stale_scans += 1
            return self._reject("stale")
        else:
            return self._reject("future")
        self.last_accept = now
        self._last_scan = (k, msg.send_time)
        out = [*closed, Record("scan", k, {"send_time": msg.send_time, "n": len(msg.z)})]
        self.scorer.expect(k)
        self._score_deferred()  # the previous scan's, if no tick came between (a backlog)
        c.hooks.plot_ages(msg.ages)
        out += self._wrap(c.on_scan(k, msg.z, steps, now))
        self.scorer.advance(k)
        self._pending_local.append(k)
        self.deadlines = {kk: t for kk, t in self.deadlines.items() if kk >= k}
        self._scan_at = (k, now)
        self._arm(k)
        return out

    def _same_numbering(self, k: int, sent: float, now: float) -> bool:
        """Whether scan ``k`` (sent at ``sent``) follows the last accepted one in the same
        numbering: the pause since this peer's last scan explains the jump, or the world's
        send times differ by the scans between them (give or take the horizon), however late
        this peer handled either (a backlog it skipped is misses, not a new numbering)."""
        h, dt = self.cfg.horizon, self.cfg.interval
        elapsed = now - self.last_accept if self.last_accept is not None else 0.0
        if k <= self.consensus.last_k + h + elapsed / dt:
            return True
        if self._last_scan is None:
            return False
        last_k, last_sent = self._last_scan
        return abs((sent - last_sent) - (k - last_k) * dt) <= max(h * dt, 1.0)

    def _due(self, k: int) -> float | None:
        """The next fusion deadline of scan ``k`` while it is being fused: the scan's, or with
        ``round_deadlines`` the next round's (its share of the scan's deadline)."""
        c = self.consensus
        if not c.busy() or c.forced() or self._scan_at is None or self._scan_at[0] != k:
            return None
        span = self.cfg.deadline * self.cfg.interval
        if c.o.round_deadlines:
            span *= ((c.round_of(k) or 0) + 1) / c.rounds
        return self._scan_at[1] + span

    def _arm(self, k: int) -> None:
        due = self._due(k)
        if due is not None:
            self.deadlines[k] = due

    def window_for(self, channel: str) -> tuple[int, int]:
        """Scan indices this peer takes on ``channel`` now: scans from the next one up to
        ``horizon`` ahead; estimates and truths from the oldest still fused (``max_age``) to
        ``horizon`` ahead of the newest accepted scan."""
        last, h = self.consensus.last_k, self.cfg.horizon
        if channel == "scan":
            return last + 1, last + h
        age = self.consensus.o.max_age
        return last - max(2, (age if age is not None else 0) + 1), last + h

    def _window(self, k: int) -> str | None:
        """Why an estimate/truth stamped ``k`` is outside what this peer keeps, or None
        (:meth:`window_for` of ``"estimate"``, written out: once a received estimate)."""
        c = self.consensus
        last = c.last_k
        if k > last + self.cfg.horizon:
            return "future"
        age = c.o.max_age
        return "stale" if k < last - max(2, (age if age is not None else 0) + 1) else None

    def _estimate(self, route: Route, msg: Estimate, now: float) -> list[Output]:
        c = self.consensus
        if msg.sender != route.name:
            return self._reject("spoofed")
        if msg.sender not in c.o.neighbours:
            return self._reject("not-neighbour")
        scans = c.hooks.payload == "scans"
        if (isinstance(msg, Forward) != scans or msg.kind not in (c.kinds or ("posterior",))
                or (isinstance(msg, Estimate) and msg.mixture.dim != self.estimator.dim)
                or isinstance(msg, Returns) != (msg.kind == "returns")):
            return self._reject("incompatible")
        if scans and not set(msg.scans.scans) <= self.estimator.roster.keys():
            return self._reject("spoofed")  # a scan of a sensor not in the network
        if msg.round >= c.rounds:
            return self._reject("round")
        why = self._window(msg.k)
        if why:
            return self._reject(why)
        out: list[Output] = [Record("estimate", msg.k, {"sender": msg.sender,
                                                        "round": msg.round})]
        if self.budget is not None and isinstance(msg, Estimate):
            msg = self.budget.bound_estimate(msg)  # at most J components on (peers.budget)
        sup = c.label_support
        clipped, backdated = (sup.clipped, sup.backdated) if sup is not None else (0, 0)
        res = c.on_estimate(msg, now)
        if sup is not None and sup.clipped > clipped:  # fused, the bits it cannot vouch for
            out += self._reject("label-mask")  # dropped (peers.label_support)
        if sup is not None and sup.backdated > backdated:  # fused, those labels re-stamped
            out += self._reject("label-scan")  # a label older than its first publication
        return out + self._wrap(res) if res else out

    def _truth(self, msg: Truth) -> list[Output]:
        why = self._window(msg.k) if self.first_k is not None else None
        if why is None:
            why = self.scorer.truth_message(msg.k, msg.states, msg.ids)
        return self._reject(why) if why else self._records()

    def _control(self, msg: Control, now: float) -> list[Output]:
        if msg.command == "start":
            self.t0 = msg.send_time
            return []
        if msg.command == "end":
            last = msg.params.get("last_k")  # the world's last scan: later ones are misses
            if type(last) is int and 0 < last - self.consensus.last_k <= END_GAP:
                self.end_k = last
            return self._world(Event.END, now)  # after an outage's start: the end of the run
        return self._reject("ctl")

    # -- reporting (peers.core_summary) ------------------------------------------------------
    def cost(self) -> dict:
        """Tuples and bytes this peer sent per scan (:func:`peers.core_summary.core_cost`)."""
        return core_cost(self)

    def mean_ospa(self, which: str) -> float:
        return self.scorer.mean(which)

    def snapshot(self) -> dict:
        """Counts, scores and state for the summary (plain data;
        :func:`peers.core_summary.core_snapshot`)."""
        return core_snapshot(self)


def positions(states: np.ndarray, index: tuple[int, int]) -> np.ndarray:
    """``(n, 2)`` positions of state rows (empty-safe)."""
    return states[:, list(index)] if len(states) else np.zeros((0, 2))


__all__ = ["CoreConfig", "Output", "PeerCore", "Publish", "Record", "Stop", "cost_per_scan",
           "positions"]
