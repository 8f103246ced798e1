"""A recorded file the code was not written on (issue 34: "another recorded file of the same
format ... the loader and the defaults must not be tuned to this one file"): what the Swiss
sample of the ``traffic`` library needed, each on a small synthetic file (docs/real-traffic.md,
"Another recorded file: Switzerland")."""

from __future__ import annotations

import gzip
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from sensornet.sim.scenario import load_document, load_scenario, scenario_text
from sensornet.sim.traffic import opensky
from sensornet.sim.traffic.calibrate import plot_sigmas
from sensornet.sim.traffic.opensky import LocalFrame

from sensornet.cli import main as cli_main

T0 = 1_533_121_200.0  # 2018-08-01 11:00 UTC
CENTRE = (47.0, 8.0)


def _records(icao: str, times, enu, frame: LocalFrame) -> list[dict]:
    """Records (the ``traffic`` samples' fields: no ``onground``) of ENU points ``(n, 3)``."""
    lat, lon, h = frame.to_geodetic(np.asarray(enu, float))
    return [{"timestamp": int(round(t * 1000)), "icao24": icao, "callsign": "SWR1",
             "latitude": float(a), "longitude": float(o), "altitude": float(z) / opensky.FOOT,
             "groundspeed": 450.0, "track": 90.0, "vertical_rate": 0.0}
            for t, a, o, z in zip(times, lat, lon, h, strict=True)]


def _line(icao: str, times, p0=(0.0, 0.0, 11000.0), v=(230.0, 0.0, 0.0)) -> list[dict]:
    frame = LocalFrame(*CENTRE)
    times = np.asarray(times, float)
    return _records(icao, times, np.asarray(p0) + np.outer(times - T0, v), frame)


def _write(path: Path, records: list[dict]) -> Path:
    with gzip.open(path, "wt", encoding="utf-8") as f:
        json.dump(records, f)
    return path


def _one_line(excinfo, *words):
    msg = str(excinfo.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


# --- the report interval against max_gap --------------------------------------------------


def test_a_file_reporting_less_often_than_max_gap_is_refused_not_read_as_no_aircraft(tmp_path):
    t = T0 + 60.0 * np.arange(20)
    f = _write(tmp_path / "minute.json.gz",
               _line("4b1801", t) + _line("4b1802", t, p0=(0.0, 5000.0, 11000.0)))
    states = opensky.load_states(f)
    with pytest.raises(ValueError) as e:
        opensky.trajectories(states, CENTRE, max_gap_s=20.0)
    _one_line(e, str(f), "'timestamp'", "60 s", "max_gap 20 s", "traffic.max_gap")
    # with max_gap above the interval the same file is two aircraft on their straight lines
    traj = opensky.trajectories(states, CENTRE, max_gap_s=90.0)
    x, present = traj.evaluate(np.array([0, 1]), np.array([T0 + 330.0, T0 + 330.0]))
    assert present.all()
    np.testing.assert_allclose(x[:, 0], 230.0 * 330.0, atol=1.0)
    np.testing.assert_allclose(x[:, 3], 230.0, atol=0.05)


def test_the_traffic_samples_ten_second_cadence_is_read_with_the_default_gap(tmp_path):
    # one report every 10 s, one lost (a 20 s gap: still interpolated), then three lost (40 s)
    t = T0 + 10.0 * np.array([0, 1, 2, 4, 5, 6, 10, 11, 12])
    traj = opensky.trajectories(opensky.load_states(_write(tmp_path / "ten.json.gz",
                                                           _line("4b1803", t))), CENTRE)
    _, present = traj.evaluate(np.zeros(4, np.intp), T0 + np.array([15.0, 35.0, 80.0, 105.0]))
    assert present.tolist() == [True, True, False, True]


# --- identities -----------------------------------------------------------------------------


def test_an_icao24_that_is_not_hexadecimal_is_named_with_its_record(tmp_path):
    recs = _line("4b1804", T0 + 10.0 * np.arange(3))
    recs[2] = dict(recs[2], icao24="~4b18z5")  # a non-ICAO (TIS-B style) address
    f = _write(tmp_path / "bad.json.gz", recs)
    with pytest.raises(ValueError) as e:
        opensky.load_states(f)
    _one_line(e, str(f), "'icao24'", "record 3", "'~4b18z5'")


# --- the command line: the loader's errors are one line there too ------------------------


def _scenario(tmp_path: Path, data_file: str) -> Path:
    text = scenario_text("paris").replace(
        '# file = "my_recording.parquet"', f'file = "{data_file}"  #')
    path = tmp_path / "mine.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("case", ["missing", "minute"])
def test_run_sim_gives_the_loader_error_in_one_line(tmp_path, monkeypatch, capsys, case):
    monkeypatch.chdir(tmp_path)
    if case == "minute":
        _write(tmp_path / "minute.json.gz", _line("4b1806", T0 + 60.0 * np.arange(30),
                                                  p0=(-30000.0, 0.0, 11000.0), v=(40.0, 0, 0)))
    scn = _scenario(tmp_path, f"{case}.json.gz")
    argv = ["run", str(scn), "--sim", "--no-rerun", "--set", "traffic.centre=[47.0, 8.0]"]
    assert cli_main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("sensornet: error: paris: [traffic] ")
    assert f"{case}.json.gz" in err
    assert ("no such file" if case == "missing" else "field 'timestamp'") in err
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


# --- plot_sigma measured on the traffic, not carried over from Paris ----------------------


def _circling_scenario(tmp_path: Path, R: float, v: float):
    """One aircraft circling the radar at ground range ``R`` and speed ``v`` for 10 min,
    reported every second; one radar at the centre (4.7 s rotation, 0.1 deg, no clutter)."""
    frame = LocalFrame(*CENTRE)
    t = T0 + np.arange(0.0, 601.0)
    th = v * (t - T0) / R
    enu = np.stack([R * np.sin(th), R * np.cos(th), np.full(len(t), 11000.0)], axis=1)
    f = _write(tmp_path / "circle.json.gz", _records("4b1807", t, enu, frame))
    doc = tomllib.loads(scenario_text("paris"))
    doc["traffic"].update(file=str(f), start=10.0, centre=list(CENTRE), radius=100000.0)
    radar = dict(doc["sensors"][0], name="r", site=list(CENTRE), clutter_rate=0.0)
    doc["sensors"] = [radar]
    return load_document(doc, "circle.toml", {"scenario.num_scans": 280})


def test_plot_sigma_rule_against_the_closed_form_of_a_circling_aircraft(tmp_path):
    R, v, T = 30000.0, 200.0, 2.0
    (row,) = plot_sigmas(_circling_scenario(tmp_path, R, v))
    assert row.plots > 100
    assert row.median_range_m == pytest.approx(R, rel=0.005)  # radar noise 30 m along range
    assert row.cross_range_m == pytest.approx(R * math.radians(0.1), rel=0.005)
    # a plot is up to one tick old, its age uniform over the tick: rms v T / sqrt(3)
    assert row.alignment_rms_m == pytest.approx(v * T / math.sqrt(3.0), rel=0.08)
    assert row.plot_sigma_m == pytest.approx(math.hypot(row.cross_range_m, row.alignment_rms_m))


def test_plot_sigma_rule_gives_paris_8s_values_on_its_training_window():
    scn = load_scenario("paris-8", {"traffic.start": 0.0, "scenario.num_scans": 145})
    rows = plot_sigmas(scn)
    shipped = {s.name: s.plot_sigma for s in scn.sensors}
    assert [r.name for r in rows] == list(shipped)
    for r in rows:  # paris-8 took the median over the aircraft, this over their plots
        assert abs(r.plot_sigma_m - shipped[r.name]) <= 3.0, (r, shipped[r.name])
