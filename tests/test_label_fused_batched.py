"""peers.labelling.label_fused's batched matching (all inputs' costs at once, the solver only
for inputs with a conflict) against the algorithm it replaced: per input, input_tracks then
tracking.labels.match_labels (one linear_sum_assignment each), kept here as the reference."""

from __future__ import annotations

import numpy as np
from sensornet.peers.labelling import FRESH_BASE, LABEL_GATE, FusedLabels, input_tracks, label_fused
from sensornet.tracking.label_matching import RELEASE
from sensornet.tracking.labels import LabelMatch, label_keys, match_labels, new_labels
from sensornet.tracking.mixture import GaussianMixture


def reference(fused, inputs, origin, k, fresh_start=0, gate=LABEL_GATE) -> FusedLabels:
    """label_fused as it was before the batched matching (one match_labels per input)."""
    n = len(fused)
    none = np.zeros((0, 3), dtype=np.int64)
    if n == 0:
        return FusedLabels(none, LabelMatch(none, none.copy(), np.zeros(0)), 0)
    tmp = new_labels(0, 0, n)
    rows, cands, src = [], [], []
    for i, (mix, labels) in enumerate(inputs):
        if labels is None or len(labels) == 0 or len(labels) > len(mix):
            continue
        t_lab, t_m, t_P = input_tracks(mix, labels)
        m = match_labels(tmp, fused.means, fused.covs, t_lab, t_m, t_P, gate)
        rows.append(m.own[:, 2])
        cands.append(m.nbr)
        src.append(np.full(len(m), i))
    labels = np.empty((n, 3), dtype=np.int64)
    won = np.zeros(n, dtype=bool)
    if rows:
        J, L, S = np.concatenate(rows), np.concatenate(cands), np.concatenate(src)
        order = np.lexsort((L[:, 2], L[:, 0], L[:, 1], J))
        Js = J[order]
        first = np.ones(len(Js), dtype=bool)
        first[1:] = Js[1:] != Js[:-1]
        labels[Js[first]] = L[order[first]]
        won[Js[first]] = True
        wrows = np.flatnonzero(won)
        keys = label_keys(labels[wrows])
        by = np.lexsort((-fused.weights[wrows], keys))
        dup = np.zeros(len(by), dtype=bool)
        dup[1:] = keys[by[1:]] == keys[by[:-1]]
        won[wrows[by[dup]]] = False
        own = (S == 0) & won[J]
        own_lab, win = L[own], labels[J[own]]
        change = label_keys(own_lab) != label_keys(win)
        match = LabelMatch(own_lab[change], win[change], np.zeros(int(change.sum())))
    else:
        match = LabelMatch(none, none.copy(), np.zeros(0))
    lost = np.flatnonzero(~won)
    labels[lost] = new_labels(origin, k, len(lost), FRESH_BASE + fresh_start)
    return FusedLabels(labels, match, len(lost))


def _mix(rng, centres, count, spread, scale):
    pick = rng.integers(0, len(centres), count)
    means = centres[pick] + rng.normal(0, spread, (count, 4))
    A = rng.normal(size=(count, 4, 4))
    covs = A @ A.swapaxes(1, 2) * scale + np.eye(4) * scale
    return GaussianMixture(rng.uniform(0.05, 1.0, count), means, covs)


def _case(rng):
    """A fused density and 1-9 inputs around a few targets, some close together (conflicts),
    with components sharing a label, labels covering the first rows only, unlabelled inputs."""
    targets = int(rng.integers(1, 12))
    centres = rng.uniform(-400, 400, (targets, 4))
    if targets > 1 and rng.random() < 0.5:  # two targets close: several candidates per input
        centres[1] = centres[0] + rng.normal(0, 8, 4)
    spread, scale = rng.uniform(1, 15), rng.uniform(5, 150)
    fused = _mix(rng, centres, int(rng.integers(0, 15)), spread, scale)
    inputs = []
    for _ in range(int(rng.integers(1, 10))):
        mix = _mix(rng, centres, int(rng.integers(0, 14)), spread, scale)
        r = rng.random()
        if r < 0.1:
            lab = None
        else:
            m = len(mix) if r < 0.7 else int(rng.integers(0, len(mix) + 2))  # may outnumber
            lab = np.column_stack((np.full(m, int(rng.integers(0, 5))), rng.integers(0, 4, m),
                                   rng.integers(0, max(1, m // 2 + 1), m)))  # repeats
        inputs.append((mix, lab))
    return fused, inputs


def test_batched_label_fused_equals_per_input_matching():
    rng = np.random.default_rng(3301)
    paired = adopted = 0
    for _ in range(400):
        fused, inputs = _case(rng)
        gate = float(rng.choice([9.0, LABEL_GATE, 100.0]))
        origin, k, start = int(rng.integers(0, 5)), int(rng.integers(0, 30)), int(rng.integers(9))
        got = label_fused(fused, inputs, origin, k, start, gate)
        ref = reference(fused, inputs, origin, k, start, gate)
        np.testing.assert_array_equal(got.labels, ref.labels)
        # the reference predates the release pairs (tests/test_label_release.py checks those)
        plain = got.own.cost != RELEASE
        np.testing.assert_array_equal(got.own.own[plain], ref.own.own)
        np.testing.assert_array_equal(got.own.nbr[plain], ref.own.nbr)
        assert got.fresh == ref.fresh
        paired += len(fused) - ref.fresh
        adopted += len(ref.own)
    assert paired > 500 and adopted > 50  # the cases do pair and relabel, not only miss


def test_a_conflict_is_solved_by_assignment_not_by_nearest():
    # fused rows 0, 1 near both tracks of the one input: the assignment pairs 0-b, 1-a (total
    # cost smaller), although track a is the nearest candidate of row 0
    eye = np.tile(np.eye(4) * 50.0, (2, 1, 1))
    fused = GaussianMixture(np.ones(2), np.array([[0.0, 0, 0, 0], [-14.0, 0, 0, 0]]), eye)
    mix = GaussianMixture(np.ones(2), np.array([[-5.0, 0, 0, 0], [10.0, 0, 0, 0]]), eye)
    out = label_fused(fused, [(mix, np.array([[1, 2, 0], [1, 3, 0]]))], 0, 5)
    np.testing.assert_array_equal(out.labels, [[1, 3, 0], [1, 2, 0]])
