"""``fusion.existence_revisit`` (issue 34): a young fused track's AA existence averaged over the
inputs whose radar could have confirmed it by its age (two looks), so a slow radar not yet
looked at twice is no evidence against it (tracking.support.revisit_weights). By hand, and
the option's wiring from the shared scenario's rotation periods."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.run.peers import consensus_options
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.support import revisit_weights

OMEGA = np.full(8, 1 / 8)
SPANS = np.array([2.35, 2.4, 2.375, 2.36, 5.0, 6.0, 5.5, 5.25])
"""paris-8's revisits in 2 s ticks: four terminal radars (4.7-4.8 s), four en-route (10-12 s)."""


def test_four_terminal_radars_report_a_track_the_en_route_ones_cannot_have_confirmed():
    """Scan 100: A (born at 96) held by the 4 terminal radars at 0.95: AA 0.475, below the
    round extraction's 0.5; the en-route radars (revisit 5-6 scans) cannot have had two looks
    in 4 scans, so it weighs 4 x 0.95 / 4 = 0.95. B, the same at age 30, keeps 0.475 (every
    radar had its looks: the AA). C (age 3, two terminal radars): the other two terminal
    radars (Le Bourget, Pontoise) could hold it with q = 3 / 2.375 - 1 and 3 / 2.36 - 1."""
    mass = np.zeros((3, 8))
    mass[0, :4] = mass[1, :4] = mass[2, :2] = 0.95
    w = mass.sum(axis=1) / 8
    labels = np.array([[1, 96, 0], [1, 70, 1], [1, 97, 2]])
    out = revisit_weights(w, labels, 100, mass, OMEGA, SPANS)
    q = [3 / 2.375 - 1, 3 / 2.36 - 1]
    np.testing.assert_allclose(out, [0.95, 0.475, 2 * 0.95 / (2 + sum(q))], rtol=1e-12)
    assert w[0] < 0.5 < out[0]


def test_a_tentative_bernoulli_is_not_holding():
    """A 2 scans old, two terminal radars at 0.99 and the en-route radars' tentative
    Bernoullis of one look (0.01, mass > 0): those count by their revisit (q = 0), not as
    holders (q = 1), nor do the other terminal radars (q = 2 / 2.375 - 1 < 0), so A's AA
    weight (2 x 0.99 + 4 x 0.01) / 8 is over 2 / 8 of the weight: 1 at most. B, one radar
    at 0.99 and tentative ones, keeps its AA weight (one holder)."""
    mass = np.zeros((2, 8))
    mass[0, :2] = mass[1, 0] = 0.99
    mass[:, 4:] = 0.01
    w = mass.sum(axis=1) / 8
    out = revisit_weights(w, np.array([[1, 98, 0], [1, 98, 1]]), 100, mass, OMEGA, SPANS)
    np.testing.assert_allclose(out, [1.0, w[1]], rtol=1e-12)
    held_any = revisit_weights(w, np.array([[1, 98, 0], [1, 98, 1]]), 100, mass, OMEGA, SPANS,
                               held_above=0.0)  # tentative ones as holders: the AA over 6
    np.testing.assert_allclose(held_any, [w[0] * 8 / 6, 0.99 / 8 * 8 / 5 + 0.04 / 5],
                               rtol=1e-12)


def test_one_input_or_no_rotation_changes_nothing():
    """A track one input holds (one member alone, or one radar's clutter) keeps its AA weight
    however young; inputs without a revisit (span 0) always count, so with none the weights
    are the AA's; three of eight at age 0 with revisits weigh their own mean (at most 1)."""
    mass = np.zeros((2, 8))
    mass[0, 4] = 0.99
    mass[1, :3] = 1.0
    w = mass.sum(axis=1) / 8
    labels = np.array([[1, 100, 0], [1, 100, 1]])
    np.testing.assert_allclose(revisit_weights(w, labels, 100, mass, OMEGA, SPANS),
                               [w[0], 1.0], rtol=1e-12)
    np.testing.assert_allclose(revisit_weights(w, labels, 100, mass, OMEGA, np.zeros(8)), w,
                               rtol=1e-12)
    with pytest.raises(ValueError, match="spans"):
        revisit_weights(w, labels, 100, mass, OMEGA, SPANS[:3])


def test_the_option_reaches_the_peers_from_the_scenario():
    """Auto (-1, the default): on for LMB peers with rotating radars, off for GM-PHD peers; 0
    turns it off for LMB peers and 1 on for GM-PHD peers. On, every peer gets every radar's
    revisit from the shared scenario (rotation period / scan period), its own and its
    neighbours'; without rotating radars it holds none."""
    scn = load_scenario("paris-8", overrides={"network.filter": "gmphd"})
    assert scn.fusion.existence_revisit == -1
    assert consensus_options(scn, "cdg").existence_revisit == ()
    scn = load_scenario("paris-8", overrides={"network.filter": "lmb",
                                              "fusion.existence_revisit": 0})
    assert consensus_options(scn, "cdg").existence_revisit == ()
    scn = load_scenario("seed000", overrides={"network.filter": "lmb"})
    assert consensus_options(scn, scn.sensor_names[0]).existence_revisit == ()
    spans = {"cdg": 2.35, "orly": 2.4, "bourget": 2.375, "pontoise": 2.36, "north": 5.0,
             "south": 6.0, "east": 5.5, "west": 5.25}
    scn = load_scenario("paris-8", overrides={"network.filter": "gmphd",
                                              "fusion.existence_revisit": 1})
    assert dict(consensus_options(scn, "cdg").existence_revisit) == pytest.approx(spans)
    scn = load_scenario("paris-8", overrides={"network.filter": "lmb"})
    got = dict(consensus_options(scn, "west").existence_revisit)
    assert got == pytest.approx(spans)
