"""Consensus rounds a scan on the labelled study's 20 peers (issue 33, docs/labelled-tracking.md
"More consensus rounds at 20 peers"): ``--rounds20 L`` / ``circulant:N:D:L`` reach the
scenario's ``network.rounds``, change the fused twin only (local peers and the centralised
reference do not consensus), and ``pool_check``'s ``network.rounds`` variant reaches its twin."""

from __future__ import annotations

import csv

import pytest
from sensornet.sim.studies.labelled import study
from sensornet.sim.studies.labelled.pool_check import _fused
from sensornet.sim.studies.labelled.study import RULES, circ20, one_run, scenario_of


def test_rounds20_reaches_the_20_peer_scenario(capsys):
    g = circ20(3)
    assert (g.name, g.scenario, g.runs) == ("circ4-20", "circulant:20:4", 3)  # the default
    assert scenario_of(g, "lmb", 0.9, 10.0, 5).network.rounds == 1
    g3 = circ20(1, 3)
    assert g3.name == "circ4-20 L=3"
    scn = scenario_of(g3, "lmb", 0.9, 10.0, 5)
    assert scn.network.rounds == 3 and len(scn.sensor_names) == 20 and scn.num_scans == 5
    assert study.main(["--rounds20", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--rounds20" in err


def test_more_rounds_change_the_fused_row_only():
    """L = 2 sends a second round (more tuples a peer-scan) and changes the fused tracks; the
    local and centralised rows are the same numbers as at L = 1."""
    one, two = (one_run(circ20(1, L), 0.99, 10.0, "lmb", 0, ("hybrid",), 6, False)
                for L in (1, 2))
    assert [r["estimate"] for r in two] == ["local", "fused", "centralised"]
    for a, b in ((one[0], two[0]), (one[2], two[2])):
        for m in ("ospa", "ospa2", "switches"):
            assert b[m] == pytest.approx(a[m], rel=1e-12, abs=1e-12)
    assert two[1]["tuples"] > 1.5 * one[1]["tuples"]
    assert abs(two[1]["ospa"] - one[1]["ospa"]) > 0.1  # 42.86 -> 41.69 m here
    assert two[1]["graph"] == "circ4-20 L=2" and one[1]["graph"] == "circ4-20"


def test_pool_check_rounds_variant_reaches_its_twin():
    base = _fused(("circ20", "lmb", 0.99, 6, dict(RULES["hybrid"]), 0))
    two = _fused(("circ20", "lmb", 0.99, 6, {**RULES["hybrid"], "network.rounds": 2}, 0))
    assert two["tuples"] > 1.5 * base["tuples"]
    assert base["cpu_ms"] > 0 and two["cpu_ms"] > 0


def test_the_study_command_runs_the_rounds(tmp_path):
    out = tmp_path / "rows.csv"
    assert study.main(["--runs3", "0", "--runs20", "1", "--rounds20", "2", "--scans", "4",
                       "--kinds", "lmb", "--rules", "hybrid", "--no-tgospa",
                       "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert {r["graph"] for r in rows} == {"circ4-20 L=2"}
    assert [r["estimate"] for r in rows] == ["local", "fused", "centralised"] * 2  # 2 Pds
