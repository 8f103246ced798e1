"""The label matching of two peers' tracks (tracking.labels.match_labels; peers.labelling
.label_fused does the same per input, batched: tests/test_label_fused_batched.py): its gate
pre-filter (only pairs that can pass the gate are solved) gives the assignment of every pair
solved, against plain loops."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from sensornet.tracking.labels import match_labels, new_labels


def reference(own_m, own_P, nbr_m, nbr_P, gate):
    """Every pair's ``(m_i - n_j)^T (P_i + Q_j)^-1 (m_i - n_j)`` by a loop, assignment on the
    costs capped at the gate, pairs above it dropped: ``[(i, j, cost)]``."""
    C = np.zeros((len(own_m), len(nbr_m)))
    for i in range(len(own_m)):
        for j in range(len(nbr_m)):
            d = own_m[i] - nbr_m[j]
            C[i, j] = d @ np.linalg.inv(own_P[i] + nbr_P[j]) @ d
    rows, cols = linear_sum_assignment(np.minimum(C, gate))
    return [(i, j, C[i, j]) for i, j in zip(rows, cols, strict=True) if C[i, j] <= gate]


def spd(rng, n, scale):
    A = rng.normal(size=(n, 4, 4))
    return A @ A.swapaxes(1, 2) * scale + np.eye(4) * scale


def test_gated_matching_equals_all_pairs_solved():
    rng = np.random.default_rng(33)
    matched = 0
    for _ in range(60):
        a, b = int(rng.integers(1, 25)), int(rng.integers(1, 15))
        centres = rng.uniform(-500, 500, size=(max(a, b), 4))
        own_m = centres[rng.integers(0, len(centres), a)] + rng.normal(0, 10, (a, 4))
        nbr_m = centres[rng.integers(0, len(centres), b)] + rng.normal(0, 10, (b, 4))
        own_P, nbr_P = spd(rng, a, rng.uniform(5, 200)), spd(rng, b, rng.uniform(5, 200))
        own_l, nbr_l = new_labels(0, 0, a), new_labels(1, 3, b)
        gate = float(rng.choice([9.0, 26.0, 100.0]))
        got = match_labels(own_l, own_m, own_P, nbr_l, nbr_m, nbr_P, gate)
        ref = reference(own_m, own_P, nbr_m, nbr_P, gate)
        assert [(int(r[2]), int(c[2])) for r, c in zip(got.own, got.nbr, strict=True)] == \
            [(i, j) for i, j, _ in ref]
        np.testing.assert_allclose(got.cost, [c for _, _, c in ref], rtol=1e-9)
        matched += len(ref)
    assert matched > 100  # the cases do pair tracks, not only leave them apart


def test_a_repeated_label_is_refused():
    m, P = np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1))
    twice = np.array([[0, 1, 2], [0, 1, 2]])
    with pytest.raises(ValueError, match="repeats a label"):
        match_labels(twice, m, P, new_labels(1, 0, 2), m, P, 26.0)
    with pytest.raises(ValueError, match="repeats a label"):
        match_labels(new_labels(1, 0, 2), m, P, twice, m, P, 26.0)
    # labels equal in two columns only are distinct
    near = np.array([[0, 1, 2], [0, 1, 3]])
    assert len(match_labels(near, m, P, new_labels(1, 0, 2), m, P, 26.0)) == 2
