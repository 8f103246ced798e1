"""The iterated-corrector PHD as a flooding peer (seed 004, docs/seed004.md): the estimator
against the offline IC of sim/studies/seed004/montecarlo.py, skipped scans, the twin, and 5 real
processes."""

from __future__ import annotations

import numpy as np
import pytest
import sensornet.sim.studies.seed004.montecarlo as seed004
from scipy.sparse.csgraph import depth_first_order
from sensornet.peers.contracts import FusionInput
from sensornet.peers.flooding import IcFloodEstimator, IcFloodFuser, corrector_order
from sensornet.protocol.messages import ScanSet
from sensornet.sim.run.peers import make_parts
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.sim.world import generate_run
from sensornet.sim.world.build import adjacency, make_filter
from sensornet.tracking.gmphd import GMPHDFilter
from sensornet.tracking.models import ConstantVelocity

from tests.test_flooding_peers import LINE, SCANS, run_line_processes

IC = {"flooding.estimator": "ic"}


def _line(**more):
    return load_scenario("seed004", {**LINE, "scenario.num_scans": SCANS, **IC, **more})


def _offline(variant: str = "linear"):
    """The offline study's pieces (sim/studies/seed004/montecarlo.py run_once): scenario, models,
    sensors, the IC
    order, the predictor, and the scans of run 0 scan by scan."""
    off = seed004.load(overrides=[f"scenario.variant='{variant}'"])
    models = off.models()
    sensors = [off.sensor_params(m) for m in models]
    order = corrector_order(off.adjacency)
    pred = GMPHDFilter(ConstantVelocity(off.scan_period, off.sigma_w), [sensors[0]],
                       off.birth(), off.survival_probability, off.reducer())
    rng_truth, rng_scan, _ = np.random.default_rng([off.seed, 0]).spawn(3)
    X = seed004.truth(off, rng_truth)
    scans = (seed004.measure(off, models, X[k], rng_scan) for k in range(off.num_scans))
    return off, sensors, order, pred, scans


def _flood_all(fuser, k: int, scans: dict[str, np.ndarray], own: str):
    """One scan's rounds at a peer whose neighbour forwards every other scan in round 1."""
    others = {o: z for o, z in scans.items() if o != own}
    out = None
    for r in range(fuser.rounds):
        nb = {"s_nb": {"posterior": ScanSet(others if r == 0 else {})}}
        out = fuser.fuse(FusionInput(k, r, ScanSet({own: scans[own]}), nb, [0.5, 0.5],
                                     scans[own]))
    return out


@pytest.mark.parametrize("variant", ["linear", "mixed"])
def test_ic_peer_on_a_complete_pool_is_the_offline_ic_number_for_number(variant):
    off, sensors, order, pred, scans = _offline(variant)
    scn = load_scenario("seed004", {**IC, "scenario.variant": variant})
    est, fuser = make_parts(scn, "s7")
    assert isinstance(est, IcFloodEstimator) and isinstance(fuser, IcFloodFuser)
    # the offline order: depth-first from sensor 0 over the same graph
    dfs = depth_first_order(off.adjacency, 0, directed=False, return_predecessors=False)
    assert est.order == tuple(f"s{i + 1}" for i in dfs) == tuple(f"s{i + 1}" for i in order)
    mix = pred.initial()
    seen = 0
    for k, z in zip(range(1, 16), scans, strict=False):
        mix = seed004.iterated_corrector(pred.predict(mix), z, sensors, order, off.reducer(),
                                         off.prune_threshold)[-1]
        est.step(1, z[6])
        pooled = {f"s{i + 1}": z[i] for i in reversed(range(len(z)))}  # any arrival order
        post = _flood_all(fuser, k, pooled, "s7")
        np.testing.assert_array_equal(post.weights, mix.weights)
        np.testing.assert_array_equal(post.means, mix.means)
        np.testing.assert_array_equal(post.covs, mix.covs)
        tracks = est.extract(post)
        np.testing.assert_array_equal(tracks[:, [0, 2]], seed004._positions(mix))
        seen += len(tracks)
    assert seen > 30  # three targets found on most of the 15 scans
    assert fuser.counts["ic_scans"] == 15 and fuser.counts["ic_skipped"] == 0
    assert fuser.counts["ic_corrections"] == 15 * 20 and fuser.counts["missing"] == 0


def test_a_scan_missing_from_the_pool_is_skipped_and_counted():
    off, sensors, order, pred, scans = _offline()
    est, fuser = make_parts(load_scenario("seed004", IC), "s1")
    lost = {4, 11}  # never arrive at s1 in scan 3
    mix = pred.initial()
    for k, z in zip(range(1, 6), scans, strict=False):
        gone = lost if k == 3 else set()
        mix = seed004.iterated_corrector(pred.predict(mix), z, sensors,
                                         [s for s in order if s not in gone], off.reducer(),
                                         off.prune_threshold)[-1]
        est.step(1, z[0])
        post = _flood_all(fuser, k, {f"s{i + 1}": z[i] for i in range(20) if i not in gone},
                          "s1")
        np.testing.assert_array_equal(post.means, mix.means)
        np.testing.assert_array_equal(post.weights, mix.weights)
    assert fuser.counts["ic_skipped"] == 2 == fuser.counts["missing"]
    assert fuser.counts["ic_corrections"] == 5 * 20 - 2 and fuser.counts["ic_scans"] == 5


def test_a_scan_without_its_last_round_is_corrected_with_the_own_scan_only():
    scn = _line()
    names, A = adjacency(scn)
    order = [names[i] for i in corrector_order(A)]
    filt = make_filter(scn, order)
    est = IcFloodEstimator("s2", filt, order)
    z1, z2 = np.array([[-100.0, -800.0]]), np.array([[-90.0, -770.0]])
    est.step(1, z1)
    local = est.extract(ScanSet({"s2": z1}))  # the local view keeps nothing
    assert est.counts["ic_scans"] == 0
    est.step(1, z2)  # scan 1 never closed here: own scan only
    assert est.counts["ic_own_only"] == 1 and est.counts["ic_skipped"] == len(order) - 1
    own = make_filter(scn, ["s2"])
    expected = own.correct(own.predict(own.initial()), [z1])
    np.testing.assert_array_equal(est.mix.means, expected.means)
    np.testing.assert_array_equal(local, own.extract(expected))
    with pytest.raises(ValueError, match="distinct sensors"):
        IcFloodEstimator("s2", filt, order[:-1])


def test_unknown_flooding_estimators_are_refused_in_one_line_naming_the_choices():
    with pytest.raises(ScenarioError) as exc:
        load_scenario("seed004", {"flooding.estimator": "pf"})
    msg = str(exc.value)
    assert "\n" not in msg and "flooding.estimator" in msg
    assert all(f"'{e}'" in msg for e in ("idpc", "ftc", "ic"))
    with pytest.raises(ScenarioError) as exc:  # a network scenario's own key
        load_scenario("seed000", {"network.filter": "flooding", "clustering.estimator": "pf"})
    assert "\n" not in str(exc.value) and "'ic'" in str(exc.value)
    with pytest.raises(seed004.ScenarioError, match="flooding.estimator"):
        seed004.load(overrides=["flooding.estimator='pf'"])
    assert load_scenario("seed004").clustering.estimator == "idpc"  # the default


# -- the twin ---------------------------------------------------------------------------------
def test_twin_ic_peers_all_give_the_offline_ic_of_the_world_scans():
    scn = _line()
    res = run_twin(scn, 0)
    names, A = adjacency(scn)
    order = corrector_order(A)
    filt = make_filter(scn, [names[i] for i in order])
    _, scans = generate_run(scn, 0)
    mix = filt.initial()
    for k in range(1, SCANS + 1):
        mix = filt.correct(filt.predict(mix), [scans[i][k - 1] for i in order])
        for n in names:
            np.testing.assert_array_equal(res.tracks[n][k], filt.extract(mix))
    for n in names:
        s = res.summary(n)
        assert s["stop_reason"] == "end of run" and s["internal_errors"] == {}, n
        f = s["fuser"]
        assert f["ic_scans"] == SCANS and f["ic_skipped"] == 0 and f["scans_complete"] == SCANS
        assert s["mean_ospa_fused"] < 30.0, n


def test_twin_ic_under_link_loss_skips_what_flooding_missed():
    scn = _line(**{"scenario.num_scans": 20, "faults.default.loss": 0.3})
    res = run_twin(scn, 0)
    for n in scn.sensor_names:
        s = res.summary(n)
        assert s["internal_errors"] == {}, n
        f = s["fuser"]
        assert f["ic_scans"] == f["scans_closed"] == 20
        assert f["ic_skipped"] == f["missing"]
        assert f["ic_corrections"] + f["ic_skipped"] == 20 * 5
    assert sum(res.summary(n)["fuser"]["ic_skipped"] for n in scn.sensor_names) > 0


def test_twin_ftc_peers_agree(monkeypatch):
    monkeypatch.setenv("LOKY_MAX_CPU_COUNT", "1")  # k-means: no lscpu subprocess for the cores
    scn = _line(**{"flooding.estimator": "ftc", "scenario.num_scans": 4})
    assert make_parts(scn, "s1")[0].method == "ftc"
    res = run_twin(scn, 0)
    for k in range(1, 5):
        for n in scn.sensor_names[1:]:
            np.testing.assert_array_equal(res.tracks[n][k], res.tracks["s1"][k])
    assert all(res.summary(n)["internal_errors"] == {} for n in scn.sensor_names)


# -- real processes ---------------------------------------------------------------------------
@pytest.mark.network
def test_five_ic_flooding_processes_over_zenoh_equal_the_twin(tmp_path):
    scn, summaries, twin = run_line_processes(tmp_path, **IC)
    for n, s in summaries.items():
        t = twin.summary(n)
        assert s["stop_reason"] == "end of run" and s["scans"] == SCANS, n
        assert s["internal_errors"] == {} and s["rejected_total"] == 0, n
        assert s["fuser"]["ic_scans"] == SCANS and s["fuser"]["ic_skipped"] == 0, n
        for c in ("ic_scans", "ic_corrections", "ic_skipped", "scans_complete", "missing"):
            assert s["fuser"][c] == t["fuser"][c], (n, c)
        assert s["estimate_bytes_sent"] == t["estimate_bytes_sent"], n
        assert s["mean_ospa_fused"] == pytest.approx(twin.mean_ospa(n, "fused"), rel=1e-9), n
