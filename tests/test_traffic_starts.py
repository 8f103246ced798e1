"""sim/studies/traffic/starts.py: which tracks hold an aircraft, from which tick, and the fused
lag behind the reference split into its stages, on tables built by hand."""

from __future__ import annotations

import numpy as np
from sensornet.sim.studies.traffic.metrics import visits
from sensornet.sim.studies.traffic.starts import (
    first_held,
    held,
    lag_stages,
    plots_so_far,
    report,
    waiting,
)
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


def test_plots_so_far_counts_within_each_visit():
    """Aircraft 9 present at scans 1-3 and 6-8 (two visits): its plots at 2, 3 (twice) and 6
    count up within each visit and restart at the second; a plot at scan 5 (absent) and
    another aircraft's plots count nowhere."""
    truth = _table([(k, 9, 0.0, 0.0) for k in (1, 2, 3, 6, 7, 8)])
    v, _ = visits(truth, np.arange(1, 9))
    n = plots_so_far(truth, v.id, [(np.array([2, 3, 3, 5, 6, 4]), np.array([9, 9, 9, 9, 9, 5])),
                                   (np.array([7]), np.array([5]))])
    np.testing.assert_array_equal(n[:, 0], [0, 1, 3, 1, 1, 1])
    np.testing.assert_array_equal(n[:, 1], 0)


def test_waiting_says_which_peers_lack_the_aircraft_and_why():
    """4 peers: reference holds 7 from scan 2, peers a, b, c from 3, 4, 7, d never, fused from
    9: the half stage is scans 4-6 (waiting for the third peer), where c and d lack it (6
    cells): c can see it (Pd 0.9) and has 1, 1, 2 plots; d cannot (Pd 0.05), 0, 1, 1."""
    ref = _table([(k, 0, 100.0 * k, 0.0) for k in range(2, 11)])
    fused = _table([(k, 0, 100.0 * k, 0.0) for k in range(9, 11)])
    loc = {nm: _table([(k, 0, 100.0 * k, 0.0) for k in range(k0, 11)])
           for nm, k0 in (("a", 3), ("b", 4), ("c", 7), ("d", 11))}
    grid = np.arange(1, 11)
    f = first_held(TRUTH, {"ref": ref, "fused": fused, **loc}, grid, 1000.0)
    st = lag_stages(f["ref"], f["fused"], np.stack([f[n] for n in loc], axis=1))
    assert (st["lag"][0], st["local"][0], st["second"][0], st["half"][0]) == (7, 1, 1, 3)
    seven = np.array([7, 7])
    plots = [(np.array([1, 2]), seven), (np.array([2, 3]), seven),
             (np.array([2, 6]), seven), (np.array([5]), seven[:1])]
    pd = np.tile([0.9, 0.9, 0.9, 0.05], (len(TRUTH.scan), 1))
    text = waiting(TRUTH, fused, ref, loc, grid, 1000.0, plots, pd)
    assert "half stage: 3 aircraft-ticks, 6 (tick, peer) cells" in text
    assert "< 0.1 in 3, < 0.5 in 3, median 0.48" in text
    assert "0 in 1, 1 in 4, 2 or more in 1; held earlier in the visit in 0" in text
    assert "c 3, 1, 0.90; d 3, 1, 0.05" in text
    # first plot to first track: a 0 (scan 1 -> 3: 2 ticks), b 1 (2 -> 4: 2), c 1 (2 -> 7: 5)
    assert "a 2 (2); b 2 (2); c 5 (2)" in text
