"""One run with a lying member and what it scores (the lying study, :mod:`.study`): the twin
run with the liars' cores wrapped, the honest peers' OSPA, the defence's detection and repair
figures, and the two references (the liars taken out, the honest sensors processed
centrally)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from sensornet.sim.run.lies import LyingCore, make_lie
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import TwinResult, run_twin
from sensornet.sim.scenario import Scenario
from sensornet.sim.studies.seed000.montecarlo import run_once


def run_with_liar(scn: Scenario, run: int, liar: str, lie: str | None) -> TwinResult:
    """One twin run of ``scn`` in which peer ``liar`` (or each of ``"a,b"``) tells lie ``lie``
    (None: the clean run)."""
    peers = {n: make_peer(scn, n, run) for n in scn.sensor_names}
    if lie is not None:
        for name in liar.split(","):
            core = peers[name]
            peers[name] = LyingCore(core, make_lie(lie, scn, core.estimator.position_index))
    return run_twin(scn, run, peers=peers)


ABSENT = "absent"
"""Not a lie: the liars' sensors taken out of the network (their edges with them), the best
any defence that leaves a liar out can give (a perfect, instant quarantine)."""


CENTRAL = "central"
"""Not a lie: the honest sensors' scans processed centrally (the iterated-corrector
multi-sensor GM-PHD of :mod:`sim.studies.seed000.montecarlo`, offline, no network), the usual
reference for
what the honest sensors' measurements can give (the *absent* cell's distributed fusion
against it shows what the fusion design, not the information, loses)."""


def without(scn: Scenario, liar: str) -> Scenario:
    """``scn`` with the sensors of ``liar`` (``"a,b"``) and their edges removed."""
    gone = set(liar.split(","))
    sensors = tuple(s for s in scn.sensors if s.name not in gone)
    fusion = scn.fusion
    if fusion.fusing_sensor in gone:
        fusion = replace(fusion, fusing_sensor=sensors[0].name)
    edges = tuple(e for e in scn.network.edges if not gone & set(e))
    return replace(scn, sensors=sensors, fusion=fusion,
                   network=replace(scn.network, edges=edges))


def honest_scores(result: TwinResult, liar: str) -> dict[str, float]:
    """Mean OSPA over the honest peers (fused, local) and over the liar's honest neighbours
    (fused); each peer's mean counts a scan without output as a miss at the cut-off."""
    peers = result.peers
    liars = [s for s in liar.split(",") if s in peers]
    honest = [n for n in peers if n not in liars]
    near = [n for n in honest if set(liars) & set(peers[n].consensus.o.neighbours)] or honest
    return {**trust_scores(result, liars, honest),
            "fused": float(np.mean([peers[n].mean_ospa("fused") for n in honest])),
            "local": float(np.mean([peers[n].mean_ospa("local") for n in honest])),
            "fused_neighbours": float(np.mean([peers[n].mean_ospa("fused") for n in near])),
            "liar_fused": float(np.mean([peers[n].mean_ospa("fused") for n in liars]))
            if liars else math.nan,
            "rejected": float(sum(sum(peers[n].rejected.values()) for n in honest))}


def trust_scores(result: TwinResult, liars: list[str], honest: list[str]) -> dict[str, float]:
    """With the defence on (else NaN): ``honest_quarantined``, the share of (honest peer,
    honest neighbour, scan) triples in quarantine; ``detect_scans``, the most scans any honest
    neighbour took from its first test of a liar to a weight of at most 0.1, counting both
    (1: at once; NaN if one never did); with repair (:attr:`TrustConfig.repair`),
    ``repair_scans`` the same to its first repaired density (NaN if one never repaired it),
    and ``liar_repaired`` / ``honest_repaired`` the share of tested rounds of the liars /
    of the honest neighbours fused repaired; ``caught_scans``, the most scans any honest
    neighbour took to stop fusing a liar's density as told (the first of weight <= 0.1 and
    its first repaired density); ``honest_held``, the share of the honest neighbours'
    tested rounds whose weight the withheld-target test held at 0
    (:attr:`TrustConfig.withhold_hold`: not a quarantine, but not fused either)."""
    seen = quarantined = 0
    delays: list[float] = []
    repair_delays: list[float] = []
    caught: list[float] = []
    rounds = {"liar": [0, 0], "honest": [0, 0]}
    held = 0
    nan = {"honest_quarantined": math.nan, "detect_scans": math.nan,
           "repair_scans": math.nan, "liar_repaired": math.nan, "honest_repaired": math.nan,
           "caught_scans": math.nan, "honest_held": math.nan}
    repairing = False
    for n in honest:
        trust = result.peers[n].consensus.trust
        if trust is None:
            return nan
        repairing = trust.cfg.repair
        for s, rec in trust.n.items():
            side = rounds["liar" if s in liars else "honest"]
            side[0] += rec.repairs
            side[1] += rec.rounds
            if s in liars:
                low = (math.nan if rec.low_k is None or rec.first_k is None
                       else rec.low_k - rec.first_k + 1)
                rep = (math.nan if rec.repaired_k is None or rec.first_k is None
                       else rec.repaired_k - rec.first_k + 1)
                delays.append(low)
                repair_delays.append(rep)
                caught.append(math.nan if math.isnan(low) and math.isnan(rep)
                              else float(np.nanmin([low, rep])))
            else:
                held += rec.holds
                seen += sum(rec.scans_in.values())
                quarantined += rec.scans_in["quarantined"]
    out = {**nan, "honest_quarantined": quarantined / max(seen, 1),
           "detect_scans": float(np.max(delays)) if delays else math.nan,
           "caught_scans": float(np.max(caught)) if caught else math.nan,
           "honest_held": held / max(rounds["honest"][1], 1)}
    if repairing:
        out |= {"repair_scans": float(np.max(repair_delays)) if repair_delays else math.nan,
                "liar_repaired": rounds["liar"][0] / max(rounds["liar"][1], 1)
                if liars else math.nan,
                "honest_repaired": rounds["honest"][0] / max(rounds["honest"][1], 1)}
    return out


def central_scores(scn: Scenario, run: int) -> dict:
    """A :data:`CENTRAL` row: the centralised filter's mean OSPA over ``scn``'s sensors as
    ``fused`` (and ``fused_neighbours``), their local filters' mean as ``local``; the
    defence's figures NaN (no peers, no network)."""
    res = run_once(replace(scn, fusion=replace(scn.fusion, rule="none")), run)
    central = float(np.mean(res.ospa["centralized"]))
    local = float(np.mean([np.mean(v) for m, v in res.ospa.items() if m.startswith("local")]))
    nan = math.nan
    return {"honest_quarantined": nan, "detect_scans": nan, "repair_scans": nan,
            "liar_repaired": nan, "honest_repaired": nan, "caught_scans": nan,
            "honest_held": nan, "fused": central, "local": local, "fused_neighbours": central,
            "liar_fused": nan, "rejected": 0.0}
