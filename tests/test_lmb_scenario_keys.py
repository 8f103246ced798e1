"""The LMB peers' adaptive-birth settings as scenario keys (issue 34 item 1; ``[lmb]``,
sim/scenario/network.py's ``LmbSpec``, sim/kinds/lmb.py): a file without ``[lmb]`` loads the
numbers the LMB peers always used, and a key reaches the filter and changes its births as
Reuter et al. 2014 eq. 31 says."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.kinds import kind
from sensornet.sim.kinds.lmb import make_lmb_filter
from sensornet.sim.scenario import ScenarioError, load_scenario

LMB = {"network.filter": "lmb"}


def test_a_file_without_the_table_loads_the_old_constants():
    """The LMB peers' constants before the keys: lambda_B 0.1, r_B,max 0.1, 30 m/s."""
    scn = load_scenario("seed000", LMB)
    f = make_lmb_filter(scn, "s1", 0)
    assert (f.birth_rate, f.birth_max_existence, f.birth_velocity_std) == (0.1, 0.1, 30.0)
    paris = load_scenario("paris", LMB)
    assert (paris.lmb.birth_rate, paris.lmb.birth_max_existence,
            paris.lmb.birth_velocity_std) == (0.1, 0.1, 30.0)


def test_the_keys_reach_the_peers_filter_and_its_births():
    scn = load_scenario("seed000", {**LMB, "lmb.birth_rate": 0.3,
                                    "lmb.birth_max_existence": 0.25,
                                    "lmb.birth_velocity_std": 200.0})
    est, _ = kind("lmb").build(scn, "s2", 0)
    f = est.filter
    assert (f.birth_rate, f.birth_max_existence, f.birth_velocity_std) == (0.3, 0.25, 200.0)
    # No tracks: every measurement is unexplained (r_U = 0), so eq. 31 (sum floored at 1)
    # gives each of m measurements min(r_B,max, lambda_B / max(m, 1)).
    for z, r_b in ((np.array([[100.0, -50.0]]), 0.25),
                   (np.array([[0.0, 0.0], [500.0, 500.0], [-800.0, 300.0]]), 0.1)):
        state = f.step(f.initial(), z, 1)
        np.testing.assert_allclose(state.pending.weights, np.full(len(z), r_b))
        np.testing.assert_allclose(state.pending.means[:, [0, 2]], z)
        np.testing.assert_allclose(state.pending.covs[:, [1, 3], [1, 3]], 200.0**2)


@pytest.mark.parametrize("key, value, message", [
    ("lmb.birth_max_existence", 1.5, "must be a probability in [0, 1], got 1.5"),
    ("lmb.birth_rate", -0.1, "must be >= 0, got -0.1"),
    ("lmb.birth_velocity_std", 0.0, "must be > 0, got 0"),
    ("lmb.births", 3, "births"),
])
def test_bad_values_are_one_line_errors(key, value, message):
    with pytest.raises(ScenarioError, match=message.replace("[", r"\[").replace("]", r"\]")) as e:
        load_scenario("seed000", {**LMB, key: value})
    assert "\n" not in str(e.value)
