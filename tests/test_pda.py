"""PDAF / IMM-PDAF (tracking/pda.py) against a hand computation, a loop reference and the
Kalman filter."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sensornet.tracking.pda import ImmPda, LinearSensor

H4 = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])


def cv4(T=1.0, q=1.0):
    F = np.array([[1, T, 0, 0], [0, 1, 0, 0], [0, 0, 1, T], [0, 0, 0, 1]], float)
    G = np.array([[T * T / 2, 0], [T, 0], [0, T * T / 2], [0, T]])
    return F, q * q * G @ G.T


def test_two_returns_by_hand():
    """P = I (so S = 2 I), returns at nu = (1, 0) and (0, 2): every number by hand."""
    lam, pd, pg = 0.01, 0.9, 0.99
    sensor = LinearSensor(H4, np.eye(2), lam, pd, pg)
    f = ImmPda([(np.eye(4), np.zeros((4, 4)))], np.eye(1), np.zeros(4), np.eye(4))
    up = f.update(sensor, np.array([[1.0, 0.0], [0.0, 2.0]]))
    # S = 2 I, |2 pi S| = (4 pi)^2, g = (0.5, 2)
    norm = 1.0 / (4 * math.pi)
    L1 = pd / lam * math.exp(-0.25) * norm
    L2 = pd / lam * math.exp(-1.0) * norm
    b = 1 - pd * pg
    d = b + L1 + L2
    b0, b1, b2 = b / d, L1 / d, L2 / d
    assert up.beta0 == pytest.approx(b0)
    np.testing.assert_allclose(up.weights, [b1, b2])
    # K = P H^T S^-1 = H^T / 2; nubar = (b1, 2 b2)
    nubar = np.array([b1, 2 * b2])
    np.testing.assert_allclose(f.x[0], [nubar[0] / 2, 0, nubar[1] / 2, 0])
    # P+ = P - (1 - b0) K S K^T + K (sum b nu nu^T - nubar nubar^T) K^T
    KSKt = np.zeros((4, 4))
    KSKt[0, 0] = KSKt[2, 2] = 0.5
    spread = b1 * np.outer([1, 0], [1, 0]) + b2 * np.outer([0, 2], [0, 2]) - np.outer(nubar, nubar)
    Kspread = np.zeros((4, 4))
    Kspread[np.ix_([0, 2], [0, 2])] = spread / 4
    np.testing.assert_allclose(f.P[0], np.eye(4) - (1 - b0) * KSKt + Kspread, atol=1e-12)


def loop_reference(xs, Ps, probs, Pi, models, sensor, Z):
    """IMM-PDAF one cycle written with loops over models and returns (no einsum)."""
    M = len(models)
    c = [sum(Pi[i, j] * probs[i] for i in range(M)) for j in range(M)]
    mixed_x, mixed_P = [], []
    for j in range(M):
        w = [Pi[i, j] * probs[i] / c[j] for i in range(M)]
        x0 = sum(w[i] * xs[i] for i in range(M))
        P0 = sum(w[i] * (Ps[i] + np.outer(xs[i] - x0, xs[i] - x0)) for i in range(M))
        mixed_x.append(x0)
        mixed_P.append(P0)
    preds = [(F @ x, F @ P @ F.T + Q) for (F, Q), x, P in zip(models, mixed_x, mixed_P,
                                                                strict=True)]
    H, R = sensor.H, sensor.R
    keep = []
    for z in Z:
        inside = False
        for x, P in preds:
            S = H @ P @ H.T + R
            nu = z - H @ x
            inside |= nu @ np.linalg.solve(S, nu) < sensor.gamma
        if inside:
            keep.append(z)
    out_x, out_P, lik = [], [], []
    b = 1 - sensor.detection_probability * sensor.gate_probability
    for x, P in preds:
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        Ls = []
        for z in keep:
            nu = z - H @ x
            dens = math.exp(-0.5 * nu @ np.linalg.solve(S, nu)) / math.sqrt(
                np.linalg.det(2 * math.pi * S))
            Ls.append(sensor.detection_probability * dens / sensor.clutter_density)
        d = b + sum(Ls)
        beta = [v / d for v in Ls]
        beta0 = b / d
        nubar = sum((be * (z - H @ x) for be, z in zip(beta, keep, strict=True)), np.zeros(2))
        x_new = x + K @ nubar
        spread = sum((be * np.outer(z - H @ x, z - H @ x) for be, z in zip(beta, keep,
                                                                               strict=True)),
                     np.zeros((2, 2))) - np.outer(nubar, nubar)
        P_new = beta0 * P + (1 - beta0) * (P - K @ S @ K.T) + K @ spread @ K.T
        out_x.append(x_new)
        out_P.append(P_new)
        lik.append(d)
    p = np.array(c) * np.array(lik)
    return np.array(out_x), np.array(out_P), p / p.sum()


@pytest.mark.parametrize("seed", range(5))
def test_imm_pda_matches_loop_reference(seed):
    rng = np.random.default_rng(seed)
    models = [cv4(q=0.5), cv4(q=20.0)]
    Pi = np.array([[0.9, 0.1], [0.2, 0.8]])
    xs = rng.normal(0, 10, (2, 4))
    A = rng.normal(0, 1, (2, 4, 4))
    Ps = A @ A.transpose(0, 2, 1) * 30 + 5 * np.eye(4)
    probs = np.array([0.7, 0.3])
    sensor = LinearSensor(H4, np.diag([25.0, 36.0]), 1e-3, 0.9, 0.99)
    Z = xs[0][[0, 2]] + rng.normal(0, 60, (12, 2))
    f = ImmPda(models, Pi, np.zeros(4), np.eye(4), probs)
    f.x, f.P = xs.copy(), Ps.copy()
    f.predict()
    up = f.update(sensor, Z)
    rx, rP, rp = loop_reference(xs, Ps, probs, Pi, models, sensor, Z)
    assert 0 < len(up.returns) < 12  # some returns gated out, some kept
    np.testing.assert_allclose(f.x, rx, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f.P, rP, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f.probs, rp, rtol=1e-9)


def test_no_clutter_pd_one_is_kalman_filter():
    """PD = PG = 1 and exactly one return per scan: the PDAF is the Kalman filter."""
    rng = np.random.default_rng(7)
    F, Q = cv4(q=2.0)
    R = np.diag([50.0**2, 50.0**2])
    sensor = LinearSensor(H4, R, 1e-6, 1.0, 1.0)
    x, P = np.array([0.0, 500, 5000, 0]), np.diag([1e4, 2500, 1e4, 2500])
    f = ImmPda([(F, Q)], np.eye(1), x, P)
    for _ in range(30):
        z = rng.normal([x[0], x[2]], 300.0)
        f.step([sensor], [z[None]])
        x, P = F @ x, F @ P @ F.T + Q
        S = H4 @ P @ H4.T + R
        K = P @ H4.T @ np.linalg.inv(S)
        x, P = x + K @ (z - H4 @ x), (np.eye(4) - K @ H4) @ P
        np.testing.assert_allclose(f.x[0], x, rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(f.P[0], P, rtol=1e-9, atol=1e-6)


def test_nothing_in_the_gate_leaves_the_prediction():
    sensor = LinearSensor(H4, np.eye(2), 1e-3, 1.0, 0.99)
    f = ImmPda([cv4()], np.eye(1), np.zeros(4), np.eye(4))
    f.predict()
    x, P = f.x.copy(), f.P.copy()
    up = f.update(sensor, np.array([[1e3, 1e3]]))
    assert len(up.returns) == 0 and up.beta0 == 1.0
    np.testing.assert_array_equal(f.x, x)
    np.testing.assert_allclose(f.P, P)


def test_sequential_two_sensor_update_gates_on_the_latest_estimate():
    """Sensor 2's gate is computed from sensor 1's posterior (seed 003 eq. 29-31)."""
    s1 = LinearSensor(H4, np.eye(2), 1e-6, 1.0, 1.0)
    s2 = LinearSensor(H4, np.eye(2), 1e-6, 1.0, 0.99)
    f = ImmPda([(np.eye(4), np.zeros((4, 4)))], np.eye(1), np.zeros(4), 100 * np.eye(4))
    # sensor 1 pulls the estimate to ~(50, 0); sensor 2's return at (52, 0) is then in the gate
    # (against the prior it would be at NIS ~ 52^2 / 101 ~ 27 > 9.2, outside)
    u1, u2 = f.step([s1, s2], [np.array([[50.0, 0.0]]), np.array([[52.0, 0.0]])], steps=0)
    assert len(u1.returns) == 1 and len(u2.returns) == 1
    after1 = 50.0 * 100 / 101
    assert after1 < f.x[0, 0] < 52.0
    alone = ImmPda([(np.eye(4), np.zeros((4, 4)))], np.eye(1), np.zeros(4), 100 * np.eye(4))
    assert len(alone.update(s2, np.array([[52.0, 0.0]])).returns) == 0
