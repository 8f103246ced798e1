"""The OpenSky loader (sim/traffic/opensky.py): frames against closed forms and published
coordinates, interpolation, gaps, the three file formats alike, one-line errors."""

from __future__ import annotations

import csv
import gzip
import json
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from pymap3d import vincenty
from sensornet.sim.traffic import excerpt, opensky
from sensornet.sim.traffic.opensky import LocalFrame

WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3
CDG = (49.009722, 2.547778)  # AIP France aerodrome reference points (49°00'35"N 002°32'52"E)
ORLY = (48.723333, 2.379444)  # (48°43'24"N 002°22'46"E)
T0 = 1_633_608_000.0
FULL = Path("/work/shared/data/adsb/quickstart.json.gz")


def _record(t, icao, lat, lon, alt_ft, onground=False):
    return {"timestamp": int(round(t * 1000)), "icao24": icao, "callsign": "TEST1",
            "latitude": lat, "longitude": lon, "altitude": alt_ft, "groundspeed": 400.0,
            "track": 90.0, "vertical_rate": 0.0, "onground": onground, "squawk": "1000"}


def _write_json(path: Path, records: list[dict]) -> Path:
    if path.suffix == ".gz":
        with gzip.open(path, "wt", encoding="utf-8") as f:
            json.dump(records, f)
    else:
        path.write_text(json.dumps(records))
    return path


def _line(frame: LocalFrame, times, p0, v):
    """Records of an aircraft moving on a straight ENU line ``p0 + v t``."""
    enu = np.asarray(p0) + np.outer(np.asarray(times) - T0, v)
    lat, lon, h = frame.to_geodetic(enu)
    return [_record(t, "abc123", float(a), float(o), float(z) / opensky.FOOT)
            for t, a, o, z in zip(times, lat, lon, h, strict=True)]


def _single_line_error(excinfo, *words):
    msg = str(excinfo.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


# --- frames -------------------------------------------------------------------------------


def test_enu_of_a_point_one_km_north_east_and_up():
    lat0, lon0 = 48.868, 2.456
    frame = LocalFrame(lat0, lon0, 0.0)
    phi = math.radians(lat0)
    w = 1 - WGS84_E2 * math.sin(phi) ** 2
    M = WGS84_A * (1 - WGS84_E2) / w**1.5  # meridional radius of curvature (closed form)
    N = WGS84_A / math.sqrt(w)  # prime-vertical radius
    north = frame.to_enu(lat0 + math.degrees(1000.0 / M), lon0, 0.0)
    east = frame.to_enu(lat0, lon0 + math.degrees(1000.0 / (N * math.cos(phi))), 0.0)
    up = frame.to_enu(lat0, lon0, 1000.0)
    np.testing.assert_allclose(north, [0.0, 1000.0, 0.0], atol=0.2)  # curvature: 0.08 m down
    np.testing.assert_allclose(east, [1000.0, 0.0, 0.0], atol=0.2)
    np.testing.assert_allclose(up, [0.0, 0.0, 1000.0], atol=1e-6)
    lat, lon, h = frame.to_geodetic(np.array([[1234.5, -6789.0, 300.0]]))
    np.testing.assert_allclose(frame.to_enu(lat, lon, h), [[1234.5, -6789.0, 300.0]], atol=1e-6)


def test_cdg_to_orly_distance_matches_the_geodesic_and_a_sphere():
    """Both aerodromes in a frame midway: the horizontal ENU distance is the Vincenty geodesic
    (to metres at 34 km) and within 0.5 % of the haversine on the mean sphere (R = 6371 km)."""
    frame = LocalFrame((CDG[0] + ORLY[0]) / 2, (CDG[1] + ORLY[1]) / 2, 0.0)
    a, b = frame.to_enu(*CDG, 0.0), frame.to_enu(*ORLY, 0.0)
    d_enu = math.hypot(*(a - b)[:2])
    d_geo, _ = vincenty.vdist(*CDG, *ORLY)
    p1, p2 = math.radians(CDG[0]), math.radians(ORLY[0])
    dl = math.radians(CDG[1] - ORLY[1])
    hav = math.sin((p1 - p2) / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    d_sphere = 2 * 6_371_008.8 * math.asin(math.sqrt(hav))
    assert 33_500 < d_enu < 35_000
    assert abs(d_enu - float(d_geo)) < 2.0
    assert abs(d_enu - d_sphere) / d_sphere < 5e-3


# --- interpolation and gaps -----------------------------------------------------------------


def test_interpolation_is_exact_on_linear_motion(tmp_path):
    frame = LocalFrame(48.9, 2.4, 0.0)
    v = np.array([180.0, -95.0, 6.0])
    times = T0 + np.array([0.0, 3.0, 4.0, 9.0, 13.0])  # uneven reports
    path = _write_json(tmp_path / "line.json.gz", _line(frame, times, [-5000, 2000, 3000], v))
    traj = opensky.trajectories(opensky.load_states(path), frame)
    tq = T0 + np.array([0.0, 1.7, 4.0, 6.25, 12.999, 13.0])
    g = traj.grid(tq)
    assert list(g.ids) == ["abc123"] and g.present.all()
    expect = np.array([-5000, 2000, 3000]) + np.outer(tq - T0, v)
    np.testing.assert_allclose(g.states[:, 0, :3], expect, atol=1e-3)
    np.testing.assert_allclose(g.states[:, 0, 3:], np.broadcast_to(v, (6, 3)), atol=1e-3)
    ids, planar = g.planar(3)
    np.testing.assert_allclose(planar[0], [expect[3, 0], v[0], expect[3, 1], v[1]], atol=1e-3)


def test_a_60_s_hole_makes_the_aircraft_absent_there_present_either_side(tmp_path):
    frame = LocalFrame(48.9, 2.4, 0.0)
    times = T0 + np.concatenate([np.arange(0, 41.0), np.arange(101.0, 141.0),  # 60 s hole
                                 np.arange(156.0, 170.0)])  # 15 s hole: under max_gap_s
    path = _write_json(tmp_path / "gap.json", _line(frame, times, [0, 0, 3000], [200, 0, 0]))
    traj = opensky.trajectories(opensky.load_states(path), frame, max_gap_s=20.0)
    tq = T0 + np.array([-1.0, 0.0, 20.0, 40.0, 41.0, 70.0, 100.9, 101.0, 120.0, 148.0, 169.0,
                        169.5])
    g = traj.grid(tq)
    expect = [False, True, True, True, False, False, False, True, True, True, True, False]
    assert g.present[:, 0].tolist() == expect
    assert np.isnan(g.states[~np.array(expect), 0]).all()
    np.testing.assert_allclose(g.states[8, 0, 0], 200 * 120.0, atol=1e-3)


def test_stale_repeated_positions_are_not_new_fixes(tmp_path):
    frame = LocalFrame(48.9, 2.4, 0.0)
    times = T0 + np.arange(0, 60.0)
    recs = _line(frame, times, [0, 0, 3000], [200, 0, 0])
    for r in recs[10:40]:  # receiver repeats the position of t = 9 s for 30 s
        r["latitude"], r["longitude"] = recs[9]["latitude"], recs[9]["longitude"]
    path = _write_json(tmp_path / "stale.json", recs)
    states = opensky.load_states(path)
    g = opensky.trajectories(states, frame).grid(T0 + np.array([5.0, 25.0, 45.0]))
    assert g.present[:, 0].tolist() == [True, False, True]  # 31 s without a new position
    g_raw = opensky.trajectories(states, frame, drop_stale=False).grid(T0 + np.array([25.0]))
    assert g_raw.present[0, 0] and g_raw.states[0, 0, 3] == pytest.approx(0.0, abs=1e-3)


# --- formats --------------------------------------------------------------------------------


def _sample_records() -> list[dict]:
    frame = LocalFrame(48.9, 2.4, 0.0)
    a = _line(frame, T0 + np.arange(0, 30.0, 2.0), [0, 0, 3000], [150, 40, -5])
    b = [dict(r, icao24="4ca7b3") for r in _line(frame, T0 + np.arange(5, 40.0, 3.0),
                                                  [9000, -4000, 9000], [-220, 10, 0])]
    recs = a + b
    recs[3]["altitude"] = None
    recs[4].update(latitude=None, longitude=None)  # no position: dropped
    recs[20]["onground"] = True
    recs.append(dict(recs[7], latitude=recs[7]["latitude"] + 1.0))  # same time: first kept
    rng = np.random.default_rng(7)
    return [recs[i] for i in rng.permutation(len(recs))]  # unsorted


def _write_csv(path: Path, recs: list[dict], columns: dict[str, str] | None = None,
               convert=None):
    columns = columns or {k: k for k in recs[0]}
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns.values())
        for r in recs:
            r = convert(r) if convert else r
            w.writerow(["" if r[k] is None else r[k] for k in columns])
    return path


def _same(a: opensky.StateVectors, b: opensky.StateVectors):
    for name in ("t", "lat", "lon", "alt_m"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-9)
    for name in ("icao", "onground", "callsign"):
        assert getattr(a, name).tolist() == getattr(b, name).tolist()


def test_json_csv_and_parquet_give_the_same_states(tmp_path):
    recs = _sample_records()
    ref = opensky.load_states(_write_json(tmp_path / "s.json.gz", recs))
    assert len(ref) == len(recs) - 2 and np.isnan(ref.alt_m).sum() == 1
    assert ref.onground.sum() == 1 and ref.aircraft.tolist() == ["4ca7b3", "abc123"]
    assert np.all(np.diff(ref.t[ref.icao == "abc123"]) > 0)
    keys = [(r["icao24"], r["timestamp"]) for r in recs]
    dup = [r for r, k in zip(recs, keys, strict=True) if keys.count(k) == 2]
    assert len(dup) == 2  # the repeated time keeps the row that comes first in the file
    assert dup[0]["latitude"] in ref.lat and dup[1]["latitude"] not in ref.lat
    with open(tmp_path / "plain.json", "w") as f:
        json.dump(recs, f)
    _same(ref, opensky.load_states(tmp_path / "plain.json"))
    _same(ref, opensky.load_states(_write_csv(tmp_path / "s.csv", recs)))
    pq.write_table(pa.Table.from_pylist(recs), tmp_path / "s.parquet")
    _same(ref, opensky.load_states(tmp_path / "s.parquet"))
    # Parquet with a typed timestamp column (as pandas/traffic write it)
    typed = pa.Table.from_pylist(recs)
    ts = pa.array([r["timestamp"] for r in recs], pa.int64()).cast(pa.timestamp("ms", "UTC"))
    typed = typed.set_column(typed.column_names.index("timestamp"), "timestamp", ts)
    pq.write_table(typed, tmp_path / "typed.pq")
    _same(ref, opensky.load_states(tmp_path / "typed.pq"))


def test_opensky_history_aliases_and_iso_times(tmp_path):
    """OpenSky's own CSV (``time`` s, ``lat``/``lon``, ``baroaltitude`` m) and ISO strings."""
    recs = _sample_records()
    ref = opensky.load_states(_write_json(tmp_path / "s.json", recs))
    cols = {"time": "time", "icao24": "icao24", "lat": "lat", "lon": "lon",
            "baroaltitude": "baroaltitude", "onground": "onground", "callsign": "callsign"}

    def history(r):
        alt = None if r["altitude"] is None else r["altitude"] * opensky.FOOT
        return {"time": r["timestamp"] / 1000, "icao24": r["icao24"], "lat": r["latitude"],
                "lon": r["longitude"], "baroaltitude": alt, "onground": r["onground"],
                "callsign": r["callsign"]}

    _same(ref, opensky.load_states(_write_csv(tmp_path / "h.csv", recs, cols, history)))
    iso = [dict(r, timestamp=np.datetime_as_string(np.datetime64(r["timestamp"], "ms")) + "Z")
           for r in recs]
    _same(ref, opensky.load_states(_write_json(tmp_path / "iso.json", iso)))


# --- selection ------------------------------------------------------------------------------


def test_select_by_window_radius_box_and_ground():
    states = opensky.load_states(excerpt.EXCERPT)
    centre = (48.868, 2.456)
    sel = opensky.select(states, start="2021-10-07T14:05:00Z", end=T0 + 7500.0, centre=centre,
                         radius_m=30_000.0)
    d, _ = vincenty.vdist(centre[0], centre[1], sel.lat, sel.lon)
    assert np.all(d <= 30_000.0) and not sel.onground.any()
    assert sel.t.min() >= T0 + 7500.0 - 2400 - 1e-6 and sel.t.max() <= T0 + 7500.0
    outside = opensky.select(states, airborne_only=False)
    d_all, _ = vincenty.vdist(centre[0], centre[1], outside.lat, outside.lon)
    assert (d_all > 30_000.0).sum() > 1000  # the radius did cut something
    assert opensky.default_frame(sel) == LocalFrame(*centre, 0.0)
    boxed = opensky.select(states, box=(48.8, 49.0, 2.2, 2.6))
    assert boxed.lat.min() >= 48.8 and boxed.lon.max() <= 2.6
    f = opensky.default_frame(boxed)
    assert (f.lat0, f.lon0, f.h0) == pytest.approx((48.9, 2.4, 0.0))


def test_the_shipped_excerpt_loads_with_at_least_ten_aircraft():
    assert excerpt.EXCERPT.stat().st_size <= 2_000_000
    assert "OpenSky" in (excerpt.EXCERPT.parent / "ATTRIBUTION.md").read_text()
    states = opensky.select(opensky.load_states(excerpt.EXCERPT))
    traj = opensky.trajectories(states)
    t0, t1 = traj.span
    assert 14 * 60 <= t1 - t0 <= 15 * 60
    g = traj.grid(np.arange(t0, t1, 5.0))
    assert len(g.ids) >= 10 and g.present.sum(axis=1).max() >= 10
    speed = np.linalg.norm(g.states[..., 3:5], axis=-1)[g.present]
    assert np.median(speed) > 60.0 and np.percentile(speed, 99) < 350.0  # aircraft speeds


@pytest.mark.skipif(not FULL.exists(), reason="the full recording is not on this machine")
def test_the_excerpt_is_cut_reproducibly(tmp_path):
    excerpt.main([str(FULL), str(tmp_path / "again.json.gz")])
    assert (tmp_path / "again.json.gz").read_bytes() == excerpt.EXCERPT.read_bytes()


# --- bad files ------------------------------------------------------------------------------


def test_bad_files_give_one_line_naming_the_file_and_the_field(tmp_path):
    good = _sample_records()
    cases = {
        "nolat.json": ([{k: v for k, v in r.items() if k != "latitude"} for r in good],
                       "latitude"),
        "badtime.json": ([dict(good[0], timestamp="yesterday"), *good[1:]], "timestamp"),
        "notime.json": ([dict(good[0], timestamp=None), *good[1:]], "timestamp"),
        "farlat.json": ([*good[:3], dict(good[3], latitude=91.5)], "latitude"),
        "badlon.json": ([*good[:3], dict(good[3], longitude="east")], "longitude"),
        "noicao.json": ([dict(good[0], icao24=None), *good[1:]], "icao24"),
        "noalt.json": ([{k: v for k, v in r.items() if k != "altitude"} for r in good],
                       "altitude"),
    }
    for name, (recs, field) in cases.items():
        path = _write_json(tmp_path / name, recs)
        with pytest.raises(ValueError) as e:
            opensky.load_states(path)
        _single_line_error(e, name, field)
    (tmp_path / "dict.json").write_text('{"timestamp": 1}')
    (tmp_path / "empty.json").write_text("[]")
    (tmp_path / "broken.csv").write_text("timestamp,icao24\n1,abc\n2")
    (tmp_path / "nolat.csv").write_text("timestamp,icao24\n1,abc\n")
    (tmp_path / "states.xlsx").write_text("")
    for name, words in (("dict.json", ("list of records",)), ("empty.json", ("no reports",)),
                        ("broken.csv", ("CSV",)),
                        ("nolat.csv", ("latitude",)), ("states.xlsx", ("unknown format",)),
                        ("missing.json", ("no such file",))):
        with pytest.raises(ValueError) as e:
            opensky.load_states(tmp_path / name)
        _single_line_error(e, name, *words)
    states = opensky.load_states(_write_json(tmp_path / "ok.json", good))
    with pytest.raises(ValueError) as e:
        opensky.select(states, start=T0 + 1e6)
    _single_line_error(e, "ok.json", "no reports left after filtering")
    with pytest.raises(ValueError, match="max_gap_s"):
        opensky.trajectories(states, max_gap_s=0.0)
