"""sim/studies/traffic/turns.py: the turn rate of each aircraft and the distance to its nearest
track, against values worked out by hand for two aircraft, one straight and one turning."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from sensornet.sim.studies.traffic.turns import by_turn_rate, turn_errors

T = 2.0
RATE = 3.0
"""Aircraft 2 turns at 3 deg/s: its heading changes by 6 degrees a tick."""


def _results() -> pd.DataFrame:
    rows = []
    for k in (1, 2, 3):
        h = math.radians(RATE * T * k)
        truth = [[0.0, 200.0, 1000.0 * k, 0.0],  # aircraft 1 flies east
                 [5e4, 200 * math.cos(h), 0.0, 200 * math.sin(h)]]
        tracks = [[30.0, 0.0, 1000.0 * k + 40.0, 0.0], [5e4 + 600.0, 0.0, 800.0, 0.0]]
        if k == 2:
            tracks = tracks[:1]  # aircraft 2 missed at tick 2
        rows.append({"peer": "p", "estimate": "local", "scan": k, "truth": truth,
                     "truth_ids": [1, 2], "tracks": tracks})
    return pd.DataFrame(rows)


def test_turn_rate_and_nearest_track_by_hand():
    e = turn_errors(_results(), T, cutoff=1000.0)
    # only tick 2 has both neighbours
    assert list(e.scan) == [2, 2]
    np.testing.assert_allclose(e.turn_rate, [0.0, RATE])
    # aircraft 1: the track 30 m east, 40 m north (50 m); aircraft 2: no track within 1 km
    np.testing.assert_allclose(e.distance, [50.0, 1000.0])
    assert list(e.miss) == [False, True]
    table = by_turn_rate(e)
    assert table.loc[("local", "< 0.5"), "distance"] == pytest.approx(50.0)
    assert table.loc[("local", ">= 1.5"), "miss"] == 1.0


def test_bad_period_is_an_error():
    with pytest.raises(ValueError, match="must be > 0"):
        turn_errors(_results(), 0.0)
