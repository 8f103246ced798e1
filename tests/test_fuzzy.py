"""Fuzzy association system and the Neyman-Pearson manoeuvre detector (tracking/fuzzy.py)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2
from sensornet.tracking.fuzzy import FuzzySystem, FuzzyWeighting, ManoeuvreDetector
from sensornet.tracking.pda import ImmPda, LinearSensor

SCENARIO = Path(__file__).parents[1] / "sim" / "scenarios" / "seed003.toml"


def load() -> dict:
    return tomllib.loads(SCENARIO.read_text(encoding="utf-8"))


H4 = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])


def direct(cfg, y1, y2):
    """The shipped rule base evaluated rule by rule: product inference, centre of gravity."""
    num = den = 0.0
    for a, b, out in cfg["rules"]:
        c1, w1 = cfg["inputs"]["nis"][a]
        c2, w2 = cfg["inputs"]["dl"][b]
        fire = math.exp(-0.5 * ((y1 - c1) / w1) ** 2) * math.exp(-0.5 * ((y2 - c2) / w2) ** 2)
        num += fire * cfg["outputs"][out]
        den += fire
    return num / den


def test_fuzzy_system_equals_direct_rule_evaluation():
    cfg = load()["fuzzy"]
    fis = FuzzySystem.from_config(cfg)
    g = np.linspace(0, 15, 31)
    for d in (0.5, 1.0, 2.5, 4.0, 7.0):
        np.testing.assert_allclose(fis(g, d), [direct(cfg, x, d) for x in g], rtol=1e-12)
    # the shipped rules' intent: with no manoeuvre near returns weigh more, in one far ones do
    assert fis(0.5, 1.0) > fis(9.0, 1.0)
    assert fis(6.0, 4.0) > fis(0.5, 4.0)


def test_fuzzy_config_errors_name_the_culprit():
    cfg = load()["fuzzy"]
    bad = dict(cfg, rules=[["small", "lowish", "high"]])
    with pytest.raises(ValueError, match="unknown inputs.dl term 'lowish'"):
        FuzzySystem.from_config(bad)
    with pytest.raises(ValueError, match="missing key 'outputs'"):
        FuzzySystem.from_config({k: v for k, v in cfg.items() if k != "outputs"})


def test_detector_threshold_is_the_chi2_quantile():
    det = ManoeuvreDetector(window=4, false_alarm=0.05)
    for eps in (1.0, 2.0, 3.0, 4.0, 100.0):
        det.new_scan()
        det.observe(eps, 2)
    assert det.statistic == (109.0, 8)  # the window forgot the first scan
    assert det.threshold(8) == pytest.approx(chi2.ppf(0.95, 8))
    assert det.fired


def test_switched_weighting_applies_degrees_only_while_the_detector_fires():
    fis = FuzzySystem(np.array([[0.0, 1.0]]), np.array([[1.0, 1.0]]), np.array([0.3]))
    w = FuzzyWeighting(fis, ManoeuvreDetector(2, 0.01), "switched")
    w.new_scan()
    w.observe(1.0, 2)
    assert w.degrees(np.array([[1.0, 2.0]])) is None
    w.observe(40.0, 2)
    np.testing.assert_allclose(w.degrees(np.array([[1.0, 2.0]])), [[0.3, 0.3]])
    always = FuzzyWeighting(fis, ManoeuvreDetector(2, 0.01), "always")
    always.new_scan()
    assert always.degrees(np.array([[1.0]])) is not None


def test_detector_false_alarm_rate_on_manoeuvre_free_runs():
    """Matched CV filter, no clutter, PD = PG = 1 (so the PDA is the Kalman filter and its
    innovations are white chi2): the per-scan false-alarm rate is the set rate."""
    T, q, sigma, L, pf = 1.0, 2.0, 50.0, 5, 0.05
    F = np.array([[1, T, 0, 0], [0, 1, 0, 0], [0, 0, 1, T], [0, 0, 0, 1]], float)
    G = np.array([[T * T / 2, 0], [T, 0], [0, T * T / 2], [0, T]])
    Q = q * q * G @ G.T
    sensor = LinearSensor(H4, sigma**2 * np.eye(2), 1e-9, 1.0, 1.0)
    fis = FuzzySystem(np.zeros((1, 2)), np.ones((1, 2)), np.ones(1))
    rng = np.random.default_rng(2026)
    runs, scans = 300, 40
    P0 = np.diag([100.0**2, 20.0**2, 100.0**2, 20.0**2])
    fired = np.zeros((runs, scans), bool)
    for r in range(runs):
        x = rng.multivariate_normal([0, 300, 0, 0], P0)
        w = FuzzyWeighting(fis, ManoeuvreDetector(L, pf), "switched")
        f = ImmPda([(F, Q)], np.eye(1), np.array([0, 300.0, 0, 0]), P0, weighting=w)
        for k in range(scans):
            x = F @ x + G @ rng.normal(0, q, 2)
            z = H4 @ x + rng.normal(0, sigma, 2)
            f.step([sensor], [z[None]])
            fired[r, k] = w.detector.fired
    rate = fired[:, L - 1:].mean()
    # overlapping windows correlate the flags: allow ~3 standard errors of about L x binomial
    n_eff = fired[:, L - 1:].size / L
    se = math.sqrt(pf * (1 - pf) / n_eff)
    assert abs(rate - pf) < 3 * se, (rate, se)


def test_fit_recovers_known_outputs_and_round_trips_through_config():
    from sensornet.tracking.fuzzy import fit, to_config

    rng = np.random.default_rng(5)
    true = FuzzySystem(np.array([[0.0, 1.0], [8.0, 1.0], [4.0, 4.0]]),
                       np.array([[2.0, 1.0], [2.0, 1.0], [2.0, 1.0]]), np.array([0.9, 0.1, 0.6]))
    g, d = rng.uniform(0, 12, 20000), rng.uniform(0, 6, 20000)
    t = rng.random(20000) < true(g, d)
    start = FuzzySystem(true.centres, true.widths, np.full(3, 0.5))
    got = fit(start, g, d, t, "outputs")
    np.testing.assert_allclose(got.outputs, true.outputs, atol=0.05)
    again = FuzzySystem.from_config(to_config(got))
    np.testing.assert_allclose(again(g[:50], d[:50]), got(g[:50], d[:50]))
