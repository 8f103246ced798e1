"""LMB peers' fused tracks by an existence test per track (``lmb.fused_extraction``, issue 34):
the hybrid rule's mass of a target is the average of the peers' (AA), so when some peers miss
targets the total runs short and the cardinality rule (``round`` of the total mass heaviest)
drops a target most peers hold; ``"round"`` reports every fused track above the threshold."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.kinds import kind
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.tracking.fusion_rules import hybrid_fuse
from sensornet.tracking.mixture import GaussianMixture

LMB = {"network.filter": "lmb"}
TARGETS = np.array([[0.0, 100.0, 0.0, 0.0], [20000.0, 0.0, 5000.0, 100.0],
                    [-15000.0, 0.0, 8000.0, -50.0], [5000.0, 50.0, -20000.0, 0.0]])
"""Four aircraft far apart (x, vx, y, vy)."""


def peer_densities() -> list[GaussianMixture]:
    """Eight peers' published PHDs: the first aircraft at every peer, each other at 6 of 8
    (two far radars miss it, different ones per aircraft), existence 1, 150 m position sd."""
    cov = np.diag([150.0**2, 20.0**2, 150.0**2, 20.0**2])
    out = []
    for p in range(8):
        held = [0] + [t for t in (1, 2, 3) if p not in ((t + 4) % 8, (t + 5) % 8)]
        out.append(GaussianMixture(np.ones(len(held)), TARGETS[held],
                                   np.repeat(cov[None], len(held), axis=0)))
    return out


def fused_count(over: dict) -> int:
    scn = load_scenario("paris-8", {**LMB, **over})
    est, _ = kind("lmb").build(scn, "cdg", 0)
    fused = hybrid_fuse(peer_densities(), [1 / 8] * 8)
    assert len(fused) == 4 and fused.mass == pytest.approx(3.25)  # 1 + 3 x 6/8
    states = est.extract(fused)  # not the peer's own density: the fused rule
    return len({tuple(np.round(s[[0, 2]])) for s in states})


def test_every_target_most_peers_hold_is_reported():
    """Round(3.25) = 3: the cardinality rule reports 3 of the 4 aircraft; the existence test
    all 4 (each 1.0 or 0.75 > 0.5)."""
    assert fused_count({"lmb.fused_extraction": "cardinality"}) == 3
    assert fused_count({"lmb.fused_extraction": "round"}) == 4
    assert fused_count({"lmb.fused_extraction": "filter", "filter.extraction": "cardinality"}) == 3


def test_the_real_traffic_scenarios_report_by_existence():
    """paris, paris-8 and switzerland-8 set it (decided on the Paris training hour); a file
    without the key takes the default, the same rule (issue 33, the synthetic LMB graphs)."""
    assert fused_count({}) == 4
    for name in ("paris", "paris-8", "switzerland-8"):
        assert load_scenario(name, LMB).lmb.fused_extraction == "round"
    assert load_scenario("seed000", LMB).lmb.fused_extraction == "auto"  # round but under GCI


def test_a_bad_rule_is_a_one_line_error():
    with pytest.raises(ScenarioError, match="fused_extraction") as e:
        load_scenario("seed000", {**LMB, "lmb.fused_extraction": "max"})
    assert "\n" not in str(e.value)
