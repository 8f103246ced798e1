"""The shipped real-traffic scenario (issue 34): ``sim/scenarios/paris.toml`` loads, its radars
stand at their sites, each plot goes to the one tick its beam crossing falls in, the time
alignment error is what the design accepts, the measurement-driven birth places births at
unexplained plots only, a short twin run tracks the aircraft, bad keys are one-line errors,
and ``sensornet run paris`` runs as processes."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
import tomllib

import numpy as np
import pytest
from pymap3d import vincenty
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError, load_document, load_scenario, scenario_text
from sensornet.sim.traffic import recorded as R
from sensornet.sim.traffic.excerpt import EXCERPT
from sensornet.sim.traffic.opensky import load_states
from sensornet.sim.world.birth import MeasurementBirthGMPHD, plots_xy, unexplained
from sensornet.sim.world.build import make_filter, sensor_params
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import RangeBearing

from tests.processes import env

SHORT = {"scenario.num_scans": 12}


def _doc() -> dict:
    return tomllib.loads(scenario_text("paris"))


def _scn(**over):
    return load_scenario("paris", {**SHORT, **over})


def test_paris_loads_with_radars_at_their_sites():
    scn = load_scenario("paris")
    assert scn.truth == "recorded" and scn.birth.model == "measurements"
    assert scn.traffic.centre == (48.868, 2.456) and scn.traffic.file == ""
    periods = [s.rotation_period for s in scn.sensors]
    assert len(set(periods)) == len(periods)  # no two in step
    assert all(4.7 <= p <= 4.8 or 10 <= p <= 12 for p in periods)
    # the sites' local positions are as far apart as the geodesic between them (Vincenty;
    # a tangent plane at ~20 km stretches distances by well under 0.1 %)
    cdg, orly = scn.sensor("cdg"), scn.sensor("orly")
    d, _ = vincenty.vdist(*cdg.site, *orly.site)
    assert math.dist(cdg.position, orly.position) == pytest.approx(float(d), rel=1e-3)
    # and north of the centre is +y, east +x
    assert cdg.position[1] > 0 and cdg.position[0] > 0 and orly.position[1] < 0


def test_truth_ids_are_the_icao24_addresses_and_every_tick_has_aircraft():
    scn = _scn()
    truth = R.recorded_truth(scn)
    icao = set(load_states(EXCERPT).aircraft)
    assert truth.num_scans == 12
    for ids, x in zip(truth.ids, truth.states, strict=True):
        assert len(ids) == len(x) > 10 and x.shape[1] == 4
        assert {format(int(i), "06x") for i in ids} <= icao
        assert len(set(ids.tolist())) == len(ids)
    # [px, vx, py, vy]: the position moves by the velocity over a tick (linear pieces)
    a, b = truth.states[0], truth.states[1]
    common = np.intersect1d(truth.ids[0], truth.ids[1])
    ia = np.searchsorted(truth.ids[0], common)
    ib = np.searchsorted(truth.ids[1], common)
    moved = b[ib][:, [0, 2]] - a[ia][:, [0, 2]]
    speed = np.hypot(a[ia][:, 1], a[ia][:, 3])
    assert np.median(np.hypot(*moved.T) / (speed * scn.scan_period)) == pytest.approx(1, abs=0.1)


def test_every_plot_is_in_exactly_the_tick_its_beam_crossing_falls_in():
    scn = _scn()
    w = R.recorded_world(scn)
    T, K = scn.scan_period, scn.num_scans
    truth, scans = R.recorded_run(scn, 0)
    for spec, radar, rotations, per_tick in zip(scn.sensors, w.radars,
                                                R.radar_rotations(scn, 0), scans, strict=True):
        t = np.concatenate([r.t_meas for r in rotations])
        inside = (t > w.t0) & (t <= w.t0 + K * T)
        assert sum(len(z) for z in per_tick) == inside.sum()  # none lost, none twice
        plots = R.tick_plots(scn, 0)[scn.sensor_names.index(spec.name)]
        lo, hi = w.t0 + (plots.tick - 1) * T, w.t0 + plots.tick * T
        assert np.all((plots.t_meas > lo) & (plots.t_meas <= hi))
        # each plot lies in the sector the beam swept during its tick (compass azimuth from
        # the site; 1 degree for the 0.1-0.15 degree bearing noise)
        site = np.asarray(spec.position)
        d = plots.z_xy - site
        az = np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 360
        beam_lo = ((lo - radar.phase) / radar.period_s * 360) % 360
        swept = T / radar.period_s * 360
        off = (az - beam_lo) % 360
        assert np.all((off <= swept + 1) | (off >= 359)), spec.name
        # the scan of tick k is the tick's plots in the sensor's kind (x-y here)
        k = 5
        np.testing.assert_array_equal(per_tick[k - 1], plots.z_xy[plots.tick == k])
        # and the filters' beam model gives every aircraft plot of a tick a Pd > 0 in that
        # tick (at the plot: the sector the world swept), and 0 to the opposite azimuth
        beam = make_filter(scn, [spec.name]).beams[0]
        real = plots.truth != ""
        for k in range(1, K + 1):
            sel = real & (plots.tick == k)
            states = np.zeros((sel.sum(), 4))
            states[:, [0, 2]] = plots.z_xy[sel]
            assert np.all(beam.detection(k, states) > 0), (spec.name, k)
            opposite = np.zeros((sel.sum(), 4))
            opposite[:, [0, 2]] = 2 * site - plots.z_xy[sel]
            if T / radar.period_s < 0.45:
                assert np.all(beam.detection(k, opposite) == 0), (spec.name, k)


def test_tick_edges_and_snapshot_sensors():
    T, t0 = 2.0, 1000.0
    ticks = R.assign_ticks(np.array([1000.0 + 1e-6, 1002.0, 1002.0 + 1e-6, 1004.0]), t0, T)
    np.testing.assert_array_equal(ticks, [1, 1, 2, 2])
    # a sensor without rotation_period: every plot at its tick's time, one per aircraft seen
    doc = _doc()
    for s in doc["sensors"]:
        del s["rotation_period"], s["phase"]
    scn = load_document(doc, "paris.toml", SHORT)
    w = R.recorded_world(scn)
    plots = R.tick_plots(scn, 0)[0]
    np.testing.assert_allclose(plots.t_meas, w.t0 + plots.tick * scn.scan_period, atol=1e-6)
    real = plots.truth != ""
    for k in np.unique(plots.tick):
        names = plots.truth[real & (plots.tick == k)]
        assert len(names) == len(set(names))


def test_the_alignment_error_is_the_distance_flown_since_the_plot():
    """Plots are treated as made at their tick (up to one tick old): the error is the
    aircraft's displacement since the plot, at most max speed x T and on average about half
    a tick of flight (beam crossings uniform over the tick)."""
    scn = load_scenario("paris", {"scenario.num_scans": 60})
    err = R.alignment_errors(scn)
    err = err[np.isfinite(err)]
    truth = R.recorded_truth(scn)
    v = np.concatenate([np.hypot(x[:, 1], x[:, 3]) for x in truth.states])
    T = scn.scan_period
    assert err.max() <= v.max() * T + 1.0
    ages = np.concatenate([T * p.tick - (p.t_meas - R.recorded_world(scn).t0)
                           for p in R.tick_plots(scn, 0)])
    assert 0.4 * T < ages.mean() < 0.6 * T and ages.min() >= 0 and ages.max() <= T
    assert 0.3 * np.median(v) * T < err.mean() < 0.7 * np.median(v) * T


def test_measurement_birth_at_unexplained_plots_only():
    doc = _doc()
    cdg = doc["sensors"][0]
    cdg["kind"] = "range-bearing"
    del cdg["plot_sigma"]
    scn = load_document(doc, "paris.toml", SHORT)
    f = make_filter(scn, ["cdg"])
    assert isinstance(f, MeasurementBirthGMPHD) and len(f.birth) == 0
    model = sensor_params(scn, "cdg").model
    assert isinstance(model, RangeBearing)
    # one heavy component near plot 0, a light one near plot 1, nothing near plot 2
    sx, sy = model.position
    z = np.array([[20000.0, 0.3], [30000.0, 1.0], [40000.0, -2.0]])
    xy, R_xy = plots_xy(model, z)
    np.testing.assert_allclose(xy[0], [sx + 20000 * math.cos(0.3), sy + 20000 * math.sin(0.3)])
    means = np.array([[xy[0, 0] + 50, 0, xy[0, 1] - 40, 0], [xy[1, 0], 0, xy[1, 1], 0]])
    mix = GaussianMixture(np.array([0.9, 0.05]), means, np.tile(np.diag([1e4, 1e2, 1e4, 1e2]),
                                                                (2, 1, 1)))
    new = unexplained(mix, xy, R_xy, 13.8)
    # brute force: the loop the vectorised distance replaces
    brute = []
    for i in range(3):
        d2 = [float((xy[i] - m[[0, 2]]) @ np.linalg.solve(P[np.ix_([0, 2], [0, 2])] + R_xy[i],
                                                            xy[i] - m[[0, 2]]))
              for w, m, P in zip(mix.weights, mix.means, mix.covs, strict=True) if w > 0.1]
        brute.append(all(d > 13.8 for d in d2))
    np.testing.assert_array_equal(new, brute)
    np.testing.assert_array_equal(new, [False, True, True])
    post = f.correct(f.predict(mix), [z])
    assert len(f.pending) == 2 and len(post)
    np.testing.assert_allclose(f.pending.means[:, [0, 2]], xy[1:])
    np.testing.assert_allclose(f.pending.means[:, [1, 3]], 0)
    assert f.predict(post).mass > post.mass * scn.survival_probability  # births entered
    assert len(f.birth) == 2


def test_a_short_twin_run_tracks_the_aircraft():
    scn = load_scenario("paris", {"scenario.num_scans": 40})
    res = run_twin(scn)
    truth = R.recorded_truth(scn)
    n_true = len(truth.states[-1])
    for n in scn.sensor_names:
        tracks = res.tracks[n][40]
        assert 0.5 * n_true <= len(tracks) <= 1.5 * n_true, (n, len(tracks), n_true)
        fused = np.mean(list(res.ospa[n]["fused"].values())[10:])
        assert fused < 0.8 * scn.metrics.ospa_cutoff, n  # tracking, not all misses
    assert all(len(i) and i.dtype.kind == "i" for i in truth.ids)


def _fail(doc: dict, over: dict | None = None) -> str:
    with pytest.raises(ScenarioError) as info:
        load_document(doc, "paris.toml", over)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("paris.toml")
    return msg


def test_bad_keys_are_one_line_errors_naming_them():
    doc = _doc()
    d = copy.deepcopy(doc)
    d["sensors"][0]["position"] = [0.0, 0.0]
    assert "sensors[0].site" in _fail(d) and "both" in _fail(d)
    d = copy.deepcopy(doc)
    del d["traffic"]["centre"], d["traffic"]["radius"]
    assert "'sensors[0].site' needs 'traffic.centre'" in _fail(d)
    d = copy.deepcopy(doc)
    d["traffic"]["radius_m"] = 1.0
    assert "unknown key 'traffic.radius_m'" in _fail(d)
    d = copy.deepcopy(doc)
    del d["traffic"]["centre"]
    assert "'traffic.radius' needs 'traffic.centre'" in _fail(d)
    d = copy.deepcopy(doc)
    d["traffic"]["start"] = "yesterday"
    assert "'traffic.start'" in _fail(d)
    d = copy.deepcopy(doc)
    del d["sensors"][1]["max_range"]
    assert "missing required key 'sensors[1].max_range'" in _fail(d)
    d = copy.deepcopy(doc)
    del d["sensors"][2]["rotation_period"]
    assert "'sensors[2].phase' needs 'rotation_period'" in _fail(d)
    d = copy.deepcopy(doc)
    d["sensors"][0]["site"] = [95.0, 2.0]
    assert "'sensors[0].site'" in _fail(d)
    assert "'sensors[0].rotation_period' must be > 0" in _fail(
        _doc(), {"sensors.cdg.rotation_period": 0.0})
    assert "'sensors[0].plot_sigma' is only for linear" in _fail(
        _doc(), {"sensors.cdg.kind": "range-bearing"})
    d = copy.deepcopy(doc)
    del d["sensors"][3]["plot_sigma"]
    assert "missing required key 'sensors[3].plot_sigma'" in _fail(d)
    d = copy.deepcopy(doc)
    d["sensors"][0]["kind"] = "range-bearing"
    del d["sensors"][0]["plot_sigma"]
    assert "'sensors[0].rotation_period' is only for recorded traffic" in _fail(
        d, {"scenario.truth": "straight"})
    assert "'birth.measurements.gate' must be > 0" in _fail(
        _doc(), {"birth.measurements.gate": 0.0})
    # a window longer than the recording: one line naming the keys, at the truth
    scn = load_scenario("paris", {"scenario.num_scans": 1000})
    with pytest.raises(ScenarioError, match=r"scenario.num_scans = 1000 .*traffic.end"):
        R.recorded_world(scn)


def test_the_file_is_relative_to_the_scenario_file(tmp_path):
    (tmp_path / "sub").mkdir()
    text = scenario_text("paris").replace('# file = "my_recording.parquet"',
                                          f'file = "{EXCERPT.name}"')
    (tmp_path / "sub" / EXCERPT.name).write_bytes(EXCERPT.read_bytes())
    path = tmp_path / "sub" / "mine.toml"
    path.write_text(text)
    scn = load_scenario(path, SHORT)
    assert scn.traffic.file == str(tmp_path / "sub" / EXCERPT.name)
    np.testing.assert_array_equal(R.recorded_truth(scn).ids[0],
                                  R.recorded_truth(_scn()).ids[0])


@pytest.mark.network
def test_sensornet_run_paris_as_processes(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "sensornet", "run", "paris", "--set", "scenario.num_scans=8",
         "--no-rerun", "--out", str(out)], capture_output=True, text=True, timeout=240,
        cwd=tmp_path, env=env())
    assert proc.returncode == 0, proc.stderr + proc.stdout
    for n in ("cdg", "orly", "north", "south"):
        summary = json.loads((out / f"peer-{n}.json").read_text())
        assert summary["scans"] == 8, n
        assert summary["stats"]["fusions"] >= 1 and summary["internal_errors"] == {}, n
