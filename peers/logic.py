"""The peer's logic as a sans-I/O state machine (no sockets, no clocks, no Zenoh, no Rerun).

Inputs: ``on_scan`` (a sensor scan), ``on_estimate`` (a decoded neighbour estimate),
``on_deadline`` (the fusion deadline of a scan passed), ``on_truth``, ``on_peer_left`` /
``on_peer_joined``. Each returns the messages to publish. Records for logging and the
summary accumulate in :attr:`PeerLogic.records` and :attr:`PeerLogic.stats`.

Per scan ``k`` (ALGORITHMS.md §3, §5): local GM-PHD step -> publish the round-0 estimate ->
``L`` consensus rounds; round ``l`` fuses the peer's current density with its neighbours'
round-``(l-1)`` densities by GCI with Metropolis weights (round 0 through the NALE buffer, so
late estimates are predicted to ``k``), then reduces. A round runs as soon as every live
neighbour's input is in, or at the deadline with whatever arrived. After round ``L`` the fused
tracks are published.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from protocol.messages import Estimate, Scan, Tracks
from tracking.fusion import aa_fuse, gci_fuse, gci_fuse_optimised
from tracking.gmphd import GMPHDFilter
from tracking.metrics import ospa
from tracking.mixture import GaussianMixture
from tracking.nale import NaleBuffer
from tracking.reduction import keep_above

FUSION_RULES = ("gci", "aa", "ratio", "none")
OMEGA_RULES = ("metropolis", "uniform", "det", "chernoff")


@dataclass(frozen=True)
class PeerOptions:
    """How one peer filters and fuses."""

    name: str
    """This peer's name (also its key in the network)."""
    sensor: str
    """The sensor whose scans this peer filters."""
    neighbours: tuple[str, ...] = ()
    """Peers whose estimates are fused here."""
    degrees: tuple[tuple[str, int], ...] = ()
    """Degree of this peer and of each neighbour in the graph (for Metropolis weights)."""
    fusion: str = "gci"
    """``"gci"``, ``"aa"`` or ``"none"``."""
    rounds: int = 1
    """Consensus rounds ``L`` per scan."""
    omega: str = "metropolis"
    """Fusion weights: ``"metropolis"``, ``"uniform"``, or optimised ``"det"``/``"chernoff"``."""
    level2: bool = True
    """Publish only components heavier than ``level2_threshold`` (seed 000 level 2)."""
    level2_threshold: float = 0.5
    cardinality: str = "separate"
    """GCI mass rule (see :func:`tracking.fusion.gci_combine`)."""
    max_age: int | None = 5
    """Neighbour estimates older than this many scans are not fused."""
    policy: str = "nale"
    """Out-of-sequence policy: ``"nale"``, ``"drop-late"`` or ``"as-is"``."""
    feedback: bool = False
    """Use the fused density as the local filter's prior for the next scan."""
    ospa_cutoff: float = 200.0
    ospa_order: float = 2.0

    def __post_init__(self) -> None:
        if self.fusion not in FUSION_RULES:
            raise ValueError(f"unknown fusion rule {self.fusion!r}; expected {FUSION_RULES}")
        if self.omega not in OMEGA_RULES:
            raise ValueError(f"unknown omega rule {self.omega!r}; expected {OMEGA_RULES}")
        if self.rounds < 1:
            raise ValueError("consensus rounds must be at least 1")
        if self.name in self.neighbours:
            raise ValueError("a peer cannot be its own neighbour")


@dataclass
class PeerStats:
    """Counters reported in the summary."""

    scans: int = 0
    stale_scans: int = 0
    estimates_in: int = 0
    estimates_out: int = 0
    tuples_out: int = 0
    """Numbers published in estimates (15 per 4-D component: ALGORITHMS.md §9)."""
    not_neighbour: int = 0
    incompatible: int = 0
    """Neighbour estimates of the wrong state dimension for this peer's filter."""
    old_round_estimates: int = 0
    fusions: int = 0
    fused_inputs: int = 0
    deadline_fusions: int = 0
    fusion_fallbacks: int = 0
    """Fusions that produced no finite density (disjoint summaries): own estimate kept."""
    tracks_out: int = 0
    peers_left: list[tuple[str, int]] = field(default_factory=list)
    peers_joined: list[tuple[str, int]] = field(default_factory=list)
    last_fused_from: dict[str, int] = field(default_factory=dict)
    """The last scan at which each neighbour's estimate was fused here."""


@dataclass
class _ScanState:
    """Fusion progress of one scan."""

    k: int
    round: int = 0
    current: GaussianMixture | None = None
    done: bool = False


class PeerBase:
    """What every peer kind shares: liveliness of neighbours, truth, and the record queue.

    Subclasses set ``o`` (options), ``alive``, ``stats``, ``last_k``, ``records``, ``_truth``
    and implement ``_score(k)``.
    """

    def on_truth(self, k: int, states: np.ndarray) -> None:
        """True target states of scan ``k`` (from the world), for OSPA in the records."""
        self._truth[k] = np.asarray(states)
        self._score(k)

    def on_peer_left(self, name: str) -> list:
        """A neighbour's liveliness token went away: stop waiting for it."""
        if name in self.alive:
            self.alive.discard(name)
            self.stats.peers_left.append((name, self.last_k))
        return []

    def on_peer_joined(self, name: str, now: float) -> list:
        """A neighbour (re)appeared: wait for its estimates again."""
        if name in self.o.neighbours and name not in self.alive:
            self.alive.add(name)
            self.stats.peers_joined.append((name, self.last_k))
        return []

    def _from_neighbour(self, est: Estimate) -> bool:
        """Whether ``est`` comes from a configured neighbour (own and strangers' are ignored;
        strangers are counted); counts the accepted ones."""
        if est.sender == self.o.name:
            return False
        if est.sender not in self.o.neighbours:
            self.stats.not_neighbour += 1
            return False
        self.stats.estimates_in += 1
        return True

    def busy(self) -> bool:
        """Whether the current scan's fusion is still to come (drivers defer side work)."""
        return False

    def drain_records(self) -> list[dict]:
        """Hand the accumulated records to the driver (and forget them)."""
        out, self.records = self.records, []
        return out


class PeerLogic(PeerBase):
    """One peer's behaviour; the runtime (Zenoh) and the twin (virtual clock) both drive it."""

    def __init__(self, options: PeerOptions, filt: GMPHDFilter) -> None:
        if options.fusion == "ratio":
            raise ValueError("the particle fusion rule ('ratio') needs single-target peers")
        self.o = options
        self.filter = filt
        self.reduce = filt.reducer
        self.mix = filt.initial()
        self.last_k = 0
        self.nale = NaleBuffer(max_age=options.max_age, policy=options.policy)
        self.alive: set[str] = set(options.neighbours)
        self._deg = dict(options.degrees)
        self._inbox: dict[tuple[int, int], dict[str, GaussianMixture]] = defaultdict(dict)
        self._scan: _ScanState | None = None
        self._seq = 0
        self._truth: dict[int, np.ndarray] = {}
        self._local_est: dict[int, np.ndarray] = {}
        self._fused_est: dict[int, np.ndarray] = {}
        self.stats = PeerStats()
        self.records: list[dict] = []
        """Per-scan records (drained by the runtime for Rerun and the summary)."""
        self.ospa_sums = {"local": 0.0, "fused": 0.0}
        self.ospa_counts = {"local": 0, "fused": 0}
        self._scored: set[tuple[str, int]] = set()
        self._unscored: list[int] = []

    def busy(self) -> bool:
        return self._scan is not None and not self._scan.done

    # -- helpers --------------------------------------------------------------------------
    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _publishable(self, mix: GaussianMixture, rnd: int = 0) -> GaussianMixture:
        """Level-2 pruning of the local (round-0) estimate before it is fused (seed 000).

        Intermediate consensus densities (rounds >= 1) go out level-1 reduced only: pruning
        them at ``w > 0.5`` drops targets whose fused mass is split over several components
        (measured: 2 rounds on seed 000 went from 25 to 45 m mean OSPA with it).
        """
        return keep_above(mix, self.o.level2_threshold) if self.o.level2 and rnd == 0 else mix

    def _estimate(self, k: int, rnd: int, mix: GaussianMixture, now: float) -> Estimate:
        self.stats.estimates_out += 1
        mix = self._publishable(mix, rnd)
        d = mix.dim
        self.stats.tuples_out += len(mix) * (1 + d + d * (d + 1) // 2)
        return Estimate(self.o.name, k, mix, round=rnd,
                        seq=self._next_seq(), send_time=now,
                        pruning=2 if self.o.level2 and rnd == 0 else 1)

    def _weights(self, senders: list[str]) -> list[float]:
        """Fusion weights for [self] + senders (Metropolis on the configured degrees).

        A neighbour whose input is missing simply has no term; its weight stays with this peer
        (``omega_ii = 1 - sum_j omega_ij`` over the neighbours present).
        """
        n = len(senders) + 1
        if self.o.omega == "uniform":
            return [1.0 / n] * n
        di = self._deg.get(self.o.name, len(self.o.neighbours))
        w = [1.0 / (1.0 + max(di, self._deg.get(s, di))) for s in senders]
        return [1.0 - sum(w), *w]

    def _predict_stored(self, mix: GaussianMixture, steps: int) -> GaussianMixture:
        """NALE multi-step prediction of a neighbour estimate (births added once), §5."""
        return self.filter.predict(mix, steps) if steps > 0 else mix

    # -- inputs ---------------------------------------------------------------------------
    def on_scan(self, scan: Scan, now: float) -> list:
        """Local filter step with the scan; publish the round-0 estimate; maybe fuse at once."""
        if scan.k <= self.last_k:
            self.stats.stale_scans += 1
            return []
        out: list = []
        if self._scan is not None and not self._scan.done:
            out += self._finish(self._scan.k, now, forced=True)
        steps = scan.k - self.last_k
        self.mix = self.filter.correct(self.filter.predict(self.mix, steps), [scan.z])
        self.last_k = scan.k
        self.stats.scans += 1
        self._scan = _ScanState(scan.k, 0, self.mix)
        self._unscored.append(scan.k)
        if self.o.fusion != "none" and self.o.neighbours:
            est = self._estimate(scan.k, 0, self.mix, now)
            out.append(est)
            self._record(scan.k, "local", n_components=len(self.mix),
                         n_published=len(est.mixture))
        else:
            self._record(scan.k, "local", n_components=len(self.mix),
                         n_published=len(self._publishable(self.mix)))
        out += self._advance(now)
        self._drop_old(scan.k)
        return out

    def score_local(self) -> None:
        """Extract and score the local estimates not yet scored.

        Kept off the critical path: drivers call it after publishing what ``on_scan`` returned,
        while the estimate travels to the neighbours (it also runs before any fusion).
        """
        while self._unscored:
            k = self._unscored.pop()
            if k == self.last_k:
                self._local_est[k] = self.filter.extract(self.mix)
                self._score(k)

    def on_estimate(self, est: Estimate, now: float) -> list:
        """Store a neighbour's estimate (round 0 through NALE); fuse if a round is complete."""
        if not self._from_neighbour(est):
            return []
        if est.round == 0:
            self.nale.offer(est.sender, est.k, est.mixture)
        if self._scan is not None and est.k < self._scan.k and est.round > 0:
            self.stats.old_round_estimates += 1
            return []
        self._inbox[(est.k, est.round)][est.sender] = est.mixture
        return self._advance(now)

    def on_deadline(self, k: int, now: float) -> list:
        """The fusion deadline of scan ``k``: run the remaining rounds with what arrived."""
        if self._scan is None or self._scan.k != k or self._scan.done:
            return []
        return self._finish(k, now, forced=True)

    # -- fusion ---------------------------------------------------------------------------
    def _inputs(self, k: int, rnd: int) -> dict[str, GaussianMixture]:
        if rnd == 0:
            got = self.nale.collect(k, self._predict_stored)
            for sender, mix in self._inbox.get((k, 0), {}).items():
                got.setdefault(sender, mix)
            return got
        return dict(self._inbox.get((k, rnd), {}))

    def _ready(self, k: int, rnd: int) -> bool:
        if self.o.fusion == "none" or not self.o.neighbours:
            return True
        have = self._inbox.get((k, rnd), {})
        return all(n in have for n in self.alive)

    def _advance(self, now: float) -> list:
        """Run every consensus round whose inputs are all in."""
        out: list = []
        st = self._scan
        while st is not None and not st.done and self._ready(st.k, st.round):
            out += self._fuse_round(st, now)
        return out

    def _finish(self, k: int, now: float, forced: bool) -> list:
        out: list = []
        st = self._scan
        if forced and st is not None and not st.done:
            self.stats.deadline_fusions += 1
        while st is not None and not st.done:
            out += self._fuse_round(st, now)
        return out

    def _fuse_round(self, st: _ScanState, now: float) -> list:
        """Consensus round ``st.round + 1`` of scan ``st.k``."""
        if self.o.fusion == "none" or not self.o.neighbours:
            st.done = True
            return self._tracks(st.k, st.current, now)
        inputs = self._inputs(st.k, st.round)
        senders = sorted(inputs)
        own = self._publishable(st.current, st.round)
        densities = [own] + [inputs[s] for s in senders]
        self.stats.fusions += 1
        self.stats.fused_inputs += len(senders)
        for sender in senders:
            self.stats.last_fused_from[sender] = st.k
        ages = self.nale.ages(st.k) if st.round == 0 else {}
        if self.o.fusion == "aa":
            fused = aa_fuse(densities, self._weights(senders), self.reduce)
        elif self.o.omega in ("det", "chernoff"):
            fused = gci_fuse_optimised(densities, self.o.omega, self.reduce, self.o.cardinality)
        else:
            fused = gci_fuse(densities, self._weights(senders), self.reduce,
                             cardinality=self.o.cardinality)
        st.round += 1
        st.current = fused
        self._record(st.k, "fusion", round=st.round, n_inputs=len(senders),
                     n_fused=len(fused), ages={s: ages.get(s, 0) for s in senders})
        if st.round < self.o.rounds:
            return [self._estimate(st.k, st.round, fused, now)]
        st.done = True
        if self.o.feedback:
            self.mix = fused
        return self._tracks(st.k, fused, now)

    def _tracks(self, k: int, fused: GaussianMixture, now: float) -> list:
        self.score_local()
        states = self.filter.extract(fused)
        self._fused_est[k] = states
        self._score(k)
        self.stats.tracks_out += 1
        return [Tracks(self.o.name, k, states, seq=self._next_seq(), send_time=now)]

    # -- bookkeeping ----------------------------------------------------------------------
    def _record(self, k: int, kind: str, **values) -> None:
        self.records.append({"k": k, "kind": kind, **values})

    def _score(self, k: int) -> None:
        X = self._truth.get(k)
        if X is None:
            return
        c, p = self.o.ospa_cutoff, self.o.ospa_order
        for kind, est in (("local", self._local_est), ("fused", self._fused_est)):
            if k in est and (kind, k) not in self._scored:
                value = ospa(est[k][:, [0, 2]], X[:, [0, 2]], c, p)
                self._scored.add((kind, k))
                self.ospa_sums[kind] += value
                self.ospa_counts[kind] += 1
                self._record(k, "ospa", which=kind, value=value)

    def mean_ospa(self, kind: str) -> float:
        """Mean OSPA so far of the ``"local"`` or ``"fused"`` estimates."""
        n = self.ospa_counts[kind]
        return self.ospa_sums[kind] / n if n else float("nan")

    def _drop_old(self, k: int) -> None:
        """Bound memory: forget inbox entries, truths and estimates of scans long past."""
        horizon = k - max(2, (self.o.max_age or 0) + 1)
        for key in [key for key in self._inbox if key[0] < k]:
            del self._inbox[key]
        for d in (self._truth, self._local_est, self._fused_est):
            for old in [kk for kk in d if kk < horizon]:
                del d[old]
        self._scored = {(kind, kk) for kind, kk in self._scored if kk >= horizon}

    def fused_tracks(self, k: int) -> np.ndarray | None:
        return self._fused_est.get(k)

    def current_fused(self) -> GaussianMixture | None:
        """The latest fused density of the current scan (None before its first round)."""
        st = self._scan
        return st.current if st is not None and st.round > 0 else None
