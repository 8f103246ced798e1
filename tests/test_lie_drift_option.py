"""``fusion.lie = "PEER:drift:RATE"`` (issue 36 item 4): the drifting liar as a scenario
value, the rate it tells, and one-line errors for a bad rate."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.run.lies import DRIFT_RATE, LyingCore, drift_lie
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.tracking.mixture import GaussianMixture


def _mix() -> GaussianMixture:
    means = np.array([[100.0, 1.0, -50.0, 2.0], [900.0, 0.0, 400.0, -1.0]])
    return GaussianMixture(np.array([0.9, 0.8]), means, np.tile(np.eye(4) * 25.0, (2, 1, 1)))


@pytest.mark.parametrize("value, rate", [("s2:drift:1.5", 1.5), ("s2:drift", DRIFT_RATE)])
def test_the_liar_drifts_at_the_rate_the_scenario_names(value, rate):
    scn = load_scenario("seed000", overrides={"fusion.lie": value})
    assert scn.fusion.lie == value
    core = make_peer(scn, "s2", 0)
    assert isinstance(core, LyingCore)
    assert not isinstance(make_peer(scn, "s1", 0), LyingCore)
    real = _mix()
    for k in (1, 4, 30):
        told = core.lie(real, k)
        want = real.means.copy()
        want[:, 0] += rate * k  # x only, by hand: rate metres per scan since scan 0
        assert np.array_equal(told.means, want)
        assert np.array_equal(told.covs, real.covs) and np.array_equal(told.weights,
                                                                        real.weights)


@pytest.mark.parametrize("value", ["s2:drift:-1", "s2:drift:0", "s2:drift:abc", "s2:drift:inf",
                                   "s2:drift:", "s2:biased:3", "s2:wobble", "s9:drift:1"])
def test_a_bad_drift_lie_is_a_one_line_error_naming_the_key(value):
    with pytest.raises(ScenarioError) as err:
        load_scenario("seed000", overrides={"fusion.lie": value})
    msg = str(err.value)
    assert "fusion.lie" in msg and "\n" not in msg


def test_drift_lie_refuses_a_rate_that_is_not_a_positive_number():
    for rate in (0.0, -2.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="rate"):
            drift_lie(rate)
