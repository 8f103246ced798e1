"""Trust's once-a-scan tests and its repair: the offset tests (or registration), the
withheld-target CUSUM and the repaired density of a neighbour about to turn suspect.

A mixin of :class:`peers.trust.Trust` (moved out of peers/trust.py to keep that module short):
its methods use the state :class:`Trust` keeps (``cfg``, ``n``, ``pos``, ``fused_in``,
``losses``, ``trace``) and its ``shift``, ``statistics`` and ``_next``.
"""

from __future__ import annotations

import functools
from collections.abc import Generator

import numpy as np
from sensornet.peers.trust_checks import (
    gls_offset,
    gls_offsets,
    offset_information,
    target_mass,
    unmatched_weights,
    whole_losses,
)
from sensornet.peers.trust_record import (
    NeighbourTrust,
    add_offsets_steps,
    offset_limits,
    push_window,
    registered_at,
    update_registration,
)
from sensornet.peers.trust_repair import corroborated_part, moved_to_own, scan_factor
from sensornet.tracking.mixture import GaussianMixture


class ScanTests:
    """The once-a-scan tests and repair of :class:`peers.trust.Trust` (its mixin)."""

    def _scan_tests(self, own: GaussianMixture, shown: dict[str, GaussianMixture],
                    late: dict[str, tuple[int, GaussianMixture]],
                    tested: dict[str, tuple[int, GaussianMixture, GaussianMixture]],
                    stats: dict[str, float]) -> Generator:
        """Round 0's other once-a-scan tests, raising ``stats`` to ``quarantine + drift``
        where they fire: the offset tests (or registration) and the withheld-target CUSUM
        (a generator of requests: :func:`peers.trust_checks.run_alone`)."""
        cfg = self.cfg
        alarm_stat = cfg.quarantine + cfg.drift
        if cfg.bias:
            follow = cfg.register and cfg.register_drift
            regs = {s: registered_at(self.n[s], a) if follow else None
                    for s, (a, _, _) in tested.items()}
            offsets = yield from self._offsets(tested, follow)
            infos = {s: _raw(info, regs[s]) for s, info in offsets.items()}
            if cfg.bias_relative:  # own's error is common to every fresh neighbour's offset
                infos = yield ("relative", infos, [s for s in infos if s not in late
                                                   and self.n[s].state != "quarantined"])
            if self.trace is not None:  # the scan's raw offsets: for the trace alone
                for s, raw in zip(infos, gls_offsets(list(infos.values())), strict=True):
                    self.n[s].raw_offset = raw
            for s, info in infos.items():
                push_window(self.n[s].residuals, _raw(info, regs[s], -1.0),
                            max(cfg.bias_windows))
            chi2s = yield from add_offsets_steps(cfg, [self.n[s] for s in infos],
                                                 list(infos.values()))
            for s, chi2 in zip(infos, chi2s, strict=True):
                rec = self.n[s]
                alarm = any(c > t for c, t in zip(chi2, offset_limits(cfg), strict=True))
                if cfg.register:
                    update_registration(rec, alarm, tested[s][0], cfg.register_drift,
                                        cfg.register_drift_chi2)
                elif alarm:
                    stats[s] = max(stats[s], alarm_stat)
        if cfg.withhold and cfg.detection_probability is not None:
            fused = {**shown, **self.fused_in}  # a repaired density is what is tested
            withheld = yield from self._withheld(own, fused,
                                                 [s for s in sorted(shown) if s not in late])
            for s in withheld:
                stats[s] = max(stats[s], alarm_stat)

    def _offsets(self, tested: dict[str, tuple[int, GaussianMixture, GaussianMixture]],
                 follow: bool) -> Generator:
        """Each tested neighbour's :func:`peers.trust_checks.offset_information` against its
        reference (registered at its scan when ``follow``), those against one reference
        (own, for every fresh one) together (:func:`offset_information_many`; a generator of
        requests)."""
        cfg = self.cfg
        groups: dict[int, tuple[GaussianMixture, list[str]]] = {}
        for s, (_, _, ref) in tested.items():
            groups.setdefault(id(ref), (ref, []))[1].append(s)
        out = {}
        for ref, names in groups.values():
            mixes = [self.shift(s, tested[s][1], tested[s][0]) if follow else tested[s][1]
                     for s in names]
            out.update(zip(names, (yield ("offsets", ref, mixes, self.pos, cfg.repeat_weight,
                                          cfg.bias_gate, cfg.gate_chi2)), strict=True))
        return {s: out[s] for s in tested}

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
                                     cfg.bias_gate, cfg.gate_chi2)
            if kept is None and cfg.repair_offset_gate > cfg.bias_gate:
                kept = self._moved(rec, rnd, own, shown[s], others)
            if kept is None:  # nothing corroborated: a miss, if its repairs keep things
                if rec.kept_k is None or k - rec.kept_k > cfg.repair_window:
                    continue
                kept = GaussianMixture.empty(shown[s].dim)
            f = scan_factor(kept, others, self.pos, cfg.repeat_weight, cfg.bias_gate,
                            cfg.gate_chi2)
            if f is not None and f > 0:
                push_window(rec.factors, np.log(f), cfg.repair_window)
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
            push_window(rec.moves, offset_information(own, mix, self.pos, cfg.repeat_weight,
                                                cfg.repair_offset_gate), cfg.repair_window)
        if len(rec.moves) < 2 or len(own) == 0 or len(mix) == 0:
            return None
        offset = gls_offset(rec.moves)
        if offset is None:
            return None
        rec.moved = offset
        moved = moved_to_own(mix, own, offset, self.pos)
        return corroborated_part(moved, others, self.pos, cfg.repeat_weight, cfg.bias_gate,
                                 cfg.gate_chi2)

    def _withheld(self, own: GaussianMixture, shown: dict[str, GaussianMixture],
                  fresh: list[str]) -> Generator:
        """Add this scan's increment to each ``fresh`` neighbour's withheld-target CUSUM
        (:attr:`TrustConfig.withhold`; references: own and the other fresh neighbours not
        quarantined) and return those above :attr:`TrustConfig.withhold_threshold` (a
        generator of requests)."""
        cfg = self.cfg
        mixes = [own] + [shown[s] for s in fresh]
        made = self.made.get("unmatched")  # the statistics' of the same inputs, if so
        if made is not None and len(made[0]) == len(mixes) and all(
                a is b for a, b in zip(made[0], mixes, strict=True)):
            U, tm = made[1], self.made["targets"]
        else:
            U, _ = unmatched_weights(mixes, self.pos, cfg.repeat_weight, cfg.bias_gate,
                                     cfg.gate_chi2)
            tm = np.array([target_mass(m, cfg.repeat_weight) for m in mixes])
        ok = np.array([True] + [self.n[s].state != "quarantined" for s in fresh])
        refs = ok[None, :] & _off_diagonal(len(mixes))
        inc = yield ("withheld", U, tm, refs, cfg.detection_probability,
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


@functools.lru_cache(maxsize=64)
def _off_diagonal(n: int) -> np.ndarray:
    """``~np.eye(n, dtype=bool)`` (read-only, made once per ``n``): each input's references
    all but itself (:meth:`ScanTests._withheld`, per peer and scan)."""
    out = ~np.eye(n, dtype=bool)
    out.flags.writeable = False
    return out


def _raw(info: tuple[np.ndarray, np.ndarray], offset: np.ndarray | None, sign: float = 1.0
         ) -> tuple[np.ndarray, np.ndarray]:
    """``(I, y + sign I offset)``: an offset's information with ``offset`` added back
    (``sign`` -1: taken out); ``info`` itself when ``offset`` is None."""
    return info if offset is None else (info[0], info[1] + sign * info[0] @ offset)
