"""The release (issue 34, docs/real-traffic.md "The fused LMB's switches"): an own track whose
fused component lost its label to a heavier component (one label on two targets) takes that
component's fresh label, so the duplicated label does not make a new id every scan."""

import numpy as np
from sensornet.peers.labelling import FRESH_BASE, _all_tracks, _pairs, label_fused
from sensornet.tracking.label_matching import RELEASE, LabelMatch, adopt_labels
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
    out = label_fused(fused, [own, nbr], origin=3, k=9)
    np.testing.assert_array_equal(out.labels, [[0, 5, 7], [3, 9, FRESH_BASE]])
    assert len(out.own) == 1 and out.own.cost[0] == RELEASE
    np.testing.assert_array_equal(out.own.own, L)
    np.testing.assert_array_equal(adopt_labels(L, out.own), [[3, 9, FRESH_BASE]])
    # the same pair as an ordinary match: the earliest-birth rule keeps L (the old defect)
    plain = LabelMatch(out.own.own, out.own.nbr, np.zeros(1))
    np.testing.assert_array_equal(adopt_labels(L, plain), L)


def test_a_release_is_skipped_when_the_new_label_is_already_ours_and_plain_pairs_unchanged():
    labels = np.array([[0, 5, 7], [3, 9, FRESH_BASE], [1, 2, 3]])
    rel = LabelMatch(L, np.array([[3, 9, FRESH_BASE]]), np.array([RELEASE]))
    np.testing.assert_array_equal(adopt_labels(labels, rel), labels)
    plain = LabelMatch(np.array([[1, 2, 3]]), np.array([[0, 1, 1]]), np.zeros(1))
    both = LabelMatch(np.vstack([plain.own, [[0, 5, 7]]]), np.vstack([plain.nbr, [[4, 9, 1]]]),
                      np.array([0.0, RELEASE]))
    # the plain pair by the rule (birth scan 1 < 2 wins), the release whatever the order says
    np.testing.assert_array_equal(adopt_labels(labels, plain),
                                  [[0, 5, 7], [3, 9, FRESH_BASE], [0, 1, 1]])
    np.testing.assert_array_equal(adopt_labels(labels, both),
                                  [[4, 9, 1], [3, 9, FRESH_BASE], [0, 1, 1]])


def test_release_pairs_are_the_own_tracks_paired_with_rows_that_lost_their_label():
    """Against a loop over the pairs, on random cases with duplicated labels across inputs."""
    rng = np.random.default_rng(34)
    seen = 0
    for _ in range(60):
        fused = _mix(rng.uniform(0, 3000, 5), rng.uniform(0.5, 1.0, 5))
        ins = [(_mix(rng.uniform(0, 3000, 4), np.ones(4)),
                np.column_stack([np.zeros(4, int), rng.integers(0, 3, 4), np.arange(4) % 2]))
               for _ in range(3)]
        out = label_fused(fused, ins, 7, 60)
        t_lab, t_m, t_P, t_src = _all_tracks(ins)
        J, t = _pairs(fused, t_m, t_P, t_src, 26.0)
        want = set()
        for j, i in zip(J.tolist(), t.tolist(), strict=True):
            row = tuple(out.labels[j])
            if t_src[i] == 0 and row[:2] == (7, 60) and row[2] >= FRESH_BASE:
                want.add((tuple(t_lab[i]), row))
        rel = out.own.cost == RELEASE
        got = {(tuple(a), tuple(b)) for a, b in zip(out.own.own[rel].tolist(),
                                                    out.own.nbr[rel].tolist(), strict=True)}
        assert got == want
        assert (out.own.cost[~rel] >= 0).all()
        seen += len(want)
    assert seen > 0  # the cases do hold duplicated labels
