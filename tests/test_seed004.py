"""Seed-004 scenario and offline Monte Carlo (sim/studies/seed004/montecarlo.py): geometry, tuple
counts, outputs."""

from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest
from sensornet.peers.flooding import flood
from sensornet.sim.studies.seed004 import montecarlo as seed004
from sensornet.tracking.mixture import GaussianMixture


@pytest.fixture(scope="module")
def scn():
    return seed004.load()


def test_scenario_is_the_seed(scn):
    assert len(scn.positions) == 20
    assert np.isfinite(scn.hops).all() and scn.hops.max() == 4  # connected, diameter 4
    assert scn.iterations == 4 and scn.sigma == 10.0 and scn.ospa_cutoff == 100.0
    assert scn.detection_probability == 0.95 and scn.survival_probability == 0.98
    b = scn.birth()
    np.testing.assert_allclose(b.weights, [0.05, 0.05, 0.05])
    np.testing.assert_allclose(b.means, [[-100, 10, -800, 30], [-800, 20, -500, 0],
                                         [0, 0, 950, -30]])
    np.testing.assert_allclose(b.covs[0], np.diag([100.0, 25.0, 100.0, 25.0]))


def test_offline_holdings_are_what_flooding_delivers(scn):
    # the experiment gives peer i the scans within t hops; the message-level flood agrees
    rng = np.random.default_rng(0)
    scans = [rng.normal(size=(3, 2)) for _ in range(20)]
    for t in range(1, 5):
        out = flood(scn.adjacency, scans, t)
        for i, held in enumerate(out.held):
            assert held == set(np.flatnonzero(scn.hops[i] <= t).tolist())


def test_tuple_counts_equal_the_closed_form(scn):
    # Pd = 1, no clutter: every scan is the 3 targets (6 tuples); in 4 iterations a peer sends
    # every scan within 3 hops (the last iteration's arrivals are not forwarded) to each neighbour
    known = replace(scn, num_scans=2, detection_probability=1.0, clutter_rate=0.0)
    out = seed004.run_once(known, 0, consensus=False)
    assert "GCI L=1" not in out and "AA L=1" not in out
    deg, hops = known.adjacency.sum(axis=1), known.hops
    flooding = np.mean(deg * (hops <= 3).sum(axis=1) * 3 * 2)
    assert out["IDPC"]["tuples"] == pytest.approx(flooding)
    assert out["IDPC t=1"]["tuples"] == pytest.approx(np.mean(deg * 3 * 2))
    centre = int(np.argmin(hops.max(axis=1)))
    assert out["centralised"]["tuples"] == pytest.approx(hops[:, centre].sum() * 3 * 2 / 20)
    assert out["local"]["tuples"] == 0.0
    # with no clutter and Pd = 1, flooding + IDPC finds the three targets at every scan
    assert out["IDPC"]["card_ok"] == 1.0 and out["IDPC"]["ospa"] < 6.0


def test_unknown_key_is_refused_in_one_line(tmp_path):
    bad = tmp_path / "s.toml"
    bad.write_text(seed004.SCENARIO.read_text().replace("[metrics]", "[metrics]\nospa_c = 1"))
    with pytest.raises(seed004.ScenarioError, match="metrics.ospa_c"):
        seed004.load(bad)
    assert seed004.main(["--scenario", str(bad), "--runs", "1"]) == 2


def test_main_writes_table_iterations_and_plot(tmp_path, capsys):
    rc = seed004.main(["--runs", "1", "--first-run", "900", "--set", "scenario.num_scans=3",
                       "--set", "consensus.rounds=[1]", "--out", str(tmp_path), "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "| IDPC |" in text and "| GCI L=1 |" in text and "| centralised |" in text
    assert "x the reference's exchange of 4-component mixtures over 4 rounds" in text
    rows = list(csv.DictReader((tmp_path / "seed004_table.csv").open()))
    assert [r["method"] for r in rows][:3] == ["IDPC", "FTC", "GCI L=1"]
    its = list(csv.DictReader((tmp_path / "seed004_iterations.csv").open()))
    assert [int(r["iterations"]) for r in its] == [1, 2, 3, 4]
    assert (tmp_path / "seed004_tradeoff.png").stat().st_size > 10_000
    back = seed004.read_outputs(tmp_path)
    assert back["IDPC"]["tuples"] == pytest.approx(float(rows[0]["tuples"]))
    assert "IDPC t=4" in back
    assert seed004.main(["--replot", "again", "--out", str(tmp_path)]) == 0


def test_gm_exchange_closed_form_and_the_reference_ratio(scn):
    """4 rounds of 4-component mixtures: deg (15*4 + 1) * 4 per peer, as a message-level count
    of the same exchange; flooding at the scenario's expected scan size is about 2x that (the
    reference: 4,100 against 2,000 tuples)."""
    A = scn.adjacency
    deg = A.sum(axis=1)
    mix = GaussianMixture(np.full(4, 0.5), np.zeros((4, 4)), np.tile(np.eye(4), (4, 1, 1)))
    sent = np.zeros(len(A))
    for _ in range(4):  # every round, every peer sends its mixture to each neighbour
        for i in np.nonzero(A)[0]:  # one entry per (peer, neighbour)
            sent[i] += seed004._n_tuples(mix)
    counted = sent.mean()
    assert seed004.gm_exchange_tuples(A, 4, 4) == pytest.approx(counted)
    assert counted == pytest.approx(deg.mean() * 61 * 4)
    # flooding at the expected scan size: clutter plus Pd per target in view, every scan
    # reaching every peer (diameter 4): deg_i * S * 2 * E|Z|
    ez = scn.clutter_rate + scn.detection_probability * 3
    flood = float(np.mean(deg * len(A) * 2 * ez))
    assert 1.8 <= flood / seed004.gm_exchange_tuples(A, 4, 4) <= 2.4


def test_flooding_through_the_fault_layer(scn):
    from sensornet.peers.faultplan import Constant, FaultPlan, LinkFaults

    clean = seed004.flooding_under_faults(scn, FaultPlan(interval=1.0), scans=2)
    assert clean["complete"] == 1.0 and clean["late"] == 0.0
    twice = seed004.flooding_under_faults(
        scn, FaultPlan(LinkFaults(duplicate=1.0), interval=1.0), scans=2)
    assert twice["complete"] == 1.0 and twice["duplicates"] > clean["duplicates"]
    lossy = FaultPlan(LinkFaults(loss=0.3), interval=1.0)
    a = seed004.flooding_under_faults(scn, lossy, scans=3)
    assert a == seed004.flooding_under_faults(scn, lossy, scans=3)  # keyed draws: repeatable
    assert a["complete"] < 1.0 and a["missing"] > 0
    # every copy takes longer than the deadline (0.5 s): each peer keeps only its own scan and
    # every forward of it arrives late
    slow = seed004.flooding_under_faults(
        scn, FaultPlan(LinkFaults(delay=Constant(0.6)), interval=1.0), scans=1)
    assert slow["missing"] == 19.0 and slow["late"] == pytest.approx(scn.adjacency.sum() / 20)


def test_sensornet_experiment_seed004(tmp_path):
    from sensornet.cli import main

    rc = main(["experiment", "seed004", "--runs", "1", "--set", "scenario.num_scans=2",
               "--set", "consensus.rounds=[1]", "--out", str(tmp_path), "--quiet"])
    assert rc == 0
    assert (tmp_path / "seed004_table.csv").exists()
