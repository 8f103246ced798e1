"""The OSPA(2) decomposition of sim/studies/labelled/ospa2_floor.py: its parts add up to
tracking.track_metrics' OSPA(2), on a hand case whose parts are known and on random tables."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.studies.labelled.ospa2_floor import (
    PARTS,
    ospa2_parts,
    ospa2_parts_dense,
    shown,
    stitch,
)
from sensornet.tracking.track_metrics import TrackTable, ospa2, ospa2_dense


def _table(rows):
    s, i, x, y = zip(*rows, strict=True)
    return TrackTable(np.array(s), np.array(i), np.stack([x, y], axis=1).astype(float))


def test_hand_case_parts():
    """Truth 1 on scans 1-4 at (0, 0); truth 2 on scans 1-4 at (1000, 0). Track 10 follows
    truth 1 from scan 2 at 30 m (one late scan), track 11 sits on truth 2 on scans 1-2, track
    12 takes truth 2 over on scans 3-4 (a switch), track 13 is clutter far away on scan 4."""
    c, p = 100.0, 2.0
    truth = _table([(k, j, 1000.0 * (j - 1), 0.0) for k in range(1, 5) for j in (1, 2)])
    est = _table([(k, 10, 0.0, 30.0) for k in (2, 3, 4)]
                 + [(k, 11, 1000.0, 0.0) for k in (1, 2)]
                 + [(k, 12, 1000.0, 0.0) for k in (3, 4)] + [(4, 13, 5000.0, 0.0)])
    parts = ospa2_parts(truth, est, c, p, window=None)
    # by hand: pair (10, 1): 3 scans at 30 m, 1 late scan: b = (90 + 100) / 4 = 47.5;
    # pair (11, 2) or (12, 2): 2 scans at 0, 2 gap scans: b = 50; two unassigned tracks
    # (one near truth 2: dup; track 13: false); d^2 = (47.5^2 + 50^2 + 2 * 100^2) / 4
    S = 47.5**2 + 50**2 + 2 * c**2
    d = np.sqrt(S / 4)
    assert parts["total"] == pytest.approx(d)
    assert parts["total"] == pytest.approx(ospa2(truth, est, c, p)[0])
    assert parts["loc"] == pytest.approx(d * 47.5 * 90 / 4 / S)
    assert parts["late"] == pytest.approx(d * 47.5 * 100 / 4 / S)
    assert parts["gap"] == pytest.approx(d * 50 * 200 / 4 / S)
    assert parts["dup"] == pytest.approx(parts["false"]) == pytest.approx(d * c**2 / S)
    assert parts["extra"] == parts["missed"] == 0.0
    assert sum(parts[k] for k in PARTS) == pytest.approx(parts["total"])
    # windowed: the parts' means add up to the mean of the windowed OSPA(2) curve
    w = ospa2_parts(truth, est, c, p, window=2)
    assert w["total"] == pytest.approx(ospa2(truth, est, c, p, window=2).mean())
    assert sum(w[k] for k in PARTS) == pytest.approx(w["total"])
    # no estimate: all missed; no truth: all false
    none = TrackTable(np.zeros(0), np.zeros(0), np.zeros((0, 2)))
    grid = np.arange(1, 5)
    assert ospa2_parts(truth, none, c, p, None, grid)["missed"] == pytest.approx(c)
    assert ospa2_parts(none, est, c, p, None, grid)["false"] == pytest.approx(c)


def test_parts_add_up_on_random_tracks():
    rng = np.random.default_rng(7)
    for _ in range(10):
        E, Y = rng.normal(0, 150, (25, 6, 2)), rng.normal(0, 150, (25, 4, 2))
        E[rng.random((25, 6)) < 0.4] = np.nan
        Y[rng.random((25, 4)) < 0.3] = np.nan
        for window in (None, 10):
            parts = ospa2_parts_dense(E, Y, 200.0, 2.0, window)
            ref = ospa2_dense(E, Y, 200.0, 2.0, window)
            np.testing.assert_allclose(parts["total"], ref)
            np.testing.assert_allclose(sum(parts[k] for k in PARTS), ref)
            assert all((parts[k] >= 0).all() for k in PARTS)


def test_stitch_joins_a_relabelled_track_and_shown_drops_first_scans():
    """Track 11 hands over to 12 at scan 3 in place (a relabel): stitched, one id and no
    ``dup`` or ``gap`` left; track 13 starts far away and keeps its id."""
    truth = _table([(k, 2, 1000.0, 0.0) for k in range(1, 5)])
    est = _table([(k, 11, 1000.0, 0.0) for k in (1, 2)] + [(k, 12, 1005.0, 0.0) for k in (3, 4)]
                 + [(3, 13, 5000.0, 0.0)])
    st = stitch(est, gate=50.0)
    assert set(st.id[st.pos[:, 0] < 2000].tolist()) == {11} and st.id[st.scan == 3].tolist() \
        in ([11, 13], [13, 11])
    before, after = ospa2_parts(truth, est, 100.0, window=None), ospa2_parts(truth, st, 100.0,
                                                                             window=None)
    assert before["gap"] > 0 and after["gap"] == 0 and after["total"] < before["total"]
    sh = shown(est, 2)
    assert sorted(zip(sh.scan.tolist(), sh.id.tolist(), strict=True)) == [(2, 11), (4, 12)]
