"""Measurement flooding (seed 004; ALGORITHMS.md §9): one peer's sans-I/O state, and a network.

In iteration 1 a peer sends its own scan to every neighbour; in iteration ``t >= 2`` it sends
the scans it received in iteration ``t - 1`` and has not sent before. Scans are keyed by
``(origin, scan)``; a copy of a scan already held is a duplicate and is dropped. After
``diameter`` iterations on a loss-free connected network every peer holds every scan.

:class:`Flooder` is one peer's state (no clock, no socket: the caller delivers what arrived and
asks what to send); :func:`flood` runs synchronous iterations over an adjacency matrix with
optional message loss, the way the offline experiment and the tests use it. Tuples are the
seed's unit: a 2-D measurement is 2 tuples, counted once per neighbour a scan is sent to.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from peers.contracts import FusionInput, LocalOutput
from protocol.messages import ScanSet

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
    decides (e.g. the fault layer: ``sim.seed004.fault_delivery``). After the last iteration
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
    from protocol.codec import encode
    from protocol.messages import Forward

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


# -- flooding as a peer mode (peers.contracts) ----------------------------------------------
class FloodEstimator:
    """The local part of a flooding peer: its scan is the payload, its estimate a clustering.

    ``step`` publishes the own scan (iteration 1 of the flooding); ``extract`` clusters a pooled
    :class:`~protocol.messages.ScanSet` with :func:`tracking.idpc.idpc` (or the FTC baseline
    :func:`tracking.idpc.ftc` with ``method="ftc"``), range-bearing scans converted to the
    plane with their origin's position first, ``S`` = the scans held (or every sensor of the
    roster with ``assumed_scans = "all"``).
    """

    kinds = ("posterior",)
    position_index = (0, 2)
    dim = 4
    """Estimates are ``[px, 0, py, 0]`` rows (clustering gives no velocity), so tracks, scores
    and views read positions from the same columns as every other point-target peer."""
    payload = "scans"
    """What it exchanges: :class:`~protocol.messages.Forward` messages, not mixtures."""

    def __init__(self, name: str, roster: Mapping[str, object], params=None,
                 assumed_scans: str = "held", seed: int = 0, method: str = "idpc") -> None:
        from tracking.idpc import ClusterParams

        if assumed_scans not in ("held", "all"):
            raise ValueError(f"assumed_scans {assumed_scans!r}: expected 'held' or 'all'")
        if method not in ("idpc", "ftc"):
            raise ValueError(f"method {method!r}: expected 'idpc' or 'ftc'")
        self.method = method
        self.name = name
        self.roster = dict(roster)
        self._rank = {o: i for i, o in enumerate(self.roster)}
        """Every sensor of the network by name -> its measurement model (``position`` and
        whether it is range-bearing); an origin outside it is refused (``spoofed``)."""
        self.params = params or ClusterParams()
        self.assumed_scans = assumed_scans
        self.seed = seed
        """Seeds the k-means split afresh for every clustering: peers holding the same scans
        compute the same estimate."""

    def _order(self, origin: str) -> int:
        return self._rank.get(origin, len(self._rank))

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        own = ScanSet({self.name: np.asarray(z, dtype=float).reshape(-1, 2)})
        return LocalOutput(own, {"posterior": own}, {"n_points": own.points})

    def predict(self, mix, steps: int):
        return mix  # scans of another index are never pooled

    def plane(self, scans: ScanSet) -> np.ndarray:
        """The pooled points ``(n, 2)`` in the plane."""
        from tracking.idpc import polar_to_cartesian
        from tracking.models import RangeBearing

        parts = []
        for origin in sorted(scans.scans, key=self._order):  # one order at every peer
            z, model = scans.scans[origin], self.roster.get(origin)
            parts.append(polar_to_cartesian(z, model.position)
                         if isinstance(model, RangeBearing) else z)
        return np.concatenate(parts) if parts else np.zeros((0, 2))

    def extract(self, scans: ScanSet) -> np.ndarray:
        from tracking.idpc import ftc, idpc

        S = len(self.roster) if self.assumed_scans == "all" else len(scans)
        cluster = ftc if self.method == "ftc" else idpc
        c = cluster(self.plane(scans), S, self.params, np.random.default_rng(self.seed)).centres
        out = np.zeros((len(c), 4))
        out[:, [0, 2]] = c
        return out

    def adopt(self, fused) -> None:
        """Nothing: a scan set is not a prior."""


class FloodFuser:
    """The flooding of one peer as consensus rounds: round ``l`` takes in what the neighbours
    forwarded in iteration ``l`` (de-duplicated by (origin, scan) in a :class:`Flooder`) and
    the peer then forwards only the scans new to it (:meth:`outgoing`). After the last round
    the scan is closed: origins never received count as missing.

    ``counts`` (in the peer summary): ``scans_closed``, ``scans_complete`` (every origin
    held), ``missing`` (origins not held at the close), ``duplicates`` (copies of scans held),
    ``late_absorbed`` (copies after their iteration, before the close: still pooled and
    forwarded), ``late`` (after the close: dropped).
    """

    kinds = ("posterior",)
    max_rounds = 1 << 30

    def __init__(self, name: str, origins: Sequence[str], rounds: int) -> None:
        self.name = name
        self.index = {o: i for i, o in enumerate(origins)}
        self.rounds = rounds
        self.k: int | None = None
        self.flooder = Flooder(self.index.get(name, -1))
        self.counts: Counter = Counter()

    def _names(self, held: dict) -> dict[str, np.ndarray]:
        names = list(self.index)
        return {names[o]: z for (o, _), z in held.items()}

    def _take(self, sender: str, scans: ScanSet, k: int) -> None:
        f = self.flooder
        for origin, z in scans.scans.items():
            o = self.index.get(origin)
            if o is not None:
                f.receive(o, k, z)

    def fuse(self, inp: FusionInput) -> ScanSet:
        f = self.flooder
        if inp.round == 0:
            if self.k is not None and inp.k <= self.k:  # the scan numbering restarted
                self.flooder = f = Flooder(self.index.get(self.name, -1))
            elif self.k is not None and (self.index.get(self.name, -1), self.k) in f.held:
                self._close(self.k)  # a scan ended without its last round
            self.k = inp.k
            for origin, z in inp.own.scans.items():  # the own scan went out in iteration 1
                f.held[(self.index[origin], inp.k)] = np.asarray(z, float).reshape(-1, 2)
        dup = f.duplicates
        for s in sorted(inp.neighbours):
            self._take(s, inp.neighbours[s]["posterior"], inp.k)
        self.counts["duplicates"] += f.duplicates - dup
        pooled = ScanSet(self._names(f.pooled_keys(inp.k)))
        if inp.round + 1 >= self.rounds:
            self._close(inp.k)
        return pooled

    def outgoing(self, fused: ScanSet) -> ScanSet:
        """What to forward in the next iteration: the scans new since the last one."""
        names = list(self.index)
        return ScanSet({names[o]: z for (o, _), z in self.flooder.outgoing()})

    def late(self, sender: str, scans: ScanSet, k: int) -> None:
        """Scans that came after their iteration: pooled (and forwarded) while the scan is
        open, else counted late."""
        if self.k is not None and k == self.k and (self.index.get(self.name, -1), k) in \
                self.flooder.held:
            dup = self.flooder.duplicates
            before = len(self.flooder.held)
            self._take(sender, scans, k)
            self.counts["duplicates"] += self.flooder.duplicates - dup
            self.counts["late_absorbed"] += len(self.flooder.held) - before
        else:
            self.counts["late"] += len(scans)

    def _close(self, k: int) -> None:
        missing = self.flooder.close(k, len(self.index))
        self.counts["scans_closed"] += 1
        self.counts["scans_complete"] += missing == 0
        self.counts["missing"] += missing


# -- the iterated-corrector baseline as a flooding peer (seed 004) ---------------------------
def corrector_order(adjacency: np.ndarray) -> np.ndarray:
    """The iterated corrector's sensor order (seed 004, ALGORITHMS.md §9): depth-first over the
    graph from sensor 0, the order in which the offline IC (``sim.seed004``) passes the density
    along; sensors it does not reach (a disconnected graph) follow in index order."""
    from scipy.sparse.csgraph import depth_first_order

    A = np.asarray(adjacency, dtype=bool)
    if len(A) == 0:
        return np.zeros(0, dtype=np.int64)
    order = depth_first_order(A, 0, directed=False, return_predecessors=False)
    return np.concatenate((order, np.setdiff1d(np.arange(len(A)), order)))


class IcFloodEstimator(FloodEstimator):
    """The iterated-corrector PHD (sensor-by-sensor update) of seed 004 (ALGORITHMS.md §9) as a
    flooding peer's estimator: the scans are flooded as for IDPC, and each peer runs one GM-PHD
    over its pooled scan set.

    ``filt`` is a :class:`tracking.gmphd.GMPHDFilter` with one :class:`~tracking.gmphd.
    SensorParams` per sensor of the network, in the corrector's fixed order ``order`` (sensor
    names; :func:`corrector_order`: depth-first from the first sensor, as the offline IC).
    Per scan: ``step`` predicts the carried posterior (``steps`` scans, births once) and
    publishes the own scan; after the last flooding round :class:`IcFloodFuser` calls
    :meth:`posterior` with the pooled scans, which corrects the prediction with each held scan
    in ``order`` (``GMPHDFilter.correct``: update, then level-1 reduction, after each sensor)
    and keeps the result as the next scan's prior. A sensor whose scan is not in the pool is
    skipped in that scan's correction and counted (``ic_skipped``). On a complete pool every
    peer computes the offline IC's posterior, number for number (tests/test_flooding_ic.py).

    ``counts``: ``ic_scans`` (posteriors kept), ``ic_corrections`` (sensor updates made),
    ``ic_skipped`` (scans missing from the pool), ``ic_own_only`` (scans whose flooding never
    reached its last round here, e.g. a peer without neighbours: corrected with the own scan
    only when the next scan arrives).
    """

    def __init__(self, name: str, filt, order: Sequence[str]) -> None:
        order = tuple(order)
        if len(order) != len(filt.sensors) or len(set(order)) != len(order):
            raise ValueError(f"order {order}: expected {len(filt.sensors)} distinct sensors, "
                             f"one per SensorParams of the filter")
        if name not in order:
            raise ValueError(f"peer {name!r} is not in the corrector order")
        super().__init__(name, {o: s.model for o, s in zip(order, filt.sensors, strict=True)})
        self.filter = filt
        self.order = order
        self._sensor = dict(zip(order, filt.sensors, strict=True))
        self.mix = filt.initial()
        """The last posterior kept (the prior of the next scan, before prediction)."""
        self.prior = None
        """This scan's prediction (set by :meth:`step`)."""
        self._open: ScanSet | None = None
        self.counts: Counter = Counter()

    def step(self, steps: int, z: np.ndarray) -> LocalOutput:
        if self._open is not None:  # the last scan never reached its last round here
            self.posterior(self._open, commit=True)
            self.counts["ic_own_only"] += 1
        self.prior = self.filter.predict(self.mix, steps)
        out = super().step(steps, z)
        self._open = out.density
        return LocalOutput(out.density, out.published,
                           {**out.info, "n_prior": len(self.prior)})

    def posterior(self, scans: ScanSet, commit: bool = False):
        """This scan's prediction corrected sensor by sensor with the held scans of ``scans``,
        in ``order`` (absent sensors skipped); ``commit``: keep it as the carried posterior
        and count. A :class:`~tracking.mixture.GaussianMixture`."""
        from dataclasses import replace

        if self.prior is None:
            raise ValueError("posterior before the first scan")
        held = [o for o in self.order if o in scans.scans]
        post = replace(self.filter, sensors=[self._sensor[o] for o in held]).correct(
            self.prior, [scans.scans[o] for o in held])
        if commit:
            self.mix, self._open = post, None
            self.counts["ic_scans"] += 1
            self.counts["ic_corrections"] += len(held)
            self.counts["ic_skipped"] += len(self.order) - len(held)
        return post

    def extract(self, density) -> np.ndarray:
        """Estimates ``(n, 4)`` from a posterior mixture, or from a scan set (the local view:
        this scan's prediction corrected with what it holds, nothing kept)."""
        if isinstance(density, ScanSet):
            density = self.posterior(density)
        return self.filter.extract(density)


class IcFloodFuser(FloodFuser):
    """:class:`FloodFuser` for :class:`IcFloodEstimator`: the rounds flood the scans as before;
    the last round returns the iterated corrector's posterior over the pooled scans (which the
    estimator keeps) instead of the scan set. Its ``counts`` are the estimator's: the summary's
    ``fuser`` counts carry both the flooding and the corrector numbers."""

    def __init__(self, name: str, origins: Sequence[str], rounds: int,
                 estimator: IcFloodEstimator) -> None:
        super().__init__(name, origins, rounds)
        self.estimator = estimator
        self.counts = estimator.counts

    def fuse(self, inp: FusionInput):
        pooled = super().fuse(inp)
        if inp.round + 1 >= self.rounds:
            return self.estimator.posterior(pooled, commit=True)
        return pooled


__all__ = ["Deliver", "FloodEstimator", "FloodFuser", "FloodOutcome", "Flooder",
           "IcFloodEstimator", "IcFloodFuser", "TUPLES_PER_MEASUREMENT", "corrector_order",
           "flood", "flooding_bytes", "flooding_tuples"]
