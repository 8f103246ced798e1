"""Flooding peers bound a forwarded scan by its origin's sensor (issue 24): too many returns or
returns outside its field are refused, counted by reason, neither pooled nor forwarded."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sensornet.peers.contracts import FusionInput
from sensornet.peers.flood_parts import FloodFuser, ScanBound, poisson_bound
from sensornet.protocol.messages import ScanSet
from sensornet.sim.kinds.flooding import scan_bounds
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario

LINE = {"sensors.positions": [[-900, 0], [-450, 0], [0, 0], [450, 0], [900, 0]],
        "sensors.radius": 500.0, "scenario.num_scans": 12}


def test_poisson_bound_is_the_tail_quantile():
    m = poisson_bound(13.0, 1e-9)
    tail = 1.0 - sum(math.exp(-13.0) * 13.0 ** i / math.factorial(i) for i in range(m + 1))
    below = tail + math.exp(-13.0) * 13.0 ** m / math.factorial(m)
    assert tail < 1e-9 <= below  # the smallest such m
    assert poisson_bound(0.0) == 0


def test_bound_refuses_floods_and_points_outside_the_field():
    b = ScanBound((-100.0, -100.0), (100.0, 100.0), 3)
    assert b.refusal(np.zeros((3, 2))) is None
    assert b.refusal(np.zeros((0, 2))) is None
    assert b.refusal(np.zeros((4, 2))) == "too_many_returns"
    assert b.refusal(np.array([[0.0, 0.0], [100.5, 0.0]])) == "outside_field"
    assert b.refusal(np.array([[0.0, -101.0]])) == "outside_field"
    assert b.refusal(np.array([[100.0, -100.0]])) is None  # the box's edge is inside
    for bad in (math.nan, math.inf, -math.inf):  # not a point of any field
        assert b.refusal(np.array([[0.0, 0.0], [bad, 0.0]])) == "outside_field"


def _inp(k, rnd, own, neighbours):
    return FusionInput(k, rnd, ScanSet(own), {s: {"posterior": ScanSet(v)}
                                               for s, v in neighbours.items()}, [1.0], None)


def test_fuser_pools_plausible_scans_and_counts_refusals_by_reason():
    bounds = {o: ScanBound((-10.0, -10.0), (10.0, 10.0), 2) for o in ("a", "b", "c", "d")}
    f = FloodFuser("a", ["a", "b", "c", "d"], rounds=2, bounds=bounds)
    own = {"a": np.array([[50.0, 50.0]] * 5)}  # the own scan is never checked
    pooled = f.fuse(_inp(1, 0, own, {"b": {"b": np.zeros((2, 2)),
                                           "c": np.zeros((3, 2)),          # a flood
                                           "d": np.array([[0.0, 99.0]])}}))  # outside
    assert sorted(pooled.scans) == ["a", "b"]
    assert f.counts["refused_too_many_returns"] == 1 and f.counts["refused_outside_field"] == 1
    assert sorted(f.outgoing(pooled).scans) == ["b"]  # the refused ones are not forwarded
    # an honest copy of d's scan from another neighbour is pooled after the forged one
    pooled = f.fuse(_inp(1, 1, own, {"c": {"d": np.array([[1.0, 1.0]])}}))
    assert sorted(pooled.scans) == ["a", "b", "d"]


@pytest.mark.parametrize("variant", ["linear", "mixed"])
def test_honest_flooding_refuses_nothing(variant):
    # every sensor's real scans (clutter over the field, targets near its edges) pass
    scn = load_scenario("seed004", {**LINE, "scenario.variant": variant})
    res = run_twin(scn, 0)
    for n in scn.sensor_names:
        counts = res.summary(n)["fuser"]
        assert not any(key.startswith("refused") for key in counts), counts
        assert counts["scans_complete"] == 12


def test_bounds_follow_each_sensor():
    scn = load_scenario("seed004", {**LINE, "scenario.variant": "mixed"})
    b = scan_bounds(scn)
    lin, radar = b["s1"], b["s2"]  # mixed: even sensors (1-based odd names) linear
    assert lin.low == (-1060.0, -1060.0) and lin.high == (1060.0, 1060.0)
    assert radar.low[0] < 0 < radar.high[0] and radar.high[1] > math.pi
    assert lin.max_returns == poisson_bound(10.0 + 3)
