"""GM-PHD predict / update / extract against plain per-pair references (Vo & Ma 2006, Table I)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal
from sensornet.sim.scenario import FilterSpec
from sensornet.tracking.gmphd import (
    DEFAULT_EXTRACTION,
    GMPHDFilter,
    SensorParams,
    extract,
    predict,
    update,
)
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition, RangeBearing
from sensornet.tracking.reduction import Reducer

# ---------------------------------------------------------------------------------------------
# helpers (independent of the code under test)


def wrap(a):
    """Angle wrapped to (-pi, pi] via the complex exponential (a different route than the code)."""
    return np.angle(np.exp(1j * np.asarray(a)))


def random_spd(rng, d, scale):
    A = rng.normal(size=(d, d))
    return A @ A.T * scale + np.eye(d) * scale * 0.5


def random_mixture(rng, n, centre=(0.0, 0.0), spread=300.0, pos_var=200.0):
    w = rng.uniform(0.05, 1.5, size=n)
    m = np.zeros((n, 4))
    m[:, 0] = centre[0] + rng.uniform(-spread, spread, size=n)
    m[:, 2] = centre[1] + rng.uniform(-spread, spread, size=n)
    m[:, 1] = rng.normal(0, 10, size=n)
    m[:, 3] = rng.normal(0, 10, size=n)
    P = np.stack([random_spd(rng, 4, pos_var / 4) for _ in range(n)])
    return GaussianMixture(w, m, P)


def h_linear(x):
    return np.array([x[0], x[2]])


def h_radar(x, pos):
    dx, dy = x[0] - pos[0], x[2] - pos[1]
    return np.array([np.hypot(dx, dy), np.arctan2(dy, dx)])


def jacobian_fd(h, x, angular, eps=1e-3):
    """Central finite-difference Jacobian of ``h`` at ``x`` (wrapping angular outputs)."""
    cols = []
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = eps
        diff = h(x + e) - h(x - e)
        if angular:
            diff[1] = wrap(diff[1])
        cols.append(diff / (2 * eps))
    return np.stack(cols, axis=1)


def reference_update(mix, Z, Pd, kappa, h, R, angular, gate=None):
    """Vo & Ma 2006 Table I, one (z, j) pair at a time. Order: missed terms, then for z, for j."""
    W, M, C = [], [], []
    for j in range(len(mix)):
        W.append((1 - Pd) * mix.weights[j])
        M.append(mix.means[j])
        C.append(mix.covs[j])
    for z in Z:
        terms = []
        for j in range(len(mix)):
            m, P = mix.means[j], mix.covs[j]
            eta = h(m)
            H = jacobian_fd(h, m, angular)
            S = H @ P @ H.T + R
            nu = z - eta
            if angular:
                nu[1] = wrap(nu[1])
            q = multivariate_normal(mean=np.zeros(len(z)), cov=S).pdf(nu)
            if gate is not None and nu @ np.linalg.solve(S, nu) > gate:
                q = 0.0
            K = P @ H.T @ np.linalg.inv(S)
            terms.append((Pd * mix.weights[j] * q, m + K @ nu, (np.eye(4) - K @ H) @ P))
        total = sum(t[0] for t in terms)
        for wq, m_upd, P_upd in terms:
            W.append(wq / (kappa + total))
            M.append(m_upd)
            C.append(P_upd)
    return np.array(W), np.array(M).reshape(-1, 4), np.array(C).reshape(-1, 4, 4)


def assert_mixture_close(mix, W, M, C, rtol=1e-7):
    assert len(mix) == len(W)
    np.testing.assert_allclose(mix.weights, W, rtol=rtol, atol=1e-300)
    np.testing.assert_allclose(mix.means, M, rtol=rtol, atol=1e-6)
    np.testing.assert_allclose(mix.covs, C, rtol=rtol, atol=1e-7 * np.abs(C).max())


def scan_near(rng, mix, model, n_clutter, lo, hi, noise):
    """Measurements from some components' means plus uniform clutter in [lo, hi]^2."""
    picks = rng.choice(len(mix), size=min(3, len(mix)), replace=False)
    if isinstance(model, LinearPosition):
        zs = mix.means[picks][:, [0, 2]] + rng.normal(0, noise, size=(len(picks), 2))
    else:
        zs = model.h(mix.means[picks]) + rng.normal(0, 1, size=(len(picks), 2)) * noise
    clutter = rng.uniform(lo, hi, size=(n_clutter, 2))
    return np.concatenate([zs, clutter])


# ---------------------------------------------------------------------------------------------
# update


@pytest.mark.parametrize("kappa", [2e-6, 3e-4])
@pytest.mark.parametrize("seed", range(3))
def test_update_linear_equals_reference(seed, kappa):
    rng = np.random.default_rng(seed)
    mix = random_mixture(rng, n=6)
    model = LinearPosition(sigma_r=15.0)
    Z = scan_near(rng, mix, model, n_clutter=4, lo=-400, hi=400, noise=10.0)
    sensor = SensorParams(model, detection_probability=0.9, clutter_intensity=kappa)
    out = update(mix, Z, sensor)
    W, M, C = reference_update(mix, Z, 0.9, kappa, h_linear, model.R, angular=False)
    assert_mixture_close(out, W, M, C)
    # Missed terms carry (1 - Pd) of the prior mass; each scan row carries <= 1.
    np.testing.assert_allclose(out.weights[: len(mix)].sum(), 0.1 * mix.mass)
    rows = out.weights[len(mix):].reshape(len(Z), len(mix)).sum(axis=1)
    assert np.all(rows < 1.0)


@pytest.mark.parametrize("kappa", [1e-4, 0.3])
@pytest.mark.parametrize("seed", range(3))
def test_update_range_bearing_equals_reference(seed, kappa):
    rng = np.random.default_rng(10 + seed)
    pos = (-200.0, 300.0)
    model = RangeBearing(sigma_r=10.0, sigma_theta=np.deg2rad(1.0), position=pos)
    mix = random_mixture(rng, n=5, centre=(700.0, 900.0), spread=300.0)
    noise = np.array([10.0, np.deg2rad(1.0)])
    Z = scan_near(rng, mix, model, n_clutter=3, lo=0.0, hi=1.0, noise=noise)
    Z[-3:, 0] = rng.uniform(500, 2000, size=3)
    Z[-3:, 1] = rng.uniform(0.2, 1.2, size=3)
    sensor = SensorParams(model, detection_probability=0.95, clutter_intensity=kappa)
    out = update(mix, Z, sensor)
    W, M, C = reference_update(
        mix, Z, 0.95, kappa, lambda x: h_radar(x, pos), model.R, angular=True
    )
    assert_mixture_close(out, W, M, C, rtol=1e-6)


def test_update_bearing_wraps_across_pi():
    pos = (0.0, 0.0)
    model = RangeBearing(sigma_r=5.0, sigma_theta=0.01, position=pos)
    r = 1000.0
    th = -np.pi + 0.001
    m = np.array([[r * np.cos(th), 0.0, r * np.sin(th), 0.0]])
    P = np.diag([25.0, 1.0, 25.0, 1.0])[None]
    mix = GaussianMixture(np.array([1.0]), m, P)
    z = np.array([[r, np.pi - 0.001]])  # 0.002 rad away across the +-pi cut
    sensor = SensorParams(model, detection_probability=0.9, clutter_intensity=1e-6)
    out = update(mix, z, sensor)
    W, M, C = reference_update(mix, z, 0.9, 1e-6, lambda x: h_radar(x, pos), model.R, True)
    assert_mixture_close(out, W, M, C, rtol=1e-6)
    # Small innovation: the detection term takes almost all the weight.
    zhat, H = model.predict(m)
    S = H[0] @ P[0] @ H[0].T + model.R
    nu = np.array([0.0, -0.002])
    q = multivariate_normal(np.zeros(2), S).pdf(nu)
    assert q > 1.0  # would be ~exp(-huge) without wrapping
    np.testing.assert_allclose(out.weights[1], 0.9 * q / (1e-6 + 0.9 * q), rtol=1e-9)
    assert out.weights[1] > 0.99
    # The updated mean moved a little, toward the measurement (y increases toward the cut).
    assert np.linalg.norm(out.means[1] - m[0]) < 5.0
    assert out.means[1, 2] > m[0, 2]


def test_update_gate_zeroes_far_pairs():
    rng = np.random.default_rng(21)
    mix = random_mixture(rng, n=5, spread=500.0, pos_var=50.0)
    model = LinearPosition(sigma_r=5.0)
    Z = scan_near(rng, mix, model, n_clutter=5, lo=-600, hi=600, noise=3.0)
    sensor = SensorParams(model, detection_probability=0.9, clutter_intensity=1e-6)
    gate = 9.21
    out = update(mix, Z, sensor, gate=gate)
    W, M, C = reference_update(mix, Z, 0.9, 1e-6, h_linear, model.R, False, gate=gate)
    assert_mixture_close(out, W, M, C)
    # The gated-out pairs exist and are exactly zero; the gated-in ones are positive.
    S = mix.covs[:, [0, 2]][:, :, [0, 2]] + model.R
    nu = Z[:, None, :] - mix.means[None, :, [0, 2]]
    d2 = np.einsum("mni,nij,mnj->mn", nu, np.linalg.inv(S), nu)
    det = out.weights[len(mix):].reshape(len(Z), len(mix))
    assert (d2 > gate).any() and (d2 <= gate).any()
    assert np.all(det[d2 > gate] == 0.0)
    assert np.all(det[d2 <= gate] > 0.0)


def test_update_min_weight_drops_only_light_pairs():
    rng = np.random.default_rng(33)
    mix = random_mixture(rng, n=6)
    model = LinearPosition(sigma_r=15.0)
    Z = scan_near(rng, mix, model, n_clutter=6, lo=-400, hi=400, noise=10.0)
    sensor = SensorParams(model, detection_probability=0.9, clutter_intensity=2e-6)
    full = update(mix, Z, sensor)
    n = len(mix)
    det_w = full.weights[n:]
    thr = float(np.median(det_w))
    assert (det_w < thr).any() and (det_w > thr).any()
    out = update(mix, Z, sensor, min_weight=thr)
    keep = det_w > thr
    # Missed terms are all kept; detection terms below the threshold dropped, order preserved.
    np.testing.assert_array_equal(out.weights[:n], full.weights[:n])
    np.testing.assert_allclose(out.weights[n:], det_w[keep], rtol=1e-12)
    np.testing.assert_allclose(out.means[n:], full.means[n:][keep], rtol=1e-12)
    np.testing.assert_allclose(out.covs[n:], full.covs[n:][keep], rtol=1e-12)
    # Normalisation is not changed by the dropped terms.
    assert len(out) == n + keep.sum()


def test_update_empty_inputs():
    model = LinearPosition(sigma_r=10.0)
    sensor = SensorParams(model, detection_probability=0.8, clutter_intensity=1e-6)
    rng = np.random.default_rng(4)
    mix = random_mixture(rng, n=3)
    out = update(mix, np.zeros((0, 2)), sensor)
    np.testing.assert_allclose(out.weights, 0.2 * mix.weights)
    np.testing.assert_array_equal(out.means, mix.means)
    empty = GaussianMixture.empty(4)
    out = update(empty, np.array([[1.0, 2.0]]), sensor)
    assert len(out) == 0 and out.dim == 4


# ---------------------------------------------------------------------------------------------
# predict


def cv_matrices(T, sigma_w):
    F = np.array([[1, T, 0, 0], [0, 1, 0, 0], [0, 0, 1, T], [0, 0, 0, 1]], dtype=float)
    G = np.array([[T * T / 2, 0], [T, 0], [0, T * T / 2], [0, T]])
    return F, sigma_w**2 * G @ G.T


def test_predict_one_step_with_births():
    rng = np.random.default_rng(5)
    mix = random_mixture(rng, n=4)
    birth = random_mixture(rng, n=2)
    motion = ConstantVelocity(T=0.7, sigma_w=1.3)
    F, Q = cv_matrices(0.7, 1.3)
    out = predict(mix, motion, 0.95, birth)
    assert len(out) == 6
    for j in range(4):
        assert out.weights[j] == pytest.approx(0.95 * mix.weights[j])
        np.testing.assert_allclose(out.means[j], F @ mix.means[j], rtol=1e-12)
        np.testing.assert_allclose(out.covs[j], F @ mix.covs[j] @ F.T + Q, rtol=1e-12)
    np.testing.assert_array_equal(out.weights[4:], birth.weights)
    np.testing.assert_array_equal(out.means[4:], birth.means)
    np.testing.assert_array_equal(out.covs[4:], birth.covs)


@pytest.mark.parametrize("steps", [0, 1, 2, 5])
def test_multi_step_equals_repeated_one_step(steps):
    rng = np.random.default_rng(6)
    mix = random_mixture(rng, n=3)
    birth = random_mixture(rng, n=1)
    motion = ConstantVelocity(T=1.0, sigma_w=2.0)
    rep = mix
    for _ in range(steps):
        rep = predict(rep, motion, 0.9, None)
    rep = GaussianMixture.concatenate([rep, birth])  # births once
    out = predict(mix, motion, 0.9, birth, steps=steps)
    np.testing.assert_allclose(out.weights, rep.weights, rtol=1e-12)
    np.testing.assert_allclose(out.means, rep.means, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(out.covs, rep.covs, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(out.weights[:3], mix.weights * 0.9**steps)


def test_transition_matches_closed_sum():
    F1, Q1 = cv_matrices(1.5, 0.5)
    motion = ConstantVelocity(T=1.5, sigma_w=0.5)
    for k in (*range(5), 17, 60):
        F, Q = motion.transition(k)
        np.testing.assert_allclose(F, np.linalg.matrix_power(F1, k), rtol=1e-14)
        ref = sum(
            (np.linalg.matrix_power(F1, t) @ Q1 @ np.linalg.matrix_power(F1, t).T
             for t in range(k)),
            np.zeros((4, 4)),
        )
        np.testing.assert_allclose(Q, ref, rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError):
        motion.transition(-1)


def test_transition_of_a_huge_jump_is_immediate_and_finite():
    """A scan index 10^9 ahead costs one closed-form evaluation, not 10^9 loop steps."""
    F, Q = ConstantVelocity(T=1.0, sigma_w=2.0).transition(10**9)
    assert np.all(np.isfinite(F)) and np.all(np.isfinite(Q))
    assert F[0, 1] == 1e9 and np.all(np.linalg.eigvalsh(Q) > 0)


# ---------------------------------------------------------------------------------------------
# extraction


def test_extract_rounds_weights():
    means = np.arange(20.0).reshape(5, 4)
    covs = np.broadcast_to(np.eye(4), (5, 4, 4))
    mix = GaussianMixture(np.array([1.6, 0.4, 0.7, 2.4, 0.5]), means, covs)
    X = extract(mix, rule="round")
    expected = np.concatenate([means[[0, 0]], means[[2]], means[[3, 3]]])
    np.testing.assert_array_equal(X, expected)
    assert extract(GaussianMixture.empty(4), rule="round").shape == (0, 4)
    # custom threshold
    np.testing.assert_array_equal(extract(mix, threshold=1.0, rule="round"), means[[0, 0, 3, 3]])


def test_extraction_default_is_cardinality_everywhere():
    """One default: ``extract``, ``GMPHDFilter`` and the scenario files' ``[filter]`` all use
    the cardinality rule (docs/algorithms.md: "our choice, the default")."""
    means = np.arange(20.0).reshape(5, 4)
    covs = np.broadcast_to(np.eye(4), (5, 4, 4))
    mix = GaussianMixture(np.array([1.6, 0.4, 0.7, 2.4, 0.5]), means, covs)
    # mass 5.6 -> 6 targets, but only the 5 components above threshold / 10
    np.testing.assert_array_equal(extract(mix), means[[3, 0, 2, 4, 1]])
    np.testing.assert_array_equal(extract(mix), extract(mix, rule="cardinality"))
    filt = GMPHDFilter(motion=ConstantVelocity(T=1.0, sigma_w=1.0),
                       sensors=[SensorParams(LinearPosition(sigma_r=1.0), 0.9, 1e-6)],
                       birth=GaussianMixture.empty(4))
    assert filt.extraction == DEFAULT_EXTRACTION == "cardinality"
    assert FilterSpec().extraction == DEFAULT_EXTRACTION


# ---------------------------------------------------------------------------------------------
# a whole filter, end to end on one target without clutter


def test_filter_tracks_single_target():
    rng = np.random.default_rng(8)
    motion = ConstantVelocity(T=1.0, sigma_w=0.5)
    model = LinearPosition(sigma_r=5.0)
    birth = GaussianMixture(
        np.array([0.1]), np.array([[0.0, 0.0, 0.0, 0.0]]), np.diag([400.0, 100, 400, 100])[None]
    )
    filt = GMPHDFilter(
        motion=motion,
        sensors=[SensorParams(model, detection_probability=0.98, clutter_intensity=1e-7)],
        birth=birth,
        survival_probability=0.99,
        reducer=Reducer(prune_threshold=1e-5, merge_threshold=4.0, max_components=50),
    )
    x = np.array([[10.0, 3.0, -5.0, -2.0]])
    mix = filt.initial()
    for _ in range(15):
        x = x @ motion.F.T
        mix = filt.step(mix, model.measure(x, rng))
    est = filt.extract(mix)
    assert est.shape == (1, 4)
    assert np.linalg.norm(est[0, [0, 2]] - x[0, [0, 2]]) < 15.0
    assert mix.mass == pytest.approx(1.0, abs=0.15)


def test_sensor_models_share_one_protocol():
    """No attribute probing: every model says which state entries it picks (or None)."""
    from sensornet.tracking.models import LinearPosition, MeasurementModel, RangeBearing

    lin, rb = LinearPosition(), RangeBearing()
    assert isinstance(lin, MeasurementModel) and isinstance(rb, MeasurementModel)
    assert lin.selected == tuple(np.argmax(lin.H_MATRIX, axis=1))
    assert rb.selected is None
