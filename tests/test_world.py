"""The simulated world: truth follows the table, scans follow Pd, clutter and the sensor model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sensornet.sim.scenario import Scenario, SensorSpec, load_scenario
from sensornet.sim.world import generate_run, generate_scans, generate_truth, sensor_rng
from sensornet.sim.world.build import measurement_box

LONG_TARGETS = [
    {"birth_scan": 1, "death_scan": 1000, "start": [-500.0, -500.0], "end": [500.0, 500.0]},
    {"birth_scan": 1, "death_scan": 1000, "start": [500.0, -500.0], "end": [-500.0, 500.0]},
    {"birth_scan": 1, "death_scan": 1000, "start": [0.0, 900.0], "end": [0.0, -900.0]},
]
RADAR = {"name": "r1", "kind": "range-bearing", "position": [1000.0, 0.0], "sigma_r": 10.0,
         "sigma_theta_deg": 2.0, "detection_probability": 0.9, "clutter_rate": 10}


@pytest.fixture(scope="module")
def seed000() -> Scenario:
    return load_scenario("seed000")


def long_run(**overrides) -> Scenario:
    """1000 scans, three targets alive throughout: enough samples for rate checks."""
    return load_scenario("seed000", {"scenario.num_scans": 1000, "targets": LONG_TARGETS,
                                     **overrides})


# --- truth ---------------------------------------------------------------------------------


def test_truth_starts_and_ends_on_the_table(seed000: Scenario) -> None:
    truth = generate_truth(seed000)
    assert truth.num_scans == 100
    for tid, tgt in enumerate(seed000.targets, start=1):
        first = truth.states[tgt.birth_scan - 1][truth.ids[tgt.birth_scan - 1] == tid]
        last = truth.states[tgt.death_scan - 1][truth.ids[tgt.death_scan - 1] == tid]
        np.testing.assert_allclose(first[0, [0, 2]], tgt.start, atol=1e-9)
        np.testing.assert_allclose(last[0, [0, 2]], tgt.end, atol=1e-9)
        # constant velocity: the state's velocity carries it from one scan to the next
        np.testing.assert_allclose(first[0, [1, 3]] * (tgt.death_scan - tgt.birth_scan),
                                   np.subtract(tgt.end, tgt.start), atol=1e-9)


def test_truth_count_per_scan_matches_the_table(seed000: Scenario) -> None:
    counts = generate_truth(seed000).counts()
    expected = np.zeros(100, dtype=int)
    for k in range(1, 101):  # table: 1-100, 20-60, 40-80, 40-80 (inclusive)
        expected[k - 1] = (1 + (20 <= k <= 60) + 2 * (40 <= k <= 80))
    np.testing.assert_array_equal(counts, expected)
    truth = generate_truth(seed000)
    assert all(s.shape == (len(i), 4) for s, i in zip(truth.states, truth.ids, strict=True))
    assert truth.positions(50).shape == (4, 2)


def test_truth_noise_is_seeded_and_optional(seed000: Scenario) -> None:
    noisy = dataclasses.replace(seed000, truth_sigma_w=1.0)
    a = generate_truth(noisy, np.random.default_rng(1))
    b = generate_truth(noisy, np.random.default_rng(1))
    exact = generate_truth(seed000)
    np.testing.assert_array_equal(a.states[50], b.states[50])
    assert not np.allclose(a.states[50], exact.states[50])
    np.testing.assert_allclose(a.states[0][:, [0, 2]], exact.states[0][:, [0, 2]])  # at birth
    with pytest.raises(ValueError):
        generate_truth(noisy)


def test_truth_is_clipped_to_the_run(seed000: Scenario) -> None:
    short = dataclasses.replace(seed000, num_scans=30)
    counts = generate_truth(short).counts()
    assert len(counts) == 30 and counts[-1] == 2


# --- scans ---------------------------------------------------------------------------------


def test_detection_rate_matches_pd() -> None:
    scn = long_run(**{"sensors.*.clutter_rate": 0, "sensors.*.detection_probability": 0.7})
    truth, scans = generate_run(scn, 0)
    n_true = truth.counts().sum()  # 3000 target-scans per sensor
    for per_sensor in scans:
        rate = sum(len(z) for z in per_sensor) / n_true
        assert rate == pytest.approx(0.7, abs=4 * np.sqrt(0.7 * 0.3 / n_true))


def test_clutter_count_matches_rate_and_stays_in_the_region() -> None:
    scn = long_run(**{"sensors.*.detection_probability": 0.0, "sensors[0].clutter_rate": 10,
                      "sensors[1].clutter_rate": 3})
    _, scans = generate_run(scn, 0)
    for spec, per_sensor in zip(scn.sensors, scans, strict=True):
        counts = np.array([len(z) for z in per_sensor])
        lam = spec.clutter_rate
        assert counts.mean() == pytest.approx(lam, abs=4 * np.sqrt(lam / len(counts)))
        assert counts.var() == pytest.approx(lam, rel=0.2)  # Poisson: variance = mean
        z = np.concatenate(per_sensor)
        low, high = measurement_box(scn, spec)
        assert np.all(z >= low) and np.all(z < high)


def test_linear_measurement_noise_is_sigma_r() -> None:
    one = [LONG_TARGETS[0]]
    scn = long_run(targets=one, **{"sensors.*.clutter_rate": 0,
                                   "sensors.*.detection_probability": 1.0})
    truth, scans = generate_run(scn, 3)
    err = np.concatenate(scans[0]) - np.concatenate([truth.positions(k) for k in range(1, 1001)])
    np.testing.assert_allclose(err.mean(axis=0), 0.0, atol=4 * 20 / np.sqrt(1000))
    np.testing.assert_allclose(err.std(axis=0), 20.0, rtol=0.1)


def test_range_bearing_scans() -> None:
    scn = long_run(sensors=[RADAR], **{"fusion.fusing_sensor": "r1"})
    truth, scans = generate_run(scn, 0)
    z = np.concatenate(scans[0])
    assert z.shape[1] == 2
    assert np.all(z[:, 1] >= -np.pi) and np.all(z[:, 1] < np.pi)
    assert np.all(z[:, 0] >= 0)
    # detections + clutter per scan: 0.9 * 3 + 10 on average
    assert len(z) / 1000 == pytest.approx(0.9 * 3 + 10, abs=0.5)
    # a clutter-free radar measures range and bearing around the truth
    clean = long_run(targets=[LONG_TARGETS[2]], sensors=[{**RADAR, "clutter_rate": 0,
                     "detection_probability": 1.0}], **{"fusion.fusing_sensor": "r1"})
    truth, scans = generate_run(clean, 0)
    pos = np.concatenate([truth.positions(k) for k in range(1, 1001)]) - [1000.0, 0.0]
    z = np.concatenate(scans[0])
    np.testing.assert_allclose(z[:, 0] - np.hypot(pos[:, 0], pos[:, 1]), 0, atol=50)
    dtheta = (z[:, 1] - np.arctan2(pos[:, 1], pos[:, 0]) + np.pi) % (2 * np.pi) - np.pi
    assert dtheta.std() == pytest.approx(np.deg2rad(2.0), rel=0.1)


def test_scan_shapes_and_empty_scans(seed000: Scenario) -> None:
    quiet = load_scenario("seed000", {"targets": [], "sensors.*.clutter_rate": 0})
    truth, scans = generate_run(quiet, 0)
    assert all(s.shape == (0, 4) for s in truth.states)
    assert all(z.shape == (0, 2) for per_sensor in scans for z in per_sensor)
    _, scans = generate_run(seed000, 0)
    assert len(scans) == 3 and all(len(per_sensor) == 100 for per_sensor in scans)


# --- determinism ---------------------------------------------------------------------------


def test_same_seed_and_run_give_identical_scans(seed000: Scenario) -> None:
    t1, a = generate_run(seed000, 4)
    t2, b = generate_run(seed000, 4)
    for k in range(100):
        np.testing.assert_array_equal(t1.states[k], t2.states[k])
        for s in range(3):
            np.testing.assert_array_equal(a[s][k], b[s][k])


def test_different_runs_and_seeds_differ(seed000: Scenario) -> None:
    _, a = generate_run(seed000, 0)
    _, b = generate_run(seed000, 1)
    _, c = generate_run(dataclasses.replace(seed000, seed=1), 0)
    assert not np.array_equal(np.concatenate(a[0]), np.concatenate(b[0]))
    assert not np.array_equal(np.concatenate(a[0]), np.concatenate(c[0]))
    # the sensors' streams are independent of each other
    assert not np.array_equal(np.concatenate(a[0]), np.concatenate(a[2]))


def test_adding_or_reordering_sensors_keeps_the_others_scans(seed000: Scenario) -> None:
    extra = SensorSpec("s4", "range-bearing", (0.0, 0.0), 5.0, 1.0)
    bigger = dataclasses.replace(seed000, sensors=(extra, *reversed(seed000.sensors)))
    _, base = generate_run(seed000, 2)
    _, more = generate_run(bigger, 2)
    for s, name in enumerate(seed000.sensor_names):
        i = bigger.sensor_names.index(name)
        for k in range(100):
            np.testing.assert_array_equal(base[s][k], more[i][k])


def test_generate_scans_accepts_one_generator(seed000: Scenario) -> None:
    truth = generate_truth(seed000)
    a = generate_scans(seed000, truth, np.random.default_rng(7))
    b = generate_scans(seed000, truth, np.random.default_rng(7))
    assert len(a) == 3
    np.testing.assert_array_equal(a[1][10], b[1][10])
    per_sensor = generate_scans(seed000, truth, [sensor_rng(seed000, 0, n)
                                                 for n in seed000.sensor_names])
    np.testing.assert_array_equal(per_sensor[0][5], generate_run(seed000, 0)[1][0][5])
