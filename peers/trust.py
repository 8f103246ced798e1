"""Trust in neighbours: a consistency test per neighbour and round, a score over scans, weights.

A member with a valid key can still lie about its own estimate, and a broken sensor does the
same by accident. Before every consensus round each neighbour's density is tested against two
references it cannot have shaped: this peer's own density, and the weighted average of the
other trusted inputs (own included, the tested neighbour left out). The statistic is the
smaller of the two tests' values, each

``T = D_CS(D_j, R) + kappa (N_j - N_R)^2 / (N_R + 1)``

(the closed-form Cauchy–Schwarz divergence of :mod:`tracking.divergence`, which compares where
the targets are, plus a cardinality term for how many), capped at :attr:`TrustConfig.cap`. A
neighbour's score is a leaky CUSUM of its per-scan statistic (the largest of its rounds),
``S_k = max(0, leak S_(k-1) + T_k - drift)``: a strong lie is caught in two scans, a mild
persistent one accumulates, an honest peer's few bad scans (a track that died a scan early, a
birth picked up late) fade. Its weight falls linearly from 1 at ``suspect`` to 0 at
``quarantine``, where it is quarantined until its score stays under ``suspect`` for ``readmit``
scans in a row. What a neighbour loses is shared over own and the trusted neighbours (the
consensus weights renormalised over the trusted set), so the weights still sum to one. Under a
product rule (GCI: ``drop_suspects``) a neighbour below full trust is dropped, not
down-weighted: any weight above 0 lets a confident lie veto the product.

With own and at least two other trusted neighbours (:attr:`TrustConfig.majority`,
W-MSR-style) the statistic is instead the neighbour's median test against those others less
the median test between them: a neighbour is scored for disagreeing with a majority that
agrees, not for a scan where everyone disagrees, and two liars telling the same lie do not
cover for each other (each one's lie would be in the other's leave-one-out average).

Faults are not lies (:attr:`TrustConfig.same_scan`, :attr:`TrustConfig.detection_probability`):
each neighbour estimate is tested once, against own's density of the scan it was made at. An
estimate used again at a later scan (its successor late or lost, predicted forward by the
out-of-sequence policy) adds statistic 0 and is no reference for the others; one that
arrives after its scan is tested at its first use against own's density of that scan. The
location part of every test (the divergence, or the empty penalty) is at most the evidence
needed to explain the whole disagreement by missed detections, ``-log(1 - Pd)`` per unit of
target weight on either side (:func:`peers.trust_checks.miss_cost`, Pd the smallest of the
peer's and its neighbours' sensors): a target missed at a scan falls under the publishing
threshold (level-2 pruning), and a target born a scan apart looks the same, so an honest
density lacks a target at rate ``1 - Pd`` and the log-likelihood ratio of that, lying
against honest, is ``-log(1 - Pd)``. In the majority's pair tests it is also at least
``unmatched_cost = drift`` per unit of target weight that one side shows and the other has
nothing within 60 m of (:func:`peers.trust_checks.unmatched_weights`): one extra target
that a neighbour keeps alone never accumulates, three phantoms do (the divergence alone
counts an extra target next to matched ones for little). Not with two neighbours, where no
majority tells an honest neighbour that lost several targets at once at Pd 0.9 from a liar
(it quarantined honest neighbours on 3 % of seed 000's Pd-0.9 evaluation triples). The
cardinality term stays.

A biased sensor (every estimate a fixed distance off under an honest covariance) is, scan by
scan, within an honest neighbour's scatter; its offset, though, is the same every scan
(:attr:`TrustConfig.bias`): the neighbour's target components are matched to own's nearest,
and the chi-square of the information-weighted mean position difference over the last 3 and
16 scans (``y' I^-1 y``, ``I = sum S_i^-1``, ``y = sum S_i^-1 d_i``, ``S_i`` the summed
position covariances: the generalised-least-squares offset) grows linearly with the window
under a bias while honest errors average out. With three or more neighbours offset against
own at a scan, each one's offset is taken relative to the median of the others'
(:attr:`TrustConfig.bias_relative`): own's own error is in all of them and is taken out.
Above 32 (3 scans) or 40 (16 scans) the neighbour is quarantined at once. The thresholds sit
above the largest honest values on the training runs 9000-9001 (28.2 and 33.2, every graph
and condition below; 30.5 and 41.9 before the relative offset, with thresholds 35 and 50).

The windows see only their last 3 or 16 scans; a sequential test sees all of them
(:attr:`TrustConfig.bias_cusum`): per neighbour, Page's CUSUM (Page 1954, "Continuous
inspection schemes", Biometrika 41) of the per-scan log-likelihood ratio of a bias ``beta``
against none, ``beta' y - beta' I beta / 2`` (the same ``(I, y)``), with ``beta`` 30 m along
each of 8 directions (a chart per direction, the CUSUM their largest): ``g_k = max(0,
g_(k-1) + l_k)``, the largest sum over the windows ending now, which takes no window length
and no start. The increments are those of independent scans; honest offsets are not
(lag-1 correlation 0.5-0.7, lag 3 0.1-0.35 on seed 000's training runs: the filters' errors
follow the same target's manoeuvres), so the honest CUSUM climbs higher than its nominal
false-alarm rate says; that is handled by the threshold, not by whitening: 20, above the
largest honest value on the training runs 9000-9001 (19.7, circulant clean; 19.2 seed 000
clean). Pre-whitening the offsets with an AR(1) of coefficient 0.65 was tried on the same
training runs (offline, on the recorded ``(I, y)``) and was no faster: at its threshold
8, the lowest with no honest quarantine on seed 000, the liar took 10-21 scans (20 here) and
honest neighbours on the seed-004 and circulant graphs were quarantined on 0.05-0.14 % of
triples (whitening takes the bias away with the noise: ``1 - rho`` of it is left per scan). On seed
000 the liar's CUSUM reaches 20 after 16-20 scans of the training runs (the 16-scan window,
after 31): a 30 m offset is about 2.5 honest standard deviations per scan there and honest
offsets of 30-40 m occur for several scans in a row while the filters converge, so no
threshold that keeps honest neighbours in catches it within 3 scans (at 4, where honest
neighbours would be quarantined on 36 % of seed 000's clean training triples, it takes
2-8).

Offsets can be repaired instead (:attr:`TrustConfig.register`, ``fusion.trust_register``):
a neighbour the offset test fires on has its generalised-least-squares offset subtracted
from its position means before it is tested and fused, re-estimated each scan until its
CUSUM is back at 0. So can lies that still carry the liar's measurements
(:attr:`TrustConfig.repair`, ``fusion.trust_repair``; :mod:`peers.trust_repair`): a
neighbour whose statistic would make it suspect is tested again with its components that
neither own nor two other trusted neighbours corroborate dropped (phantoms), its weights
scaled by the median, over the last 16 scans, of what own weighs the same targets per unit
of its weight (inflated weights), and, when nothing at all is corroborated, moved back by
its offset against own over pairs up to 250 m apart with covariances at least own's (a
confident shifted lie); where that statistic is smaller, the repaired density is scored
and fused in its place. A repair keeps only what others already show a target at and adds
no mass, so a lie without the liar's measurements (empty, stuck) is not repaired and is
caught as before. Both are on by default: on the training runs 9000-9002 (seed 000, seed
004's graph with one and two liars, the circulant graph) they were better than exclusion
alone or equal in every cell, clean runs and honest quarantines unchanged or lower. The
evaluation runs: docs/security.md.

Withheld targets have a sequential test of their own (:attr:`TrustConfig.withhold`): the
leaky score's drift and leak slow a neighbour that publishes nothing (its statistic is about
5 a scan with one target, weight 0.1 at the fourth scan at best), and a scan at which own
is briefly empty too (statistic 0) lets the score fade. Per
neighbour, Page's CUSUM of the log-likelihood ratio that it withholds the targets its
references show against an honest filter that missed them (a Bernoulli miss per unit of
target weight, Wald's SPRT increment: ``log(0.99 / (1 - Pd))`` per unit withheld,
``log(0.01 / Pd)`` per unit shown, :func:`peers.trust_checks.withheld_increments`; the
median over own and the other trusted fresh neighbours, the smallest with fewer than three)
has no drift and no leak: a scan with nothing to compare holds it, each matched unit of
target weight takes ``log(Pd / 0.01)`` off. Honest misses are not independent across
targets: a filter drops every track at once (a whole loss: the neighbour shows no target
while its references show one or more) on 1.15 %
of the training triples (1,107 of 96,632, runs 9000-9001, every graph and condition below;
``python -m sensornet.sim.studies.lying.trust_calibration --runs 2`` prints them and the runs of
each
length, :attr:`Trust.losses`). So one scan's increment is at most ``-log 0.0115 = 4.47``
(two lost targets are no more evidence than one scan of a whole loss). Above one scan's
worth (:attr:`TrustConfig.withhold_hold`, 4.47) the neighbour's weight is held at 0 for the
scan, without a quarantine or any hysteresis: an empty liar from its second scan, an honest
filter from the second scan of a whole loss until it shows its targets again (while it
shows nothing, nothing of it is worth fusing). Above :attr:`TrustConfig.withhold_threshold`,
14, more than three scans of a whole loss, it is quarantined. Before the hold the
threshold was 10, between two scans (8.94) and three (13.4), and what follows is that
design's record. At Pd 0.99 (the training
runs clean and with link faults) honest whole losses lasted two scans 92 times (per tester
and neighbour) and three once (seed 000 clean, s2 at scans 81-83 of run 9000, seen by both
its testers); at Pd 0.9 they last longer (three or four scans 51 times) but a unit of target
weight is worth less (``log(0.99 / 0.1) = 2.3``) and four reached 10 (circulant). So a
neighbour that withholds everything is quarantined at its third scan, an honest one that
loses everything for two is not, and the honest three-scan loss is quarantined like a liar:
seed 000 clean 2.67 -> 4.33 % of its training triples (the two testers of s2), circulant at
Pd 0.9 0.09 -> 0.30 %, every other training cell unchanged (``python -m
sensornet.sim.studies.lying.trust_calibration --runs 2``). On the training runs' lies it takes seed
000's
*empty* from 7 scans to 3 and leaves seed 004's two *empty* liars at 3. The parameters
(alternative 0.99, cap, threshold) were set on the training runs only. With the hold
(training runs 9000-9002, ``python -m sensornet.sim.studies.lying.study --runs 3 --setups seed000
--first-run 9000``): seed 000's *empty* at weight 0 at its second scan (3 before), every
honest peer's fused OSPA equal or lower (hybrid clean 14.14 -> 14.10 m), honest
neighbours held on 0.17 % of their rounds; ``python -m sensornet.sim.studies.lying.trust_calibration
--runs 2``: no quarantine begun by the withheld test (seed 000 clean 4.08 -> 2.42 %,
circulant Pd 0.9 0.26 -> 0.05 %).

A neighbour whose non-empty density at a scan repeats, bit for bit, the one it sent at an
earlier scan is quarantined at once (:attr:`TrustConfig.repeat`): a filter's posterior changes
every scan, so that is a stuck sensor or a replay.

Calibration (``python -m sensornet.sim.studies.lying.trust_calibration --runs 2``, training runs
9000-9001 only;
the
lying study evaluates on 7000..): seed 000, seed 004's graph with GM-PHD peers and the 20-peer
circulant graph of degree 4, each clean, at Pd 0.9 and with link faults (30 ms latency, 20 %
loss, 20 % reordering): 108,288 (peer, neighbour, scan) triples. ``cap = 8``, ``drift = 2``,
``leak = 0.8`` were chosen on the same training runs with the training runs' lies of
:mod:`sim.studies.lying.study`; ``suspect`` and ``quarantine`` (3.5 and 8.6) were the 99th and
99.9th
percentiles of the honest scores before the majority term, which lowered them to 2.05 and 6.59
(kept: the target is per condition, not pooled); with the median test and the repeat test the
pooled 99th / 99.9th percentiles were 2.38 / 7.38, with the same-scan test, the
missed-detection bound and the unmatched term 2.05 / 5.52 (thresholds kept). Honest
neighbours quarantined, clean / Pd 0.9 / link faults: seed 000 2.67 / 0 / 2.85 %, seed 004
0 / 0 / 0 %, circulant 0.13 / 0.09 / 0.06 %; with the withheld-target test seed 000
4.33 / 0 / 2.85 %, seed 004 0 / 0 / 0 %, circulant 0.13 / 0.30 / 0.06 % (its largest honest
values 13.3, seed 000 clean, and 13.4, circulant at Pd 0.9) (before the same-scan test and the
missed-detection bound: 3.58 / 0.67 / 3.94, 0 / 0 / 0 and 0.21 / 0.29 / 0.50 %; the
instrumented counts, ``begun by``, showed every one begun by the divergence test: under link
faults a neighbour's empty estimate after a miss, reused and predicted forward for two or
three scans, counted each time; at Pd 0.9 an honest density lacking a missed target). The
repeat test fired 5 times on honest peers under link faults (circulant, run 9000) before it
skipped birth-only densities, never since. ``kappa = 3`` (tried on the same training runs)
quarantines honest neighbours on 7.92 % (seed 000, clean) and 1.14 % (circulant, Pd 0.9)
of triples: kept at 1. Seed 000 misses the 0.5 % target on the training runs, clean and
with link faults: each peer has two neighbours (no majority), and an honest filter that
loses its only target and re-acquires it from the birth component at the target's start
(75 m off, a tight covariance, scans 3-8 of run 9000) is, for four scans, what a liar is
(at Pd 0.99 two disjoint single targets cost 9.2 to explain by misses, above the cap); no
setting of the score tried (``leak`` 0.6-0.8, ``readmit`` 1-5, ``quarantine`` 8.6-14, no
empty penalty) brings seed 000 under 0.5 % while a lie still reaches weight 0.1 within a
few scans (at 0 % there, *biased* is never caught and *empty* only after 40 scans). How
soon each lie reaches weight <= 0.1 on the evaluation runs is in docs/security.md
(``python -m sensornet.sim.studies.lying.study``'s defence table).

Pure logic (no I/O): :class:`peers.consensus.Consensus` calls :meth:`Trust.weigh` before each
fusion, whatever the fuser (GCI, AA, hybrid, the single-target rules). This module keeps
each neighbour's score, state and weight over the scans; the tests of one scan are in
:mod:`peers.trust_checks`, the settings in :mod:`peers.trust_config`.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np
from sensornet.peers.trust_checks import (
    cusum_directions,
    divergence_test,
    gls_offset,
    is_repeat,
    neighbour_statistics,
    offset_chi2,
    offset_cusum,
    offset_information,
    relative_offsets,
    target_mass,
    unmatched_weights,
    whole_losses,
    withheld_increments,
)
from sensornet.peers.trust_config import TrustConfig
from sensornet.peers.trust_repair import corroborated_part, moved_to_own, scan_factor
from sensornet.tracking.divergence import log_overlaps
from sensornet.tracking.mixture import GaussianMixture

STATES = ("trusted", "suspect", "quarantined")
MAX_LOG = 200
"""State changes kept for the summary (a flapping neighbour cannot grow it)."""
LOW = 0.1
"""A neighbour at or under this trust counts as detected (issue 24's target)."""


def offset_limits(cfg: TrustConfig) -> tuple[float, ...]:
    """The limits of :meth:`Trust._offset`'s values: per window of
    :attr:`TrustConfig.bias_windows` its chi-square threshold, then (with
    :attr:`TrustConfig.bias_cusum`) the CUSUM's."""
    return (*cfg.bias_thresholds, *((cfg.bias_cusum_threshold,) if cfg.bias_cusum else ()))


def alarm_limits(cfg: TrustConfig) -> tuple[float, ...]:
    """The limits of the values in :attr:`Trust.history`'s last field: :func:`offset_limits`,
    then (with :attr:`TrustConfig.withhold`) the withheld-target CUSUM's."""
    return (*offset_limits(cfg), *((cfg.withhold_threshold,) if cfg.withhold else ()))


def _push(window: deque, item, n: int) -> None:
    """Add ``item`` as the newest of ``window`` (newest first), keeping the ``n`` newest: the
    per-neighbour windows are bounded whatever a neighbour sends."""
    window.appendleft(item)
    while len(window) > n:
        window.pop()


@dataclass
class NeighbourTrust:
    """One neighbour's record."""

    score: float = 0.0
    state: str = "trusted"
    streak: int = 0
    """Scans in a row under ``suspect`` while quarantined."""
    scan_max: float = 0.0
    """Largest statistic of the scan being fused."""
    last_statistic: float = float("nan")
    last_weight: float = 1.0
    first_k: int | None = None
    """The first scan it was tested at."""
    low_k: int | None = None
    """The first scan its weight was at most :data:`LOW` (detected)."""
    last_mix: GaussianMixture | None = None
    """Its last round-0 density (the repeat test) and the scan it came at."""
    last_k: int = -1
    tested: int = -1
    """The newest scan whose estimate from this neighbour was tested
    (:attr:`TrustConfig.same_scan`)."""
    offsets: deque = field(default_factory=deque)
    """The offset test's window: per scan ``(I, y)``, ``(2, 2)`` and ``(2,)``."""
    last_offset_chi2: tuple[float, ...] = ()
    """Per window of :attr:`TrustConfig.bias_windows`: the last chi-square of the offset;
    then (:attr:`TrustConfig.bias_cusum`) the offset CUSUM's value."""
    cusum: np.ndarray | None = None
    """The offset CUSUM's charts, ``(directions,)`` (:func:`peers.trust_checks.offset_cusum`)."""
    withheld: float = 0.0
    """The withheld-target CUSUM (:attr:`TrustConfig.withhold`)."""
    registered: np.ndarray | None = None
    """The position offset ``(2,)`` subtracted from its densities (:attr:`TrustConfig.register`),
    or None."""
    rounds: int = 0
    """Rounds it was tested in."""
    holds: int = 0
    """Rounds its weight was held at 0 by the withheld-target test
    (:attr:`TrustConfig.withhold_hold`) where its score alone left it above 0."""
    repairs: int = 0
    """Rounds its repaired (:attr:`TrustConfig.repair`) or registered
    (:attr:`TrustConfig.register`) density was fused in."""
    factors: deque = field(default_factory=deque)
    """Log mass factors of its repairs' last scans (:attr:`TrustConfig.repair_window`)."""
    moves: deque = field(default_factory=deque)
    """Per scan with nothing corroborated, its ``(I, y)`` against own up to
    :attr:`TrustConfig.repair_offset_gate` apart (:meth:`Trust._moved`)."""
    kept_k: int | None = None
    """The last scan a repair of it kept a component."""
    repaired_k: int | None = None
    """The first scan its repaired or registered density was fused at."""
    scans_in: Counter = field(default_factory=Counter)
    """Scans spent in each state."""


class Trust:
    """Per-neighbour consistency tests and weights for one peer."""

    def __init__(self, cfg: TrustConfig, neighbours: tuple[str, ...],
                 position_index: tuple[int, int] = (0, 2)) -> None:
        self.cfg = cfg
        self.pos = list(position_index)
        self.n = {s: NeighbourTrust() for s in neighbours}
        self.scans = 0
        self._k: int | None = None
        self.own_at: dict[int, GaussianMixture] = {}
        """Own's round-0 density of the last :attr:`TrustConfig.keep_own` scans (late
        estimates are tested against the scan they were made at)."""
        self.events: list[dict] = []
        """State changes ``{"k", "neighbour", "from", "to", "score"}`` (drained by records)."""
        self.records: list[dict] = []
        self.log: list[dict] = []
        """Every state change (bounded: the first :data:`MAX_LOG`), for the summary."""
        self.fused_in: dict[str, GaussianMixture] = {}
        """The repaired densities the last round fuses in place of the neighbours' own
        (:attr:`TrustConfig.repair`)."""
        self.losses: Counter | None = None
        """When a Counter (calibration): fresh neighbour estimates whose references showed a
        target (``"compared"``), those that showed none (``"lost"``), and per length ``n``
        the runs of ``n`` such scans in a row that ended (:func:`peers.trust_checks.
        whole_losses`; what :attr:`TrustConfig.withhold_cap` was set from)."""
        self._loss_runs: dict[str, int] = {}
        self.history: list[tuple[int, str, float, float, float]] | None = None
        """When a list: every ``(k, neighbour, statistic, score, values)``, ``values`` those
        of :func:`alarm_limits` (calibration; the statistic without the offset and
        withheld-target tests' parts)."""

    # -- one round ----------------------------------------------------------------------------
    def statistics(self, own: GaussianMixture, inputs: dict[str, GaussianMixture],
                   weights: dict[str, float], left_out: set[str] = frozenset()
                   ) -> dict[str, float]:
        """``T_j`` of every neighbour in ``inputs`` against ``own`` and the leave-one-out
        average of the other trusted inputs (weights ``weights``, own's under ``""``):
        :func:`peers.trust_checks.neighbour_statistics`, quarantined neighbours and
        ``left_out`` (stale inputs) left out of the references."""
        out = {s for s in inputs if self.n[s].state == "quarantined"} | set(left_out)
        return neighbour_statistics(self.cfg, own, inputs, weights, out,
                                    (self.pos[0], self.pos[1]))

    def weigh(self, k: int, rnd: int, own: GaussianMixture,
              inputs: dict[str, GaussianMixture], weights: list[float],
              drop_suspects: bool = False,
              late: dict[str, tuple[int, GaussianMixture]] | None = None) -> list[float]:
        """Weights for ``[own, *sorted(inputs)]`` after the test: each neighbour's consensus
        weight times its trust, what is taken renormalised over the trusted set (or given to
        own, :attr:`TrustConfig.renormalise`). ``drop_suspects`` (product rules such as GCI,
        where any weight above 0 lets a confident lie veto the product): a neighbour below
        full trust gets weight 0. ``late`` (round 0): the neighbours whose input was made at
        an earlier scan (predicted forward), with that scan and the density as received
        (:attr:`TrustConfig.same_scan`)."""
        names = sorted(inputs)
        if not self.cfg.enabled:
            return list(weights)
        if rnd == 0:
            self._keep_own(k, own)
        if not names:
            return list(weights)
        if self._k != k:
            self._start_scan(k)
        if self.scans <= self.cfg.warmup:
            return list(weights)
        cfg = self.cfg
        late = (late or {}) if rnd == 0 and cfg.same_scan else {}
        late = {s: v for s, v in late.items() if s in inputs and v[0] < k}
        wmap = {"": weights[0], **dict(zip(names, weights[1:], strict=True))}
        shown = {s: self.shift(s, m) for s, m in inputs.items()}  # registered, if any
        stats = self.statistics(own, shown, wmap, set(late))
        self.fused_in = {}
        if cfg.repair:
            stats = self._repair(k, rnd, own, shown, wmap, stats, set(late))
        tested = {s: (k, inputs[s], own) for s in names if s not in late}
        for s, (a, mix) in late.items():  # each estimate once, against own of its scan
            ref = self.own_at.get(a)
            if a <= self.n[s].tested or ref is None:
                stats[s] = 0.0  # no new evidence
            else:
                stats[s] = self._single(ref, self.shift(s, mix))
                tested[s] = (a, mix, ref)
        if rnd == 0:
            for s, (a, _, _) in tested.items():
                self.n[s].tested = max(self.n[s].tested, a)
        if rnd == 0 and cfg.repeat:
            for s, (a, mix, _) in tested.items():
                if self._repeated(self.n[s], a, mix):
                    stats[s] = cfg.quarantine + cfg.drift
        raw = dict(stats)
        if rnd == 0 and cfg.bias:
            infos = {s: offset_information(ref, mix, self.pos, cfg.repeat_weight,
                                           cfg.bias_gate)
                     for s, (_, mix, ref) in tested.items()}
            if cfg.bias_relative:  # own's error is common to every fresh neighbour's offset
                infos = relative_offsets(infos, [s for s in infos if s not in late
                                                 and self.n[s].state != "quarantined"])
            for s, info in infos.items():
                rec = self.n[s]
                chi2 = self._offset(rec, info)
                alarm = any(c > t for c, t in zip(chi2, offset_limits(cfg), strict=True))
                if cfg.register:
                    self._register(rec, alarm)
                elif alarm:
                    stats[s] = max(stats[s], cfg.quarantine + cfg.drift)
        if rnd == 0 and cfg.withhold and cfg.detection_probability is not None:
            fused = {**shown, **self.fused_in}  # a repaired density is what is tested
            for s in self._withheld(own, fused, [s for s in names if s not in late]):
                stats[s] = max(stats[s], cfg.quarantine + cfg.drift)
        held = {s for s in names if self._held(self.n[s])}
        out = [0.0]
        for s in names:
            rec = self.n[s]
            rec.scan_max = max(rec.scan_max, stats[s])
            rec.last_statistic = stats[s]
            score = self._next(rec.score, rec.scan_max)
            t = self._trust(rec, score)
            if s in held:
                rec.holds += t > 0.0  # counted where the hold, not the score, zeroes it
                t = 0.0
            if drop_suspects and t < 1.0:
                t = 0.0
            rec.last_weight = t
            rec.rounds += 1
            if t > 0.0 and (s in self.fused_in or rec.registered is not None):
                rec.repairs += 1  # a repaired (or registered) density fused
                rec.repaired_k = k if rec.repaired_k is None else rec.repaired_k
            elif s in self.fused_in:
                del self.fused_in[s]
            if rec.first_k is None:
                rec.first_k = k
            if rec.low_k is None and t <= LOW:
                rec.low_k = k
            if self.history is not None:
                self.history.append((k, s, raw[s], score, (
                    *rec.last_offset_chi2, *((rec.withheld,) if cfg.withhold else ()))
                    if s in tested and rec.last_offset_chi2 else ()))
            out.append(wmap[s] * t)
            self.records.append({"k": k, "kind": "trust", "round": rnd + 1, "neighbour": s,
                                 "statistic": round(stats[s], 4), "score": round(score, 4),
                                 "weight": round(t, 4), "state": rec.state,
                                 "held": s in held, "withheld": round(rec.withheld, 4)})
        kept = sum(out[1:])
        if self.cfg.renormalise and kept + wmap[""] > 0:
            scale = 1.0 / (kept + wmap[""])
            out = [wmap[""] * scale] + [w * scale for w in out[1:]]
        else:
            out[0] = 1.0 - kept
        return out

    def _repair(self, k: int, rnd: int, own: GaussianMixture,
                shown: dict[str, GaussianMixture],
                wmap: dict[str, float], stats: dict[str, float], late: set[str]
                ) -> dict[str, float]:
        """:attr:`TrustConfig.repair`: each fresh neighbour whose statistic would take its
        score above ``repair_from`` (or, within ``repair_window`` scans of a repair that
        kept a component, above ``drift``) is tested again with its repaired density: its
        components own and the other trusted fresh neighbours do not corroborate dropped
        (all of them, while its repairs keep components: a miss), its weights scaled by its
        median mass factor (:mod:`peers.trust_repair`). Where that statistic is smaller it
        replaces the neighbour's and the repaired density is fused (:meth:`fused_input`)."""
        cfg = self.cfg
        out = dict(stats)
        for s in sorted(shown):
            rec = self.n[s]
            recent = rec.kept_k is not None and k - rec.kept_k <= cfg.repair_window
            if s in late or stats[s] <= cfg.drift or (
                    not recent and self._next(rec.score, stats[s]) <= cfg.repair_from):
                continue  # it would not accumulate, or not become suspect
            others = [own] + [m for t, m in shown.items() if t != s and t not in late
                              and self.n[t].state != "quarantined"]
            kept = corroborated_part(shown[s], others, self.pos, cfg.repeat_weight,
                                     cfg.bias_gate)
            if kept is None and cfg.repair_offset_gate > cfg.bias_gate:
                kept = self._moved(rec, rnd, own, shown[s], others)
            if kept is None:  # nothing corroborated: a miss, if its repairs keep things
                if rec.kept_k is None or k - rec.kept_k > cfg.repair_window:
                    continue
                kept = GaussianMixture.empty(shown[s].dim)
            f = scan_factor(kept, others, self.pos, cfg.repeat_weight, cfg.bias_gate)
            if f is not None and f > 0:
                _push(rec.factors, np.log(f), cfg.repair_window)
            if not rec.factors:
                continue
            rep = kept.scaled(float(np.exp(np.median(rec.factors))))
            t = self.statistics(own, {**shown, s: rep}, wmap, late)[s]
            if t < stats[s]:
                out[s] = t
                self.fused_in[s] = rep
                if len(rep):
                    rec.kept_k = k
        return out

    def _moved(self, rec: NeighbourTrust, rnd: int, own: GaussianMixture,
               mix: GaussianMixture, others: list[GaussianMixture]) -> GaussianMixture | None:
        """A neighbour none of whose components is corroborated, registered
        (:attr:`TrustConfig.repair_offset_gate`): its generalised-least-squares offset
        against own over the scans of :attr:`TrustConfig.repair_window` it was in this case,
        pairs up to the wider gate apart (at least two scans: one scan's nearest pairs may be
        any), subtracted, and each component's covariance at least own's nearest one's (by
        determinant: a neighbour caught with a constant offset is not taken to be more
        precise than own); then its corroborated part, or None."""
        cfg = self.cfg
        if rnd == 0:
            _push(rec.moves, offset_information(own, mix, self.pos, cfg.repeat_weight,
                                                cfg.repair_offset_gate), cfg.repair_window)
        if len(rec.moves) < 2 or len(own) == 0 or len(mix) == 0:
            return None
        offset = gls_offset(rec.moves)
        if offset is None:
            return None
        moved = moved_to_own(mix, own, offset, self.pos)
        return corroborated_part(moved, others, self.pos, cfg.repeat_weight, cfg.bias_gate)

    def fused_input(self, s: str, mix: GaussianMixture) -> GaussianMixture:
        """What of neighbour ``s``'s density ``mix`` the last round fuses: its repaired
        density (:attr:`TrustConfig.repair`) if the round used one, else ``mix`` less its
        registered offset (:meth:`shift`)."""
        rep = self.fused_in.get(s)
        return self.shift(s, mix) if rep is None else rep

    def _keep_own(self, k: int, own: GaussianMixture) -> None:
        self.own_at[k] = own
        for a in [a for a in self.own_at if a < k - self.cfg.keep_own]:
            del self.own_at[a]

    def _single(self, ref: GaussianMixture, mix: GaussianMixture) -> float:
        """The divergence test of ``mix`` against ``ref`` alone (a late estimate against own's
        density of its scan)."""
        L = log_overlaps([ref, mix])
        w = self.cfg.repeat_weight
        return divergence_test(self.cfg, L[1, 1], L[1, 0], L[0, 0], mix.mass, ref.mass,
                               target_mass(mix, w), target_mass(ref, w))

    def _repeated(self, rec: NeighbourTrust, k: int, mix: GaussianMixture) -> bool:
        """Whether ``mix`` (round 0 of scan ``k``) repeats, bit for bit, the non-empty density
        the neighbour sent at an earlier scan (:attr:`TrustConfig.repeat`); remembers it."""
        prev, prev_k = rec.last_mix, rec.last_k
        if k <= prev_k:
            return False
        rec.last_mix, rec.last_k = mix, k
        return is_repeat(prev, mix, self.cfg.repeat_weight)

    def _withheld(self, own: GaussianMixture, shown: dict[str, GaussianMixture],
                  fresh: list[str]) -> list[str]:
        """Add this scan's increment to each ``fresh`` neighbour's withheld-target CUSUM
        (:attr:`TrustConfig.withhold`; references: own and the other fresh neighbours not
        quarantined) and return those above :attr:`TrustConfig.withhold_threshold`."""
        cfg = self.cfg
        mixes = [own] + [shown[s] for s in fresh]
        U, _ = unmatched_weights(mixes, self.pos, cfg.repeat_weight, cfg.bias_gate)
        tm = np.array([target_mass(m, cfg.repeat_weight) for m in mixes])
        ok = np.array([True] + [self.n[s].state != "quarantined" for s in fresh])
        refs = ok[None, :] & ~np.eye(len(mixes), dtype=bool)
        inc = withheld_increments(U, tm, refs, cfg.detection_probability,
                                  cfg.withhold_alternative, cfg.withhold_cap)
        for s, v in zip(fresh, inc[1:], strict=True):
            self.n[s].withheld = max(0.0, self.n[s].withheld + float(v))
        if self.losses is not None:
            for s, lost in zip(fresh, whole_losses(tm, refs, cfg.repeat_weight)[1:],
                               strict=True):
                if lost == 1.0:
                    self._loss_runs[s] = self._loss_runs.get(s, 0) + 1
                elif lost == 0.0 and self._loss_runs.get(s):
                    self.losses[self._loss_runs.pop(s)] += 1
                if not np.isnan(lost):
                    self.losses["compared"] += 1
                    self.losses["lost"] += int(lost)
        return [s for s in fresh if self.n[s].withheld > cfg.withhold_threshold]

    def _held(self, rec: NeighbourTrust) -> bool:
        """Whether the neighbour's withheld-target CUSUM holds its weight at 0 this scan
        (:attr:`TrustConfig.withhold_hold`; every round of the scan, as its round-0 test
        left it)."""
        cfg = self.cfg
        return (cfg.withhold and cfg.withhold_hold is not None
                and cfg.detection_probability is not None
                and rec.withheld > cfg.withhold_hold)

    def _offset(self, rec: NeighbourTrust, info: tuple) -> tuple[float, ...]:
        """Add this scan's ``(I, y)`` (:func:`peers.trust_checks.offset_information`) to the
        neighbour's window and return, per window of :attr:`TrustConfig.bias_windows`, the
        chi-square of its mean offset (:attr:`TrustConfig.bias`)."""
        cfg = self.cfg
        _push(rec.offsets, info, max(cfg.bias_windows))
        chi2 = offset_chi2(rec.offsets, cfg.bias_windows)
        if cfg.bias_cusum:
            if rec.cusum is None:
                rec.cusum = np.zeros(cfg.bias_cusum_directions)
            rec.cusum = offset_cusum(rec.cusum, info, cfg.bias_cusum_offset,
                                     cusum_directions(cfg.bias_cusum_directions))
            chi2 = (*chi2, float(rec.cusum.max()))
        rec.last_offset_chi2 = chi2
        return chi2

    def shift(self, s: str, mix: GaussianMixture) -> GaussianMixture:
        """``mix`` of neighbour ``s`` with its registered offset subtracted from every
        component's position (:attr:`TrustConfig.register`); ``mix`` itself if none."""
        rec = self.n.get(s)
        if rec is None or rec.registered is None or len(mix) == 0:
            return mix
        means = mix.means.copy()
        means[:, self.pos] -= rec.registered
        return GaussianMixture(mix.weights, means, mix.covs)

    def _register(self, rec: NeighbourTrust, alarm: bool) -> None:
        """Registration (:attr:`TrustConfig.register`): from an offset alarm on, the
        neighbour's offset is its generalised-least-squares estimate over the window kept,
        re-estimated each scan, until its CUSUM is back at 0."""
        if not alarm and (rec.registered is None
                          or (rec.cusum is not None and float(rec.cusum.max()) <= 0.0)):
            rec.registered = None
            return
        offset = gls_offset(rec.offsets)
        if offset is not None:
            rec.registered = offset

    def _next(self, score: float, statistic: float) -> float:
        return max(0.0, self.cfg.leak * score + statistic - self.cfg.drift)

    def _trust(self, rec: NeighbourTrust, score: float) -> float:
        cfg = self.cfg
        if rec.state == "quarantined" or score >= cfg.quarantine:
            return 0.0
        if score <= cfg.suspect:
            return 1.0
        return (cfg.quarantine - score) / (cfg.quarantine - cfg.suspect)

    # -- scans --------------------------------------------------------------------------------
    def _start_scan(self, k: int) -> None:
        """Close the previous scan: scores, states, hysteresis."""
        if self._k is not None:
            self._close(self._k)
        self._k = k
        self.scans += 1

    def _close(self, k: int) -> None:
        cfg = self.cfg
        for s, rec in self.n.items():
            if self.scans <= cfg.warmup:
                continue
            rec.score = self._next(rec.score, rec.scan_max)
            rec.scan_max = 0.0
            old = rec.state
            if rec.score >= cfg.quarantine:
                rec.state, rec.streak = "quarantined", 0
            elif rec.state == "quarantined":
                rec.streak = rec.streak + 1 if rec.score < cfg.suspect else 0
                if rec.streak >= cfg.readmit:
                    rec.state = "trusted"
            else:
                rec.state = "suspect" if rec.score > cfg.suspect else "trusted"
            rec.scans_in[rec.state] += 1
            if rec.state != old:
                event = {"k": k, "neighbour": s, "from": old, "to": rec.state,
                         "score": round(rec.score, 3)}
                self.events.append(event)
                if len(self.log) < MAX_LOG:
                    self.log.append(event)

    def finish(self) -> None:
        if self._k is not None:
            self._close(self._k)
            self._k = None

    def summary(self) -> dict:
        return {"neighbours": {s: {"state": r.state, "score": round(r.score, 3),
                                   "scans": dict(r.scans_in), "first_scan": r.first_k,
                                   "low_scan": r.low_k,
                                   "rounds": r.rounds, "repairs": r.repairs, "holds": r.holds,
                                   "repaired_scan": r.repaired_k,
                                   "registered": (None if r.registered is None else
                                                  [round(float(x), 2) for x in r.registered])}
                               for s, r in self.n.items()},
                "changes": list(self.log)}

    def drain_records(self) -> list[dict]:
        out = self.records + [{"kind": "trust-event", **e} for e in self.events]
        self.records, self.events = [], []
        return out
