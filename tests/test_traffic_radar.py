"""Sensors scanning recorded traffic (sim/traffic/radar.py): the detection curve, the noise,
clutter, each radar's own clock and beam, the range limit, the ADS-B receiver."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sensornet.sim.traffic import opensky, radar
from sensornet.sim.traffic.excerpt import EXCERPT
from sensornet.sim.traffic.opensky import LocalFrame, Trajectories
from sensornet.tracking.models import RangeBearing, wrap_angle

FRAME = LocalFrame(48.868, 2.456, 0.0)
T0 = 1_633_615_200.0


def _static(points: np.ndarray) -> Trajectories:
    """Aircraft standing still at ENU ``points (A, 3)`` from T0 - 10 s to T0 + 1e5 s."""
    A = len(points)
    return Trajectories(frame=FRAME, ids=np.array([f"{i:06x}" for i in range(A)]),
                        t=np.tile([T0 - 10.0, T0 + 1e5], A), enu=np.repeat(points, 2, axis=0),
                        starts=np.arange(0, 2 * A + 1, 2), max_gap_s=1e9)


def _moving(p0: np.ndarray, v: np.ndarray) -> Trajectories:
    """Aircraft on straight lines ``p0 + v (t - T0)`` (A, 3), reported every second."""
    A = len(p0)
    t = T0 + np.arange(-10.0, 400.0)
    enu = p0[:, None, :] + (t - T0)[None, :, None] * v[:, None, :]
    return Trajectories(frame=FRAME, ids=np.array([f"{i:06x}" for i in range(A)]),
                        t=np.tile(t, A), enu=enu.reshape(-1, 3),
                        starts=np.arange(0, A * len(t) + 1, len(t)))


def _radar(**kw) -> radar.RotatingRadar:
    return radar.RotatingRadar("site", FRAME.lat0, FRAME.lon0, 0.0, **kw)


def _ring(ranges, heights=0.0, bearing_deg=None) -> np.ndarray:
    ranges = np.asarray(ranges, float)
    b = (np.radians(bearing_deg) if bearing_deg is not None
         else np.linspace(0, 2 * math.pi, len(ranges), endpoint=False))
    return np.stack([ranges * np.cos(b), ranges * np.sin(b),
                     np.broadcast_to(heights, ranges.shape)], axis=1)


def test_detection_rate_follows_the_pd_curve_and_stops_at_max_range():
    r = _radar(max_range_m=100_000.0, r50_m=80_000.0, pd_max=0.95, clutter_per_scan=0.0)
    ranges = np.linspace(5_000.0, 130_000.0, 26)
    pts = _ring(ranges, heights=np.where(np.arange(26) % 2, 9_000.0, 500.0))
    traj = _static(pts)
    rng = np.random.default_rng(11)
    n = 600
    t0 = r.rotation_starts(T0, T0 + 2 * r.period_s)[0]
    scans = r.scans(traj, t0, t0 + n * r.period_s, rng)
    assert len(scans) == n
    seen = np.concatenate([s.truth for s in scans])
    counts = np.array([(seen == i).sum() for i in traj.ids])
    p = r.pd(np.linalg.norm(pts - r.site(FRAME), axis=1))  # slant range, not ground range
    assert np.all(p[ranges > 100_000.0] == 0.0) and counts[ranges > 100_000.0].sum() == 0
    sd = np.sqrt(n * p * (1 - p))
    assert np.all(np.abs(counts - n * p) <= 4.5 * sd + 1), (counts, n * p)
    # the curve itself: pd_max near, half of it at r50 (Swerling I), falling, 0 beyond
    near, at50, far = r.pd(np.array([1_000.0, 80_000.0, 99_000.0]))
    assert near == pytest.approx(0.95, abs=1e-3) and at50 == pytest.approx(0.475, abs=1e-9)
    assert np.all(np.diff(r.pd(np.linspace(1e3, 99e3, 50))) <= 0) and far < at50


def test_range_and_bearing_noise_have_the_stated_sigmas():
    r = _radar(sigma_r=40.0, sigma_b_deg=0.1, pd_max=1.0, r50_m=1e7, max_range_m=2e5,
               clutter_per_scan=0.0)
    pts = np.repeat(_ring([45_000.0], 3_000.0, bearing_deg=[30.0]), 100, axis=0)
    traj = _static(pts)
    t0 = r.rotation_starts(T0, T0 + 2 * r.period_s)[0]
    scans = r.scans(traj, t0, t0 + 200 * r.period_s, np.random.default_rng(5))
    z = np.concatenate([s.z_rb for s in scans])
    xy = np.concatenate([s.z_xy for s in scans])
    assert len(z) == 20_000
    true_r, true_b = 45_000.0, math.radians(30.0)
    dr, db = z[:, 0] - true_r, wrap_angle(z[:, 1] - true_b)
    assert np.std(dr) == pytest.approx(40.0, rel=0.05) and abs(dr.mean()) < 4 * 40 / 141
    assert np.std(db) == pytest.approx(math.radians(0.1), rel=0.05)
    assert abs(db.mean()) < 4 * math.radians(0.1) / 141
    # x-y plots are the same measurements; their covariance is the stated R_xy
    np.testing.assert_allclose(xy, z[:, :1] * np.stack([np.cos(z[:, 1]), np.sin(z[:, 1])], 1),
                               atol=1e-6)
    emp = np.cov((xy - pts[0, :2]).T)
    np.testing.assert_allclose(emp, scans[0].R_xy[0], rtol=0.08, atol=100.0)
    model = r.measurement_model(FRAME)
    assert isinstance(model, RangeBearing)
    zhat = model.h(np.array([[pts[0, 0], 0.0, pts[0, 1], 0.0]]))
    np.testing.assert_allclose(zhat, [[true_r, true_b]], atol=1e-6)  # same convention


def test_clutter_count_is_poisson_with_the_stated_mean_inside_coverage():
    r = _radar(clutter_per_scan=3.0, max_range_m=60_000.0)
    traj = _static(_ring([500_000.0]))  # one aircraft far beyond range
    t0 = r.rotation_starts(T0, T0 + 2 * r.period_s)[0]
    scans = r.scans(traj, t0, t0 + 4000 * r.period_s, np.random.default_rng(2))
    n = np.array([len(s.truth) for s in scans])
    assert len(n) == 4000 and all((s.truth == "").all() for s in scans)
    assert abs(n.mean() - 3.0) < 4 * math.sqrt(3.0 / 4000)
    assert n.var() == pytest.approx(3.0, rel=0.1)
    rc = np.concatenate([s.z_rb[:, 0] for s in scans])
    assert rc.max() <= 60_000.0
    inner = (rc <= 30_000.0).mean()  # uniform in area: a quarter within half the range
    assert abs(inner - 0.25) < 4 * math.sqrt(0.25 * 0.75 / len(rc))


def test_each_radar_scans_on_its_own_period_and_phase():
    term = radar.RotatingRadar("CDG-T", 49.0097, 2.5479, period_s=4.8)
    term2 = radar.RotatingRadar("ORY-T", 48.7262, 2.3652, period_s=4.8)
    enroute = radar.RotatingRadar("EN-R", 48.6, 2.0, period_s=10.0, phase_s=23.5)
    t1 = T0 + 3600.0
    for r in (term, term2, enroute):
        t = r.scan_times(T0, t1)
        np.testing.assert_allclose(np.diff(t), r.period_s, rtol=0, atol=1e-6)
        k = (t - r.phase) / r.period_s
        np.testing.assert_allclose(k, np.round(k), atol=1e-6)
        assert T0 <= t[0] - r.period_s < T0 + r.period_s and t[-1] <= t1
    assert enroute.phase == pytest.approx(3.5)
    a, b = term.scan_times(T0, t1), term2.scan_times(T0, t1)
    gap = np.abs(a[:, None] - b[None, :]).min()
    assert gap > 0.2, "two terminal radars with default phases scan in step"
    traj = opensky.trajectories(opensky.select(opensky.load_states(EXCERPT)))
    s0, s1 = traj.span
    merged = radar.merged(term.scans(traj, s0, s1, np.random.default_rng(0)),
                          enroute.scans(traj, s0, s1, np.random.default_rng(1)))
    times = [s.t for s in merged]
    assert times == sorted(times) and {s.radar for s in merged} == {"CDG-T", "EN-R"}


def test_each_aircraft_is_plotted_when_the_beam_crosses_it():
    """Static aircraft: the plot time is start + azimuth/360 x period. Moving aircraft: the
    plot is the aircraft where it is at that time, on the beam (noise set near zero)."""
    r = _radar(period_s=5.0, phase_s=0.0, pd_max=1.0, r50_m=1e7, max_range_m=2e5,
               clutter_per_scan=0.0, sigma_r=1e-6, sigma_b_deg=1e-9)
    compass = np.array([0.5, 90.0, 200.0, 359.0])
    pts = _ring(np.full(4, 30_000.0), 1_000.0, bearing_deg=90.0 - compass)
    start = r.rotation_starts(T0, T0 + 20.0)[0]
    s = r.scan(_static(pts), start, np.random.default_rng(0))
    order = np.argsort(s.truth)
    np.testing.assert_allclose(s.t_meas[order] - start, compass / 360.0 * 5.0, atol=1e-6)
    assert s.t == pytest.approx(start + 5.0) and np.all(np.diff(s.t_meas) >= 0)
    p0 = _ring(np.full(8, 20_000.0), 3_000.0)
    v = np.stack([-p0[:, 1], p0[:, 0], np.zeros(8)], 1) / 20_000.0 * 250.0  # tangential
    traj = _moving(p0, v)
    s = r.scan(traj, start, np.random.default_rng(0))
    assert len(s.truth) == 8
    idx = np.searchsorted(traj.ids, s.truth)
    truth, present = traj.evaluate(idx, s.t_meas)
    assert present.all()
    np.testing.assert_allclose(s.z_xy, truth[:, :2], atol=1e-3)
    beam = 2 * math.pi * (s.t_meas - start) / 5.0
    az = np.arctan2(truth[:, 0], truth[:, 1]) % (2 * math.pi)
    np.testing.assert_allclose(wrap_angle(az - beam), 0.0, atol=1e-4)  # 0.1 ms of beam
    snap = _radar(period_s=5.0, phase_s=0.0, sweep=False, clutter_per_scan=0.0)
    s = snap.scan(traj, start, np.random.default_rng(0))
    assert np.all(s.t_meas == start + 5.0)


def test_same_seed_same_scans_and_every_draw_from_the_generator():
    traj = opensky.trajectories(opensky.select(opensky.load_states(EXCERPT)))
    r = radar.RotatingRadar("CDG", 49.0097, 2.5479)
    s0, s1 = traj.span
    a = r.scans(traj, s0, s0 + 120, np.random.default_rng(3))
    b = r.scans(traj, s0, s0 + 120, np.random.default_rng(3))
    c = r.scans(traj, s0, s0 + 120, np.random.default_rng(4))
    assert all(np.array_equal(x.z_rb, y.z_rb) for x, y in zip(a, b, strict=True))
    assert not all(np.array_equal(x.z_rb, y.z_rb) for x, y in zip(a, c, strict=True))
    assert np.mean([(x.truth != "").sum() for x in a]) >= 10  # real aircraft seen


def test_adsb_receiver_range_dropouts_and_noise():
    rx = radar.AdsbReceiver("rx", FRAME.lat0, FRAME.lon0, max_range_m=100_000.0, p_drop=0.2,
                            sigma_m=15.0, period_s=1.0, phase_s=0.25)
    pts = _ring(np.r_[np.full(50, 60_000.0), np.full(5, 140_000.0)], 10_000.0)
    traj = _static(pts)
    scans = rx.scans(traj, T0, T0 + 400.0, np.random.default_rng(9))
    assert len(scans) == 400 and all((s.t - 0.25) % 1.0 == pytest.approx(0.0) for s in scans)
    ids = np.concatenate([s.ids for s in scans])
    assert not np.isin(traj.ids[50:], ids).any()  # beyond range: never
    n, kept = 50 * 400, len(ids)
    assert abs(kept - 0.8 * n) < 4.5 * math.sqrt(n * 0.8 * 0.2)
    err = np.concatenate([s.z_xy - pts[np.searchsorted(traj.ids, s.ids), :2] for s in scans])
    assert np.std(err, axis=0) == pytest.approx([15.0, 15.0], rel=0.05)
    assert rx.measurement_model(FRAME).sigma_r == 15.0


def test_bad_sensor_parameters_are_refused():
    with pytest.raises(ValueError, match="period_s"):
        radar.RotatingRadar("x", 48.0, 2.0, period_s=0.0)
    with pytest.raises(ValueError, match="out of range"):
        radar.RotatingRadar("x", 98.0, 2.0)
    with pytest.raises(ValueError, match="p_drop"):
        radar.AdsbReceiver("x", 48.0, 2.0, p_drop=1.0)
