"""tracking.point_tracks: ids of extracted points by frame-to-frame association."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.point_tracks import PointTrackConfig, PointTracker


def _scenes(rng: np.random.Generator):
    """Scans 1..14: targets A (0, 0) -> (130, 130) and B (0, 120) -> (130, -10), 10 m a scan,
    crossing at scan 7 (0.5 m apart there); A missed at scan 9; C born at scan 6 at (200, 0)
    moving +y; B gone after scan 10. Noise 0.3 m. Each scan: (points (n, 2), truth (n,))
    shuffled, so the tracker cannot lean on the order."""
    out = []
    for k in range(1, 15):
        t = k - 1
        pts = {}
        if k != 9:
            pts["A"] = (10.0 * t, 10.0 * t + 0.25 * (k == 7))
        if k <= 10:
            pts["B"] = (10.0 * t, 120.0 - 10.0 * t - 0.25 * (k == 7))
        if k >= 6:
            pts["C"] = (200.0, 10.0 * (k - 6))
        names = list(pts)
        P = np.array([pts[n] for n in names]) + rng.normal(0.0, 0.3, (len(names), 2))
        perm = rng.permutation(len(names))
        out.append((k, P[perm], np.array(names)[perm]))
    return out


def test_crossing_targets_a_missed_scan_and_a_new_target_keep_their_ids():
    rng = np.random.default_rng(7)
    tr = PointTracker(2, PointTrackConfig(gate=15.0, m=3, n=4, max_missed=2))
    seen: dict[str, set] = {"A": set(), "B": set(), "C": set()}
    status: dict[str, list] = {"A": [], "B": [], "C": []}
    for k, P, names in _scenes(rng):
        ids, st = tr.update(k, P)
        assert ids.shape == (len(P), 3) and st.shape == (len(P),) and ids.dtype == np.int64
        assert len({tuple(i) for i in ids.tolist()}) == len(P)  # one id per point
        for n, i, s in zip(names, ids.tolist(), st.tolist(), strict=True):
            seen[n].add(tuple(i))
            status[n].append(s)
    # one id per target over the crossing and the missed scan; births stamped (origin, k, i)
    assert all(len(v) == 1 for v in seen.values()), seen
    (a,), (b,), (c,) = seen["A"], seen["B"], seen["C"]
    assert {a, b} == {(2, 1, 0), (2, 1, 1)} and c == (2, 6, 0)
    # M-of-N 3 of 4: tentative on the first two scans, confirmed from the third on; A stays
    # confirmed over its miss
    assert status["C"][:2] == [0, 0] and all(status["C"][2:])
    assert status["A"][:2] == [0, 0] and all(status["A"][2:])
    # B, gone after scan 10, is deleted once it missed more than 2 scans (at scan 14's update)
    assert tr.deleted == 1 and len(tr.ids) == 2


def test_a_track_is_deleted_and_a_point_at_its_place_gets_a_new_id():
    tr = PointTracker(0, PointTrackConfig(gate=5.0, max_missed=1))
    first, _ = tr.update(1, [[0.0, 0.0]])
    again, _ = tr.update(3, [[0.0, 0.0]])  # one scan missed: still the track
    assert first.tolist() == again.tolist() == [[0, 1, 0]]
    late, _ = tr.update(6, [[0.0, 0.0]])  # two missed: deleted, a new id
    assert late.tolist() == [[0, 6, 0]] and tr.deleted == 1


def test_nearest_within_the_gate_and_a_single_target_keeps_one_id():
    # the assignment minimises the total distance: an independent brute force over the 3!
    # orders of 3 tracks and 3 points agrees
    rng = np.random.default_rng(3)
    for _ in range(20):
        tr = PointTracker(1, PointTrackConfig(gate=1e9))
        A = rng.uniform(0, 10, (3, 2))
        ids0, _ = tr.update(1, A)
        B = A + rng.normal(0, 3, (3, 2))
        ids1, _ = tr.update(2, B)
        perms = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
        cost = [sum(np.linalg.norm(A[p[j]] - B[j]) for j in range(3)) for p in perms]
        best = perms[int(np.argmin(cost))]
        assert ids1.tolist() == ids0[list(best)].tolist()
    one = PointTracker(4)  # defaults: any distance, confirmed at once
    for k in range(1, 30):
        ids, st = one.update(k, rng.normal(0, 1e3, (1, 2)))
        assert ids.tolist() == [[4, 1, 0]] and st.tolist() == [1]


def test_bad_input_is_refused_with_a_clear_error():
    tr = PointTracker(0)
    tr.update(5, np.zeros((0, 2)))
    with pytest.raises(ValueError, match="scan 5 after scan 5"):
        tr.update(5, np.zeros((1, 2)))
    with pytest.raises(ValueError, match="not finite"):
        tr.update(6, [[np.nan, 0.0]])
    with pytest.raises(ValueError, match="M-of-N"):
        PointTrackConfig(m=3, n=2)
    with pytest.raises(ValueError, match="gate"):
        PointTrackConfig(gate=0.0)


def test_births_are_numbered_by_position_whatever_the_order_of_the_points():
    P = np.array([[30.0, 1.0], [-5.0, 7.0], [30.0, -2.0], [12.0, 0.0]])
    want = {(-5.0, 7.0): 0, (12.0, 0.0): 1, (30.0, -2.0): 2, (30.0, 1.0): 3}  # x, then y
    for perm in ([0, 1, 2, 3], [3, 2, 1, 0], [2, 0, 3, 1]):
        ids, _ = PointTracker(1).update(9, P[perm])
        assert [int(i) for i in ids[:, 2]] == [want[tuple(p)] for p in P[perm].tolist()]
        assert (ids[:, :2] == [1, 9]).all()
