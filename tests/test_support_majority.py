"""The majority support rule (``fusion.support = -1``, tracking.support.MAJORITY): by hand, more
than half of the round's inputs and at least 2; in a twin of 6 GM-PHD peers of degree 4 (5
inputs a round) it reports a subset of the tracks ``fusion.support = 2`` reports, with the
same ids and states, and fewer (tracks only two inputs held, on their first scan); and the
automatic default (-2) resolves as declared (sim.run.peers.support_inputs)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.campaign.runners import scenario_source
from sensornet.sim.run.peers import SUPPORT_AUTO, consensus_options, support_inputs
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world.graphs import network_scenario
from sensornet.tracking.support import MAJORITY, SupportRule


def test_majority_by_hand():
    """5 inputs need 3, 4 need 3, 3 need 2, 2 and 1 need 2 (the rule of 2 on small graphs);
    a track held by fewer is reported from its second scan in a row, as with a fixed count."""
    rule = SupportRule(min_inputs=MAJORITY, scans=2)
    assert [rule.needed(n) for n in (1, 2, 3, 4, 5, 9)] == [2, 2, 2, 3, 3, 5]
    A, B = [0, 1, 0], [1, 1, 0]
    np.testing.assert_array_equal(rule.keep(np.array([A, B]), np.array([2, 3]), 5),
                                  [False, True])
    np.testing.assert_array_equal(rule.keep(np.array([A, B]), np.array([2, 3]), 5),
                                  [True, True])
    np.testing.assert_array_equal(SupportRule(MAJORITY).keep(np.array([A]), np.array([2]), 3),
                                  [True])
    with pytest.raises(ValueError, match="input count"):
        rule.keep(np.array([A]), np.array([2]))
    with pytest.raises(ValueError, match="min_inputs"):
        SupportRule(min_inputs=-2)
    assert SupportRule(min_inputs=3).needed(None) == 3


def _fused(twin, name):
    t = twin.peers[name].scorer.results.table(name)
    return {k: (np.asarray(tr, float).reshape(-1, 4), [tuple(i) for i in ids])
            for k, e, tr, ids in zip(t["scan"], t["estimate"], t["tracks"], t["track_ids"],
                                     strict=True) if e == "fused"}


def test_twin_majority_removes_tracks_only():
    """5 GM-PHD peers, circulant degree 4, Pd 0.6 (so tracks held by two inputs of five are
    common), run 100, 30 scans: ``fusion.support = -1`` reports a subset of ``= 2``'s fused
    tracks at every peer and scan (same ids and states), and some are gone; a value below -1
    is refused at load."""
    src = scenario_source("circulant-5-4.toml", network_scenario(5, 4, scans=30,
                                                                 detection_probability=0.6))
    over = {"network.filter": "gmphd"}
    two = run_twin(load_scenario(src, overrides={**over, "fusion.support": 2}), 100)
    maj = run_twin(load_scenario(src, overrides={**over, "fusion.support": -1}), 100)
    removed = 0
    for name in two.peers:
        a, b = _fused(two, name), _fused(maj, name)
        assert a.keys() == b.keys()
        for k in a:
            (Xa, ia), (Xb, ib) = a[k], b[k]
            assert set(ib) <= set(ia)
            for x, i in zip(Xb, ib, strict=True):
                np.testing.assert_array_equal(x, Xa[ia.index(i)])
            removed += len(ia) - len(ib)
    assert removed > 0
    with pytest.raises(ValueError, match="fusion.support"):
        load_scenario(src, overrides={**over, "fusion.support": -3})


@pytest.mark.parametrize(("name", "over", "want"), [
    ("seed000", {}, MAJORITY),  # GM-PHD, fixed birth points, shared ids
    ("seed000", {"network.birth_ids": "own"}, 2),
    ("seed000", {"network.filter": "lmb"}, 2),
    ("paris-8", {}, 2),  # GM-PHD measurement births (recorded traffic)
    ("seed000", {"fusion.support": 2}, 2),  # an explicit value is kept
    ("seed000", {"fusion.support": 0}, 0),
    ("paris-8", {"fusion.support": -1}, MAJORITY),
])
def test_auto_support_resolves_as_declared(name, over, want):
    """``fusion.support`` auto (-2, the default): the majority for GM-PHD peers whose births
    are alike at every peer (fixed birth points, shared ids), 2 otherwise; explicit values
    kept. What every peer's consensus gets (sim.run.peers.consensus_options)."""
    scn = load_scenario(name, overrides=over)
    assert scn.fusion.support == over.get("fusion.support", SUPPORT_AUTO)
    assert support_inputs(scn) == want
    assert {consensus_options(scn, p).support_inputs for p in scn.sensor_names} == {want}
