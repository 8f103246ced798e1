"""The switch tracer of issue 34 (sim/studies/traffic/switches.py): each switch's cause and the
previous holder of the new label, on hand-made tracks where the answer is known."""

import numpy as np
from sensornet.sim.studies.traffic.switches import per_aircraft_rates, trace
from sensornet.sim.world import Truth
from sensornet.tracking.track_metrics import TrackTable

K = 8


def _truth():
    """Aircraft 0xa (x = 0) and 0xb (x = 50 km), both still, 8 ticks."""
    st = [np.array([[0.0, 0, 0, 0], [50e3, 0, 0, 0]]) for _ in range(K)]
    return Truth(st, [np.array([0xA, 0xB]) for _ in range(K)])


def _table(rows):
    """``rows``: (tick, id, x) -> a TrackTable at y = 0."""
    s, i, x = (np.array(c) for c in zip(*rows, strict=True))
    return TrackTable(s.astype(np.int64), i.astype(np.int64), np.column_stack((x, 0 * x)))


def test_settle_handover_and_rates():
    # a: track 1 (label (3, 2, 9)) to tick 4, then 2 (label (0, 2, 9), same birth scan): settle
    # b: track 3 to tick 5, then track 1 (a's old label, moved over 50 km): a handover
    rows = ([(k, 1, 0.0) for k in range(1, 5)] + [(k, 2, 0.0) for k in range(5, K + 1)]
            + [(k, 3, 50e3) for k in range(1, 6)] + [(k, 1, 50e3) for k in range(6, K + 1)])
    label = {1: (3, 2, 9), 2: (0, 2, 9), 3: (1, 1, 1)}
    ev, tot = trace(_truth(), _table(rows), label, {}, 1000.0, 2.0)
    got = [(e["tick"], e["aircraft"], e["cause"], e["held_by"], e["held_ago"]) for e in ev]
    # the settle's new label is 0 ticks old at tick 5 (first seen there); track 1 was last
    # on 0xa at tick 4, two ticks before it took 0xb at tick 6
    assert got == [(5, "00000a", "settle", "-", -1), (6, "00000b", "handover", "00000a", 2)]
    assert tot["switches"] == 2 and tot["hours"] == 2 * K * 2.0 / 3600
    np.testing.assert_allclose(per_aircraft_rates(ev, tot), [1 / (K * 2 / 3600)] * 2)
