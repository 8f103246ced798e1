"""A member lying about its own estimate (sim.studies.lying.study, docs/security.md "What is not
protected").

Seed 000 on the twin, 30 scans, runs 8000-8001 (neither the measurement's runs 7000.. nor the
runs its thresholds were read from). s2 lies; s1 and s3 are honest. The margins below were read
off runs 9003-9006 (30 scans): GCI empty/shifted 200/197 m against 30 m clean, GCI
inflated/phantoms +0.9 m, AA inflated/phantoms +79/+118 m, AA empty/shifted 57/37 m.
"""

import numpy as np
import pytest
from sensornet.sim.studies.lying.study import (
    LIES,
    SETUPS,
    LyingCore,
    honest_scores,
    make_lie,
    run_with_liar,
    scenario_for,
)
from sensornet.tracking.mixture import GaussianMixture

RUNS = (8000, 8001)
SCANS = 30
HONEST = ("s1", "s3")


SHARED = pytest.mark.xdist_group("lying_member_results")
"""The tests of ``results`` on one xdist worker, so its 32 twin runs are made once, not once
on each worker (``tests/conftest.py`` puts the group in the node id)."""


@pytest.fixture(scope="module")
def results():
    out = {}
    for rule in ("gci", "aa"):
        scn = scenario_for(SETUPS[0], rule, SCANS)
        for lie in ("clean", *LIES):
            out[rule, lie] = [run_with_liar(scn, r, "s2", None if lie == "clean" else lie)
                              for r in RUNS]
    return out


def fused(results, rule, lie):
    return float(np.mean([honest_scores(r, "s2")["fused"] for r in results[rule, lie]]))


@SHARED
def test_lies_are_well_formed_and_accepted(results):
    for (rule, lie), runs in results.items():
        for res in runs:
            liar = res.peers["s2"]
            assert isinstance(liar, LyingCore) == (lie != "clean")
            if lie != "clean":
                assert liar.lies_told >= SCANS
            for n in HONEST:
                assert not res.peers[n].rejected, (rule, lie, n, res.peers[n].rejected)
                assert res.peers[n].consensus.stats.last_fused_from.get("s2") == SCANS


@SHARED
def test_local_filtering_is_untouched(results):
    for (rule, lie), runs in results.items():
        for res, clean in zip(runs, results[rule, "clean"], strict=True):
            for n in HONEST:
                assert res.ospa[n]["local"] == clean.ospa[n]["local"], (rule, lie, n)


@SHARED
def test_every_lie_hurts_under_some_rule(results):
    for lie in ("empty", "shifted", "inflated", "phantoms"):  # a 30 m bias costs less
        worst = max(fused(results, rule, lie) - fused(results, rule, "clean")
                    for rule in ("gci", "aa"))
        assert worst > 10.0, lie


@SHARED
def test_gci_is_vetoed_by_nothing_and_by_a_confident_wrong_estimate(results):
    cutoff = scenario_for(SETUPS[0], "gci", SCANS).metrics.ospa_cutoff
    assert fused(results, "gci", "clean") < 60.0
    assert fused(results, "gci", "empty") > 0.95 * cutoff
    assert fused(results, "gci", "shifted") > 0.9 * cutoff
    for lie in ("empty", "shifted"):  # AA keeps the honest peers' own components
        assert fused(results, "aa", lie) < 0.5 * cutoff


@SHARED
def test_gci_limits_phantom_mass_that_aa_takes_in(results):
    for lie in ("inflated", "phantoms"):
        assert abs(fused(results, "gci", lie) - fused(results, "gci", "clean")) < 5.0, lie
        assert fused(results, "aa", lie) > fused(results, "aa", "clean") + 30.0, lie


def test_the_lies():
    scn = scenario_for(SETUPS[0], "gci", SCANS)
    mix = GaussianMixture(np.array([0.9, 0.6]), np.array([[0.0, 1.0, 50.0, 0.0],
                                                          [300.0, 0.0, -20.0, 2.0]]),
                          np.stack([np.diag([100.0, 25.0, 100.0, 25.0])] * 2))
    assert len(make_lie("empty", scn)(mix)) == 0
    s = make_lie("shifted", scn)(mix)
    assert np.allclose(s.means[:, 0], mix.means[:, 0] + 110.0)
    assert np.allclose(s.means[:, 1:], mix.means[:, 1:])
    assert np.allclose(s.covs, np.eye(4)) and np.allclose(s.weights, mix.weights)
    assert np.isclose(make_lie("inflated", scn)(mix).mass, 5 * mix.mass)
    p = make_lie("phantoms", scn)(mix)
    assert len(p) == len(mix) + 3 and np.isclose(p.mass, mix.mass + 3)
    assert np.allclose(p.means[2:][:, [0, 2]], [[-800, 800], [800, 800], [-800, -800]])
    with pytest.raises(ValueError):
        make_lie("bigger", scn)


def test_the_scenario_hook_makes_the_same_liar_as_the_study():
    """``fusion.lie = "s2:shifted"`` (what a real peer process gets with --set) builds the
    study's liar: the same honest peers' fused OSPA, scan for scan."""
    from sensornet.sim.run.twin import run_twin
    from sensornet.sim.scenario import load_scenario

    hooked = load_scenario("seed000", overrides={"scenario.num_scans": 20,
                                                 "fusion.lie": "s2:shifted"})
    res = run_twin(hooked, 8000)
    assert isinstance(res.peers["s2"], LyingCore) and res.peers["s2"].lies_told > 0
    assert not isinstance(res.peers["s1"], LyingCore)
    plain = load_scenario("seed000", overrides={"scenario.num_scans": 20})
    study = run_with_liar(plain, 8000, "s2", "shifted")
    for n in HONEST:
        assert res.peers[n].mean_ospa("fused") == study.peers[n].mean_ospa("fused")
    assert res.peers["s1"].mean_ospa("fused") != run_twin(plain, 8000).peers["s1"].mean_ospa(
        "fused")


def test_absent_takes_the_liars_sensors_and_edges_out():
    from sensornet.sim.scenario import load_scenario
    from sensornet.sim.studies.lying.study import without

    scn = without(scenario_for(SETUPS[0], "hybrid"), "s2")
    assert list(scn.sensor_names) == ["s1", "s3"]
    assert scn.fusion.fusing_sensor == "s1"  # s2 was the fusing sensor
    custom = load_scenario("seed004")
    two = without(custom, "s15,s19")
    assert all({"s15", "s19"}.isdisjoint(e) for e in two.network.edges)
    assert len(two.network.edges) < len(custom.network.edges)
    assert len(two.sensors) == len(custom.sensors) - 2


def test_the_circulant_setup_is_the_calibrations_graph_and_not_in_the_default_study():
    from sensornet.sim.studies.base import Request
    from sensornet.sim.studies.lying.study import CIRCULANT, plan_of
    from sensornet.sim.world.graphs import circulant

    scn = scenario_for(CIRCULANT, "hybrid+repair")
    assert len(scn.sensor_names) == 20 and scn.network.rounds == 2
    assert scn.fusion.trust and scn.fusion.trust_repair and scn.fusion.trust_register
    deg = {n: sum(n in e for e in scn.network.edges) for n in scn.sensor_names}
    assert set(deg.values()) == {4} and int(circulant(20, 4).sum()) == 2 * len(scn.network.edges)
    assert CIRCULANT.liar in scn.sensor_names
    default = plan_of(Request("lying", runs=1, options={}))[0]
    assert CIRCULANT not in default.setups
    chosen = plan_of(Request("lying", runs=1, options={"setups": ["circ4-20"]}))[0]
    assert chosen.setups == (CIRCULANT,)


def test_central_is_the_offline_centralised_filter_over_the_honest_sensors():
    """The *central* cell is sim.studies.seed000.montecarlo's iterated-corrector GM-PHD over the
    honest
    sensors' scans of the same run (not the twin): the same number computed directly."""
    from sensornet.sim.studies.lying.study import CENTRAL, lie_once, without
    from sensornet.sim.studies.seed000.montecarlo import run_once

    scn = scenario_for(SETUPS[0], "hybrid+trust", 12)
    row = lie_once(scn, 8000, SETUPS[0], "hybrid+trust", CENTRAL)
    two = without(scn, "s2")
    direct = run_once(two, 8000)
    assert row["fused"] == pytest.approx(float(np.mean(direct.ospa["centralized"])))
    assert row["local"] == pytest.approx(float(np.mean(
        [np.mean(direct.ospa[f"local {s}"]) for s in HONEST])))
    assert np.isnan(row["caught_scans"]) and np.isnan(row["honest_quarantined"])


def test_an_empty_liar_is_caught_by_the_hold_and_honest_holds_are_counted():
    """With the defence on, the empty liar is at weight 0 within 3 scans of its first test
    (the withheld-target hold), and the study reports it and the honest neighbours' held
    share, which is what their records hold."""
    scn = scenario_for(SETUPS[0], "hybrid+trust", SCANS)
    res = run_with_liar(scn, 8000, "s2", "empty")
    sc = honest_scores(res, "s2")
    assert sc["caught_scans"] <= 3 and sc["detect_scans"] <= 3
    recs = [res.peers[n].consensus.trust.n for n in HONEST]
    assert all(r["s2"].holds > 0 for r in recs)
    honest = [r[s] for r, s in zip(recs, ("s3", "s1"), strict=True)]
    assert sc["honest_held"] == pytest.approx(
        sum(h.holds for h in honest) / sum(h.rounds for h in honest))
    from sensornet.sim.run.launcher import trust_note

    note = trust_note({n: res.summary(n) for n in HONEST})
    assert "held (withholding targets): s2 by s1 (" in note and ", s3 (" in note
