"""Discrete-event twin of the peer network: the same peer state machines on a virtual clock.

No processes and no sockets: scans, estimates and deadlines are events in one priority queue
ordered by virtual time. Every estimate a peer publishes is delivered to every other peer
(as Zenoh does with a wildcard subscription) after the link's delay; a delay of ``None``
drops the message. With zero delays and generous deadlines it computes what the real
processes compute, which the tests check.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from peers.faults import FaultInjector
from peers.logic import PeerLogic
from protocol.messages import Estimate, Scan, Tracks
from sim.build import fault_injector, make_peer
from sim.scenario import Scenario
from sim.world import generate_run

LinkDelay = Callable[[str, str, Estimate], float | None]
"""``(sender, receiver, message) -> delay in virtual seconds, or None to drop it``."""


def no_delay(sender: str, receiver: str, msg: Estimate) -> float | None:
    return 0.0


@dataclass
class TwinResult:
    """What a twin run produced, per peer."""

    peers: dict[str, PeerLogic]
    tracks: dict[str, dict[int, np.ndarray]] = field(default_factory=dict)
    """``tracks[peer][k]``: the fused states ``(n, 4)`` the peer published for scan ``k``."""
    faults: FaultInjector | None = None
    """The fault injector used (its ``log`` says what was done to each message)."""

    def mean_ospa(self, peer: str, kind: str = "fused") -> float:
        return self.peers[peer].mean_ospa(kind)


def run_twin(scn: Scenario, run: int = 0, delay: LinkDelay | None = None,
             peers: dict[str, PeerLogic] | None = None,
             faults: FaultInjector | None = None) -> TwinResult:
    """One run of the scenario's network on the virtual clock.

    Link behaviour: ``faults`` (a :class:`~peers.faults.FaultInjector`: delays, loss,
    duplication, reordering, partitions) if given, else ``delay`` if given, else the
    scenario's ``[faults]`` table, else instant delivery.
    """
    truth, scans = generate_run(scn, run)
    names = scn.sensor_names
    peers = peers if peers is not None else {n: make_peer(scn, n, run) for n in names}
    if faults is None and delay is None:
        faults = fault_injector(scn, run)
    link_delay = delay or no_delay
    # like the runtime, a peer subscribes to its neighbours' estimate keys only
    listeners = {n: [m for m in names if n in peers[m].o.neighbours] for n in names}
    interval = scn.scan_period / scn.network.speed
    result = TwinResult(peers=peers, tracks={n: {} for n in names}, faults=None)
    queue: list = []
    order = itertools.count()

    def push(t: float, kind: str, target: str, payload) -> None:
        heapq.heappush(queue, (t, next(order), kind, target, payload))

    def emit(t: float, sender: str, messages: list) -> None:
        for msg in messages:
            if isinstance(msg, Tracks):
                result.tracks[sender][msg.k] = msg.states
            elif isinstance(msg, Estimate):
                for other in listeners[sender]:
                    if faults is not None:
                        for d in faults.deliveries(sender, other, t, msg):
                            push(t + d, "estimate", other, msg)
                    else:
                        d = link_delay(sender, other, msg)
                        if d is not None:
                            push(t + d, "estimate", other, msg)

    for k in range(1, scn.num_scans + 1):
        t = k * interval
        for i, n in enumerate(names):
            push(t, "scan", n, (k, scans[i][k - 1], truth.states[k - 1]))
            push(t + scn.network.deadline * interval, "deadline", n, k)
    result.faults = faults
    while queue:
        t, _, kind, target, payload = heapq.heappop(queue)
        peer = peers[target]
        if kind == "scan":
            k, z, x = payload
            peer.on_truth(k, x)
            emit(t, target, peer.on_scan(Scan(target, k, z), t))
            peer.score_local()
        elif kind == "estimate":
            emit(t, target, peer.on_estimate(payload, t))
        else:
            emit(t, target, peer.on_deadline(payload, t))
    return result
