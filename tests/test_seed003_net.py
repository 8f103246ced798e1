"""Seed 003 peers over the peer core (sim/studies/seed003/network.py): the twin against the offline
filters,
the late-sensor fallback, the returns on the wire, and (network) real processes against the twin."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from sensornet.peers.contracts import FusionInput
from sensornet.peers.pda_parts import CiFuser, PdaEstimator
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.messages import Estimate, Returns
from sensornet.sim.studies.seed003 import montecarlo as seed003
from sensornet.sim.studies.seed003 import network as seed003_net
from sensornet.tracking.imm import POS
from sensornet.tracking.mixture import GaussianMixture

RUN = 1


def _tracks(res, peer: str) -> np.ndarray:
    t = res.tracks[peer]
    return np.array([t[k][0] for k in sorted(t)])


def _offline_sequential(cfg, run: int, n_sensors: int = 2) -> np.ndarray:
    X, sens, target, region, m0, P0 = seed003_net.draws(cfg, run)
    flt = seed003.make_filter(cfg, seed003_net.METHOD, m0, P0)
    est, _ = seed003.run_filter(cfg, flt, sens[:n_sensors], [p[:n_sensors] for p in target],
                                [r[:n_sensors] for r in region], None)
    return est


def test_measurement_sharing_twin_is_the_offline_sequential_filter():
    """Both peers' tracks equal the offline two-sensor sequential filter (the pre-gate lost no
    return the receivers' gates take) up to rounding: the filter's small matrix products may
    sum in another order when the scan holds other returns (the offline filter sees them all)."""
    cfg = seed003_net.load()
    res = seed003_net.twin(cfg, "meas", RUN)
    ref = _offline_sequential(cfg, RUN)
    for peer in ("s1", "s2"):
        np.testing.assert_allclose(_tracks(res, peer), ref, rtol=1e-9, atol=1e-6)
        assert res.peers[peer].consensus.fuser.counts["fallbacks"] == 0


def test_estimate_sharing_twin_is_offline_ci():
    cfg = seed003_net.load()
    res = seed003_net.twin(cfg, "ci", RUN)
    X, sens, target, region, m0, P0 = seed003_net.draws(cfg, RUN)
    peers = [PdaEstimator(seed003.make_filter(cfg, seed003_net.METHOD, m0, P0), s, POS, False)
             for s in sens]
    fuser = CiFuser()
    ref = []
    for k in range(len(target)):
        posts = [p.step(1, np.vstack([target[k][i], region[k][i]])).published["posterior"]
                 for i, p in enumerate(peers)]
        fused = fuser.fuse(FusionInput(k + 1, 0, posts[0], {"s2": {"posterior": posts[1]}},
                                       [0.5, 0.5], np.zeros((0, 2))))
        ref.append(peers[0].extract(fused)[0])
    np.testing.assert_allclose(_tracks(res, "s1"), np.array(ref), rtol=0, atol=1e-9)
    np.testing.assert_allclose(_tracks(res, "s2"), np.array(ref), rtol=0, atol=1e-6)


def test_late_s2_returns_fall_back_to_s1_only_and_are_counted():
    """Every s2 -> s1 message held 5 scan intervals: s1 fuses at its deadline with its own
    sensor only, on every scan (counted), and its tracks are the one-sensor filter's; s2 gets
    s1's returns in time and keeps the two-sensor estimate."""
    cfg = seed003_net.load()
    cfg["faults"] = {"links": [{"from": "s2", "to": "s1", "delay": 0.5}]}  # interval 0.1 s
    res = seed003_net.twin(cfg, "meas", RUN)
    counts = res.peers["s1"].consensus.fuser.counts
    K = int(cfg["scenario"]["num_scans"])
    assert counts["fallbacks"] == counts["missing_s2"] == K
    assert counts["first_fallback_scan"] == 1
    np.testing.assert_allclose(_tracks(res, "s1"), _offline_sequential(cfg, RUN, 1),
                               rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(_tracks(res, "s2"), _offline_sequential(cfg, RUN),
                               rtol=1e-9, atol=1e-6)
    assert res.peers["s2"].consensus.fuser.counts["fallbacks"] == 0
    row = seed003_net.make_row(cfg, "meas", "s1", res.summary("s1"), res.tracks["s1"])
    assert row.missing_inputs == K


def test_lost_returns_are_counted_per_dropped_message():
    cfg = seed003_net.load(overrides={"scenario.num_scans": 40})
    cfg["faults"] = {"links": [{"from": "s2", "to": "s1", "loss": 0.3}]}
    res = seed003_net.twin(cfg, "meas", RUN)
    dropped = sum(1 for r in res.faults.log
                  if r.sender == "s2" and r.receiver == "s1" and r.action == "drop-loss")
    assert 0 < dropped < 40
    assert res.peers["s1"].consensus.fuser.counts["missing_s2"] == dropped


def test_pda_view_holds_gates_weights_and_the_detector():
    """What the Rerun view draws: per sensor the gate and the validated returns with weights
    that, with beta0, sum to 1; the detector's D_L beside chi2.isf(pf, dof)."""
    from scipy.stats import chi2

    cfg = seed003_net.load(overrides={"scenario.num_scans": 8})
    res = seed003_net.twin(cfg, "meas", RUN)
    est = res.peers["s1"].estimator
    view = est.pda_view()
    assert set(view["sensors"]) == {"s1", "s2"}
    for name, v in view["sensors"].items():
        up = est.last_updates[name]
        assert v["returns"].shape == (len(v["weights"]), 2)
        assert float(np.sum(v["weights"])) + up.beta0 == pytest.approx(1.0)
        assert v["gamma"] == pytest.approx(chi2.ppf(0.99, 2))
    d, threshold = view["detector"]
    dof = est.filter.weighting.detector.statistic[1]
    assert dof == 2 * 2 * int(cfg["detector"]["window"])  # L scans x 2 sensors x n_z
    assert threshold == pytest.approx(chi2.isf(float(cfg["detector"]["false_alarm"]), dof))
    assert d >= 0


def test_returns_survive_the_wire():
    """A peer's pre-gated returns go out as a Returns message (16 bytes a return), arrive
    bit for bit, and a receiving core takes them in its "returns" slot; the old form (a
    mixture of kind "returns") and a Returns for a peer that shares estimates are refused."""
    cfg = seed003_net.load()
    Z = np.array([[1.5, -2.25], [1e4, 3e3], [0.0, 7.0]])
    back = decode(encode(Returns("s1", 3, Z, seq=2, send_time=1.0)))
    assert isinstance(back, Returns) and back.kind == "returns"
    np.testing.assert_array_equal(back.z, Z)
    assert decode(encode(Returns("s1", 3, np.zeros((0, 2))))).z.shape == (0, 2)
    meas, ci = seed003_net.make_core(cfg, "s2", "meas"), seed003_net.make_core(cfg, "s2", "ci")
    key = meas.keys.estimate("s1")
    for c in (meas, ci):
        c.receive(key, encode(Returns("s1", 1, Z)), 0.0, admitted=True)
    assert meas.rejected["incompatible"] == 0 and meas.received["estimate"] == 1
    assert ci.rejected["incompatible"] == 1
    old = GaussianMixture(np.ones(1), np.zeros((1, 6)), np.eye(6)[None])
    meas.receive(key, encode(Estimate("s1", 1, old, kind="returns")), 0.0, admitted=True)
    assert meas.rejected["incompatible"] == 1


def test_unknown_mode_and_sensor_are_one_line_errors():
    cfg = seed003_net.load()
    with pytest.raises(ValueError,
                       match="key .pda.mode. is .gossip., expected one of .meas., .ci."):
        seed003_net.make_core(cfg, "s1", "gossip")
    with pytest.raises(ValueError, match="no sensor named"):
        seed003_net.make_core(cfg, "s9", "meas")


SCANS = 10
"""Scans of each mode's real run (2 scans/s): enough to hold every peer's tracks to the twin's
scan by scan, and 5 s a mode (the two modes run at once)."""
LATE_INPUTS = 1
"""Inputs of a run that may miss their fusion deadline on a busy machine (10 %)."""


@pytest.mark.network
def test_processes_equal_the_twin(tmp_path):
    """World + 2 PDA peers as processes over Zenoh on loopback, SCANS at 2 scans/s, each
    mode: every peer publishes a track per scan, fuses every scan with the other's input, and
    its tracks equal the twin's to 1 micrometre (the same code on the same numbers; only the
    memory layout of small matrix products may differ between processes)."""
    a = seed003_net._parser().parse_args(
        ["run", "--run", str(RUN), "--speed", "2", "--set", f"scenario.num_scans={SCANS}",
         "--no-rerun", "--timeout", "90"])
    cfg = seed003_net.load(seed003_net._overrides(a.set))
    # the two modes' runs side by side (each its own network, ports and folder): a run is
    # mostly its 5 s of pacing at 2 scans/s, and one after the other they were the whole test
    with ThreadPoolExecutor(max_workers=len(seed003_net.MODES)) as pool:
        done = dict(zip(seed003_net.MODES, pool.map(
            lambda mode: seed003_net.run_mode(a, cfg, mode, tmp_path / mode),
            seed003_net.MODES), strict=True))
    for mode, (rows, code) in done.items():
        assert code == 0, (tmp_path / mode / "logs").glob("*.log")
        assert [r.peer for r in rows] == ["s1", "s2"]
        for r in rows:
            # a loaded machine may push one input past its deadline (counted): that run's
            # tracks then differ from the twin's from that scan on; otherwise they are equal
            assert r.tracks == SCANS and r.missing_inputs <= LATE_INPUTS, r
            if r.missing_inputs == 0:
                assert r.twin_diff <= 1e-6, r


def _rows(out: str) -> dict[str, list[str]]:
    """The end-of-run table's rows by peer."""
    return {c[1].strip(): [x.strip() for x in c[2:]] for c in
            (ln.split("|") for ln in out.splitlines()) if len(c) > 3 and c[1].strip() in
            ("s1", "s2")}


@pytest.mark.parametrize("mode", seed003_net.MODES)
def test_cli_run_seed003_sim_is_the_common_run(capsys, mode):
    """`run seed003` is the common run of the one scenario loader (one PDA peer kind, the
    mode a setting), not a second command line: the twin's table for both peers."""
    from sensornet.cli import main

    assert main(["run", "seed003", "--sim", "--set", "scenario.num_scans=10",
                 "--set", f"pda.mode={mode}"]) == 0
    rows = _rows(capsys.readouterr().out)
    assert sorted(rows) == ["s1", "s2"] and all(r[0] == "10" for r in rows.values())


def test_cli_run_seed003_refuses_bad_settings_in_one_line(capsys):
    from sensornet.cli import main

    assert main(["run", "seed003", "--sim", "--set", "faults.default.los=0.1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "faults.default.los" in err[0]
    assert main(["run", "seed003", "--sim", "--set", "clutter.nope=1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "clutter.nope" in err[0]
    assert main(["run", "seed003", "--sim", "--set", "pda.mode=both"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pda.mode" in err[0] and "'meas'" in err[0]


def _received(scn) -> dict[str, int]:
    """Per peer, the neighbour inputs its fusions had over the run (the twin)."""
    from sensornet.sim.run.twin import run_twin

    res = run_twin(scn, RUN)
    return {n: res.summary(n)["stats"]["fused_inputs"] for n in res.peers}


def test_cli_run_seed003_takes_link_faults_from_set_and_from_the_file(tmp_path, capsys):
    """Link faults as for the other scenarios: ``--set faults....`` or the file's [faults]
    table (``run path/seed003.toml``). A lost link s2 -> s1 leaves s1 without s2's returns at
    every scan and s2 with all of s1's; the twin counts the losses."""
    from sensornet.sim.scenario import load_scenario

    from sensornet.cli import main

    lost = '[{from = "s2", to = "s1", loss = 1.0}]'
    assert main(["run", "seed003", "--sim", "--set", "scenario.num_scans=12",
                 "--set", f"faults.links={lost}"]) == 0
    out = capsys.readouterr().out
    assert "'deliver': 12, 'drop-loss': 12" in out
    assert _received(load_scenario("seed003", {"scenario.num_scans": 12,
                                               "faults.links": [{"from": "s2", "to": "s1",
                                                                 "loss": 1.0}]})) == \
        {"s1": 0, "s2": 12}
    text = seed003.SCENARIO.read_text(encoding="utf-8")
    path = tmp_path / "seed003.toml"
    path.write_text(text.replace("num_scans = 100", "num_scans = 12")
                    + f"\n[faults]\nlinks = {lost}\n", encoding="utf-8")
    assert "num_scans = 12" in path.read_text()
    assert main(["run", str(path), "--sim"]) == 0
    assert "'drop-loss': 12" in capsys.readouterr().out
    assert _received(load_scenario(path)) == {"s1": 0, "s2": 12}
    assert _received(load_scenario(path, {"faults.links[0].loss": 0.0})) == {"s1": 12, "s2": 12}


def test_cli_experiment_seed003_writes_the_table(tmp_path, capsys):
    from sensornet.cli import main

    assert main(["experiment", "seed003", "--runs", "2", "--jobs", "1", "--quiet",
                 "--out", str(tmp_path / "exp")]) == 0
    out = capsys.readouterr().out
    assert sum(ln.split()[0] in ("PDAF", "IMM-PDAF", "fuzzy") for ln in out.splitlines()
               if ln.strip()) == 8
    for name in ("seed003_table.csv", "seed003_rmse.csv", "seed003_rmse.png"):
        assert (tmp_path / "exp" / name).is_file()
    assert len((tmp_path / "exp" / "seed003_rmse.csv").read_text().splitlines()) == 1 + 100
    path = tmp_path / "seed003.toml"  # a scenario file of that name: its settings are used
    path.write_text(seed003.SCENARIO.read_text(encoding="utf-8").replace(
        "num_scans = 100", "num_scans = 80"), encoding="utf-8")
    assert main(["experiment", str(path), "--runs", "1", "--jobs", "1", "--quiet",
                 "--out", str(tmp_path / "file")]) == 0
    assert len((tmp_path / "file" / "seed003_rmse.csv").read_text().splitlines()) == 1 + 80
