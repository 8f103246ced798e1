"""Calibrate the trust thresholds of :mod:`peers.trust` on clean training runs.

Runs the honest networks (seed 000, seed 004's graph with GM-PHD peers, the 20-peer circulant
graph of degree 4) on the twin with the test on and nothing down-weighted (thresholds at
infinity), under the conditions honest peers must ride out: Pd 0.9 and link faults (latency,
loss, reordering). Every (peer, neighbour, scan) score is kept; the printed quantiles are what
:class:`peers.trust.TrustConfig`'s ``suspect`` and ``quarantine`` were set from. Training runs
9000.. are used here only (the lying study evaluates on 7000..).

    python -m sensornet.sim.studies.lying.trust_calibration --runs 4
"""

from __future__ import annotations

import argparse
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
from sensornet.peers.trust import NeighbourTrust, Trust, TrustConfig, alarm_limits
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.scenario.overrides import parse_overrides
from sensornet.sim.studies.lying.study import LyingCore, make_lie
from sensornet.sim.world.graphs import network_scenario

OPEN = TrustConfig(suspect=1e9, quarantine=2e9, bias_thresholds=(np.inf, np.inf),
                   bias_cusum_threshold=np.inf, withhold_threshold=np.inf)
"""The test runs, nothing is down-weighted."""


def open_like(cfg: TrustConfig) -> TrustConfig:
    """``cfg`` (a peer's, with its scenario's detection probability) with :data:`OPEN`'s
    thresholds."""
    return replace(cfg, suspect=OPEN.suspect, quarantine=OPEN.quarantine,
                   bias_thresholds=OPEN.bias_thresholds,
                   bias_cusum_threshold=OPEN.bias_cusum_threshold,
                   withhold_threshold=OPEN.withhold_threshold)

Seq = tuple[np.ndarray, np.ndarray]
"""Per scan: the statistic without the offset and withheld-target tests (``(n,)``), and the
offset test's chi-square per window of :attr:`peers.trust.TrustConfig.bias_windows`, its
CUSUM, then the withheld-target CUSUM (``(n, windows + 2)``: :func:`peers.trust.alarm_limits`)."""
LIMITS = len(alarm_limits(OPEN))


def _per_scan(history: list, who: str | None = None) -> dict[str, Seq]:
    """Per neighbour (or only ``who``): the largest statistic of each scan's rounds and the
    scan's offset chi-square (computed at round 0), in scan order."""
    per: dict[str, dict[int, list[float]]] = {}
    for k, s, stat, _, chi2 in history:
        if who is not None and s != who:
            continue
        d = per.setdefault(s, {})
        chi2 = np.array(chi2 or [0.0] * LIMITS)  # none yet: no round 0 so far
        if k in d:
            d[k] = [max(d[k][0], stat), np.maximum(d[k][1], chi2)]
        else:
            d[k] = [stat, chi2]
    out = {}
    for s, d in per.items():
        ks = sorted(d)
        out[s] = (np.array([d[k][0] for k in ks]),
                  np.array([d[k][1] for k in ks]).reshape(len(ks), LIMITS))
    return out

CONDITIONS = {
    "clean": {},
    "pd0.9": {"sensors.*.detection_probability": 0.9},
    "faults": {"faults.default.delay": 0.03, "faults.default.loss": 0.2,
               "faults.default.reorder": 0.2},
}


def setups(tmp: Path) -> dict[str, tuple[str, dict]]:
    circ = tmp / "circulant20d4.toml"
    circ.write_text(network_scenario(20, 4))
    return {"seed000": ("seed000", {}),
            "seed004-gmphd": ("seed004", {"network.filter": "gmphd", "network.rounds": 1}),
            "circ4-20": (str(circ), {"network.rounds": 2})}


def sequences(source: str, overrides: dict, run: int,
              losses: Counter | None = None) -> list[Seq]:
    """Per (peer, neighbour): the per-scan statistic (largest of the scan's rounds) of one
    clean twin run with the test open, in scan order. ``losses``: the peers' whole-loss
    counts (:attr:`peers.trust.Trust.losses`) are added to it."""
    scn = load_scenario(source, overrides={**overrides, "fusion.trust": True})
    peers = {n: make_peer(scn, n, run) for n in scn.sensor_names}
    for p in peers.values():
        p.consensus.trust.cfg = open_like(p.consensus.trust.cfg)
        p.consensus.trust.history = []
        p.consensus.trust.losses = Counter()
    run_twin(scn, run, peers=peers)
    out = []
    for p in peers.values():
        out += list(_per_scan(p.consensus.trust.history).values())
        if losses is not None:
            losses.update(p.consensus.trust.losses)
    return out


def loss_line(c: Counter) -> str:
    """Whole losses (:func:`peers.trust_checks.whole_losses`): their share of the compared
    triples and the runs of each length that ended."""
    runs = {n: m for n, m in sorted((k, v) for k, v in c.items() if isinstance(k, int))}
    return (f"whole losses {c['lost']} of {c['compared']} "
            f"({100 * c['lost'] / max(c['compared'], 1):.2f} %), runs {runs}")


def liar_sequences(scenario: str, overrides: dict, liar: str, lie: str,
                   run: int) -> list[Seq]:
    """Per honest neighbour of ``liar``: the liar's per-scan statistic (test open), training
    runs only (for the detection delay the thresholds give; :mod:`sim.studies.lying.study`'s
    lies)."""
    scn = load_scenario(scenario, overrides={**overrides, "fusion.trust": True})
    peers = {n: make_peer(scn, n, run) for n in scn.sensor_names}
    core = peers[liar]
    peers[liar] = LyingCore(core, make_lie(lie, scn, core.estimator.position_index))
    for p in peers.values():
        p.consensus.trust.cfg = open_like(p.consensus.trust.cfg)
        p.consensus.trust.history = []
    run_twin(scn, run, peers=peers)
    out = []
    for n, p in peers.items():
        if n == liar or liar not in p.consensus.o.neighbours:
            continue
        out += list(_per_scan(p.consensus.trust.history, liar).values())
    return out


def simulate(seqs: list[Seq], cfg: TrustConfig) -> dict[str, float]:
    """The scores :class:`peers.trust.Trust` would reach on these statistics: the share of
    (pair, scan) triples at weight < 1 (suspect) and at weight 0 (quarantined, with the
    hysteresis), and the scores' quantiles; ``first_low``: per sequence, the first scan (1:
    the first) at weight <= 0.1, or None; ``causes``: the quarantines begun, by the test
    that fired at that scan (``offset``, ``repeat``, else ``divergence``: the divergence,
    miss and unmatched terms' score; ``withhold``: the withheld-target CUSUM); ``held``: the
    share of triples whose weight the withheld-target hold alone takes to 0
    (:attr:`TrustConfig.withhold_hold`: not quarantined, the score below it)."""
    t = Trust(cfg, ())
    scores, low, zero, n, first_low, held_only = [], 0, 0, 0, [], 0
    causes = {"divergence": 0, "offset": 0, "repeat": 0, "withhold": 0}
    lim = np.array(alarm_limits(cfg))
    for raw, chi2 in seqs:
        seq = raw.copy()
        hit = np.zeros(len(seq), bool)
        held = np.zeros(len(seq), bool)
        if cfg.bias and not cfg.register and len(seq):  # registered, not quarantined
            m = min(chi2.shape[1], len(lim) - cfg.withhold)  # the offset columns both have
            hit = (chi2[:, :m] > lim[:m]).any(axis=1)
        hold = np.zeros(len(seq), bool)
        if cfg.withhold and len(seq) and chi2.shape[1] == len(lim):
            held = chi2[:, -1] > lim[-1]
            if cfg.withhold_hold is not None:
                hold = chi2[:, -1] > cfg.withhold_hold
        seq[hit | held] = np.maximum(seq[hit | held], cfg.quarantine + cfg.drift)
        rec = NeighbourTrust()
        first = None
        for i, stat in enumerate(seq):
            score = t._next(rec.score, stat)
            w0 = t._trust(rec, score)  # the score's weight; the hold may take it to 0
            held_only += bool(hold[i]) and w0 > 0.0
            w = 0.0 if hold[i] else w0
            low += w < 1.0
            zero += w0 == 0.0
            if first is None and w <= 0.1:
                first = i + 1
            n += 1
            rec.score = score
            if score >= cfg.quarantine and rec.state != "quarantined":
                causes["offset" if hit[i] else "withhold" if held[i] else "repeat"
                       if raw[i] == cfg.quarantine + cfg.drift else "divergence"] += 1
            if score >= cfg.quarantine:
                rec.state, rec.streak = "quarantined", 0
            elif rec.state == "quarantined":
                rec.streak = rec.streak + 1 if score < cfg.suspect else 0
                if rec.streak >= cfg.readmit:
                    rec.state = "trusted"
            scores.append(score)
        first_low.append(first)
    q = np.quantile(scores, [0.99, 0.995, 0.999]) if scores else [np.nan] * 3
    return {"triples": n, "down": low / max(n, 1), "quarantined": zero / max(n, 1),
            "held": held_only / max(n, 1),
            "q99": q[0], "q99.5": q[1], "q99.9": q[2], "first_low": first_low,
            "causes": causes}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.lying.trust_calibration",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--first-run", type=int, default=9000)
    ap.add_argument("--save", help="write the statistics here (.npz)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="scenario override for every run, e.g. fusion.trust_repair=true "
                         "(repeatable)")
    a = ap.parse_args(argv)
    try:  # the scenario's own checks: fusion.trust_register=False is refused, not truthy
        sets = parse_overrides(a.set)
        fusion = load_scenario("seed000", overrides={**sets, "fusion.trust": True}).fusion
    except ValueError as e:
        ap.error(str(e))
    cfg = TrustConfig(register=fusion.trust_register, repair=fusion.trust_repair)
    with tempfile.TemporaryDirectory() as tmp:
        pooled, all_losses = [], Counter()
        for label, (source, over) in setups(Path(tmp)).items():
            for cond, extra in CONDITIONS.items():
                if label.startswith("seed004") and cond == "pd0.9":
                    extra = {"sensors.detection_probability": 0.9}
                losses = Counter()
                seqs = [q for r in range(a.first_run, a.first_run + a.runs)
                        for q in sequences(source, {**over, **extra, **sets}, r, losses)]
                all_losses.update(losses)
                pooled += seqs
                stat = np.concatenate([q[0] for q in seqs])
                chi2 = np.concatenate([q[1] for q in seqs if len(q[0])])
                sim = simulate(seqs, cfg)
                print(f"{label:14s} {cond:7s} statistic q50 {np.quantile(stat, 0.5):.2f} "
                      f"q90 {np.quantile(stat, 0.9):.2f} q99 {np.quantile(stat, 0.99):.2f}; "
                      f"score q99 {sim['q99']:.2f} q99.9 {sim['q99.9']:.2f}; down "
                      f"{100 * sim['down']:.2f} %, quarantined {100 * sim['quarantined']:.2f} %"
                      f" of {sim['triples']}, held {100 * sim['held']:.2f} % (begun by: "
                      + ", ".join(f"{c} {m}" for c, m in sim["causes"].items())
                      + "); offset chi2 per window, offset CUSUM, withheld CUSUM q99.9 "
                      f"{np.round(np.quantile(chi2, 0.999, axis=0), 1)} max "
                      f"{np.round(chi2.max(axis=0), 1)}; " + loss_line(losses), flush=True)
        if a.save:
            np.savez_compressed(a.save, *[x for q in pooled for x in q])
        sim = simulate(pooled, cfg)
        print(f"pooled: score q99 {sim['q99']:.2f} q99.5 {sim['q99.5']:.2f} q99.9 "
              f"{sim['q99.9']:.2f}; down {100 * sim['down']:.2f} %, quarantined "
              f"{100 * sim['quarantined']:.2f} % of {sim['triples']} (peer, neighbour, scan), "
              f"held {100 * sim['held']:.2f} %; "
              + loss_line(all_losses) + ", -log of the rate "
              f"{-np.log(max(all_losses['lost'], 1) / max(all_losses['compared'], 1)):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
