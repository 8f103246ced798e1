"""Flooding as a peer mode (seed 004, :mod:`peers.contracts`): the estimator and fuser parts.

:class:`FloodEstimator` publishes the own scan and clusters a pooled scan set (IDPC or FTC);
:class:`FloodFuser` runs the flooding of :class:`peers.flooder.Flooder` as consensus rounds.
:class:`IcFloodEstimator` / :class:`IcFloodFuser` are the iterated-corrector PHD over the same
flooded scans (the sensor order from :func:`corrector_order`).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from sensornet.peers.contracts import FusionInput, LocalOutput
from sensornet.peers.flooder import Flooder
from sensornet.protocol.messages import ScanSet
from sensornet.tracking.idpc import ClusterParams, dbscan_class, ftc, idpc, polar_to_cartesian
from sensornet.tracking.models import RangeBearing

CLUSTERED_KEPT = 32
"""Pooled scan sets whose clustering a process keeps (:data:`_CLUSTERED`)."""
_CLUSTERED: dict[tuple, np.ndarray] = {}
"""The last :data:`CLUSTERED_KEPT` pooled sets' cluster centres, by everything they depend on
(method, ``S``, parameters, seed and the points' bytes): once flooding is complete every peer
pools the same points, so in a host of ten (or the twin's one process) one of them clusters
and the others read the same centres (issue 38); a set that differs by a bit is clustered
afresh. Read-only; each caller copies them into its own estimate rows."""


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
        if assumed_scans not in ("held", "all"):
            raise ValueError(f"assumed_scans {assumed_scans!r}: expected 'held' or 'all'")
        if method not in ("idpc", "ftc"):
            raise ValueError(f"method {method!r}: expected 'idpc' or 'ftc'")
        if method == "ftc":
            dbscan_class()  # scikit-learn is optional: say so when the peer is built
        self.method = method
        self.name = name
        self.roster = dict(roster)
        self._rank = {o: i for i, o in enumerate(self.roster)}
        self._planes: list[tuple[ScanSet, np.ndarray]] = []
        """The last two scan sets given to :meth:`plane` (by identity) and their points."""
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
        """The pooled points ``(n, 2)`` in the plane, read-only: the last two scan sets' are
        kept, as the clustering and a watched peer's report ask for the same ones (issue 38)."""
        for held, points in self._planes:
            if held is scans:
                return points
        parts = []
        for origin in sorted(scans.scans, key=self._order):  # one order at every peer
            z, model = scans.scans[origin], self.roster.get(origin)
            parts.append(polar_to_cartesian(z, model.position)
                         if isinstance(model, RangeBearing) else z)
        points = np.concatenate(parts) if parts else np.zeros((0, 2))
        points.flags.writeable = False
        self._planes = [(scans, points), *self._planes[:1]]
        return points

    def extract(self, scans: ScanSet) -> np.ndarray:
        """Estimate rows ``(k, 4)`` of the clustered points; a pooled set's centres are kept
        by content (:data:`_CLUSTERED`): the co-hosted peers that hold the same scans cluster
        them once."""
        S = len(self.roster) if self.assumed_scans == "all" else len(scans)
        points = self.plane(scans)
        key = ((self.method, S, self.params, self.seed, points.shape, points.tobytes())
               if len(scans) > 1 else None)  # an own scan alone is no other peer's
        c = None if key is None else _CLUSTERED.get(key)
        if c is None:
            cluster = ftc if self.method == "ftc" else idpc
            c = cluster(points, S, self.params, np.random.default_rng(self.seed)).centres
            if key is not None:
                c.flags.writeable = False
                if len(_CLUSTERED) >= CLUSTERED_KEPT:
                    del _CLUSTERED[next(iter(_CLUSTERED))]  # the oldest
                _CLUSTERED[key] = c
        out = np.zeros((len(c), 4))
        out[:, [0, 2]] = c
        return out

    def adopt(self, fused) -> None:
        """Nothing: a scan set is not a prior."""


@dataclass(frozen=True)
class ScanBound:
    """What one origin's scan can plausibly hold: at most ``max_returns`` returns, each inside
    the sensor's measurement box ``[low, high]`` (its field: the region for a linear sensor,
    ``[0, r_max] x [-pi, pi]`` for a radar, widened by a margin of measurement noise).

    A forwarded scan is raw data nobody can check against a density; these bounds at least
    keep a flooding member (or a relay) from injecting a flood of returns or points its
    origin's sensor cannot produce (issue 24)."""

    low: tuple[float, float]
    high: tuple[float, float]
    max_returns: int

    def __post_init__(self) -> None:
        box = np.array([self.low, self.high], dtype=float)
        box.flags.writeable = False
        object.__setattr__(self, "_box", box)  # the bounds as one array, made once

    def refusal(self, z: np.ndarray) -> str | None:
        """None if ``z`` ``(m, 2)`` is plausible, else the reason: ``too_many_returns`` or
        ``outside_field`` (a NaN fails both comparisons, so it is outside too)."""
        if len(z) > self.max_returns:
            return "too_many_returns"
        if len(z) and not ((z >= self._box[0]) & (z <= self._box[1])).all():
            return "outside_field"
        return None


def poisson_bound(mean: float, tail: float = 1e-9) -> int:
    """The smallest ``m`` with ``P(N > m) < tail`` for ``N ~ Poisson(mean)``: an honest scan
    (clutter plus at most one return per target) exceeds it about once in ``1/tail`` scans."""
    if mean <= 0:
        return 0
    m, term = 0, math.exp(-mean)
    cdf = term
    while 1.0 - cdf >= tail and m < 100_000:
        m += 1
        term *= mean / m
        cdf += term
    return m


class FloodFuser:
    """The flooding of one peer as consensus rounds: round ``l`` takes in what the neighbours
    forwarded in iteration ``l`` (de-duplicated by (origin, scan) in a :class:`Flooder`) and
    the peer then forwards only the scans new to it (:meth:`outgoing`). After the last round
    the scan is closed: origins never received count as missing.

    ``counts`` (in the peer summary): ``scans_closed``, ``scans_complete`` (every origin
    held), ``missing`` (origins not held at the close), ``duplicates`` (copies of scans held),
    ``late_absorbed`` (copies after their iteration, before the close: still pooled and
    forwarded), ``late`` (after the close: dropped), and ``refused_<reason>`` (a neighbour's
    forwarded scan outside its origin's :class:`ScanBound`: neither pooled nor forwarded).
    """

    kinds = ("posterior",)
    max_rounds = 1 << 30

    def __init__(self, name: str, origins: Sequence[str], rounds: int,
                 bounds: Mapping[str, ScanBound] | None = None) -> None:
        self.name = name
        self.index = {o: i for i, o in enumerate(origins)}
        self.rounds = rounds
        self.bounds = dict(bounds or {})
        """Per origin, what its scans can plausibly hold (none: not checked)."""
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
            if o is None or (o, k) in f.held:
                if o is not None:
                    f.receive(o, k, z)  # a copy: counted a duplicate, never re-checked
                continue
            bound = self.bounds.get(origin)
            reason = bound.refusal(np.asarray(z, float).reshape(-1, 2)) if bound else None
            if reason is not None:
                self.counts[f"refused_{reason}"] += 1
                continue
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
    """The iterated corrector's sensor order (seed 004, docs/seed004.md): depth-first over the
    graph from sensor 0, the order in which the offline IC (``sim.studies.seed004.montecarlo``)
    passes the density
    along; sensors it does not reach (a disconnected graph) follow in index order."""
    # heavy dependency: scipy.sparse (only the iterated corrector's order needs it)
    from scipy.sparse.csgraph import depth_first_order

    A = np.asarray(adjacency, dtype=bool)
    if len(A) == 0:
        return np.zeros(0, dtype=np.int64)
    order = depth_first_order(A, 0, directed=False, return_predecessors=False)
    return np.concatenate((order, np.setdiff1d(np.arange(len(A)), order)))


class IcFloodEstimator(FloodEstimator):
    """The iterated-corrector PHD (sensor-by-sensor update) of seed 004 (docs/seed004.md) as a
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
                 estimator: IcFloodEstimator,
                 bounds: Mapping[str, ScanBound] | None = None) -> None:
        super().__init__(name, origins, rounds, bounds)
        self.estimator = estimator
        self.counts = estimator.counts

    def fuse(self, inp: FusionInput):
        pooled = super().fuse(inp)
        if inp.round + 1 >= self.rounds:
            return self.estimator.posterior(pooled, commit=True)
        return pooled
