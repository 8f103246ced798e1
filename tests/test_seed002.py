"""Seed 002: the scenario file, extended returns in the world, ET-GM-PHD peers' parts."""

import numpy as np
import pytest
from sensornet.peers.extended import EtGmphdEstimator
from sensornet.peers.fusers import GciFuser, HybridFuser
from sensornet.sim.run.peers import consensus_options, make_parts
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.sim.world import generate_run, labelled_sensor_scans, sensor_rng
from sensornet.sim.world.extended import make_et_filter, with_partition
from sensornet.tracking.metrics import ospa
from sensornet.tracking.partition import DistancePartitioner, GridSpectralPartitioner


def test_scenario_loads_with_extended_table():
    scn = load_scenario("seed002")
    assert scn.network.filter == "et-gmphd" and scn.extended.partition == "distance"
    assert scn.sensor("s1").position == (1000.0, 0.0) and len(scn.sensors) == 3
    assert len(scn.targets) == 4
    gs = load_scenario("seed002", {"extended.partition": "grid-spectral"})
    assert isinstance(make_et_filter(gs, "s1").partitioner, GridSpectralPartitioner)
    assert isinstance(make_et_filter(scn, "s1").partitioner, DistancePartitioner)


@pytest.mark.parametrize("key,value,msg", [
    ("extended.partition", "kmeans", "extended.partition"),
    ("extended.rho", 1.0, "extended.rho"),
    ("extended.p_lower", 0.9, "extended.p_upper"),
    ("extended.rate", 0, "extended.rate"),
    ("extended.units", "km", "extended.units"),
    ("extended.k_spread", -1, "extended.k_spread"),
    ("extended.core_level", 1.5, "extended.core_level"),
])
def test_bad_partition_parameters_are_one_line_errors(key, value, msg):
    with pytest.raises(ScenarioError, match=msg) as err:
        load_scenario("seed002", {key: value})
    assert "\n" not in str(err.value)


def test_et_filter_without_extended_table_is_refused():
    with pytest.raises(ScenarioError, match="needs an \\[extended\\] table"):
        load_scenario("seed000", {"network.filter": "et-gmphd"})
    rb = load_scenario("seed002", {"sensors.s1.kind": "range-bearing",
                                   "sensors.s1.sigma_theta_deg": 1.0})
    with pytest.raises(ScenarioError, match="linear"):
        make_et_filter(rb, "s1")


def test_world_draws_poisson_returns_per_detected_target():
    scn = load_scenario("seed002", {"sensors.*.clutter_rate": 0})
    truth, _ = generate_run(scn, 0)
    scans, origins = labelled_sensor_scans(scn, scn.sensor("s1"), truth,
                                           sensor_rng(scn, 0, "s1"))
    per_target = np.concatenate([np.bincount(o, minlength=5)[ids]
                                 for o, ids in zip(origins, truth.ids, strict=True)])
    assert per_target.mean() == pytest.approx(10 * 0.99, rel=0.05)
    # detected with Pd then Poisson(10): variance Pd (10 + 100) - (10 Pd)^2 = 10.89
    assert per_target.var() == pytest.approx(0.99 * 110 - 9.9**2, rel=0.3)
    assert all(len(z) == len(o) for z, o in zip(scans, origins, strict=True))
    # point-target scenarios keep their draws: seed000's scans have one return per target
    s0 = load_scenario("seed000", {"sensors.*.clutter_rate": 0})
    t0, sc0 = generate_run(s0, 0)
    assert all(len(z) <= len(x) for z, x in zip(sc0[0], t0.states, strict=True))


def test_make_parts_builds_et_peers_fused_by_the_mixture_fusers():
    scn = load_scenario("seed002")
    est, fuser = make_parts(scn, "s2")
    assert isinstance(est, EtGmphdEstimator) and isinstance(fuser, HybridFuser)
    _, fuser = make_parts(load_scenario("seed002", {"fusion.rule": "gci"}), "s2")
    assert isinstance(fuser, GciFuser)
    opts = consensus_options(scn, "s2")
    assert opts.policy == "nale" and set(opts.neighbours) == {"s1", "s3"}


@pytest.mark.parametrize("partition", ["distance", "grid-spectral"])
def test_et_filter_tracks_the_seed002_targets(partition):
    scn = with_partition(load_scenario("seed002"), partition)
    truth, scans = generate_run(scn, 1)
    filt = make_et_filter(scn, "s1")
    mix, errs = filt.initial(), []
    for k in range(1, 61):
        mix = filt.step(mix, scans[0][k - 1])
        errs.append(ospa(truth.positions(k), filt.extract(mix)[:, [0, 2]], 200.0, 2.0))
    assert np.mean(errs) < 60.0


def test_experiment_smoke_and_table(tmp_path, capsys):
    from sensornet.sim.studies.seed002 import montecarlo as seed002

    base = load_scenario("seed002", {"scenario.num_scans": 15})
    res = seed002.run_experiment(1, clutters=(10,), first_run=3, progress=False, base=base)
    assert [r.partition for r in res] == ["distance", "grid-spectral"]
    for r in res:
        assert r.clutter == 10 and r.partition_ms > 0 and r.step_ms >= r.partition_ms
        assert 0.0 < r.ari <= 1.0 and r.partitions_per_scan >= 1
    rows = seed002.summarise(res)
    table = seed002.format_table(rows)
    assert "grid-spectral" in table and "40.8" in table  # the paper's distance time at 10
    assert seed002.truth_labels(np.array([2, 0, 2, 0])).tolist() == [2, -1, 2, -2]
    seed002.write_png(rows, str(tmp_path / "fig.png"))
    assert (tmp_path / "fig.png").stat().st_size > 10_000


def test_experiment_cli_refuses_bad_flags(capsys):
    from sensornet.sim.studies.seed002 import montecarlo as seed002

    assert seed002.main(["--runs", "0"]) == 2
    assert "--runs" in capsys.readouterr().err


def test_rerun_view_colours_cells_and_greys_one_point_cells():
    """The peer sends its scan's cells in its telemetry (it logs nothing to Rerun); the view
    colours them by cell, one-point cells grey, with the extents of the cells of 3+ points."""
    import rerun as rr
    from sensornet.peers.core import Record
    from sensornet.peers.observer import Observer
    from sensornet.peers.rerun_layout import cell_marks
    from sensornet.protocol.bundle import unpack_bundle
    from sensornet.protocol.codec import decode
    from sensornet.sim.run.peers import make_peer

    from sensornet.view import Batcher, ViewState

    scn = load_scenario("seed002", {"extended.partition": "grid-spectral"})
    core = make_peer(scn, "s1")
    truth, scans = generate_run(scn, 0)
    est = core.consensus.estimator
    assert est.partition_view() is None
    for k in range(1, 4):
        est.step(1, scans[0][k - 1])
    z, labels = est.partition_view()
    assert len(z) == len(labels) == len(scans[0][2])
    colors, extents, extent_colors = cell_marks(z, labels)
    single = np.bincount(labels)[labels] == 1
    assert single.any() and (colors[single] == 128).all() and not (colors[~single] == 128).all()
    assert len(extents) == len(extent_colors) == (np.bincount(labels) >= 3).sum() >= 1
    sent = []
    obs = Observer(core, 1.0).attach(sent.append)
    obs.record(Record("local", 3, {"n_components": 1}))
    obs.flush(idle=True, force=True)
    ((_, report),) = unpack_bundle(sent[0]).entries  # one put: a bundle of the report
    msg = decode(report)
    # the view's points travel as float32 (telemetry protocol 2: for the eye), so equal to
    # the partition's plots as float32 numbers
    np.testing.assert_array_equal(msg.points["cells"], z.astype(np.float32))
    calls = []

    class Rec:
        def send_columns(self, path, indexes, columns):
            calls.append((path, list(columns)))

    view = ViewState(Batcher(rr, Rec()), ["s1"])
    view.message(msg)
    view.b.flush()
    drawn = dict(calls)
    assert {"peers/s1/cells/points", "peers/s1/cells/extents"} <= set(drawn)
    strips = drawn["peers/s1/cells/extents"][0].as_arrow_array().to_pylist()[0]
    assert len(strips) == len(extents)


def test_sensornet_experiment_seed002_runs_the_partitioner_comparison(capsys):
    from sensornet.cli import main

    assert main(["experiment", "seed002", "--runs", "1", "--quiet",
                 "--set", "scenario.num_scans=5"]) == 0
    out = capsys.readouterr().out
    assert "grid-spectral" in out and "paper ms" in out
