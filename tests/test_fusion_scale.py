"""Consensus fusion on the 20-peer circulant network of degree 4 (the scale benchmarks' graph),
run on the twin (run 0, 50 scans): the default must beat every peer's own filter, and more
rounds must not make it worse. With the old default (GCI, level-2 pruning) these failed: L = 2
gave 62 m fused against 34 m local, and L = 4 without pruning at Pd 0.9 gave 110 m vs 60 m.

50 scans, not the scenario's 100: they hold seed 000's births at scans 20 and 40 (four targets
from 40), and every asserted quantity keeps a wide margin (run 0, 100 -> 50 scans): L = 2 worst
peer fused/local 0.29 -> 0.31 (bound 1), mean fused / half the mean local 0.43 -> 0.40 (bound
1); fused L = 1, 2, 4: 8.29, 7.15, 5.40 -> 9.21, 7.18, 5.56 m; undefended L = 4 without pruning
at Pd 0.9: 0.21 -> 0.33 and 0.30 -> 0.31; plain GCI fused - local +13.6 -> +14.6 m. Runs 1 and
2 at 50 scans keep them as wide (worst peer 0.33, 0.38; rounds' gaps 1.7 m or more; GCI +26,
+17 m). The twin is causal: a 50-scan run is the 100-scan run's first 50 scans, to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.fusion.advice import fusion_warnings
from sensornet.sim.world.graphs import network_scenario

from sensornet.cli import main

SCANS = 50


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("graphs") / "circulant20d4.toml"
    path.write_text(network_scenario(20, 4, scans=SCANS))
    return str(path)


def _ospa(source: str, sets: dict) -> tuple[np.ndarray, np.ndarray]:
    """Every peer's mean local and fused OSPA ``(20,)``, ``(20,)`` of twin run 0."""
    scn = load_scenario(source, overrides=sets)
    res = run_twin(scn, 0)
    names = scn.sensor_names
    return (np.array([res.mean_ospa(n, "local") for n in names]),
            np.array([res.mean_ospa(n, "fused") for n in names]))


@pytest.fixture(scope="module")
def default_runs(source) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    return {L: _ospa(source, {"network.rounds": L}) for L in (1, 2, 4)}


def test_the_default_rule_is_the_hybrid(source):
    scn = load_scenario(source)
    assert scn.fusion.rule == "hybrid" and scn.fusion.level2_pruning and scn.fusion.trust
    assert scn.num_scans == SCANS
    assert fusion_warnings(scn) == []


HEAVY = pytest.mark.timeout(900)
"""Twin runs of 20 peers x 50 scans at up to 4 rounds with the defence on (the default): the
fixture's three runs cost about 21 CPU s (L = 1, 2, 4: 4, 6, 10 s), minutes of wall time when
the shared 2-core machine runs at load 15-20 (the suite's 300 s was once passed there)."""


SHARED = pytest.mark.xdist_group("fusion_scale_default_runs")
"""The tests of ``default_runs`` on one xdist worker, so its runs are made once, not once on
each worker (``tests/conftest.py`` puts the group in the node id)."""


@HEAVY
@SHARED
def test_default_fusion_beats_every_peer_at_two_rounds(default_runs):
    local, fused = default_runs[2]
    assert np.all(fused < local), (fused, local)
    assert fused.mean() <= 0.5 * local.mean()


@HEAVY
@SHARED
def test_more_rounds_do_not_make_the_default_worse(default_runs):
    f1, f2, f4 = (default_runs[L][1].mean() for L in (1, 2, 4))
    assert f2 <= f1 and f4 <= f2, (f1, f2, f4)


@HEAVY
def test_four_rounds_at_pd_0_9_without_pruning_beat_local(source):
    """The subject is the hybrid rule's consensus without level-2 pruning (not the default, and
    not the defence): the undefended network, so ``fusion.trust = false`` pinned. With the
    defence on the run cost 2.5x the CPU (67 s against 27 s over 100 scans: its test of every
    neighbour's unpruned mixture at every round) for the same verdict (worst peer 0.25)."""
    local, fused = _ospa(source, {"network.rounds": 4, "fusion.level2_pruning": False,
                                  "sensors.*.detection_probability": 0.9,
                                  "fusion.trust": False})
    assert np.all(fused < local), (fused, local)
    assert fused.mean() <= 0.5 * local.mean()


def test_plain_gci_is_still_there_and_warned_about(source):
    scn = load_scenario(source, overrides={"fusion.rule": "gci", "network.rounds": 2})
    warnings = fusion_warnings(scn)
    assert len(warnings) == 1 and "'gci' with 20 peers and 2 round(s)" in warnings[0]
    emd = load_scenario(source, overrides={"fusion.rule": "gci", "fusion.cardinality": "emd"})
    assert len(fusion_warnings(emd)) == 2
    # with the defence on, as a user who sets fusion.rule = "gci" gets it (off it is worse still)
    local, fused = _ospa(source, {"fusion.rule": "gci", "network.rounds": 2})
    assert fused.mean() > local.mean()  # what the warning says: measured worse than local


def test_run_and_experiment_say_so_in_one_line_at_start(capsys, tmp_path):
    sets = ["--set", "fusion.rule=gci", "--set", "fusion.cardinality=emd",
            "--set", "scenario.num_scans=5"]
    assert main(["run", "seed000", "--sim", *sets]) == 0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("warning: ")]
    assert len(lines) == 1 and "'emd' under-counts" in lines[0]
    assert main(["experiment", "seed000", "--runs", "1", "--jobs", "1", "--quiet",
                 "--out", str(tmp_path / "exp"), *sets]) == 0
    assert "'emd' under-counts" in capsys.readouterr().err
    assert main(["run", "seed000", "--sim", "--set", "scenario.num_scans=5"]) == 0
    assert "warning:" not in capsys.readouterr().err  # the default: nothing to say
