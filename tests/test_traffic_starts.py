"""sim/studies/traffic/starts.py: which tracks hold an aircraft, from which tick, and the fused
lag behind the reference split into its stages, on tables built by hand."""

from __future__ import annotations

import numpy as np
from sensornet.sim.studies.traffic.starts import first_held, held, lag_stages, report
from sensornet.tracking.track_metrics import TrackTable


def _table(rows: list[tuple[int, int, float, float]]) -> TrackTable:
    a = np.array(rows, float).reshape(-1, 4)
    return TrackTable(a[:, 0].astype(int), a[:, 1].astype(int), a[:, 2:])


TRUTH = _table([(k, 7, 100.0 * k, 0.0) for k in range(1, 11)]
               + [(k, 8, 0.0, 5000.0) for k in range(3, 9)])
"""Aircraft 7 at scans 1-10, aircraft 8 at scans 3-8 (one visit each)."""


def test_held_by_any_track_within_the_cut_off():
    """A track 999 m away holds, 1001 m does not; a track of another scan never does."""
    est = _table([(1, 0, 999.0, 100.0 * 0), (2, 0, 200.0, 1001.0), (4, 1, 0.0, 5000.0)])
    h = held(TRUTH, est, 1000.0)
    want = np.zeros(len(TRUTH.scan), bool)
    want[0] = True  # aircraft 7 at scan 1 (999 m)
    want[10 + 1] = True  # aircraft 8 at scan 4
    np.testing.assert_array_equal(h, want)


def test_first_held_and_the_stages():
    """Reference holds 7 from scan 2, one peer from 3, the second (also a majority of 2 peers)
    from 6, fused from 8: lag 6 = local 1 + second 3 + half 0 + after 2; 8 never held by
    fused: lag its length minus the reference's first tick, all "local"."""
    ref = _table([(k, 0, 100.0 * k, 0.0) for k in range(2, 11)]
                 + [(k, 1, 0.0, 5000.0) for k in range(3, 9)])
    fused = _table([(k, 0, 100.0 * k, 10.0) for k in range(8, 11)])
    p1 = _table([(k, 0, 100.0 * k, 0.0) for k in range(3, 11)])
    p2 = _table([(k, 0, 100.0 * k, 0.0) for k in range(6, 11)])
    grid = np.arange(1, 11)
    f = first_held(TRUTH, {"ref": ref, "fused": fused, "a": p1, "b": p2}, grid, 1000.0)
    np.testing.assert_array_equal(f["start"], [1, 3])
    np.testing.assert_array_equal(f["scans"], [10, 6])
    np.testing.assert_array_equal(f["ref"], [1, 0])
    np.testing.assert_array_equal(f["fused"], [7, 6])
    np.testing.assert_array_equal(f["a"], [2, 6])
    st = lag_stages(f["ref"], f["fused"], np.stack([f["a"], f["b"]], axis=1))
    np.testing.assert_array_equal(st["lag"], [6, 6])
    np.testing.assert_array_equal(st["local"], [1, 6])
    np.testing.assert_array_equal(st["second"], [3, 0])
    np.testing.assert_array_equal(st["half"], [0, 0])
    np.testing.assert_array_equal(st["after"], [2, 0])
    text = report(TRUTH, fused, ref, {"a": p1, "b": p2}, grid, 1000.0)
    assert "lag ticks in all 12" in text and "local 7, second 3, half 0, after 2" in text
