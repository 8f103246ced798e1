"""Trust in neighbours: a consistency test per neighbour and round, a score over scans, weights.

A member with a valid key can still lie about its own estimate, and a broken sensor does the
same by accident, so before every consensus round each neighbour's density is tested against
references it cannot have shaped (own's density; the others' leave-one-out average or, with a
majority, their median), ``T = D_CS(D_j, R) + kappa (N_j - N_R)^2 / (N_R + 1)`` (the
Cauchy-Schwarz divergence of :mod:`tracking.divergence` plus a cardinality term). A leaky CUSUM
of ``T`` down-weights a neighbour above ``suspect`` and quarantines it at ``quarantine``, with
hysteresis; sequential tests (Page 1954 CUSUMs) catch a constant offset (repaired by
registration) and withheld targets, and a bit-identical repeat is quarantined at once. Under a
product rule (GCI) a suspect is dropped: any weight above 0 lets a confident lie veto a target.

Pure logic (no I/O): :class:`peers.consensus.Consensus` calls :meth:`Trust.weigh` before each
fusion. This module keeps each neighbour's score, state and weight over the scans; the tests of
one scan are in :mod:`peers.trust_checks`, the settings in :mod:`peers.trust_config`, the
once-a-scan tests and repair (a mixin) in :mod:`peers.trust_scan`. The design
in full and the calibration log of every threshold (training runs 9000.., never the evaluation
runs): docs/trust-calibration.md.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Generator

import numpy as np
from sensornet.peers.trust_checks import (
    centred,
    neighbour_statistics_steps,
    offset_information,
    run_alone,
)
from sensornet.peers.trust_config import TrustConfig
from sensornet.peers.trust_record import (
    LOW,
    MAX_LOG,
    STATES,
    NeighbourTrust,
    alarm_limits,
    is_held,
    is_repeated,
    offset_limits,
    registered_at,
    residual_passes,
)
from sensornet.peers.trust_scan import ScanTests
from sensornet.tracking.mixture import GaussianMixture

__all__ = ["LOW", "MAX_LOG", "STATES", "NeighbourTrust", "Trust", "TrustConfig", "alarm_limits",
           "offset_information", "offset_limits"]  # sim/ and tests import these from here

class Trust(ScanTests):
    """Per-neighbour consistency tests and weights for one peer."""

    def __init__(self, cfg: TrustConfig, neighbours: tuple[str, ...],
                 position_index: tuple[int, int] = (0, 2)) -> None:
        self.cfg = cfg
        self.state_pos = list(position_index)
        self.pos = [0, 1] if cfg.single_target else list(position_index)
        """The position entries of the densities tested (single-target: their positions)."""
        self.n = {s: NeighbourTrust() for s in neighbours}
        self.made: dict = {}
        """What this round's statistics made that its other tests take
        (:func:`peers.trust_checks.neighbour_statistics`' ``keep``)."""
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
        self.trace: list[dict] | None = None
        """When a list: per closed scan and neighbour ``{"k", "neighbour", "state",
        "weight", "registered", "moved", "offset"}`` (the studies' view of registration:
        what was subtracted, and the scan's raw offset ``I^-1 y`` against own or None)."""
        self.history: list[tuple[int, str, float, float, float]] | None = None
        """When a list: every ``(k, neighbour, statistic, score, values)``, ``values`` those
        of :func:`alarm_limits` (calibration; the statistic without the offset and
        withheld-target tests' parts)."""

    # -- one round ----------------------------------------------------------------------------
    def statistics(self, own: GaussianMixture, inputs: dict[str, GaussianMixture],
                   weights: dict[str, float], left_out: set[str] = frozenset(),
                   keep: dict | None = None) -> dict[str, float]:
        """``T_j`` of every neighbour in ``inputs`` against ``own`` and the leave-one-out
        average of the other trusted inputs (weights ``weights``, own's under ``""``):
        :func:`peers.trust_checks.neighbour_statistics`, quarantined neighbours and
        ``left_out`` (stale inputs) left out of the references (``keep``: as there)."""
        return run_alone(self._statistics_steps(own, inputs, weights, left_out, keep))

    def _statistics_steps(self, own: GaussianMixture, inputs: dict[str, GaussianMixture],
                          weights: dict[str, float], left_out: set[str] = frozenset(),
                          keep: dict | None = None) -> Generator:
        """:meth:`statistics` as requests (:func:`peers.trust_checks.run_alone`)."""
        out = {s for s in inputs if self.n[s].state == "quarantined"} | set(left_out)
        return (yield from neighbour_statistics_steps(self.cfg, own, inputs, weights, out,
                                                      (self.pos[0], self.pos[1]), keep))

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
        (:attr:`TrustConfig.same_scan`). Several peers' at once, the same numbers:
        :func:`peers.trust_batch.weigh_together`."""
        return run_alone(self.weigh_steps(k, rnd, own, inputs, weights, drop_suspects, late))

    def weigh_steps(self, k: int, rnd: int, own: GaussianMixture,
                    inputs: dict[str, GaussianMixture], weights: list[float],
                    drop_suspects: bool = False,
                    late: dict[str, tuple[int, GaussianMixture]] | None = None) -> Generator:
        """:meth:`weigh` as a generator of requests (:func:`peers.trust_checks.run_alone`):
        its divergences, offsets and charts computed with other peers' by a host."""
        names = sorted(inputs)
        if not self.cfg.enabled:
            return list(weights)
        if rnd == 0:
            self._keep_own(k, _collapsed(own, self.state_pos) if self.cfg.single_target
                           else own)
        if not names:
            return list(weights)
        if self._k != k:
            self._start_scan(k)
        if self.scans <= self.cfg.warmup:
            return list(weights)
        cfg = self.cfg
        if cfg.single_target:  # one target: where its moment-matched estimate is
            p = self.state_pos
            own, inputs = _collapsed(own, p), {s: _collapsed(m, p) for s, m in inputs.items()}
            late = {s: (a, _collapsed(m, p)) for s, (a, m) in (late or {}).items()}
        late = (late or {}) if rnd == 0 and cfg.same_scan else {}
        late = {s: v for s, v in late.items() if s in inputs and v[0] < k}
        wmap = {"": weights[0], **dict(zip(names, weights[1:], strict=True))}
        shown = {s: self.shift(s, m) for s, m in inputs.items()}  # registered, if any
        if rnd > 0 and cfg.test_once and self._settled(k, names) and (
                yield from self._agree(own, shown)):
            return self._reuse(k, rnd, names, weights)
        self.made = {}  # what the statistics made that this round's other tests take
        stats = yield from self._statistics_steps(own, shown, wmap, set(late), self.made)
        self.fused_in = {}
        if cfg.repair:
            stats = self._repair(k, rnd, own, shown, wmap, stats, set(late))
        tested = yield from self._test_late(k, own, inputs, late, stats)
        if rnd == 0:
            self._repeat_test(tested, stats)
        raw = dict(stats)
        if rnd == 0:
            yield from self._scan_tests(own, shown, late, tested, stats)
        held = {s for s in names if is_held(cfg, self.n[s])}
        return self._normalised(wmap[""], [wmap[s] * self._weight(
            k, rnd, s, stats[s], raw[s], s in tested, s in held, drop_suspects)
            for s in names])

    def _normalised(self, own: float, kept: list[float]) -> list[float]:
        """``[own's, *kept]`` weights: what the neighbours lost shared over own and the
        trusted ones (:attr:`TrustConfig.renormalise`) or given to own."""
        total = sum(kept)
        if self.cfg.renormalise and total + own > 0:
            scale = 1.0 / (total + own)
            return [own * scale] + [w * scale for w in kept]
        return [1.0 - total] + kept

    def _settled(self, k: int, names: list[str]) -> bool:
        """Whether round 1 of scan ``k`` found nothing in ``names`` (:attr:`TrustConfig.
        test_once`): each tested at this scan and quarantined, or at full trust with a
        scan statistic of at most ``drift``, neither held nor repaired."""
        cfg = self.cfg
        for s in names:
            rec = self.n[s]
            if rec.tested != k or s in self.fused_in:
                return False
            if rec.state != "quarantined" and (rec.last_weight != 1.0
                                               or rec.scan_max > cfg.drift):
                return False
        return True

    def _agree(self, own: GaussianMixture, shown: dict[str, GaussianMixture]) -> Generator:
        """The guard of :attr:`TrustConfig.test_once`: whether every neighbour's density of
        this round (``shown``) is within ``drift`` of own's by its divergence test against
        own alone (:func:`peers.trust_checks.divergence_test`; one matrix of overlaps, no
        reference average, majority or once-a-scan test; a generator of requests, its value
        the answer)."""
        cfg = self.cfg
        names = sorted(shown)
        mixes = [own] + [shown[s] for s in names]
        L = yield ("overlaps", mixes)
        L0 = (yield ("overlaps", centred(mixes))) if cfg.location_only else None
        mass, targets = yield ("masses", mixes, cfg.repeat_weight)
        tests = yield ("own_tests", cfg, L, L0, mass, targets)
        return not any(t > cfg.drift for t in tests)

    def _reuse(self, k: int, rnd: int, names: list[str], weights: list[float]) -> list[float]:
        """A later round of a settled scan (:meth:`_settled`): each neighbour's round-1
        trust again, recorded as :meth:`_weight` records a round."""
        self.made, self.fused_in = {}, {}
        out = []
        for s, w in zip(names, weights[1:], strict=True):
            rec = self.n[s]
            rec.rounds += 1
            if rec.last_weight > 0.0 and rec.registered is not None:
                rec.repairs += 1  # its registered density fused, as _weight counts it
            out.append(w * rec.last_weight)
            self.records.append({"k": k, "kind": "trust", "round": rnd + 1, "neighbour": s,
                                 "statistic": round(rec.last_statistic, 4),
                                 "score": round(self._next(rec.score, rec.scan_max), 4),
                                 "weight": round(rec.last_weight, 4), "state": rec.state,
                                 "held": False, "withheld": round(rec.withheld, 4)})
        return self._normalised(weights[0], out)

    def _test_late(self, k: int, own: GaussianMixture, inputs: dict[str, GaussianMixture],
                   late: dict[str, tuple[int, GaussianMixture]], stats: dict[str, float]
                   ) -> Generator:
        """Each estimate tested once, against own of its scan (:attr:`TrustConfig.same_scan`):
        a ``late`` one's statistic (in ``stats``) against own's density of the scan it was
        made at, or 0 if it was tested before. A generator of requests (:meth:`_single_steps`:
        a host computes its peers' late tests with their other divergences, not one by one);
        its value the tested ones, ``{s: (scan, density, reference)}``."""
        tested = {s: (k, inputs[s], own) for s in sorted(inputs) if s not in late}
        for s, (a, mix) in late.items():
            ref = self.own_at.get(a)
            if a <= self.n[s].tested or ref is None:
                stats[s] = 0.0  # no new evidence
            else:
                stats[s] = yield from self._single_steps(ref, self.shift(s, mix, a))
                tested[s] = (a, mix, ref)
        return tested

    def _repeat_test(self, tested: dict[str, tuple[int, GaussianMixture, GaussianMixture]],
                     stats: dict[str, float]) -> None:
        """Round 0: remember the scans tested; a density repeated bit for bit
        (:attr:`TrustConfig.repeat`) gets statistic ``quarantine + drift`` in ``stats``."""
        cfg = self.cfg
        for s, (a, _, _) in tested.items():
            self.n[s].tested = max(self.n[s].tested, a)
        if cfg.repeat:
            for s, (a, mix, _) in tested.items():
                if is_repeated(cfg, self.n[s], a, mix):
                    stats[s] = cfg.quarantine + cfg.drift

    def _weight(self, k: int, rnd: int, s: str, stat: float, raw: float, tested: bool,
                held: bool, drop_suspects: bool) -> float:
        """Neighbour ``s``'s trust this round from its statistic ``stat`` (``raw``: before the
        once-a-scan tests, for :attr:`history`), recorded in its record and :attr:`records`."""
        cfg = self.cfg
        rec = self.n[s]
        rec.scan_max = max(rec.scan_max, stat)
        rec.last_statistic = stat
        score = self._next(rec.score, rec.scan_max)
        t = self._trust(rec, score)
        if held:
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
            self.history.append((k, s, raw, score, (
                *rec.last_offset_chi2, *((rec.withheld,) if cfg.withhold else ()))
                if tested and rec.last_offset_chi2 else ()))
        self.records.append({"k": k, "kind": "trust", "round": rnd + 1, "neighbour": s,
                             "statistic": round(stat, 4), "score": round(score, 4),
                             "weight": round(t, 4), "state": rec.state,
                             "held": held, "withheld": round(rec.withheld, 4)})
        return t

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
        return run_alone(self._single_steps(ref, mix))

    def _single_steps(self, ref: GaussianMixture, mix: GaussianMixture) -> Generator:
        """:meth:`_single` as requests: the overlaps (:func:`tracking.divergence.log_overlaps`,
        centred too with :attr:`TrustConfig.location_only`, as :func:`peers.trust_checks.
        centred`) and masses computed with the host's other requests (the same
        numbers: :func:`peers.trust_batch.run_together`)."""
        L = yield ("overlaps", [ref, mix])
        L0 = (yield ("overlaps", centred([ref, mix]))) if self.cfg.location_only else None
        masses, targets = yield ("masses", [ref, mix], self.cfg.repeat_weight)
        return (yield ("own_tests", self.cfg, L, L0, masses, targets))[0]

    def shift(self, s: str, mix: GaussianMixture, k: int | None = None) -> GaussianMixture:
        """``mix`` of neighbour ``s`` (made at scan ``k``; None: the scan being fused) with
        its registered offset at that scan subtracted from every component's position
        (:attr:`TrustConfig.register`); ``mix`` itself if none."""
        rec = self.n.get(s)
        if rec is None or rec.registered is None or len(mix) == 0:
            return mix
        offset = registered_at(rec, self._k if k is None else k)
        means = mix.means.copy()
        means[:, self.pos] -= offset
        return GaussianMixture(mix.weights, means, mix.covs)

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
                if rec.streak >= cfg.readmit and (not cfg.readmit_offset
                                                  or residual_passes(cfg, rec)):
                    rec.state = "trusted"
            else:
                rec.state = "suspect" if rec.score > cfg.suspect else "trusted"
            rec.scans_in[rec.state] += 1
            if self.trace is not None:
                self.trace.append({"k": k, "neighbour": s, "state": rec.state,
                                   "weight": rec.last_weight,
                                   "registered": _copy(registered_at(rec, k)),
                                   "moved": _copy(rec.moved), "offset": _copy(rec.raw_offset)})
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


def _copy(v: np.ndarray | None) -> np.ndarray | None:
    return None if v is None else np.array(v, dtype=float)


def _collapsed(mix: GaussianMixture, pos: list[int]) -> GaussianMixture:
    """A single-target summary as one 2-D component: the position part (entries ``pos``)
    of its moment-matched Gaussian, at its mass (:attr:`TrustConfig.single_target`)."""
    if len(mix) == 0:
        return GaussianMixture.empty(2)
    mean, cov = mix.moments()
    return GaussianMixture(np.array([mix.mass]), mean[pos][None], cov[np.ix_(pos, pos)][None])
