"""Single-target PDA peers (seed 003): a PDA-family filter (PDAF, IMM-PDAF, fuzzy PDA, fuzzy
IMM) per position sensor in dense clutter, sharing measurements (the sequential update) or
estimates (covariance intersection) by ``pda.mode``."""

from __future__ import annotations

from sensornet.sim import seed003_net
from sensornet.sim.kinds import PeerKind, View
from sensornet.sim.scenario import FUSION_RULES, Scenario


def build(scn: Scenario, name: str, run: int = 0):
    p = scn.pda
    return seed003_net.make_parts(p.config, name, p.mode, run, method=p.method,
                                  pregate=p.pregate)


def check(scn: Scenario):
    if scn.pda is None or not scn.pda.config:
        return ("network.filter", "key 'network.filter' is 'pda', which needs the seed-003 "
                "tables ([scenario] study = \"seed003\": sim/scenarios/seed003.toml)")
    return None


PDA = PeerKind("pda", "PDA-family filter per position sensor, one target in clutter (seed 003)",
               build, FUSION_RULES, same_scan=True, trust=False,  # pda.mode decides the fusion
               view=View(single_target=True), check=check)
