"""One-line warnings for fusion settings the fusion-quality study measured to hurt.

``sensornet run`` and ``sensornet experiment`` print these at start (docs/fusion-study.md has
the measurements behind each).
"""

from __future__ import annotations

from sensornet.sim.scenario import Scenario

GCI_SAFE_PEERS = 3
"""Above this many peers (or with more than one round) plain GCI was measured worse than no
fusion: 20 peers of degree 4, one round, local 34.2 m, GCI fused 40.9 m (docs/fusion-study.md)."""


def fusion_warnings(scn: Scenario) -> list[str]:
    """What is wrong with the scenario's fusion settings, one line each (empty: nothing)."""
    if scn.network.filter not in ("gmphd", "et-gmphd") or scn.fusion.rule != "gci":
        return []
    out = []
    n, rounds = len(scn.sensors), scn.network.rounds
    if scn.fusion.cardinality == "emd":
        out.append("fusion.cardinality 'emd' under-counts targets: one fusion of n consistent "
                   "estimates keeps about (1 + 1/n)^(-2(n-1)) of a target's mass (0.23 at "
                   "n = 5), worse than no fusion on every graph measured; use 'separate' or "
                   "fusion.rule 'hybrid' (docs/fusion-study.md)")
    if n > GCI_SAFE_PEERS or rounds > 1:
        out.append(f"fusion.rule 'gci' with {n} peers and {rounds} round(s): a product of "
                   "densities, so a target that one input missed or pruned is erased, and "
                   "rounds spread each miss; measured worse than no fusion on 20-peer graphs; "
                   "the default 'hybrid' (AA weights, GCI locations) is not "
                   "(docs/fusion-study.md)")
    return out
