"""Link faults from the scenario file in the twin, and the fault-parameter sweep."""

from __future__ import annotations

import csv

import pytest
from sensornet.sim.campaign.sweep import summarise, sweep, write_outputs
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.sim.world.build import fault_injector

BASE = {"birth.model": "truth", "scenario.num_scans": 30}


def test_faults_table_is_validated_on_load():
    with pytest.raises(ScenarioError, match="faults.default.loss"):
        load_scenario("seed000", overrides={"faults.default.loss": 1.5})
    with pytest.raises(ScenarioError, match="faults.default.lost"):
        load_scenario("seed000", overrides={"faults.default.lost": 0.1})
    assert fault_injector(load_scenario("seed000")) is None


def test_loss_in_the_scenario_reaches_the_twin():
    scn = load_scenario("seed000", overrides={**BASE, "faults.default.loss": 1.0})
    result = run_twin(scn, 0)
    counts = result.faults.counts()
    # 3 peers x 2 listeners x 30 scans, every one lost: nobody fuses a neighbour
    assert counts["drop-loss"] == 180
    for peer in result.peers.values():
        assert peer.consensus.stats.fused_inputs == 0
        assert peer.consensus.stats.estimates_in == 0


def test_duplicates_are_counted_redundant_by_nale():
    scn = load_scenario("seed000", overrides={**BASE, "faults.default.duplicate": 1.0})
    result = run_twin(scn, 1)
    assert result.faults.counts()["duplicate"] == 180
    for peer in result.peers.values():
        # two copies from each of 2 neighbours
        assert peer.consensus.stats.estimates_in == 2 * 2 * 30
        assert peer.consensus.nale.counts.redundant == 2 * 30


def test_same_seed_same_faults_and_same_result():
    scn = load_scenario("seed000", overrides={
        **BASE, "faults.default.delay": {"kind": "scans", "low": 0, "high": 2},
        "faults.default.reorder": 0.5, "faults.default.loss": 0.2})
    a, b = run_twin(scn, 3), run_twin(scn, 3)
    assert [r.action for r in a.faults.log] == [r.action for r in b.faults.log]
    assert a.peers["s1"].mean_ospa("fused") == b.peers["s1"].mean_ospa("fused")
    c = run_twin(scn, 4)
    assert [r.delays for r in a.faults.log] != [r.delays for r in c.faults.log]


def test_twin_decisions_do_not_depend_on_timing():
    """Two rounds, and a deadline that moves when round-1 estimates leave (and in what order):
    each message still gets the same decision, keyed by its link, scan, round and kind."""
    over = {**BASE, "network.rounds": 2, "faults.default.loss": 0.2,
            "faults.default.duplicate": 0.2, "faults.peers.s3.partitions": [[1.0, 1.5]],
            "faults.default.delay": {"kind": "uniform", "low": 0.0, "high": 0.08}}
    logs = [run_twin(load_scenario("seed000", {**over, "network.deadline": d}), 2).faults.log
            for d in (0.9, 0.3)]
    keyed = [{(r.sender, r.receiver, r.msg_id): (r.t, r.action, r.delays, r.reordered)
              for r in log} for log in logs]
    assert len(keyed[0]) == len(logs[0]) and len(keyed[1]) == len(logs[1])  # one each
    assert keyed[0] == keyed[1]
    assert any(":r1" in msg for _, _, msg in keyed[0])
    orders = [[(r.sender, r.receiver, r.msg_id) for r in log] for log in logs]
    assert orders[0] != orders[1]  # the messages did leave in another order


def test_sweep_writes_rows_csv_and_plot(tmp_path):
    base = {**BASE, "faults.default.delay": {"kind": "scans", "low": 0, "high": 0}}
    rows = sweep("seed000", "faults.default.delay.high", [0, 2], ["nale", "as-is"], runs=2,
                 base=base, jobs=1, progress=False)
    assert [(r["value"], r["policy"], r["run"]) for r in rows] == [
        (v, p, r) for v in (0, 2) for p in ("nale", "as-is") for r in (0, 1)]
    summary = summarise(rows)
    assert len(summary) == 4 and all(s["runs"] == 2 for s in summary)
    # zero delay: nothing is late; two scans of delay: late estimates for both policies
    late = {(s["value"], s["policy"]): s["late"] for s in summary}
    assert late[(0, "nale")] == 0 and late[(2, "nale")] > 0 and late[(2, "as-is")] > 0
    paths = write_outputs(rows, "faults.default.delay.high", tmp_path)
    with paths[0].open() as fh:
        assert len(list(csv.DictReader(fh))) == 8
    assert paths[1].stat().st_size > 10_000


def test_sweep_rejects_a_bad_value_before_running():
    with pytest.raises(ScenarioError):
        sweep("seed000", "faults.default.loss", [0.1, 2.0], ["nale"], runs=1, base=BASE,
              progress=False)
