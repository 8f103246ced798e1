"""IMM-EKF, IMM particle filter, resampling, summaries and the particle fusion rule (seed 001)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.imm import (
    IMMEKF,
    IMMParams,
    constant_acceleration,
    constant_velocity,
    radar_h,
    radar_jacobian,
    radar_log_likelihood,
)
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import RangeBearing
from sensornet.tracking.particles import (
    GaussianRatio,
    IMMParticleFilter,
    ParticleParams,
    ParticlePrediction,
    RatioConfig,
    collapse_to_models,
    counts_to_indices,
    gci_summaries,
    interaction_indices,
    kmeans_summary,
    moment_summary,
    residual_counts,
    systematic_counts,
    weighted_moments,
)

ONE_MODEL = IMMParams(sigma_cv=0.5, transition=((1.0,),), initial_probs=(1.0,),
                      model_names=("CV",))


def _ca_q_closed_form(T: float, sigma: float, gain: str) -> np.ndarray:
    """One axis' CA process noise written out: ``sigma^2 g g^T`` for the paper's
    ``g = [T^2/2, T, 1]`` (seed 001 eq. 24) or the integrated-jerk ``g = [T^3/6, T^2/2, T]``."""
    if gain == "paper":
        q = [[T**4 / 4, T**3 / 2, T**2 / 2], [T**3 / 2, T**2, T], [T**2 / 2, T, 1.0]]
    else:
        q = [[T**6 / 36, T**5 / 12, T**4 / 6], [T**5 / 12, T**4 / 4, T**3 / 2],
             [T**4 / 6, T**3 / 2, T**2]]
    return sigma**2 * np.array(q)


@pytest.mark.parametrize("T", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("gain", ["paper", "integrated"])
def test_ca_process_noise_matches_closed_form(T, gain):
    """``IMMParams(ca_noise_gain=...)``'s CA ``Q``: the closed form per axis, no cross-axis
    terms, and the paper's gain is the default."""
    sigma = 0.3
    params = IMMParams(T=T, sigma_ca=sigma, ca_noise_gain=gain)
    ca = params.models()[1]
    assert ca.name == "CA"
    q = _ca_q_closed_form(T, sigma, gain)
    np.testing.assert_allclose(ca.Q[:3, :3], q, rtol=1e-14, atol=0)
    np.testing.assert_allclose(ca.Q[3:, 3:], q, rtol=1e-14, atol=0)
    assert not ca.Q[:3, 3:].any() and not ca.Q[3:, :3].any()
    np.testing.assert_array_equal(constant_acceleration(T, sigma, gain).Q, ca.Q)
    if gain == "paper":
        np.testing.assert_array_equal(IMMParams(T=T, sigma_ca=sigma).models()[1].Q, ca.Q)


def test_ca_noise_gain_rejects_unknown_name():
    with pytest.raises(ValueError, match="ca_noise_gain"):
        IMMParams(ca_noise_gain="jerk")


def _kf(m, P, F, Q, H, R, z):
    m, P = F @ m, F @ P @ F.T + Q
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    return m + K @ (z - H @ m), (np.eye(len(m)) - K @ H) @ P


def test_pf_converges_to_kalman_filter_with_linear_gaussian_sensor():
    """One CV model, position sensor: PF mean/cov approach the KF's as particles grow."""
    H = np.zeros((2, 6))
    H[0, 0] = H[1, 3] = 1.0
    R = 25.0 * np.eye(2)
    model = constant_velocity(1.0, 0.5)
    m0 = np.array([0.0, 10.0, 0.0, 0.0, -5.0, 0.0])
    P0 = np.diag([100.0, 4.0, 0.0, 100.0, 4.0, 0.0])
    zs = np.array([[10.0, -5.0], [22.0, -9.0], [29.0, -16.0], [41.0, -19.0]])
    m, P = m0, P0
    for z in zs:
        m, P = _kf(m, P, model.F, model.Q, H, R, z)

    def loglik(z):
        return lambda X: -0.5 * np.sum((X[..., [0, 3]] - z) ** 2, axis=-1) / 25.0

    errs = {}
    for n in (500, 20000):
        e = []
        for seed in range(3):
            pf = IMMParticleFilter(ONE_MODEL, ParticleParams(n_particles=n, jitter=0.0))
            rng = np.random.default_rng(seed)
            st = pf.initialise(m0, P0, rng)
            for z in zs:
                st, _ = pf.step(st, loglik(z), rng)
            pos = [0, 1, 3, 4]
            e.append(np.abs(st.means[0][pos] - m[pos]).max() / np.sqrt(P[0, 0]))
            cov_err = np.abs(np.diag(st.covs[0])[pos] / np.diag(P)[pos] - 1)
            e[-1] = max(e[-1], cov_err.max())
        errs[n] = np.mean(e)
    assert errs[20000] < errs[500]
    assert errs[20000] < 0.05  # mean within 5 % of a KF std, variances within 5 %


def test_residual_resampling_keeps_floor_counts():
    rng = np.random.default_rng(3)
    w = rng.random((2, 50)) ** 4
    w /= w.sum(axis=1, keepdims=True)
    counts = residual_counts(w, 50, rng)
    assert np.all(counts.sum(axis=1) == 50)
    assert np.all(counts >= np.floor(50 * w))
    assert np.all(counts <= np.floor(50 * w) + 1)  # systematic residual draws: at most one more


@pytest.mark.parametrize("M", [2, 3])
def test_interaction_indices_equal_systematic_sampling_over_all_particles(M):
    """The block-boundary form draws the same particles as systematic sampling over the
    ``M*N`` cumulative weights, including models of probability 0 and 1."""
    rng = np.random.default_rng(11)
    cases = [rng.dirichlet(np.full(M, 0.4)) for _ in range(300)]
    cases += [np.eye(M)[0], np.eye(M)[-1], np.r_[1e-300, np.ones(M - 1)] / (M - 1)]
    P = np.full((M, M), 0.02 / (M - 1)) + (0.98 - 0.02 / (M - 1)) * np.eye(M)
    for k, p in enumerate(cases):
        N = (7, 50, 800)[k % 3]
        mu = P * p[:, None]
        mu /= mu.sum(axis=0)
        u = rng.random(M)
        ref = counts_to_indices(systematic_counts(np.repeat(mu.T, N, axis=1), N, u)).ravel()
        np.testing.assert_array_equal(interaction_indices(mu, N, u), ref)


def test_moment_summary_keeps_mean_and_covariance():
    rng = np.random.default_rng(4)
    X = rng.standard_normal((2, 300, 6)) * [1, 2, 3, 4, 5, 6] + [[0] * 6, [5] * 6][0]
    X[1] += 3.0
    w = rng.random((2, 300))
    w /= w.sum(axis=1, keepdims=True)
    probs = np.array([0.3, 0.7])
    mix = moment_summary(X, w, probs)
    flat_w = (probs[:, None] * w).reshape(-1)
    mean, cov = weighted_moments(X.reshape(-1, 6), flat_w)
    m2, c2 = mix.moments()
    np.testing.assert_allclose(m2, mean, atol=1e-10)
    np.testing.assert_allclose(c2, cov, atol=1e-9)
    km = kmeans_summary(X.reshape(-1, 6), flat_w, 3, rng)
    m3, c3 = km.moments()
    np.testing.assert_allclose(m3, mean, atol=1e-9)
    np.testing.assert_allclose(c3, cov, atol=1e-8)


def test_particle_fusion_rule_reproduces_product_of_likelihoods():
    """Prior particles weighted by two peers' posterior/prediction ratios = joint posterior."""
    rng = np.random.default_rng(5)
    m0 = np.array([100.0, 1.0, 0.0, -50.0, 2.0, 0.0])
    P0 = np.diag([400.0, 4.0, 1e-4, 400.0, 4.0, 1e-4])
    H = np.zeros((2, 6))
    H[0, 0] = H[1, 3] = 1.0
    Rs = [np.diag([100.0, 400.0]), np.diag([300.0, 50.0])]
    zs = [np.array([110.0, -40.0]), np.array([95.0, -60.0])]
    ratios = []
    for R, z in zip(Rs, zs, strict=True):
        m, P = _kf(m0, P0, np.eye(6), np.zeros((6, 6)), H, R, z)
        post = GaussianMixture(np.ones(1), m[None], P[None])
        pred = GaussianMixture(np.ones(1), m0[None], P0[None])
        ratios.append(GaussianRatio.from_summaries(post, pred, RatioConfig("position", True)))
    # analytical joint posterior
    Hs, Rj, zj = np.vstack([H, H]), np.block([[Rs[0], np.zeros((2, 2))],
                                              [np.zeros((2, 2)), Rs[1]]]), np.concatenate(zs)
    mj, Pj = _kf(m0, P0, np.eye(6), np.zeros((6, 6)), Hs, Rj, zj)
    X = rng.multivariate_normal(m0, P0, size=200000)
    logw = ratios[0].log_eval(X) + ratios[1].log_eval(X)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    mean, cov = weighted_moments(X, w)
    ess = 1.0 / np.sum(w**2)
    for i in (0, 3):
        assert abs(mean[i] - mj[i]) < 5 * np.sqrt(Pj[i, i] / ess)
        assert abs(cov[i, i] / Pj[i, i] - 1) < 0.05
    # the same rule in closed form on Gaussians (the IMM-EKF fusion path)
    mm, cc, _ = ratios[0].apply_gaussian(m0[None], P0[None])
    mm, cc, _ = ratios[1].apply_gaussian(mm, cc)
    np.testing.assert_allclose(mm[0], mj, atol=1e-6)
    np.testing.assert_allclose(cc[0], Pj, atol=1e-6)


def test_ratio_clipping_removes_negative_information():
    post = GaussianMixture(np.ones(1), np.zeros((1, 6)), 4.0 * np.eye(6)[None])
    pred = GaussianMixture(np.ones(1), np.zeros((1, 6)), np.diag([1.0, 1, 1, 9, 1, 1])[None])
    r = GaussianRatio.from_summaries(post, pred, RatioConfig("position", clip=True))
    assert np.all(np.linalg.eigvalsh(r.A) >= -1e-12)
    unclipped = GaussianRatio.from_summaries(post, pred, RatioConfig("position", clip=False))
    assert np.linalg.eigvalsh(unclipped.A).min() < 0


@pytest.mark.parametrize("bearing", [np.pi - 1e-4, -np.pi + 1e-4])
def test_bearing_wrap_in_ekf_and_pf_updates(bearing):
    """A target just across the +-pi bearing cut: the update must not see a 2 pi residual."""
    sensor = RangeBearing(3.0, np.deg2rad(0.1), (0.0, 0.0))
    x = np.array([-1000.0, 0.0, 0.0, 1000.0 * np.sin(bearing), 0.0, 0.0])
    x[0] = 1000.0 * np.cos(bearing)
    z = np.array([1000.0, -bearing])  # measured on the other side of the cut
    X = np.array([x, x])
    assert np.all(radar_log_likelihood(sensor, z, X) > -20)
    ekf = IMMEKF()
    st = ekf.initialise(x, np.diag([4.0, 1, 0.01, 4.0, 1, 0.01]))
    post = ekf.update(st, z, sensor)
    assert np.abs(post.means[:, [0, 3]] - x[[0, 3]]).max() < 5.0
    zhat, Hj = radar_jacobian(sensor, X)
    np.testing.assert_allclose(zhat, radar_h(sensor, X))


def test_imm_ekf_tracks_constant_velocity_segment():
    rng = np.random.default_rng(7)
    sensor = RangeBearing(3.0, np.deg2rad(0.08), (0.0, 0.0))
    x = np.array([6000.0, 20.0, 0.0, 8400.0, -11.0, 0.0])
    ekf = IMMEKF()
    st = ekf.initialise(x + [10, 1, 0, -10, 1, 0], np.diag([400.0, 4, 0.01, 400.0, 4, 0.01]))
    err = []
    for _ in range(100):
        x = constant_velocity().F @ x
        z = sensor.measure(x[None, [0, 1, 3, 4]], rng)[0]
        st = ekf.step(st, z, sensor)
        err.append(np.hypot(*(st.estimate[[0, 3]] - x[[0, 3]])))
    assert np.sqrt(np.mean(np.square(err[20:]))) < 10.0
    assert st.probs[0] > 0.5  # CV favoured on a CV segment


def test_model_probability_switches_to_ca_within_a_few_scans():
    rng = np.random.default_rng(8)
    sensor = RangeBearing(3.0, np.deg2rad(0.05), (0.0, 0.0))
    x = np.array([5000.0, 20.0, 0.0, 5000.0, 0.0, 0.0])
    pf = IMMParticleFilter(IMMParams(), ParticleParams(n_particles=800))
    ekf = IMMEKF()
    P0 = np.diag([25.0, 1, 0.01, 25.0, 1, 0.01])
    st, se = pf.initialise(x, P0, rng), ekf.initialise(x, P0)
    cv = constant_velocity()
    ca_f = np.kron(np.eye(2), np.array([[1.0, 1, 0.5], [0, 1, 1], [0, 0, 1]]))
    probs = []
    for k in range(60):
        if k == 30:
            x[5] = 3.0  # strong acceleration from scan 30 on
        x = (cv.F if k < 30 else ca_f) @ x
        z = sensor.measure(x[None, [0, 1, 3, 4]], rng)[0]
        st, _ = pf.step(st, lambda X, z=z: radar_log_likelihood(sensor, z, X), rng)
        se = ekf.step(se, z, sensor)
        probs.append((st.probs[1], se.probs[1]))
    probs = np.array(probs)
    assert probs[25:30].max(axis=0).max() < 0.5  # CV before the manoeuvre
    assert np.all(probs[36:40] > 0.9)  # CA within 6 scans of onset, PF and EKF


def test_determinism_with_seed():
    sensor = RangeBearing(3.0, np.deg2rad(0.08), (0.0, 0.0))
    pf = IMMParticleFilter(IMMParams(), ParticleParams(n_particles=200))
    x = np.array([6000.0, 20.0, 0.0, 8400.0, -11.0, 0.0])
    z = np.array([np.hypot(6020, 8389), np.arctan2(8389, 6020)])

    def run(seed):
        rng = np.random.default_rng(seed)
        st = pf.initialise(x, np.diag([100.0, 4, 0.01, 100.0, 4, 0.01]), rng)
        for _ in range(3):
            st, _ = pf.step(st, lambda X: radar_log_likelihood(sensor, z, X), rng)
        return st.particles

    np.testing.assert_array_equal(run(1), run(1))
    assert not np.array_equal(run(1), run(2))


def test_gci_of_summaries_collapses_per_own_model():
    a = GaussianMixture(np.array([0.6, 0.4]), np.zeros((2, 6)), np.tile(np.eye(6), (2, 1, 1)))
    b = GaussianMixture(np.array([0.5, 0.5]), np.ones((2, 6)), np.tile(2 * np.eye(6), (2, 1, 1)))
    fused = gci_summaries(a, [b], 0.5)
    assert len(fused) == 4 and np.isclose(fused.mass, 1.0)
    probs, means, covs = collapse_to_models(fused, 2)
    # GCI weights w_a^(1-omega) w_b^omega, equal overlaps: mu = sqrt(.6), sqrt(.4) normalised
    np.testing.assert_allclose(probs, np.sqrt([0.6, 0.4]) / np.sqrt([0.6, 0.4]).sum())
    # CI of N(0, I) and N(1, 2I) at omega 0.5: P = (0.5 + 0.25)^-1 I, m = P (0.5 * 1 / 2)
    np.testing.assert_allclose(means[0], np.full(6, 0.25 / 0.75))
    np.testing.assert_allclose(covs[0], np.eye(6) / 0.75)


def test_predicted_summary_matches_particles():
    rng = np.random.default_rng(9)
    X = rng.standard_normal((2, 100, 6))
    pred = ParticlePrediction(X, np.array([0.2, 0.8]))
    mean, cov = pred.summary().moments()
    w = np.concatenate([np.full(100, 0.002), np.full(100, 0.008)])
    m2, c2 = weighted_moments(X.reshape(-1, 6), w)
    np.testing.assert_allclose(mean, m2, atol=1e-12)
    np.testing.assert_allclose(cov, c2, atol=1e-12)
