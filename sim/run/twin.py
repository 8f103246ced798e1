"""Discrete-event twin of the peer network: the same sans-I/O peers on a virtual clock.

No processes and no sockets, but the same bytes: every scan, truth and estimate is encoded and
handed to :meth:`peers.core.PeerCore.receive` exactly as the Zenoh runtime does, liveliness
changes go through :meth:`~peers.core.PeerCore.liveliness`, and deadlines through
:meth:`~peers.core.PeerCore.tick`; so decoding, validation, bounds and departures are covered
here too. Every estimate a peer publishes reaches each peer that fuses it after the link's
delay (``None`` drops it). With zero delays and generous deadlines it computes what the real
processes compute, which the tests check. ``run_twin(..., workers=2)`` plays the same peers
over two forked processes, instant by instant (:mod:`sim.run.twin_split`), to the same bits.
"""

from __future__ import annotations

import heapq
import itertools
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
from sensornet.peers.batching import FusionBatch, prepare_local_steps
from sensornet.peers.core import PeerCore, Publish, Record, Stop
from sensornet.peers.faults import FaultInjector
from sensornet.peers.session import MAX_MESSAGE_BYTES
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Estimate, Scan, Truth
from sensornet.sim.run import twin_split
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import Scenario
from sensornet.sim.world import generate_run, plot_ages
from sensornet.sim.world.build import fault_injector

LinkDelay = Callable[[str, str, Estimate], float | None]
"""``(sender, receiver, message) -> delay in virtual seconds, or None to drop it``."""

TRUTH_DELAY = 0.5
"""The world publishes the truth of a scan half an interval after it (as the real world)."""


def no_delay(sender: str, receiver: str, msg: Estimate) -> float | None:
    return 0.0


@dataclass(frozen=True)
class Inject:
    """A raw message put on ``key`` at virtual time ``t`` and delivered to ``target``."""

    t: float
    target: str
    key: str
    payload: bytes


@dataclass(frozen=True)
class Liveliness:
    """Peer ``name``'s liveliness token appears (``joined``) or goes away, as seen by
    ``target`` at virtual time ``t``."""

    t: float
    target: str
    name: str
    joined: bool


@dataclass
class TwinResult:
    """What a twin run produced, per peer."""

    peers: dict[str, PeerCore]
    tracks: dict[str, dict[int, np.ndarray]] = field(default_factory=dict)
    """``tracks[peer][k]``: the fused states ``(n, d)`` the peer published for scan ``k``."""
    faults: FaultInjector | None = None
    """The fault injector used (its ``log`` says what was done to each message)."""
    stops: dict[str, str] = field(default_factory=dict)
    ages: dict[str, list[int]] = field(default_factory=dict)
    """Ages (scans) of the neighbour estimates each peer fused."""
    transport_drops: dict[str, int] = field(default_factory=dict)
    """Messages over the transport's size limit, dropped before they reached each peer."""
    ospa: dict[str, dict[str, dict[int, float]]] = field(default_factory=dict)
    """``ospa[peer][which][k]``: the OSPA of each scan's ``"local"``/``"fused"`` estimate."""
    split: dict | None = None
    """Over worker processes (``run_twin(workers=N)``): the groups and the counts of
    :func:`sim.run.twin_split.run_split`; None in one process."""

    def tally(self, peer: str, outputs: list) -> None:
        """Keep what ``peer``'s outputs say for the result: its stop, fusion ages (a scan's
        first round's: later rounds' records say 0 for every sender), OSPA."""
        for o in outputs:
            if isinstance(o, Stop):
                self.stops[peer] = o.reason
            elif isinstance(o, Record) and o.kind == "fusion" and o.values["round"] <= 1:
                self.ages.setdefault(peer, []).extend(o.values["ages"].values())
            elif isinstance(o, Record) and o.kind == "ospa":
                per = self.ospa.setdefault(peer, {"local": {}, "fused": {}})
                per[o.values["which"]][o.k] = o.values["value"]

    def mean_ospa(self, peer: str, kind: str = "fused") -> float:
        return self.peers[peer].mean_ospa(kind)

    def summary(self, peer: str) -> dict:
        """The peer's summary as the real process writes it (no wall-clock figures; bytes
        are the encoded messages the core published, as the runtime counts them)."""
        s = self.peers[peer].snapshot()
        st = s["stats"]
        ages = self.ages.get(peer, [])
        sent = self.peers[peer].sent_bytes
        s.update(messages_sent=st["estimates_out"] + st["tracks_out"],
                 bytes_sent=sum(sent.values()), estimate_bytes_sent=sent["estimate"],
                 mean_estimate_age=sum(ages) / len(ages) if ages else None,
                 latency_ms_median=None, latency_ms_p99=None, stop_reason=self.stops.get(peer))
        return s


def world_events(scn: Scenario, truth, scans, keys: Keys, interval: float,
                 inject: Iterable[Inject], events: Iterable[Liveliness],
                 ages=None) -> list[tuple]:
    """What the world (and ``inject``, ``events``) puts on the twin's clock, in order:
    ``(t, kind, target, *payload)``; the start, every scan and truth, the "end", then the
    world's leaving. ``ages``: each plot's age, sent with the scans (as
    :func:`sim.world.plot_ages` gives them), or None."""
    names, network = scn.sensor_names, keys.network
    out: list[tuple] = []
    start = encode(Control("start", network, {"speed": scn.network.speed}, send_time=0.0))
    for n in names:
        out.append((0.0, "live", n, "world", True))
        out.append((0.0, "msg", n, keys.ctl(), start))
    for k in range(1, scn.num_scans + 1):
        t = k * interval
        x = truth.states[k - 1]
        t_msg = encode(Truth(k, truth.ids[k - 1], x, send_time=t + TRUTH_DELAY * interval))
        for i, n in enumerate(names):
            a = None if ages is None else ages[i][k - 1]
            out.append((t, "msg", n, keys.scan(n), encode(Scan(n, k, scans[i][k - 1], seq=k,
                                                               send_time=t, ages=a))))
            out.append((t + TRUTH_DELAY * interval, "msg", n, keys.truth(), t_msg))
    for m in inject:
        out.append((m.t, "msg", m.target, m.key, m.payload))
    for e in events:
        out.append((e.t, "live", e.target, e.name, e.joined))
    end = (scn.num_scans + 1) * interval + 1.0
    stop = encode(Control("end", network, {}, send_time=end))
    for n in names:
        out.append((end - 0.5, "msg", n, keys.ctl(), stop))  # as the world: "end", then leave
        out.append((end, "live", n, "world", False))
    return out


def run_twin(scn: Scenario, run: int = 0, delay: LinkDelay | None = None,
             peers: dict[str, PeerCore] | None = None,
             faults: FaultInjector | None = None, network: str = "twin",
             inject: Iterable[Inject] = (), events: Iterable[Liveliness] = (),
             data=None, batch: bool = False, world: list[tuple] | None = None,
             workers: int = 1) -> TwinResult:
    """One run of the scenario's network on the virtual clock.

    Link behaviour: ``faults`` (a :class:`~peers.faults.FaultInjector`: delays, loss,
    duplication, reordering, partitions) if given, else ``delay`` if given, else the
    scenario's ``[faults]`` table, else instant delivery. ``inject``: raw messages (attacks);
    ``events``: liveliness changes (departures, returns). ``data``: the run's ``(truth,
    scans)`` for scenarios that draw their own (as :func:`sim.world.generate_run` returns them).
    ``batch``: as the peers of one host (:mod:`peers.batching`), the consensus rounds that
    become ready at one virtual instant are fused together once every event of that instant
    has been handled (the same fused numbers; what a completed round publishes then goes out
    at that instant, as events after it). ``world``: the world's events ``(t, kind, target,
    *payload)`` (as :func:`world_events` gives them) instead of the scenario's, e.g. a bag's
    (:mod:`sensornet.bag_twin`); ``inject`` and ``events`` are then ignored.

    ``workers``: 1 plays every peer here; N > 1 splits the peers over N forked worker
    processes synchronised per virtual instant (:mod:`sim.run.twin_split`: the same tracks
    and summaries, tested to the bit; ``faults`` take the same decisions, being drawn per
    link and message; ``delay`` must be a function of its arguments; ``result.peers`` are
    the workers' final cores, copied back, not the objects passed in).
    """
    truth, scans = (data if data is not None else (None, None) if world is not None
                    else generate_run(scn, run))
    names = scn.sensor_names
    keys = Keys(network)
    peers = peers if peers is not None else {
        n: make_peer(scn, n, run, network=network) for n in names}
    if faults is None and delay is None:
        faults = fault_injector(scn, run)
    # like the runtime, a peer subscribes to its neighbours' estimate keys only
    listeners = {n: [m for m in names if n in peers[m].consensus.o.neighbours] for n in names}
    interval = scn.scan_period / scn.network.speed
    clock = _Clock(peers=peers, keys=keys, listeners=listeners, faults=faults,
                   link_delay=delay or no_delay,
                   result=TwinResult(peers=peers, tracks={n: {} for n in names}, faults=faults))
    if world is None:
        world = world_events(scn, truth, scans, keys, interval, inject, events,
                             plot_ages(scn, run))
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if workers > 1:
        return _run_split(clock, names, world, batch, workers)
    for t, kind, target, *payload in world:
        clock.push(t, kind, target, *payload)
    clock.run(names, FusionBatch() if batch else None)
    return clock.result


@dataclass
class _Clock:
    """The twin's event queue and the peers it drives: the state of one :func:`run_twin`,
    with a method per kind of work (deliver, handle a peer's outputs, fuse an instant)."""

    peers: dict[str, PeerCore]
    keys: Keys
    listeners: dict[str, list[str]]
    """``listeners[sender]``: the peers subscribed to ``sender``'s estimates."""
    faults: FaultInjector | None
    link_delay: LinkDelay
    result: TwinResult
    queue: list = field(default_factory=list)
    """Heap of ``(t, order, kind, target, payload)``; ``order`` keeps equal times in push order."""
    order: itertools.count = field(default_factory=itertools.count)
    scheduled: dict[str, float] = field(default_factory=dict)
    """Each peer's pending tick time (one tick event per due time)."""

    def push(self, t: float, kind: str, target: str, *payload) -> None:
        heapq.heappush(self.queue, (t, next(self.order), kind, target, payload))

    def carry_out(self, t: float, sender: str, outputs: list) -> None:
        """Deliver ``sender``'s published estimates to its listeners after each link's delay
        (or the fault injector's deliveries); keep its published tracks."""
        for o in outputs:
            if not isinstance(o, Publish):
                continue
            if o.channel == "tracks":
                self.result.tracks[sender][o.k] = o.message.states
                continue
            for other in self.listeners[sender]:
                ds = (self.faults.deliveries(sender, other, t, o.message)
                      if self.faults is not None else
                      [d for d in [self.link_delay(sender, other, o.message)] if d is not None])
                for d in ds:
                    self.push(t + d, "msg", other, self.keys.estimate(sender), o.payload)

    def handle(self, t: float, target: str, core: PeerCore, out: list) -> None:
        """A peer's outputs at ``t`` (and its tick's): carried out, tallied, its next tick
        scheduled once."""
        out += core.tick(t)
        self.carry_out(t, target, out)
        self.result.tally(target, out)
        due = core.next_due()
        if due is not None and self.scheduled.get(target) != due:
            self.scheduled[target] = due
            self.push(max(due, t), "tick", target)

    def start(self, names: list[str], fusions: FusionBatch | None) -> None:
        """Ready to play: ``fusions`` (a host's batching) set on the peers, the keys known."""
        if fusions is not None:
            for core in self.peers.values():
                core.consensus.batch = fusions
        self.fusions = fusions
        self.name_of = {id(core.consensus): n for n, core in self.peers.items()}
        self.truth_key = self.keys.truth()
        self.scan_keys = {self.keys.scan(n) for n in names}
        self.prepared_at: float | None = None

    def dispatch(self, t: float, kind: str, target: str, payload: tuple) -> None:
        """One event of the queue, handled by its peer (with ``fusions``, the instant's
        scans get their local steps computed together first)."""
        peers, result, queue, fusions = self.peers, self.result, self.queue, self.fusions
        if target in result.stops:
            pass
        elif kind == "msg" and payload[0] == self.truth_key and not peers[target].wants_truth:
            pass  # not subscribed (peers.transport): Zenoh does not deliver it
        elif kind == "msg" and len(payload[1]) > MAX_MESSAGE_BYTES:
            result.transport_drops[target] = result.transport_drops.get(target, 0) + 1
            self.handle(t, target, peers[target], [])  # the transport drops it (peers.session)
        elif kind == "msg":
            scan_keys = self.scan_keys
            if fusions is not None and self.prepared_at != t and payload[0] in scan_keys:
                # as a host: the instant's scans, their local steps computed together first
                self.prepared_at = t
                prepare_local_steps([(peers[target], *payload)] + [
                    (peers[q[3]], *q[4]) for q in queue if q[0] == t and q[2] == "msg"
                    and q[4][0] in scan_keys and q[3] not in result.stops])
            self.handle(t, target, peers[target],
                        peers[target].receive(payload[0], payload[1], t))
        elif kind == "live":
            self.handle(t, target, peers[target],
                        peers[target].liveliness(payload[0], payload[1], t))
        else:
            self.scheduled.pop(target, None)
            self.handle(t, target, peers[target], [])

    def fuse(self, t: float) -> None:
        """The instant's events are handled: its consensus rounds fused together."""
        for c in self.fusions.run(t):
            name = self.name_of[id(c)]
            if name not in self.result.stops:
                self.handle(t, name, self.peers[name], self.peers[name].completed(t))

    def run(self, names: list[str], fusions: FusionBatch | None) -> None:
        """Play the queue to its end; with ``fusions`` (a host's batching), an instant's scans
        get their local steps computed together and its consensus rounds fused together."""
        self.start(names, fusions)
        queue = self.queue
        while queue:
            t, _, kind, target, payload = heapq.heappop(queue)
            self.dispatch(t, kind, target, payload)
            while fusions is not None and fusions.jobs and (not queue or queue[0][0] != t):
                self.fuse(t)


@dataclass
class _WorkerClock(_Clock):
    """A twin worker's clock (:mod:`sim.run.twin_split`): its peers' queue; what they
    publish to another worker's peers goes to :attr:`outbox`."""

    local: set[str] = field(default_factory=set)
    outbox: list = field(default_factory=list)

    def push(self, t: float, kind: str, target: str, *payload) -> None:
        if target in self.local:
            heapq.heappush(self.queue, (t, next(self.order), kind, target, payload))
        else:
            self.outbox.append((t, kind, target, *payload))

    def wave(self, t: float, incoming: list) -> None:
        """The messages from other workers queued, then every local event at ``t``."""
        for m in incoming:
            self.push(*m)
        queue = self.queue
        while queue and queue[0][0] == t:
            t, _, kind, target, payload = heapq.heappop(queue)
            self.dispatch(t, kind, target, payload)

    def reply(self, cpu: float) -> tuple:
        """What the parent needs after a command: the messages out, the queue's head,
        whether rounds wait for the batch, and the command's CPU seconds."""
        out, self.outbox = self.outbox, []
        return ("ok", out, self.queue[0][0] if self.queue else None,
                bool(self.fusions is not None and self.fusions.jobs), cpu)


def _run_split(clock: _Clock, names: list[str], world: list[tuple], batch: bool,
               workers: int) -> TwinResult:
    """:func:`run_twin` over ``workers`` forked processes (:mod:`sim.run.twin_split`):
    ``clock`` (its queue empty) split into a :class:`_WorkerClock` per group of peers, each
    with its peers' world events in the one-process order; the results merged back."""
    groups = twin_split.split_peers(names, clock.listeners, workers)
    owner = {n: w for w, g in enumerate(groups) for n in g}
    clocks = []
    for g in groups:
        local = {n: clock.peers[n] for n in g}
        clocks.append(_WorkerClock(
            peers=local, keys=clock.keys, listeners=clock.listeners, faults=clock.faults,
            link_delay=clock.link_delay, local=set(g),
            result=TwinResult(peers=local, tracks={n: {} for n in g}, faults=clock.faults)))
    for t, kind, target, *payload in world:  # a target of no worker: worker 0's KeyError
        c = clocks[owner.get(target, 0)]
        heapq.heappush(c.queue, (t, next(c.order), kind, target, tuple(payload)))
    parts, stats = twin_split.play(clocks, groups, names, batch)
    got: dict = {k: {} for k in ("peers", "tracks", "stops", "ages", "transport_drops",
                                 "ospa")}
    for part in parts:
        for k in got:
            got[k].update(part[k])
    r = TwinResult(peers={n: got["peers"][n] for n in names},
                   tracks={n: got["tracks"][n] for n in names}, faults=clock.faults,
                   split=stats, **{k: {n: got[k][n] for n in names if n in got[k]}
                                   for k in ("stops", "ages", "transport_drops", "ospa")})
    if clock.faults is not None:  # the same decisions (per link and message), by time
        clock.faults.log[:] = sorted((rec for p in parts for rec in p["faults"][0]),
                                     key=lambda rec: rec.t)
        clock.faults._counts = sum((p["faults"][1] for p in parts), Counter())
    return r

