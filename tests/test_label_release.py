"""The release (issue 34, docs/real-traffic.md "The fused LMB's switches"): an own track whose
fused component lost its label to a heavier component (one label on two targets) takes that
component's fresh label, so the duplicated label does not make a new id every scan."""

import numpy as np
from sensornet.peers.labelling import (
    FRESH_BASE,
    RELEASED_BASE,
    _all_tracks,
    _pairs,
    label_fused,
    released_label,
)
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
    # the released label, the same at every peer that releases L (origin 3 or any other)
    rel = released_label(L)
    np.testing.assert_array_equal(out.labels, np.vstack([L, rel]))
    np.testing.assert_array_equal(label_fused(fused, [own, nbr], origin=5, k=9).labels[1],
                                  rel[0])
    assert rel[0, 0] == 0 and rel[0, 1] == 5 and rel[0, 2] >= RELEASED_BASE  # L's origin, birth
    assert len(out.own) == 1 and out.own.cost[0] == RELEASE
    np.testing.assert_array_equal(out.own.own, L)
    np.testing.assert_array_equal(adopt_labels(L, out.own), rel)
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


def test_the_lighter_holder_takes_the_released_label_not_a_runner_up():
    """A second input carries another label on the lighter aircraft (at some peers the two
    aircraft's ids are crossed): the row still takes the released label, a new id, not that
    label (taking it made the two aircraft trade ids every few scans on the training hour)."""
    fused = _mix([0.0, 5000.0], [1.0, 0.8])
    own = (_mix([5000.0], [0.8]), L)
    nbr = (_mix([0.0], [1.0]), L)
    b0 = np.array([[2, 8, 1]])  # born later than L: L wins the row first
    nbr2 = (_mix([5000.0], [0.8]), b0)
    out = label_fused(fused, [own, nbr, nbr2], origin=3, k=9)
    np.testing.assert_array_equal(out.labels, np.vstack([L, released_label(L)]))
    assert out.fresh == 0
    np.testing.assert_array_equal(adopt_labels(L, out.own), released_label(L))


def _reference(fused, ins, origin, k):
    """label_fused's labels and own pairs by loops over rows and pairs (the pairs themselves
    from _pairs, tested against match_labels elsewhere)."""
    t_lab, t_m, t_P, t_src = _all_tracks(ins)
    J, t = _pairs(fused, t_m, t_P, t_src, 26.0)
    n, w = len(fused), fused.weights
    order = lambda lab: (lab[1], lab[0], lab[2])  # noqa: E731 (the network rule's order)
    cands = {j: sorted({tuple(t_lab[i]) for jj, i in zip(J, t, strict=True)
                         if jj == j}, key=order)
             for j in set(J.tolist())}
    first = {j: c[0] for j, c in cands.items()}
    released = {j for j in first if any(first[o] == first[j] and w[o] > w[j] for o in first)}
    labels = {j: first[j] for j in first if j not in released}
    derived = {j: tuple(released_label(np.array([first[j]]))[0])
               for j in released if j not in labels}
    for j, c in derived.items():
        if not any(derived[o] == c and w[o] > w[j] for o in derived) \
                and c not in labels.values():
            labels[j] = c
    fresh = [j for j in range(n) if j not in labels]
    for c, j in enumerate(fresh):
        labels[j] = (origin, k, FRESH_BASE + c)
    plain, rel = set(), set()
    for j, i in zip(J.tolist(), t.tolist(), strict=True):
        if t_src[i] != 0:
            continue
        own = tuple(t_lab[i])
        if j in fresh or (j in released and own == first[j]):
            rel.add((own, labels[j]))
        elif own != labels[j]:
            plain.add((own, labels[j]))
    return np.array([labels[j] for j in range(n)]), plain, rel


def test_labels_and_own_pairs_against_a_loop():
    """Random cases with labels duplicated across inputs (so rows lose labels and take
    released labels, or fresh ones) against :func:`_reference`."""
    rng = np.random.default_rng(34)
    seen = {"released": 0, "fresh": 0}
    for _ in range(150):
        fused = _mix(rng.uniform(0, 3000, 5), rng.uniform(0.5, 1.0, 5))
        ins = [(_mix(rng.uniform(0, 3000, 4), np.ones(4)),
                np.column_stack([np.zeros(4, int), rng.integers(0, 3, 4), np.arange(4) % 2]))
               for _ in range(3)]
        out = label_fused(fused, ins, 7, 60)
        labels, plain, rel = _reference(fused, ins, 7, 60)
        np.testing.assert_array_equal(out.labels, labels)
        is_rel = out.own.cost == RELEASE
        pairs = [(tuple(a), tuple(b)) for a, b in zip(out.own.own.tolist(),
                                                      out.own.nbr.tolist(), strict=True)]
        assert {p for p, r in zip(pairs, is_rel, strict=True) if r} == rel
        assert {p for p, r in zip(pairs, is_rel, strict=True) if not r} == plain
        assert (out.own.cost[~is_rel] >= 0).all()
        seen["released"] += int((labels[:, 2] >= RELEASED_BASE).sum())
        seen["fresh"] += int((labels[:, 2] < RELEASED_BASE).sum()
                             - (labels[:, 2] < FRESH_BASE).sum())
    assert seen["released"] > 0 and seen["fresh"] > 0  # both branches are exercised
