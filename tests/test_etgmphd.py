"""ET-GM-PHD update against a brute-force stacked-measurement sum over every partition."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal
from sensornet.tracking.etgmphd import ETGMPHDFilter, ExtendedSensor, update
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.gmphd import update as gmphd_update
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.partition import DistancePartitioner, ScanTooLarge
from sensornet.tracking.reduction import Reducer

H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])


def set_partitions(m):
    """Every partition of range(m) as label arrays (Bell(m) of them)."""
    if m == 0:
        yield np.zeros(0, dtype=int)
        return
    for sub in set_partitions(m - 1):
        k = sub.max() + 1 if len(sub) else 0
        for lab in range(k + 1):
            yield np.append(sub, lab)


def brute_force(mix, z, partitions, s: ExtendedSensor):
    """Granström et al. 2012 eq. 5-12 written per partition, cell and component, stacked."""
    Pd, g, kappa, R = s.detection_probability, s.rate, s.clutter_intensity, s.sigma**2 * np.eye(2)
    ws, ms, Ps = [w * (1 - (1 - np.exp(-g)) * Pd) for w in mix.weights], list(mix.means), list(
        mix.covs)
    terms, dW = [], []
    for labels in partitions:
        cells = []
        for c in np.unique(labels):
            W = z[labels == c]
            n = len(W)
            HW, RW = np.tile(H, (n, 1)), np.kron(np.eye(n), R)
            zW = W.reshape(-1)
            comps = []
            for w, m, P in zip(mix.weights, mix.means, mix.covs, strict=True):
                S = HW @ P @ HW.T + RW
                beta = multivariate_normal(HW @ m, S).pdf(zW) / kappa**n
                Gam = np.exp(-g) * g**n * Pd
                K = P @ HW.T @ np.linalg.inv(S)
                comps.append((Gam * beta * w, m + K @ (zW - HW @ m), P - K @ HW @ P))
            d = (n == 1) + sum(c[0] for c in comps)
            cells.append((d, comps))
        terms.append(cells)
        dW.append(np.prod([d for d, _ in cells]))
    wp = np.array(dW) / np.sum(dW)
    for p, cells in enumerate(terms):
        for d, comps in cells:
            for a, m, P in comps:
                ws.append(wp[p] * a / d)
                ms.append(m)
                Ps.append(P)
    return GaussianMixture(np.array(ws), np.array(ms), np.array(Ps))


def _prior(rng, J=3):
    means = np.column_stack([rng.uniform(-60, 60, J), rng.normal(0, 2, J),
                             rng.uniform(-60, 60, J), rng.normal(0, 2, J)])
    covs = np.array([np.diag(rng.uniform([50, 4, 50, 4], [400, 25, 400, 25])) for _ in range(J)])
    return GaussianMixture(rng.uniform(0.2, 1.0, J), means, covs)


@pytest.mark.parametrize("m", [1, 2, 3, 4, 5, 6])
def test_update_equals_brute_force_over_all_partitions(m):
    rng = np.random.default_rng(m)
    mix = _prior(rng)
    z = rng.uniform(-60, 60, (m, 2))
    s = ExtendedSensor(sigma=20.0, detection_probability=0.9, clutter_intensity=1e-5, rate=4.0)
    parts = list(set_partitions(m))
    got, want = update(mix, z, parts, s), brute_force(mix, z, parts, s)
    assert got.mass == pytest.approx(want.mass, rel=1e-9)
    x = rng.uniform(-80, 80, (200, 4)) * [1, 0.05, 1, 0.05]
    np.testing.assert_allclose(got.pdf(x), want.pdf(x), rtol=1e-8, atol=1e-300)
    # every cell with more than one measurement carries its partitions' weight (sum over j)
    assert len(got) == 3 + 3 * (2**m - 1)  # distinct non-empty cells x components


def test_subset_of_partitions_and_distance_partitioner():
    rng = np.random.default_rng(7)
    mix = _prior(rng, 4)
    z = np.concatenate([rng.normal([0, 0], 20, (3, 2)), rng.normal([200, 0], 20, (2, 2))])
    s = ExtendedSensor()
    parts = DistancePartitioner(sigma=20.0)(z) + [np.arange(5)]
    got, want = update(mix, z, parts, s), brute_force(mix, z, parts, s)
    x = np.column_stack([rng.uniform(-50, 250, 300), np.zeros(300), rng.uniform(-60, 60, 300),
                         np.zeros(300)])
    np.testing.assert_allclose(got.pdf(x), want.pdf(x), rtol=1e-8)


def test_singleton_partition_is_the_gm_phd_update_with_effective_pd():
    """One partition of singletons: detection terms are GM-PHD's with Pd' = e^-g g Pd, and the
    missed term is (1 - (1 - e^-g) Pd); as g -> 0 with Pd' fixed both become GM-PHD's."""
    rng = np.random.default_rng(3)
    mix = _prior(rng, 4)
    z = rng.uniform(-60, 60, (5, 2))
    kappa = 1e-5
    for g in (0.5, 3.0):
        s = ExtendedSensor(20.0, 0.95, kappa, g)
        got = update(mix, z, [np.arange(5)], s)
        pd_eff = np.exp(-g) * g * 0.95
        ref = gmphd_update(mix, z, SensorParams(LinearPosition(20.0), pd_eff, kappa))
        J = len(mix)
        np.testing.assert_allclose(got.weights[:J], mix.weights * (1 - (1 - np.exp(-g)) * 0.95))
        # cells are ordered by membership, GM-PHD pairs by measurement: compare as sets
        x = rng.uniform(-80, 80, (200, 4)) * [1, 0.05, 1, 0.05]
        det = got.select(np.arange(J, len(got)))
        np.testing.assert_allclose(np.sort(det.weights), np.sort(ref.weights[J:]), rtol=1e-10)
        np.testing.assert_allclose(det.pdf(x), ref.select(np.arange(J, len(ref))).pdf(x),
                                   rtol=1e-10)
    # missed-detection factors agree to O(g^2) as the rate g -> 0
    for g in (1e-2, 1e-3):
        et_missed = 1 - (1 - np.exp(-g)) * 0.95
        assert et_missed == pytest.approx(1 - np.exp(-g) * g * 0.95, abs=g * g)


def test_filter_tracks_one_extended_target_and_counts_oversized_scans():
    rng = np.random.default_rng(0)
    birth = GaussianMixture([0.1], [[0.0, 0.0, 0.0, 0.0]], [np.diag([100.0, 25, 100, 25])])
    filt = ETGMPHDFilter(ConstantVelocity(), ExtendedSensor(clutter_intensity=1e-6), birth,
                         DistancePartitioner(sigma=20.0, max_measurements=50),
                         reducer=Reducer(prune_threshold=1e-4, merge_threshold=4.0))
    mix = filt.initial()
    x = np.array([0.0, 5.0, 0.0, -3.0])
    for _ in range(15):
        x = ConstantVelocity().F @ x
        z = x[[0, 2]] + 20 * rng.standard_normal((rng.poisson(10), 2))
        mix = filt.step(mix, z)
    est = filt.extract(mix)
    assert len(est) == 1
    assert np.hypot(*(est[0, [0, 2]] - x[[0, 2]])) < 30
    mix = filt.step(mix, np.zeros((51, 2)))
    assert filt.counts["scans_too_large"] == 1 and filt.last_partitions == []
    with pytest.raises(ScanTooLarge):
        filt.partitioner(np.zeros((51, 2)))
