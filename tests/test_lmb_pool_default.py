"""``fusion.existence_prior = -1`` (auto, sim.run.peers.existence_prior): the pooling prior is
0.01 for LMB peers that publish tentative tracks and off otherwise (GM-PHD peers, or LMB peers
without tentative tracks: the extraction before pooling); a value set is taken as is."""

from __future__ import annotations

import pytest
from sensornet.sim.run.peers import LMB_EXISTENCE_PRIOR, consensus_options, existence_prior
from sensornet.sim.scenario import ScenarioError, load_scenario


@pytest.mark.parametrize(("over", "want"), [
    ({"network.filter": "lmb", "lmb.tentative_threshold": 0.1}, LMB_EXISTENCE_PRIOR),
    ({"network.filter": "lmb", "lmb.tentative_threshold": 0.0}, 0.0),
    ({"network.filter": "gmphd"}, 0.0),
    ({"network.filter": "gmphd", "fusion.existence_prior": 0.05}, 0.05),
    ({"network.filter": "lmb", "lmb.tentative_threshold": 0.1, "fusion.existence_prior": 0.0},
     0.0),
])
def test_auto_prior(over, want):
    scn = load_scenario("seed000", overrides={"fusion.existence_prior": -1.0, **over})
    assert existence_prior(scn) == want
    assert consensus_options(scn, scn.sensor_names[0]).existence_prior == want


def test_bad_prior():
    with pytest.raises(ScenarioError, match="existence_prior"):
        load_scenario("seed000", overrides={"fusion.existence_prior": -2.0})
