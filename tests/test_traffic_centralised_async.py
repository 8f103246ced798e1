"""The asynchronous centralised reference (sim.studies.traffic.asynchronous, issue 34): its
sequential per-radar updates at the plots' own times against a brute-force Kalman filter run
in time order, its motion against Van Loan's integral, its beam sectors against the beam's
own clock, and its batches against the world's tick scans."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from sensornet.sim.scenario import load_scenario
from sensornet.sim.studies.traffic.asynchronous import (
    AsyncGmphd,
    AsyncLmb,
    Batch,
    ElapsedMotion,
    batch_pd,
    plot_batches,
)
from sensornet.sim.traffic.recorded import recorded_run, recorded_world, tick_plots
from sensornet.sim.world.birth import Beam
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_confirmation import Confirmation
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.reduction import Reducer

SIGMA_W, T = 3.0, 2.0
SIGMAS = (40.0, 150.0)  # radar 0, radar 1 plot noise (m per axis)
VSTD = 30.0  # birth velocity sd (m/s)


def van_loan(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """``F`` and ``Q = int_0^dt e^{As} L q L^T e^{A^T s} ds`` of the white-noise-acceleration
    CV model by Van Loan's matrix exponential (1978), state ``[px, vx, py, vy]``."""
    A = np.zeros((4, 4))
    A[0, 1] = A[2, 3] = 1.0
    L = np.zeros((4, 2))
    L[1, 0] = L[3, 1] = 1.0
    M = np.zeros((8, 8))
    M[:4, :4], M[:4, 4:], M[4:, 4:] = -A, L @ (q * np.eye(2)) @ L.T, A.T
    E = expm(M * dt)
    F = E[4:, 4:].T
    return F, F @ E[:4, 4:]


def test_elapsed_motion_is_van_loan_and_additive():
    m = ElapsedMotion(T, SIGMA_W)
    for dt in (0.0, 0.1, 0.5, 2.0, 7.3):
        F, Q = m.at(dt).transition(1)
        F_ref, Q_ref = van_loan(dt, SIGMA_W**2 * T)
        np.testing.assert_allclose(F, F_ref, atol=1e-12)
        np.testing.assert_allclose(Q, Q_ref, rtol=1e-9, atol=1e-12)
    # two predictions of 0.7 and 1.3 s are one of 2 s (the tick model's Q is not)
    F1, Q1 = m.at(0.7).transition(1)
    F2, Q2 = m.at(1.3).transition(1)
    F, Q = m.at(2.0).transition(1)
    np.testing.assert_allclose(F2 @ F1, F)
    np.testing.assert_allclose(F2 @ Q1 @ F2.T + Q2, Q, rtol=1e-12)
    # one tick's velocity variance is the tick model's
    assert Q[1, 1] == pytest.approx(ConstantVelocity(T, SIGMA_W).Q[1, 1])
    with pytest.raises(ValueError, match="dt >= 0"):
        m.at(-1.0)


def scenario_case(seed: int = 4) -> tuple[list[Batch], list[np.ndarray]]:
    """One target (constant velocity plus random velocity steps), two radars with plots at
    their own times, one plot per batch: the batches in time order and the true states."""
    rng = np.random.default_rng(seed)
    times = {0: [0.3, 2.1, 4.0, 6.2, 8.1], 1: [1.2, 3.3, 5.05, 7.4]}
    ev = sorted((t, s) for s, ts in times.items() for t in ts)
    x = np.array([1000.0, 120.0, -500.0, -60.0])
    last, batches, truth = 0.0, [], []
    for t, s in ev:
        dt = t - last
        x = x + np.array([dt * x[1], 0.0, dt * x[3], 0.0])
        x[[1, 3]] += rng.normal(0.0, 1.0, 2)
        last = t
        z = x[[0, 2]] + rng.normal(0.0, SIGMAS[s], 2)
        batches.append(Batch(s, t, t - 0.25, t + 0.25, z[None]))
        truth.append(x.copy())
    return batches, truth


def brute_force(batches: list[Batch]) -> list[tuple[np.ndarray, np.ndarray]]:
    """A Kalman filter in time order: the first plot with zero velocity (sd ``VSTD``) as its
    prior, then per plot predict over the elapsed time (Van Loan) and update with its
    radar's noise. Returns ``(mean (4,), cov (4, 4))`` after each plot from the second."""
    H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    b0 = batches[0]
    x = np.array([b0.z[0, 0], 0.0, b0.z[0, 1], 0.0])
    P = np.diag([SIGMAS[b0.sensor] ** 2, VSTD**2, SIGMAS[b0.sensor] ** 2, VSTD**2])
    t, out = b0.t, []
    for b in batches[1:]:
        F, Q = van_loan(b.t - t, SIGMA_W**2 * T)
        x, P, t = F @ x, F @ P @ F.T + Q, b.t
        R = SIGMAS[b.sensor] ** 2 * np.eye(2)
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (b.z[0] - H @ x)
        P = (np.eye(4) - K @ H) @ P
        out.append((x, P))
    return out


def lmb_filter(s: int) -> LmbFilter:
    return LmbFilter(motion=ConstantVelocity(T, SIGMA_W),
                     sensor=SensorParams(LinearPosition(SIGMAS[s]), 1.0, 1e-12),
                     survival_probability=1.0, birth_velocity_std=VSTD)


def test_async_lmb_equals_brute_force_kalman_in_time_order():
    batches, _ = scenario_case()
    ref = brute_force(batches)
    lmb = AsyncLmb([lmb_filter(0), lmb_filter(1)], [None, None], [1.0, 1.0],
                   ElapsedMotion(T, SIGMA_W), 1.0)
    st = lmb.initial()
    st = lmb.correct(st, batches[0])
    assert len(st.tracks) == 0 and len(st.pending) == 1  # the first plot: a birth
    for b, (x, P) in zip(batches[1:], ref, strict=True):
        st = lmb.correct(st, b)
        assert len(st.tracks) == 1 and len(st.tracks.weights) == 1
        assert st.tracks.existence[0] > 0.99
        np.testing.assert_allclose(st.tracks.means[0], x, rtol=1e-7, atol=1e-6)
        np.testing.assert_allclose(st.tracks.covs[0], P, rtol=1e-6, atol=1e-6)
        assert lmb.time == b.t


def test_async_gmphd_equals_brute_force_kalman_in_time_order():
    batches, _ = scenario_case(seed=9)
    ref = brute_force(batches)
    sensors = [SensorParams(LinearPosition(s), 1.0, 1e-12) for s in SIGMAS]
    g = AsyncGmphd(sensors, [None, None], ElapsedMotion(T, SIGMA_W), 1.0,
                   Reducer(prune_threshold=1e-5, merge_threshold=4.0, max_components=50),
                   0.5, "threshold", None, 0.2, VSTD, 13.8, Confirmation())
    # birth weight 0.2 > HEAVY: the birth explains the target's next plot (no second birth)
    lm = g.initial()
    lm = g.correct(lm, batches[0])
    assert len(lm) == 0 and len(g.pending) == 1
    for b, (x, P) in zip(batches[1:], ref, strict=True):
        lm = g.correct(lm, b)
        assert len(lm) == 1 and lm.mixture.weights[0] > 0.99
        np.testing.assert_allclose(lm.mixture.means[0], x, rtol=1e-7, atol=1e-6)
        np.testing.assert_allclose(lm.mixture.covs[0], P, rtol=1e-6, atol=1e-6)


def test_async_refuses_a_batch_from_the_past():
    batches, _ = scenario_case()
    lmb = AsyncLmb([lmb_filter(0), lmb_filter(1)], [None, None], [1.0, 1.0],
                   ElapsedMotion(T, SIGMA_W), 1.0)
    st = lmb.correct(lmb.initial(), batches[1])
    with pytest.raises(ValueError, match="before the state's time"):
        lmb.correct(st, batches[0])


def test_batch_pd_is_the_sector_the_beam_swept_in_the_slice():
    period, phase = 4.0, 1.3  # beam north at 1.3 + n 4 s, clockwise
    beam = Beam(period=period, phase=phase, T=2.0, site=(100.0, -200.0),
                pd=lambda r: np.full(len(r), 0.9), margin_deg=0.0)
    rng = np.random.default_rng(0)
    az = rng.uniform(0, 360, 400)
    means = np.zeros((400, 4))
    means[:, 0] = 100.0 + 5e3 * np.sin(np.radians(az))
    means[:, 2] = -200.0 + 5e3 * np.cos(np.radians(az))
    for start in (0.0, 0.5, 3.9, 11.2):
        b = Batch(0, start + 0.25, start, start + 0.5, np.zeros((0, 2)))
        pd = batch_pd(beam, 0.5, b, means)
        # the beam crosses azimuth a at phase + (n + a / 360) period: inside iff one such time
        # falls in the slice (its ends have measure zero here)
        hit = (az / 360 * period + phase - start) % period
        inside = hit <= 0.5
        np.testing.assert_array_equal(pd > 0, inside)
        assert np.all(pd[inside] == 0.9)
    assert np.all(batch_pd(None, 0.7, b, means) == 0.7)


def test_plot_batches_hold_the_tick_scans_at_their_own_times():
    scn = load_scenario("paris-8", overrides={"traffic.start": 0.0, "scenario.num_scans": 10})
    slice_s = 0.5
    batches = plot_batches(scn, 0, slice_s)
    _, scans = recorded_run(scn, 0)
    t0 = recorded_world(scn).t0
    assert len(batches) == scn.num_scans
    for k, bs in enumerate(batches):
        assert [b.t for b in bs] == sorted(b.t for b in bs)
        for s in range(len(scn.sensors)):
            mine = [b for b in bs if b.sensor == s]
            assert len(mine) == 4  # every slice of the tick, empty ones too
            z = np.concatenate([b.z for b in mine]).reshape(-1, 2)
            ref = scans[s][k]
            assert sorted(map(tuple, z)) == sorted(map(tuple, ref))
    # every plot is in the batch whose slice holds its own time
    p = tick_plots(scn, 0)[0]
    flat = [b for bs in batches for b in bs if b.sensor == 0]
    for t, z in zip(p.t_meas - t0, p.z, strict=True):
        (b,) = [b for b in flat if b.start < t <= b.end]
        assert abs(t - b.t) <= slice_s / 2 + 1e-9
        assert any(np.array_equal(z, y) for y in b.z)
    with pytest.raises(ValueError, match="slice_s must divide"):
        plot_batches(scn, 0, 0.7)
