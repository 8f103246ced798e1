"""LMB peers under the GCI rule (issue 33, docs/labelled-tracking.md "The GCI and AA rules under
the LMB defaults"): GCI's fused weights are a PHD's with a separate cardinality, not
existences. Three inputs holding three targets at existence 1, one target's position a little
apart at each: the fused weights are 1.41, 1.41 and 0.18 (mass 3). An existence test per track
(``lmb.fused_extraction`` ``"round"``) drops the third; the cap of
``fusion.existence_mature`` (a pooled existence, at most 1) cuts the two above 1, so the
cardinality rule's round of the mass drops it too. So under GCI the auto values resolve to the
filter's rule and no cap; hybrid and AA keep theirs."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.kinds import kind
from sensornet.sim.kinds.lmb import fused_extraction
from sensornet.sim.run.peers import existence_absent, existence_mature
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.tracking.fusion import gci_fuse
from sensornet.tracking.gmphd import extract_index
from sensornet.tracking.mature_existence import MatureExistence
from sensornet.tracking.mixture import GaussianMixture

LMB = {"network.filter": "lmb"}
GCI = {**LMB, "fusion.rule": "gci", "fusion.cardinality": "separate"}


def gci_density() -> GaussianMixture:
    """The module docstring's fused density (GCI, separate cardinality, equal weights)."""
    cov = np.diag([10.0**2, 2.0**2, 10.0**2, 2.0**2])

    def peer(dy: float) -> GaussianMixture:
        X = np.array([[0.0, 0, 0, 0], [1000.0, 0, 0, 0], [2000.0, 0, dy, 0]])
        return GaussianMixture(np.ones(3), X, np.repeat(cov[None], 3, axis=0))

    f = gci_fuse([peer(0.0), peer(25.0), peer(-25.0)], [1 / 3] * 3, None,
                 cardinality="separate")
    keep = f.weights > 1e-6
    return GaussianMixture(f.weights[keep], f.means[keep], f.covs[keep])


def reported(over: dict, mix: GaussianMixture) -> int:
    est, _ = kind("lmb").build(load_scenario("seed000", over), "s1", 0)
    return len(est.extract(mix))  # not the peer's own density: the fused rule


def test_the_gci_density_of_the_docstring():
    f = gci_density()
    assert np.sort(f.weights) == pytest.approx([0.176, 1.412, 1.412], abs=1e-3)
    assert f.mass == pytest.approx(3.0)


def test_under_gci_every_target_is_reported_by_default():
    f = gci_density()
    assert reported(GCI, f) == 3
    assert reported({**GCI, "lmb.fused_extraction": "round"}, f) == 2  # the old default
    assert reported(LMB, f) == 2  # the hybrid's default: an existence test per track


def test_the_mature_cap_would_drop_a_target_under_gci():
    """Every input holds every target (mass 1 each), the labels are mature: the cap is the
    pooled existence, below 1, so the two rows above 1 are cut and round(mass) falls to 2."""
    f = gci_density()
    labels = np.array([[0, 1, i] for i in range(len(f))])
    rule = MatureExistence(0.99, young=2)
    mass = np.ones((len(f), 3))
    rule.caps(f.weights, labels, 10, mass)
    cap = rule.caps(f.weights, labels, 11, mass)
    capped = GaussianMixture(np.minimum(f.weights, cap), f.means, f.covs)
    assert len(extract_index(f, 0.5, "cardinality")) == 3
    assert len(extract_index(capped, 0.5, "cardinality")) == 2


@pytest.mark.parametrize("rule", ["hybrid", "aa"])
def test_hybrid_and_aa_keep_the_existence_rules(rule):
    scn = load_scenario("seed000", {**LMB, "fusion.rule": rule})
    assert scn.lmb.fused_extraction == "auto"
    assert fused_extraction(scn) == "round"
    assert existence_mature(scn) == scn.survival_probability > 0
    assert existence_absent(scn) == scn.lmb.tentative_threshold > 0


def test_gci_resolves_to_the_filter_rule_and_no_cap():
    scn = load_scenario("seed000", GCI)
    assert fused_extraction(scn) == scn.filter.extraction == "cardinality"
    assert existence_mature(scn) == 0.0 and existence_absent(scn) == 0.0


def test_explicit_values_win_under_gci():
    scn = load_scenario("seed000", {**GCI, "lmb.fused_extraction": "round",
                                    "fusion.existence_mature": 1})
    assert fused_extraction(scn) == "round"
    assert existence_mature(scn) == scn.survival_probability
    assert existence_absent(scn) == scn.lmb.tentative_threshold


def test_a_bad_rule_is_still_a_one_line_error():
    with pytest.raises(ScenarioError, match="fused_extraction"):
        load_scenario("seed000", {**LMB, "lmb.fused_extraction": "gci"})
