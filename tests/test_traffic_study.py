"""The real-traffic study (issue 34 item 4, sim/studies/traffic): its metrics equal
tracking.track_metrics' whole-run ones, continuity per aircraft is a direct count, the
centralised measurement-birth GM-PHD is the unlabelled filter's numbers, the study's rows come
from the metrics of its tables, and another recording (the excerpt moved in time and place,
mirrored, renamed) runs through the same command with only the file, window and sites
changed."""

from __future__ import annotations

import gzip
import json

import numpy as np
import pytest
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.traffic import study as S
from sensornet.sim.studies.traffic.centralised import central_measurement_gmphd
from sensornet.sim.studies.traffic.metrics import (
    hota_sparse,
    ospa2_curve,
    per_aircraft,
    set_errors,
    visits,
)
from sensornet.sim.traffic.excerpt import EXCERPT
from sensornet.sim.world import generate_run
from sensornet.sim.world.build import make_filter
from sensornet.tracking.gmphd import extract
from sensornet.tracking.metrics import gospa, ospa
from sensornet.tracking.track_metrics import TrackTable, hota, ospa2, track_report


def _random_tables(rng: np.random.Generator, T: int = 40) -> tuple[TrackTable, TrackTable]:
    """Three truths on lines over parts of ``T`` scans, estimates near them with gaps, swaps
    and a false track."""
    S, I, X, Se, Ie, Xe = [], [], [], [], [], []
    for j, (a, b) in enumerate([(1, 30), (5, T), (12, 25)]):
        for k in range(a, b + 1):
            p = np.array([100.0 * k, 300.0 * j])
            S.append(k), I.append(j), X.append(p)
            if rng.random() < 0.85:
                Se.append(k), Ie.append(10 * j + (k > 20)), Xe.append(p + rng.normal(0, 60, 2))
    for k in range(8, 16):
        Se.append(k), Ie.append(99), Xe.append([5000.0, 5000.0])
    return (TrackTable(np.array(S), np.array(I), np.array(X)),
            TrackTable(np.array(Se), np.array(Ie), np.array(Xe)))


def test_chunked_ospa2_equals_the_whole_run_curve():
    truth, est = _random_tables(np.random.default_rng(1))
    grid = np.arange(1, 41)
    whole = ospa2(truth, est, c=500.0, p=2.0, window=10, scans=grid)
    for chunk in (1, 7, 13, 400):
        np.testing.assert_allclose(ospa2_curve(truth, est, grid, 500.0, 2.0, 10, chunk), whole,
                                   rtol=1e-12)


def test_sparse_hota_equals_the_dense_one():
    truth, est = _random_tables(np.random.default_rng(2))
    grid = np.arange(1, 41)
    a, b = hota_sparse(truth, est, 500.0, grid), hota(truth, est, 500.0, grid)
    for k in ("hota", "deta", "assa", "loca"):
        assert a[k] == pytest.approx(b[k], rel=1e-12)
    assert 0.2 < a["hota"] < 1.0


def test_set_errors_are_per_scan_ospa_and_gospa():
    truth, est = _random_tables(np.random.default_rng(3))
    grid = np.arange(1, 41)
    o, g = set_errors(truth, est, grid, 500.0, 2.0)
    for k in (1, 9, 21, 40):
        X, Y = est.pos[est.scan == k], truth.pos[truth.scan == k]
        assert o[k - 1] == pytest.approx(ospa(X, Y, 500.0, 2.0))
        assert g[k - 1] == pytest.approx(gospa(X, Y, 500.0, 2.0))


def test_continuity_and_switches_per_aircraft_are_direct_counts():
    # aircraft 7 present in scans 1..20; track 1 holds scans 1-8, nothing 9-10, track 2 holds
    # 11-15, track 1 again 16-20: 13 scans on its longest track, 2 switches
    # aircraft 8 present 1..10, held by track 3 throughout; track 4 is far (false)
    ts = np.arange(1, 21)
    truth = TrackTable(np.r_[ts, np.arange(1, 11)], np.r_[np.full(20, 7), np.full(10, 8)],
                       np.r_[np.c_[ts * 50.0, 0 * ts], np.c_[np.arange(1, 11) * 50.0,
                                                             np.full(10, 5000.0)]])
    s1 = np.r_[np.arange(1, 9), np.arange(16, 21)]
    s2 = np.arange(11, 16)
    est = TrackTable(np.r_[s1, s2, np.arange(1, 11), [3]],
                     np.r_[np.full(13, 1), np.full(5, 2), np.full(10, 3), [4]],
                     np.r_[np.c_[s1 * 50.0 + 20, 0 * s1], np.c_[s2 * 50.0 - 20, 0 * s2],
                           np.c_[np.arange(1, 11) * 50.0, np.full(10, 5030.0)],
                           [[-9000.0, 0.0]]])
    pa = per_aircraft(truth, est, 200.0, np.arange(1, 21), 2.0)
    assert pa["id"].tolist() == [7, 8]
    assert pa["scans"].tolist() == [20, 10]
    np.testing.assert_allclose(pa["continuity"], [13 / 20, 1.0])
    assert pa["switches"].tolist() == [2, 0]
    np.testing.assert_allclose(pa["switches_per_hour"], [2 / (20 * 2 / 3600), 0.0])


def test_visits_split_an_aircraft_where_it_is_absent():
    # aircraft 5 at scans 1-3 and 6-7 (absent 4-5), aircraft 9 at 2-4; rows unsorted
    truth = TrackTable(np.array([7, 1, 2, 3, 6, 2, 3, 4]), np.array([5, 5, 5, 5, 5, 9, 9, 9]),
                       np.arange(16.0).reshape(8, 2))
    v, owner = visits(truth, np.arange(1, 8))
    assert owner.tolist() == [5, 5, 9]
    assert v.id.tolist() == [1, 0, 0, 0, 1, 2, 2, 2]
    np.testing.assert_array_equal(v.pos, truth.pos)
    # a track holding the first visit and another the second: each visit fully held, and
    # no switch between them (the aircraft was gone)
    est = TrackTable(np.array([1, 2, 3, 6, 7]), np.array([1, 1, 1, 2, 2]),
                     truth.pos[[1, 2, 3, 4, 0]])
    pa = per_aircraft(v, est, 1.0, np.arange(1, 8), 2.0)
    np.testing.assert_allclose(pa["continuity"][:2], [1.0, 1.0])
    assert pa["switches"].tolist() == [0, 0, 0]
    assert per_aircraft(truth, est, 1.0, np.arange(1, 8), 2.0)["continuity"][0] == 0.6


def test_central_measurement_gmphd_is_the_unlabelled_filter_with_labels():
    scn = load_scenario("paris", {"scenario.num_scans": 15})
    truth, scans = generate_run(scn, 0)
    central, plain = central_measurement_gmphd(scn), make_filter(scn, scn.sensor_names)
    lm, mix = central.initial(), None
    for k in range(1, 16):
        zs = [s[k - 1] for s in scans]
        lm = central.step(lm, zs, k)
        mix = plain.correct(plain.predict(mix if mix is not None else lm.mixture.select(
            np.zeros(0, int)), 1), zs)
        np.testing.assert_allclose(lm.mixture.weights, mix.weights, rtol=1e-12)
        ex = central.extract(lm)
        np.testing.assert_allclose(ex.states, extract(mix, plain.extraction_threshold,
                                                      plain.extraction), rtol=1e-12)
        assert len({tuple(r) for r in ex.labels.tolist()}) == len(ex.labels)
    assert len(ex.states) >= 0.7 * len(truth.states[-1])
    assert ex.status.sum() >= 0.7 * len(truth.states[-1])  # confirmed by scan 15


def test_study_rows_come_from_the_track_metrics_of_its_tables():
    over = {"scenario.num_scans": 20}
    part = S.run_part("paris", over, "gmphd", "fused", 0, with_hota=True, keep_tables=True)
    scn = load_scenario("paris", over)
    grid = np.arange(1, 21)
    assert [r["peer"] for r in part.rows] == scn.sensor_names
    for r in part.rows:
        rep = track_report(part.truth, part.tables[r["peer"]], c=1000.0, p=2.0, window=10,
                           scans=grid, with_tgospa=False)
        assert r["ospa2"] == pytest.approx(rep["ospa2_mean"])
        assert r["switches_all"] == rep["switches"]
        assert r["hota"] == pytest.approx(rep["hota"])
        pa = part.aircraft[r["peer"]]
        rv = track_report(visits(part.truth, grid)[0], part.tables[r["peer"]], c=1000.0,
                          scans=grid, with_tgospa=False, with_hota=False)
        np.testing.assert_allclose(pa["continuity"], rv["per_truth"]["continuity"])
        assert r["switches"] == rv["switches"]
        assert r["ospa"] < 1000.0
    summ = S.summarise([part], scn.scan_period, 5)[0]
    assert summ["ospa2"] == pytest.approx(np.mean([r["ospa2"] for r in part.rows]))
    assert 0 < summ["aircraft"] and 0.0 <= summ["cont_p10"] <= summ["cont_median"] <= 1.0


def _moved_recording(path) -> None:
    """The excerpt as another recording: 400 days and 5 h later, mirrored east-west about its
    centre and moved to near Frankfurt, every icao24 renamed."""
    with gzip.open(EXCERPT, "rt") as f:
        recs = json.load(f)
    out = []
    for r in recs:
        r = dict(r)
        r["timestamp"] = r["timestamp"] + (400 * 86400 + 5 * 3600) * 1000
        r["latitude"] = r["latitude"] - 48.868 + 50.033
        r["longitude"] = 8.570 - (r["longitude"] - 2.456)
        if r.get("track") is not None:
            r["track"] = (360.0 - r["track"]) % 360.0
        r["icao24"] = f"{int(r['icao24'], 16) ^ 0x5A5A5A:06x}"
        out.append(r)
    with gzip.open(path, "wt") as f:
        json.dump(out, f)


def test_another_recording_runs_with_only_file_window_and_sites_changed(tmp_path, capsys):
    f = tmp_path / "frankfurt.json.gz"
    _moved_recording(f)
    sites = {"cdg": [50.05, 8.57], "orly": [49.90, 8.40], "bourget": [50.15, 8.75],
             "pontoise": [50.00, 8.25], "north": [50.55, 8.60], "south": [49.50, 8.45],
             "east": [50.00, 9.20], "west": [50.10, 7.90]}
    sets = ["traffic.centre=[50.033, 8.570]"] + [f"sensors.{n}.site=[{a}, {b}]"
                                                 for n, (a, b) in sites.items()]
    md = tmp_path / "table.md"
    argv = ["paris-8", "--file", str(f), "--start", "2022-11-11T19:05:00+00:00",
            "--minutes", "1", "--kinds", "gmphd", "--no-hota", "--quiet", "--min-scans", "10",
            "--md", str(md), "--json", str(tmp_path / "s.json")]
    for s in sets:
        argv += ["--set", s]
    assert S.main(argv) == 0
    text = md.read_text()
    assert "paris-8: 8 radars, 30 ticks of 2 s" in text
    summary = json.loads((tmp_path / "s.json").read_text())
    by = {r["estimate"]: r for r in summary}
    assert set(by) == {"local", "fused", "centralised"}
    assert by["fused"]["peers"] == 8 and by["centralised"]["peers"] == 1
    assert by["fused"]["aircraft"] >= 10  # the moved traffic was there and tracked
    assert by["fused"]["ospa"] < 700.0 and by["centralised"]["ospa"] < 700.0
    assert by["fused"]["cont_median"] > 0.5


def test_bad_kind_is_refused(capsys):
    assert S.main(["paris", "--kinds", "imm"]) == 2
    assert "unknown kind or estimate: imm" in capsys.readouterr().err


def test_targets_without_local_or_reference_say_not_run():
    """A study of the fused estimate alone has no ratio to judge: the targets table says the
    estimate was not run, not "nan **no**" (a user would read that as a failed target)."""
    fused = {"kind": "lmb", "estimate": "fused", "ospa2": 195.6, "ospa2_by_peer": {"cdg": 195.6},
             "cont_median": 0.98, "cont_p10": 0.96, "sw_per_hour": 0.24}
    text = S.targets([fused])
    assert "nan" not in text and text.count("– (not run)") == 2
    local = {**fused, "estimate": "local", "ospa2": 300.0, "ospa2_by_peer": {"cdg": 300.0}}
    assert "0.65 **no**" in S.targets([fused, local])
