"""sim.studies.traffic.heal_prototype: an own track whose fused component lost its label to a
heavier one takes the component's fresh label; everything else as peers.labelling gives it."""

import numpy as np
from sensornet.peers.labelling import FRESH_BASE
from sensornet.peers.labelling import label_fused as reference
from sensornet.sim.studies.traffic.heal_prototype import RELEASE, adopt_labels, label_fused
from sensornet.tracking.label_matching import LabelMatch
from sensornet.tracking.label_matching import adopt_labels as reference_adopt
from sensornet.tracking.mixture import GaussianMixture

L = np.array([[0, 5, 7]])


def _mix(xs, w):
    m = np.zeros((len(xs), 4))
    m[:, 0] = xs
    return GaussianMixture(np.asarray(w, float), m, np.tile(np.eye(4) * 1e4, (len(xs), 1, 1)))


def test_the_lighter_holder_of_a_duplicated_label_releases_it():
    fused = _mix([0.0, 5000.0], [1.0, 0.8])
    own = (_mix([5000.0], [0.8]), L)  # our track of the lighter aircraft carries L
    nbr = (_mix([0.0], [1.0]), L)  # a neighbour's track of the heavier one carries L too
    ref = reference(fused, [own, nbr], origin=3, k=9)
    out = label_fused(fused, [own, nbr], origin=3, k=9)
    np.testing.assert_array_equal(out.labels, ref.labels)
    np.testing.assert_array_equal(out.labels, [[0, 5, 7], [3, 9, FRESH_BASE]])
    assert len(ref.own) == 0  # the reference tells our estimator nothing: L stays duplicated
    assert len(out.own) == 1 and out.own.cost[0] == RELEASE
    np.testing.assert_array_equal(adopt_labels(L, out.own), [[3, 9, FRESH_BASE]])
    np.testing.assert_array_equal(reference_adopt(L, LabelMatch(L, out.labels[1:], np.zeros(1))), L)


def test_a_release_is_skipped_when_the_fresh_label_is_already_ours_and_others_unchanged():
    labels = np.array([[0, 5, 7], [3, 9, FRESH_BASE], [1, 2, 3]])
    rel = LabelMatch(L, np.array([[3, 9, FRESH_BASE]]), np.array([RELEASE]))
    np.testing.assert_array_equal(adopt_labels(labels, rel), labels)
    plain = LabelMatch(np.array([[1, 2, 3]]), np.array([[0, 1, 1]]), np.zeros(1))
    np.testing.assert_array_equal(adopt_labels(labels, plain), reference_adopt(labels, plain))


def test_without_duplicates_it_is_the_reference():
    rng = np.random.default_rng(3)
    for _ in range(20):
        fused = _mix(rng.uniform(0, 20_000, 5), rng.uniform(0.5, 1.0, 5))
        ins = [(_mix(rng.uniform(0, 20_000, 4), np.ones(4)),
                np.column_stack([np.full(4, o), rng.integers(0, 50, 4), np.arange(4)]))
               for o in range(3)]
        a, b = label_fused(fused, ins, 0, 60), reference(fused, ins, 0, 60)
        np.testing.assert_array_equal(a.labels, b.labels)
        plain = a.own.cost != RELEASE
        np.testing.assert_array_equal(a.own.own[plain], b.own.own)
        np.testing.assert_array_equal(a.own.nbr[plain], b.own.nbr)
