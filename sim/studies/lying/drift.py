"""A liar that drifts (issue 36 item 4): its estimates' offset grows by ``rate`` m per scan.

Seed 000 on the twin (3 peers in a full mesh, s2 lies :func:`sim.run.lies.drift_lie`), the
hybrid rule with the defence off and on, and the clean run. Per run: the honest peers' mean
fused OSPA over the last 30 scans (a scan without output at the cut-off), and from each honest
peer's trust trace (:attr:`peers.trust.Trust.trace`) the liar's state per scan and what was
subtracted from it: the scans it was trusted again after a quarantine and the residual offset
(the real bias ``rate * k`` less the registered correction) at each of them.

    python -m sensornet.sim.studies.lying.drift --runs 4 --first-run 9000   # training
    python -m sensornet.sim.studies.lying.drift --runs 4 --first-run 7000   # evaluation
    python -m sensornet.sim.studies.lying.drift --variants --runs 4 --first-run 9000

Training runs 9000.. choose, evaluation runs 7000.. report (nothing is chosen on them).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, replace

import numpy as np
from sensornet.sim.run.lies import LyingCore, drift_lie, make_lie
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import TwinResult, run_twin
from sensornet.sim.scenario import Scenario, load_scenario

LIAR = "s2"
LAST = 30
"""Scans at the end the fused OSPA is averaged over (the drift has grown by then)."""
RULES = {"off": {"fusion.rule": "hybrid", "fusion.trust": False},
         "trust": {"fusion.rule": "hybrid", "fusion.trust": True}}


def scenario(rule: str, scans: int | None = None, overrides: dict | None = None) -> Scenario:
    """Seed 000 under ``RULES[rule]`` (and ``overrides``), ``scans`` scans if given."""
    ov = {**RULES[rule], **(overrides or {})}
    if scans is not None:
        ov["scenario.num_scans"] = scans
    return load_scenario("seed000", overrides=ov)


def run_drift(scn: Scenario, run: int, rate: float | str | None, liar: str = LIAR,
              trust: dict | None = None) -> TwinResult:
    """One twin run with ``liar`` drifting at ``rate`` m/scan (a string: that lie of
    :func:`sim.run.lies.make_lie`; None: the clean run); every honest peer's trust (if on)
    keeps its trace and takes the :class:`peers.trust.TrustConfig` changes ``trust``."""
    peers = {n: make_peer(scn, n, run) for n in scn.sensor_names}
    if rate is not None:
        core = peers[liar]
        pos = core.estimator.position_index
        peers[liar] = LyingCore(core, make_lie(rate, scn, pos) if isinstance(rate, str)
                                else drift_lie(rate, pos))
    for core in peers.values():
        if trust and core.consensus.trust is not None:
            core.consensus.trust.cfg = replace(core.consensus.trust.cfg, **trust)
    for name, core in peers.items():
        if name != liar and core.consensus.trust is not None:
            core.consensus.trust.trace = []
    return run_twin(scn, run, peers=peers)


def last_fused(result: TwinResult, scn: Scenario, honest: list[str], last: int = LAST) -> float:
    """The honest peers' mean fused OSPA over the last ``last`` scans (a scan without output
    counts at the cut-off)."""
    K = scn.num_scans
    cut = scn.metrics.ospa_cutoff
    ks = range(K - last + 1, K + 1)
    return float(np.mean([[result.ospa.get(n, {}).get("fused", {}).get(k, cut) for k in ks]
                          for n in honest]))


@dataclass
class Returns:
    """What the honest peers' traces say about the liar."""

    quarantined: int
    """(peer, scan) pairs with the liar quarantined."""
    returns: list[tuple[str, int, float]]
    """Each return to trusted after a quarantine: ``(peer, scan, residual offset m)``."""
    worst_trusted: float
    """The largest residual offset at a scan the liar was trusted after its first
    quarantine by that peer (0: never)."""
    last_registered: float
    """The mean correction along x at the last scan (NaN: none)."""


def returns(result: TwinResult, rate: float, honest: list[str], liar: str = LIAR) -> Returns:
    """The liar's quarantines and returns in the honest peers' traces, with the residual
    offset ``|rate * k - correction|`` (the correction: registered offset, else the repair's
    moved offset, else 0) along x at each."""
    q = 0
    back: list[tuple[str, int, float]] = []
    worst = 0.0
    last: list[float] = []
    for n in honest:
        trust = result.peers[n].consensus.trust
        rows = [r for r in (trust.trace or []) if r["neighbour"] == liar]
        seen_q = False
        prev = "trusted"
        for r in rows:
            corr = r["registered"] if r["registered"] is not None else r["moved"]
            resid = abs(rate * r["k"] - (0.0 if corr is None else float(corr[0])))
            if r["state"] == "quarantined":
                q += 1
                seen_q = True
            elif seen_q and r["state"] == "trusted":
                worst = max(worst, resid)
                if prev == "quarantined":
                    back.append((n, r["k"], resid))
            prev = r["state"]
        if rows:
            reg = rows[-1]["registered"]
            last.append(math.nan if reg is None else float(reg[0]))
    return Returns(q, back, worst, float(np.mean(last)) if last else math.nan)


def trusted_residuals(result: TwinResult, honest: list[str], liar: str = LIAR,
                      window: int = 3) -> list[tuple[str, int, float]]:
    """``(peer, scan, residual)`` at every scan an honest peer had the liar trusted after its
    first quarantine of it: the residual the peer's own offset test sees, the mean over the
    last ``window`` scans with an offset of ``|raw offset - correction|`` along x (the
    correction: the registered offset predicted to that scan, else the repair's moved
    offset, else 0), comparable with :func:`honest_sigma`."""
    out = []
    for n in honest:
        rows = [r for r in (result.peers[n].consensus.trust.trace or [])
                if r["neighbour"] == liar]
        seen, recent = False, []
        for r in rows:
            corr = r["registered"] if r["registered"] is not None else r["moved"]
            if r["offset"] is not None:
                recent = [*recent, float(r["offset"][0]) - (0.0 if corr is None
                                                            else float(corr[0]))][-window:]
            if r["state"] == "quarantined":
                seen = True
            elif seen and r["state"] == "trusted" and recent:
                out.append((n, r["k"], abs(float(np.mean(recent)))))
    return out


def honest_sigma(result: TwinResult, honest: list[str]) -> float:
    """The standard deviation along x of the honest neighbours' per-scan raw offsets in the
    honest peers' traces (a clean run: every neighbour honest)."""
    xs = [float(r["offset"][0]) for n in honest
          for r in (result.peers[n].consensus.trust.trace or []) if r["offset"] is not None]
    return float(np.std(xs)) if xs else math.nan


def measure(runs: range, rates: tuple[float, ...] = (1.0, 2.0), scans: int | None = None,
            overrides: dict | None = None) -> list[dict]:
    """One row per run, rule and rate (``None``: clean)."""
    rows = []
    for rule in RULES:
        scn = scenario(rule, scans, overrides)
        honest = [n for n in scn.sensor_names if n != LIAR]
        for run in runs:
            for rate in (None, *rates):
                res = run_drift(scn, run, rate)
                row = {"rule": rule, "rate": rate, "run": run,
                       "last30": last_fused(res, scn, honest)}
                if rule == "trust" and rate is not None:
                    ret = returns(res, rate, honest)
                    tr = trusted_residuals(res, honest)
                    row |= {"quarantined": ret.quarantined, "returns": ret.returns,
                            "worst_residual": max((x[2] for x in tr), default=0.0),
                            "worst_trusted": ret.worst_trusted,
                            "registered": ret.last_registered}
                if rule == "trust" and rate is None:
                    row |= {"sigma": honest_sigma(res, honest),
                            "honest_quarantined": sum(
                                res.peers[n].consensus.trust.n[s].scans_in["quarantined"]
                                for n in honest for s in res.peers[n].consensus.trust.n)}
                rows.append(row)
                print(row, flush=True)
    return rows


VARIANTS = {"before": {"register_drift": False, "readmit_offset": False},
            "window-16": {"register_window": 16}, "default": {}}
"""Registration as before issue 36 (the window's mean, the scores alone readmit), the drift
fit over the offset test's 16 scans, and the default (32)."""


def variants(runs: range, lies: tuple = ("biased", 1.0, 2.0)) -> list[dict]:
    """The defence on, per :data:`VARIANTS` entry and lie (``None``: clean): the honest
    peers' whole-run and last-30 fused OSPA, mean over ``runs``."""
    scn = scenario("trust")
    honest = [n for n in scn.sensor_names if n != LIAR]
    rows = []
    for lie in (None, *lies):
        for name, change in VARIANTS.items():
            res = [run_drift(scn, r, lie, trust=change) for r in runs]
            rows.append({"lie": lie or "clean", "variant": name,
                         "fused": float(np.mean([np.mean([x.peers[n].mean_ospa("fused")
                                                          for n in honest]) for x in res])),
                         "last30": float(np.mean([last_fused(x, scn, honest) for x in res]))})
            print(rows[-1], flush=True)
    return rows


def table(rows: list[dict]) -> str:
    """Mean last-30 fused OSPA per rule and rate (runs in brackets)."""
    lines = ["| rule | clean | " + " | ".join(
        f"drift {r:g} m/scan" for r in dict.fromkeys(x["rate"] for x in rows if x["rate"]))
        + " |", "|---|---|---|---|"]
    for rule in dict.fromkeys(r["rule"] for r in rows):
        cells = []
        for rate in dict.fromkeys(x["rate"] for x in rows):
            v = [r["last30"] for r in rows if r["rule"] == rule and r["rate"] == rate]
            cells.append(f"{np.mean(v):.1f} ± {np.std(v, ddof=1) if len(v) > 1 else 0:.1f}")
        lines.append(f"| {rule} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sensornet.sim.studies.lying.drift",
                                description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=4)
    p.add_argument("--first-run", type=int, default=9000,
                   help="first run (default 9000: training; 7000: evaluation)")
    p.add_argument("--rates", default="1,2", help="comma-separated drift rates (m/scan)")
    p.add_argument("--scans", type=int, default=None)
    p.add_argument("--variants", action="store_true",
                   help="compare the registration variants (VARIANTS) instead, defence on")
    p.add_argument("--lies", default="biased,1,2",
                   help="with --variants: lies of sim.run.lies or drift rates (m/scan)")
    a = p.parse_args(argv)
    if a.variants:
        lies = tuple(x if x.isalpha() else float(x) for x in a.lies.split(","))
        variants(range(a.first_run, a.first_run + a.runs), lies)
        return 0
    rows = measure(range(a.first_run, a.first_run + a.runs),
                   tuple(float(x) for x in a.rates.split(",")), a.scans)
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
