"""A mature fused track's existence after a miss at its inputs (tracking.mature_existence,
``fusion.existence_mature``; docs/labelled-tracking.md "Fused tracks outlive their targets"):
by hand against Bayes' rule for independent misses, and the rows it must leave alone."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.gmphd import extract_index
from sensornet.tracking.mature_existence import MatureExistence
from sensornet.tracking.mixture import GaussianMixture

PS, PD = 0.99, 0.9
LABEL = np.array([[0, 41, 7]])


def _missed(r: float) -> float:
    """An LMB track's existence after one scan without a detection (Reuter et al. 2014,
    eq. 21 with no measurement): ``Ps r (1 - Pd) / (1 - Ps r Pd)``."""
    p = PS * r
    return p * (1 - PD) / (1 - p * PD)


def _rule(w_prev: float = 1.0) -> MatureExistence:
    rule = MatureExistence(PS, young=2)
    rule.caps(np.array([w_prev]), LABEL, 80, np.ones((1, 5)))
    return rule


def test_a_target_every_input_missed_falls_as_bayes_says():
    """Five inputs that held the track at r = 1 each miss it once (r = 0.908 each, their mean
    is what the hybrid rule's weight is): the cap is the prior Ps odds times five miss
    likelihood ratios ``(1 - Pd)``, Bayes' rule for independent sensors, to 1e-12; the
    cardinality extraction then drops the track, which the fused weight alone keeps."""
    r = _missed(1.0)
    cap = _rule().caps(np.array([r]), LABEL, 81, np.full((1, 5), r))
    odds = PS / (1 - PS) * (1 - PD) ** 5
    np.testing.assert_allclose(cap, [odds / (1 + odds)], rtol=1e-12)
    assert cap[0] < 0.05
    fused = GaussianMixture(np.array([r]), np.zeros((1, 4)), np.eye(4)[None])
    assert len(extract_index(fused, 0.5, "cardinality")) == 1
    capped = GaussianMixture(np.minimum(fused.weights, cap), fused.means, fused.covs)
    assert len(extract_index(capped, 0.5, "cardinality")) == 0


def test_one_miss_among_five_detections_keeps_the_target():
    """A live target at Pd 0.9: four inputs detect it (r 0.999), one misses (0.908): the cap
    stays above the fused weight (the rule changes nothing)."""
    m = np.array([[0.999, 0.999, _missed(1.0), 0.999, 0.999]])
    w = m.mean(axis=1)
    cap = _rule().caps(w, LABEL, 81, m)
    assert cap[0] > w[0]


@pytest.mark.parametrize("case", ["young", "unseen", "one input", "first call"])
def test_rows_it_leaves_alone(case):
    """No cap (inf) for a young label (at most ``young`` scans old), a label without a fused
    weight the scan before, a track one input holds, or at the first call."""
    r = _missed(1.0)
    mass = np.full((1, 5), r)
    labels = LABEL
    rule = _rule()
    if case == "young":
        labels = np.array([[0, 79, 7]])
        rule = MatureExistence(PS, young=2)
        rule.caps(np.array([1.0]), labels, 80, np.ones((1, 5)))
    elif case == "unseen":
        labels = np.array([[0, 41, 8]])
    elif case == "one input":
        mass = np.array([[r, 0, 0, 0, 0]])
    else:
        rule = MatureExistence(PS, young=2)
    assert np.isinf(rule.caps(np.array([r]), labels, 81, mass)).all()


def test_the_prior_is_the_last_fused_weight_predicted():
    """Two scans after the last call the prior is ``Ps^2 w_prev``; labels twice in one scan
    add their weights (at most 1)."""
    rule = MatureExistence(PS, young=2)
    rule.caps(np.array([0.3, 0.3]), np.repeat(LABEL, 2, axis=0), 80, np.ones((2, 5)))
    r = np.array([[0.4, 0.5]])
    cap = rule.caps(np.array([0.45]), LABEL, 82, r)
    r0 = PS**2 * 0.6
    z = np.log(r0 / (1 - r0)) + sum(np.log(x / (1 - x)) - np.log(r0 / (1 - r0))
                                    for x in r[0])
    np.testing.assert_allclose(cap, [1 / (1 + np.exp(-z))], rtol=1e-12)


def test_bad_input_is_a_one_line_error():
    with pytest.raises(ValueError, match="survival"):
        MatureExistence(0.0)
    with pytest.raises(ValueError, match="rows"):
        MatureExistence(PS).caps(np.ones(2), LABEL, 1, np.ones((2, 5)))
