"""ET-GM-PHD peers (seed 002) exchanging mixtures and fusing by GCI: twin and real processes."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario

SCANS = 30
SETS = [f"scenario.num_scans={SCANS}", "network.speed=10"]


def _scenario():
    return load_scenario("seed002", {"scenario.num_scans": SCANS, "network.speed": 10})


def test_twin_et_peers_fuse_every_scan_with_both_neighbours():
    scn = _scenario()
    res = run_twin(scn, 0)
    for name in scn.sensor_names:
        s = res.summary(name)
        assert s["stop_reason"] == "end of run" and s["internal_errors"] == {}
        assert s["stats"]["fusions"] == SCANS and s["stats"]["fused_inputs"] == 2 * SCANS
        assert s["rejected_total"] == 0
        assert res.mean_ospa(name, "fused") < 60 and res.mean_ospa(name, "local") < 60
        core = res.peers[name]
        local = [r for r in core.consensus.records if r["kind"] == "local"] or []
        assert all(r.get("n_partitions", 1) >= 1 for r in local)
    # full graph, one round, uniform-degree Metropolis weights: every peer fuses the same
    fused = [res.mean_ospa(n, "fused") for n in scn.sensor_names]
    assert np.ptp(fused) < 1e-6


def test_twin_counts_an_oversized_scan_instead_of_hanging():
    scn = load_scenario("seed002", {"scenario.num_scans": 5, "extended.max_measurements": 30,
                                    "sensors.*.clutter_rate": 40})
    res = run_twin(scn, 0)
    est = res.peers["s1"].consensus.estimator
    assert est.filter.counts["scans_too_large"] >= 4
    assert res.summary("s1")["stats"]["scans"] == 5


@pytest.mark.network
def test_et_peers_over_zenoh_fuse_like_the_twin(tmp_path):
    scn = _scenario()
    handle = start_run(scn, "seed002", tmp_path, overrides=SETS, rerun=False)
    try:
        codes = wait_run(handle, timeout=SCANS / 10 + 60)
    finally:
        handle.stop_all()
    assert codes == {"world": 0, "s1": 0, "s2": 0, "s3": 0}, codes
    summaries = read_summaries(tmp_path, scn.sensor_names)
    twin = run_twin(scn, 0)
    for name, s in summaries.items():
        assert s["stop_reason"] == "end of run" and s["scans"] == SCANS
        assert s["stats"]["fusions"] == SCANS
        assert s["stats"]["fused_inputs"] >= 2 * SCANS - 4, name
        assert s["internal_errors"] == {}
        assert s["mean_ospa_local"] == pytest.approx(twin.mean_ospa(name, "local"), rel=1e-9)
        if s["stats"]["fused_inputs"] == 2 * SCANS and s["stats"]["deadline_fusions"] == 0:
            assert s["mean_ospa_fused"] == pytest.approx(twin.mean_ospa(name, "fused"),
                                                         rel=1e-6)
