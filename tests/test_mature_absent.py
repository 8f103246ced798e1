"""Inputs without a mature fused track count in its pool (tracking.mature_existence ``absent``,
``fusion.existence_absent``; docs/labelled-tracking.md "Inputs without the track count"): a dead
target that two of five inputs hold no more is dropped (kept without the rule), by hand against
Bayes' rule with the absent inputs censored at the publication threshold; a live target with one
input absent, a prior below the threshold, bad values and the scenario's auto value."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.run.peers import consensus_options
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.gmphd import extract_index
from sensornet.tracking.mature_existence import MatureExistence
from sensornet.tracking.mixture import GaussianMixture

PS, PD, TAU = 0.99, 0.9, 0.15
LABEL = np.array([[0, 41, 7]])


def _odds(r: float) -> float:
    return r / (1 - r)


def _missed(r: float) -> float:
    """An LMB track's existence after one scan without a detection (Reuter et al. 2014,
    eq. 21 with no measurement): ``Ps r (1 - Pd) / (1 - Ps r Pd)``."""
    p = PS * r
    return p * (1 - PD) / (1 - p * PD)


def _rule(absent: float, w_prev: float) -> MatureExistence:
    rule = MatureExistence(PS, young=2, absent=absent)
    rule.caps(np.array([w_prev]), LABEL, 80, np.ones((1, 5)))
    return rule


def _extracted(w: float, cap: float) -> int:
    mix = GaussianMixture(np.array([min(w, cap)]), np.zeros((1, 4)), np.eye(4)[None])
    return len(extract_index(mix, 0.5, "round"))


def test_a_dead_target_two_inputs_no_longer_hold_is_dropped():
    """The traced case (circ20 Pd 0.9, the scan after a death): the fused weight the scan
    before 0.964, three inputs missed the target once (0.908 each), two hold no component of
    it. Without the rule the three alone pool to about 0.7 and the fused weight, their mean
    with the two zeros (0.545), is extracted; with it each absent input counts at ``TAU`` (the
    odds ratio ``odds(TAU) / odds(r0)``, Bayes' rule for independent inputs, to 1e-12) and
    the track goes."""
    r = _missed(1.0)
    mass = np.array([[r, r, r, 0.0, 0.0]])
    w = mass.mean(axis=1)
    old = _rule(0.0, 0.964).caps(w, LABEL, 81, mass)
    new = _rule(TAU, 0.964).caps(w, LABEL, 81, mass)
    r0 = PS * 0.964
    odds = _odds(r0) * (_odds(r) / _odds(r0)) ** 3 * (_odds(TAU) / _odds(r0)) ** 2
    np.testing.assert_allclose(new, [odds / (1 + odds)], rtol=1e-12)
    assert old[0] > 0.5 and _extracted(w[0], old[0]) == 1
    assert new[0] < 1e-3 and _extracted(w[0], new[0]) == 0


def test_a_live_target_one_input_lacks_stays():
    """Four inputs detect the target (0.999), one holds nothing: the cap stays above the fused
    weight (the rule changes nothing)."""
    mass = np.array([[0.999, 0.999, 0.0, 0.999, 0.999]])
    w = mass.mean(axis=1)
    cap = _rule(TAU, 1.0).caps(w, LABEL, 81, mass)
    assert cap[0] > w[0]


def test_an_absent_input_only_lowers():
    """With the prior below ``TAU`` an absent input adds nothing (its existence below the
    threshold says nothing against a track already less likely than that)."""
    mass = np.array([[0.3, 0.4, 0.0, 0.0, 0.0]])
    w = mass.mean(axis=1)
    np.testing.assert_allclose(_rule(TAU, 0.1).caps(w, LABEL, 81, mass),
                               _rule(0.0, 0.1).caps(w, LABEL, 81, mass), rtol=1e-12)


def test_bad_value_is_a_one_line_error():
    with pytest.raises(ValueError, match="absent"):
        MatureExistence(PS, absent=1.0)
    with pytest.raises(ValueError, match="absent"):
        MatureExistence(PS, absent=-0.1)


@pytest.mark.parametrize(("kind", "value", "expected"),
                         [("lmb", -1.0, 0.15), ("lmb", 0.0, 0.0), ("lmb", 0.3, 0.3),
                          ("gmphd", -1.0, 0.0)])
def test_scenario_value(kind, value, expected):
    """Auto (-1) is the LMB's tentative threshold (what its inputs publish from); GM-PHD peers
    (no mature pool) get 0."""
    scn = load_scenario("seed000", overrides={"network.filter": kind,
                                              "fusion.existence_absent": value})
    assert consensus_options(scn, scn.sensor_names[0]).existence_absent == expected


def test_the_default_is_auto():
    """On by default for LMB peers that pool young tracks (evaluated once, 5 Dec); off where
    the mature pool is (the real-traffic scenarios publish no tentative tracks)."""
    lmb = load_scenario("seed000", overrides={"network.filter": "lmb"})
    assert consensus_options(lmb, lmb.sensor_names[0]).existence_absent == 0.15
    off = load_scenario("seed000", overrides={"network.filter": "lmb",
                                              "lmb.tentative_threshold": 0.0})
    assert consensus_options(off, off.sensor_names[0]).existence_absent == 0.0
