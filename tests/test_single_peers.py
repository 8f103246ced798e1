"""Single-target IMM peers (seed 001) in the twin and as real processes over Zenoh."""

from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from sensornet.sim.run.launcher import read_summaries, start_run, wait_run
from sensornet.sim.run.peers import make_peer
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError, load_scenario, parse_overrides


@pytest.mark.parametrize("rule", ["ratio", "gci"])
@pytest.mark.parametrize("kind", ["imm-pf", "imm-ekf"])
def test_fused_beats_each_radar_alone_in_the_twin(rule, kind):
    scn = load_scenario("seed001", overrides={"scenario.num_scans": 150, "fusion.rule": rule,
                                              "network.filter": kind})
    result = run_twin(scn, 0)
    for name, peer in result.peers.items():
        local, fused = peer.mean_ospa("local"), peer.mean_ospa("fused")
        assert fused < 0.7 * local, (name, local, fused)
        assert fused < 5.0  # metres, for docs/seed001.md's geometry A
        assert peer.consensus.stats.fused_inputs == scn.num_scans
    again = run_twin(scn, 0)
    assert again.peers["r1"].mean_ospa("fused") == result.peers["r1"].mean_ospa("fused")


def test_no_fusion_means_local_only():
    scn = load_scenario("seed001", overrides={"scenario.num_scans": 80, "fusion.rule": "none"})
    result = run_twin(scn, 1)
    for peer in result.peers.values():
        assert peer.consensus.stats.fused_inputs == 0 and peer.consensus.stats.estimates_out == 0


def test_ratio_rule_needs_single_target_peers():
    with pytest.raises(ScenarioError, match="ratio"):  # refused at load (sim/kinds rules)
        load_scenario("seed000", overrides={"fusion.rule": "ratio"})
    scn = dataclasses.replace(load_scenario("seed001"),
                              fusion=dataclasses.replace(load_scenario("seed001").fusion,
                                                         rule="aa"))
    with pytest.raises(ScenarioError, match="aa"):
        make_peer(scn, "r1")


@pytest.mark.network
def test_two_imm_pf_peers_with_latency_as_processes(tmp_path):
    # 5 scans/s (the scenario's 20 leaves a particle filter behind the world on a busy machine,
    # each peer by its own lag, and estimates a few scans apart are not fused); 60 scans: the
    # twin's fused/local OSPA is 0.27-0.44 over runs 0-2 with 60, 80 or 120 (the bound is 0.7;
    # run 0 at 60: 0.33 and 0.35), and 60 is 4 s less than 80 at 5 scans/s
    sets = ["scenario.num_scans=60", "network.speed=5",
            'faults.default.delay={kind="uniform", low=0.0, high=0.02}']
    scn = load_scenario("seed001", overrides=parse_overrides(sets))
    handle = start_run(scn, "seed001", tmp_path, overrides=sets)
    try:
        codes = wait_run(handle, timeout=scn.num_scans / 5 + 120)
    finally:
        handle.stop_all()
    assert all(c == 0 for c in codes.values()), codes
    summaries = read_summaries(tmp_path, scn.sensor_names)
    for name, s in summaries.items():
        assert s["scans"] == scn.num_scans
        assert s["stats"]["fused_inputs"] >= 0.95 * scn.num_scans, (name, s["stats"])
        assert s["mean_ospa_fused"] < 0.7 * s["mean_ospa_local"], (name, s)
        assert s["injected_faults"]["reorder"] + s["injected_faults"]["deliver"] > 0
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    text = subprocess.run([exe, "rrd", "print", str(tmp_path / "rerun" / "view.rrd")],
                          capture_output=True, text=True, timeout=120,
                          env={**os.environ, "RERUN_ANALYTICS": "0"}).stdout
    for entity in ("/peers/r1/particles", "/metrics/model_probability/r1/CA",
                   "/metrics/ospa/r1/fused", "/peers/r1/fused/means"):
        assert entity in text, entity
