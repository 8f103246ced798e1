"""The member flood of tests/test_attack_flood.py through the discrete-event twin (the same
cores, the same bytes, a virtual clock): 6,000 estimates under s2's name, stamped with the scan
s1 is on and fresh round numbers, injected into s1 over ten scans. Every one is refused before
decoding, s2's genuine estimates still get through, and s1's tracks are the clean run's to the
last bit."""

from __future__ import annotations

import numpy as np
from sensornet.protocol.codec import encode
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Estimate
from sensornet.sim.run.twin import Inject, run_twin
from sensornet.sim.scenario import load_scenario, parse_overrides
from sensornet.tracking.mixture import GaussianMixture

FLOOD = 6000


def test_a_fresh_round_flood_through_the_twin_changes_nothing():
    scn = load_scenario("seed000", overrides=parse_overrides(["scenario.num_scans=30"]))
    interval = scn.scan_period / scn.network.speed
    rng = np.random.default_rng(3)
    mix = GaussianMixture(rng.uniform(0.1, 1, 20), rng.normal(0, 500, (20, 4)),
                          np.tile(np.eye(4) * 100.0, (20, 1, 1)))
    key = Keys("twin").estimate("s2")
    flood = []
    for i in range(FLOOD):  # scans 10..19, ten messages a millisecond of virtual time
        k = 10 + i * 10 // FLOOD
        t = k * interval + (i % 600) * 1e-4
        flood.append(Inject(t, "s1", key, encode(Estimate("s2", k, mix, round=1000 + i))))
    clean = run_twin(scn, 0)
    attacked = run_twin(scn, 0, inject=flood)
    s1, before = attacked.summary("s1"), clean.summary("s1")
    assert s1["rejected"].get("round", 0) == FLOOD, s1["rejected"]
    # decoded from s2's key: exactly s2's own estimates, as in the clean run
    assert s1["admitted_by_sender"]["estimate/s2"] == before["admitted_by_sender"]["estimate/s2"]
    assert s1["mean_ospa_fused"] == before["mean_ospa_fused"]
    assert s1["stats"]["last_fused_from"] == before["stats"]["last_fused_from"]
    assert len(clean.tracks["s1"]) == scn.num_scans
    for k, states in clean.tracks["s1"].items():
        np.testing.assert_array_equal(attacked.tracks["s1"][k], states)
