"""The gap trace's per-target split of OSPA(2) (sim.studies.labelled.gap_trace): its parts summed
over targets, with the false part, are ospa2_floor's parts in every window (to 1e-12) on a case
with a late, a switched, a dead-but-reported and a clutter track and a missed target; hops on a
ring; the kinds of id change."""

from __future__ import annotations

import numpy as np
from sensornet.sim.studies.labelled.gap_trace import change_kind, hops, parts_by_truth
from sensornet.sim.studies.labelled.ospa2_floor import PARTS, ospa2_parts_dense


def _case() -> tuple[np.ndarray, np.ndarray]:
    T = 30
    t = np.arange(T, dtype=float)[:, None]
    Y = np.full((T, 3, 2), np.nan)
    Y[:, 0] = np.hstack([10 * t, 0 * t])
    Y[5:20, 1] = np.hstack([0 * t, 500 + 5 * t])[5:20]
    Y[12:, 2] = np.hstack([-400 + 0 * t, -300 + 3 * t])[12:]  # never tracked: missed
    E = np.full((T, 5, 2), np.nan)
    E[2:, 0] = Y[2:, 0] + 7.0  # late by two scans
    E[7:14, 1] = Y[7:14, 1] + 3.0  # target 1 under one id, then another (a switch)
    E[14:24, 2] = np.vstack([Y[14:20, 1], Y[19, 1] + np.arange(1, 5)[:, None] * [0, 5.0]])
    E[9:11, 3] = [[800.0, -800.0]] * 2  # clutter
    E[16:18, 4] = Y[16:18, 0] + 20.0  # a second track of target 0
    return E, Y


def test_parts_by_target_add_up_to_the_floor_study():
    E, Y = _case()
    per, false = parts_by_truth(E, Y, window=10)
    ref = ospa2_parts_dense(E, Y, 200.0, 2.0, 10)
    for key in PARTS:
        got = per[key].sum(axis=1) + (false if key == "false" else 0.0)
        np.testing.assert_allclose(got, ref[key], rtol=1e-12, atol=1e-12)
    assert per["missed"][:, 2].sum() > 0 and per["late"][:, 0].sum() > 0
    assert per["dup"][:, 0].sum() > 0 and false.sum() > 0
    assert per["extra"][:, 1].sum() > 0  # the switched-to track outlives target 1


def test_hops_on_a_ring():
    n = 6
    A = np.zeros((n, n), dtype=int)
    A[np.arange(n), (np.arange(n) + 1) % n] = A[(np.arange(n) + 1) % n, np.arange(n)] = 1
    H = hops(A)
    np.testing.assert_array_equal(H[0], [0, 1, 2, 3, 2, 1])
    assert (H == H.T).all()


def test_change_kinds():
    assert change_kind((0, 22, 5), (0, 21, 5)) == "earlier"
    assert change_kind((0, 41, 5), (0, 41, 6)) == "same-scan"
    assert change_kind((0, 41, 5), (0, 42, 5)) == "later"
    assert change_kind((3, 41, 5), (0, 41, 5)) == "own"
