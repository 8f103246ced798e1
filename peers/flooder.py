"""Measurement flooding (seed 004; docs/seed004.md), sans-I/O: one peer's state, and a network.

In iteration 1 a peer sends its own scan to every neighbour; in iteration ``t >= 2`` it sends
the scans it received in iteration ``t - 1`` and has not sent before. Scans are keyed by
``(origin, scan)``; a copy of a scan already held is a duplicate and is dropped. After
``diameter`` iterations on a loss-free connected network every peer holds every scan.

:class:`Flooder` is one peer's state (no clock, no socket: the caller delivers what arrived and
asks what to send); :func:`flood` runs synchronous iterations over an adjacency matrix with
optional message loss, the way the offline experiment and the tests use it. Tuples are the
seed's unit: a 2-D measurement is 2 tuples, counted once per neighbour a scan is sent to
(:func:`flooding_tuples`; encoded bytes: :func:`flooding_bytes`). Flooding as a peer mode of
the network runtime is :mod:`peers.flood_parts`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from sensornet.protocol.codec import encode
from sensornet.protocol.messages import Forward, ScanSet

TUPLES_PER_MEASUREMENT = 2
"""A 2-D measurement is 2 tuples (seed 004)."""

ScanKey = tuple[int, int]
"""``(origin peer, scan index)``."""


@dataclass
class Flooder:
    """One peer's flooding state for the scans it is collecting."""

    peer: int
    """This peer's index (the origin of its own scans)."""
    held: dict[ScanKey, np.ndarray] = field(default_factory=dict)
    """Every scan held, own and received, ``(m, 2)`` points each."""
    duplicates: int = 0
    """Copies received of scans already held (dropped)."""
    late: int = 0
    """Scans received after their scan index was closed (dropped)."""
    _pending: list[ScanKey] = field(default_factory=list)
    _closed_before: int = 0

    def own(self, scan: int, points: np.ndarray) -> None:
        """This peer's own measurements of ``scan``: held, and sent in the next iteration."""
        self._add((self.peer, scan), points)

    def receive(self, origin: int, scan: int, points: np.ndarray) -> bool:
        """A scan from a neighbour; True when it is new (held and queued for forwarding)."""
        if scan < self._closed_before:
            self.late += 1
            return False
        if (origin, scan) in self.held:
            self.duplicates += 1
            return False
        self._add((origin, scan), points)
        return True

    def outgoing(self) -> list[tuple[ScanKey, np.ndarray]]:
        """What to send to every neighbour this iteration: the scans new since the last call."""
        out = [(k, self.held[k]) for k in self._pending]
        self._pending = []
        return out

    def pooled(self, scan: int) -> dict[int, np.ndarray]:
        """The scans of index ``scan`` held now, by origin."""
        return {o: z for (o, s), z in self.held.items() if s == scan}

    def pooled_keys(self, scan: int) -> dict[ScanKey, np.ndarray]:
        """The scans of index ``scan`` held now, by key."""
        return {key: z for key, z in self.held.items() if key[1] == scan}

    def close(self, scan: int, peers: int) -> int:
        """Stop collecting scans ``<= scan`` (their deadline passed); returns how many of the
        ``peers`` origins of ``scan`` never arrived (missing), and forgets those scans."""
        missing = peers - len(self.pooled(scan))
        self._closed_before = max(self._closed_before, scan + 1)
        self.held = {k: z for k, z in self.held.items() if k[1] > scan}
        self._pending = [k for k in self._pending if k[1] > scan]
        return missing

    def _add(self, key: ScanKey, points: np.ndarray) -> None:
        self.held[key] = np.asarray(points, dtype=float).reshape(-1, 2)
        self._pending.append(key)


@dataclass(frozen=True)
class FloodOutcome:
    """What one scan's flooding left behind."""

    held: list[set[int]]
    """Per peer, the origins whose scan it holds."""
    tuples_sent: np.ndarray
    """``(S,)`` tuples each peer sent (2 per measurement per neighbour)."""
    duplicates: np.ndarray
    """``(S,)`` duplicate copies each peer received and dropped."""
    late: np.ndarray
    """``(S,)`` copies that arrived after the last iteration (the scan's deadline)."""


Deliver = Callable[[int, int, ScanKey, int], Sequence[float]]
"""``deliver(sender, receiver, (origin, scan), iteration)``: the delays, in iterations, of the
copies that arrive (``[]`` lost, ``[0.0]`` this iteration, two entries duplicated); a copy
``d`` iterations late is received in iteration ``iteration + floor(d)``."""


def flood(adjacency: np.ndarray, scans: Sequence[np.ndarray], iterations: int, scan: int = 0,
          loss: float = 0.0, rng: np.random.Generator | None = None,
          deliver: Deliver | None = None) -> FloodOutcome:
    """Flood one scan index over ``adjacency (S, S)`` for ``iterations`` synchronous iterations.

    ``scans[i]`` is peer i's own ``(m_i, 2)`` scan. Each (sender, receiver, scan) message is lost
    with probability ``loss`` (one draw from ``rng`` each, in a fixed order), or ``deliver``
    decides (e.g. the fault layer: ``sim.studies.seed004.montecarlo.fault_delivery``). After the
    last iteration
    every peer closes the scan: a copy still in flight then counts as late at its receiver.
    """
    A = np.asarray(adjacency, dtype=bool)
    S = len(A)
    neighbours = [np.flatnonzero(A[i]) for i in range(S)]
    peers = [Flooder(i) for i in range(S)]
    for i, z in enumerate(scans):
        peers[i].own(scan, z)
    sent = np.zeros(S, dtype=np.int64)
    if loss > 0 and rng is None:
        raise ValueError("flood with loss needs an rng")
    in_flight: dict[int, list[tuple[int, ScanKey, np.ndarray]]] = {}
    for it in range(iterations):
        messages = [(i, peers[i].outgoing()) for i in range(S)]  # all send, then all receive
        for i, out in messages:
            for key, z in out:
                sent[i] += TUPLES_PER_MEASUREMENT * len(z) * len(neighbours[i])
                for j in neighbours[i]:
                    if deliver is not None:
                        for d in deliver(i, int(j), key, it):
                            in_flight.setdefault(it + int(np.floor(d)), []).append((j, key, z))
                    elif not (loss > 0 and rng.random() < loss):
                        in_flight.setdefault(it, []).append((j, key, z))
        for j, key, z in in_flight.pop(it, []):
            peers[j].receive(key[0], key[1], z)
    held = [set(p.pooled(scan)) for p in peers]
    for p in peers:
        p.close(scan, S)
    for j, key, z in (m for arrivals in in_flight.values() for m in arrivals):
        peers[j].receive(key[0], key[1], z)  # after the close: counted late
    return FloodOutcome(held, sent, np.array([p.duplicates for p in peers]),
                        np.array([p.late for p in peers]))


def flooding_tuples(hops: np.ndarray, sizes: np.ndarray, iterations: int) -> np.ndarray:
    """Closed form of the tuples each peer sends flooding one scan index, loss-free: ``(S,)``.

    In iteration ``t`` peer i sends the scans of the peers at hop distance ``t - 1``, so after
    ``T`` iterations ``tuples_i = deg_i * sum_{j: hop(i, j) <= T - 1} 2 |Z_j|``.
    ``hops (S, S)`` hop distances (``inf`` if unreachable), ``sizes (S,)`` points per scan.
    """
    hops = np.asarray(hops, dtype=float)
    deg = (hops == 1).sum(axis=1)
    reach = hops <= iterations - 1
    return deg * (reach @ (TUPLES_PER_MEASUREMENT * np.asarray(sizes, dtype=np.int64)))


def flooding_bytes(hops: np.ndarray, scans: Sequence[np.ndarray], iterations: int,
                   names: Sequence[str], k: int = 1) -> np.ndarray:
    """Encoded bytes each peer sends flooding one scan index, loss-free, per iteration:
    ``(S, iterations)``, once per neighbour. In iteration ``t`` peer i sends one
    :class:`~protocol.messages.Forward` holding the scans of the peers at hop distance
    ``t - 1`` (as :func:`flooding_tuples`), to each of its ``deg_i`` neighbours."""
    hops = np.asarray(hops, dtype=float)
    deg = (hops == 1).sum(axis=1)
    out = np.zeros((len(hops), iterations), dtype=np.int64)
    for i in range(len(hops)):  # one message per (peer, iteration): S x T encodes
        for t in range(iterations):
            ring = np.flatnonzero(hops[i] == t)
            msg = Forward(names[i], k, ScanSet({names[j]: scans[j] for j in ring}), round=t,
                          seq=k * iterations + t, send_time=float(k))
            out[i, t] = deg[i] * len(encode(msg))
    return out
