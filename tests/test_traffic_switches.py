"""sim.studies.traffic.switches.trace: each identity switch with what became of the old track
and its cause, on hand-made truths and tracks."""

import numpy as np
from sensornet.sim.studies.traffic.switches import trace
from sensornet.sim.world import Truth
from sensornet.tracking.track_metrics import TrackTable

SITES = {"a": (np.array([0.0, 0.0]), 100_000.0), "b": (np.array([90_000.0, 0.0]), 50_000.0)}


def _truth(T, gap):
    """Aircraft 0xa1 flying east along y = 0, 0xb2 along y = gap; ``[px, vx, py, vy]``."""
    xs = 100.0 * np.arange(T)
    states = [np.array([[x, 100.0, 0.0, 0.0], [x, 100.0, gap, 0.0]]) for x in xs]
    return Truth(states, [np.array([0xA1, 0xB2])] * T)


def _table(rows):
    s, i, p = zip(*rows, strict=True)
    return TrackTable(np.array(s), np.array(i), np.array(p, dtype=float))


def test_two_tracks_trading_aircraft_is_a_swap_by_handover():
    T = 8
    truth = _truth(T, 1500.0)  # beyond the gate: CLEAR keeps no stale pair
    rows = []
    for k in range(1, T + 1):
        x = 100.0 * (k - 1)
        a, b = (0, 1) if k <= 4 else (1, 0)  # the ids trade aircraft at scan 5
        rows += [(k, a, (x, 0.0)), (k, b, (x, 1500.0))]
    ev, tot = trace(truth, _table(rows), {0: "L0", 1: "L1"}, SITES, 1000.0, 2.0)
    assert tot["switches"] == 2 and [e["tick"] for e in ev] == [5, 5]
    assert {e["aircraft"] for e in ev} == {"0000a1", "0000b2"}
    # each new label last held the other aircraft: a handover (the first class that applies,
    # before crossing: sim.studies.traffic.switches)
    assert all(e["fate"] == "swap" and e["cause"] == "handover" for e in ev)
    assert {e["aircraft"]: e["held_by"] for e in ev} == {"0000a1": "0000b2", "0000b2": "0000a1"}
    assert ev[0]["near_m"] == 1500.0 and ev[0]["cover"] == 1 and ev[0]["turn"] == 0.0


def test_a_track_replaced_by_a_new_id_is_reborn_and_by_an_old_one_a_relabel():
    T = 8
    truth = _truth(T, 20_000.0)
    rows = []
    for k in range(1, T + 1):
        x = 100.0 * (k - 1)
        rows.append((k, 0 if k <= 3 else 2, (x, 0.0)))  # a's track dropped, new id 2 at 4
        rows.append((k, 1 if k <= 5 else 3, (x, 20_000.0)))  # b's: id 3, seen since 2 far off
        if 2 <= k <= 5:
            rows.append((k, 3, (x, 60_000.0)))
    ev, _ = trace(truth, _table(rows), {}, SITES, 1000.0, 2.0)
    by = {e["aircraft"]: e for e in ev}
    assert by["0000a1"]["tick"] == 4 and by["0000a1"]["cause"] == "reborn"
    assert by["0000a1"]["new_age"] == 0 and by["0000a1"]["fate"] == "dropped"
    assert by["0000b2"]["tick"] == 6 and by["0000b2"]["cause"] == "relabel"
    assert by["0000b2"]["new_age"] == 4 and by["0000b2"]["new"] == 3
