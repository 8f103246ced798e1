"""IDPC and FTC on hand-made point sets (seed 004; tracking/idpc.py)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.idpc import ClusterParams, ftc, idpc, local_density, polar_to_cartesian
from sensornet.tracking.models import RangeBearing

S = 20  # sensors whose scans are pooled
PARAMS = ClusterParams(cutoff=25.0, zeta=0.3, radius_factor=1.25, detection_probability=0.95)
CLUSTERERS = pytest.mark.parametrize("cluster", [idpc, ftc], ids=["idpc", "ftc"])


def _pooled(centres, rng, sigma=10.0, per_target=S, clutter=0):
    """``per_target`` points N(centre, sigma^2 I) per centre plus uniform clutter."""
    pts = [c + sigma * rng.standard_normal((per_target, 2)) for c in np.asarray(centres, float)]
    pts.append(rng.uniform(-1000.0, 1000.0, size=(clutter, 2)))
    return np.concatenate(pts)


def _matched(found, truth, tol):
    """Each true centre has its own estimate within ``tol`` m (greedy; the sets are small)."""
    found = [np.asarray(f) for f in found]
    for t in np.asarray(truth, float):
        d = [np.linalg.norm(f - t) for f in found]
        j = int(np.argmin(d))
        assert d[j] < tol, (t, found)
        found.pop(j)


def test_local_density_counts_other_points_within_cutoff():
    pts = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 4.0], [10.0, 0.0]])
    rho = local_density(pts, 4.5)
    assert rho.tolist() == [2, 1, 1, 0]


@CLUSTERERS
def test_two_touching_clusters_are_two_targets(cluster):
    # 35 m apart with sigma = 10 m: the point clouds touch and one DBSCAN / merged IDPC cluster
    # holds both; its size (~2 S) makes the k-means split give two.
    rng = np.random.default_rng(4)
    truth = [(0.0, 0.0), (35.0, 0.0)]
    out = cluster(_pooled(truth, rng), S, PARAMS, rng)
    assert out.count == 2
    _matched(out.centres, truth, 8.0)


@CLUSTERERS
def test_oversized_cluster_splits_into_its_targets(cluster):
    rng = np.random.default_rng(5)
    truth = [(100.0, 100.0), (125.0, 140.0), (150.0, 100.0)]
    out = cluster(_pooled(truth, rng), S, PARAMS, rng)
    assert out.count == 3
    _matched(out.centres, truth, 12.0)


@CLUSTERERS
def test_separated_targets_in_clutter(cluster):
    rng = np.random.default_rng(6)
    truth = [(-100.0, -800.0), (-800.0, -500.0), (0.0, 950.0)]
    pts = _pooled(truth, rng, per_target=19, clutter=200)
    out = cluster(pts, S, PARAMS, rng)
    assert out.count == 3
    _matched(out.centres, truth, 8.0)  # centroid std ~ 10/sqrt(19) m per axis


@CLUSTERERS
def test_clutter_only_gives_no_target(cluster):
    rng = np.random.default_rng(7)
    pts = rng.uniform(-1000.0, 1000.0, size=(S * 10, 2))
    out = cluster(pts, S, PARAMS, rng)
    assert out.count == 0
    assert (out.labels == -1).all()


@CLUSTERERS
def test_empty_set(cluster):
    out = cluster(np.zeros((0, 2)), S, PARAMS)
    assert out.count == 0 and out.centres.shape == (0, 2)


def test_one_target_split_by_the_seed_is_merged_back():
    # A seed on the edge of a wide cloud leaves points beyond L d_c for a second seed; the balls
    # intersect, the clusters merge, and the size (~S Pd) does not call for a split.
    rng = np.random.default_rng(8)
    pts = _pooled([(0.0, 0.0)], rng, sigma=18.0)
    out = idpc(pts, S, PARAMS, rng)
    assert out.count == 1
    assert np.linalg.norm(out.centres[0]) < 20.0  # only the dense core counts: a coarse centre


def test_polar_to_cartesian_inverts_the_radar_model():
    radar = RangeBearing(10.0, np.deg2rad(0.5), (300.0, -200.0))
    xy = np.array([[0.0, 0.0], [-700.0, 900.0], [1000.0, -1000.0]])
    states = np.column_stack((xy[:, 0], np.zeros(3), xy[:, 1], np.zeros(3)))
    z, _ = radar.predict(states)
    np.testing.assert_allclose(polar_to_cartesian(z, radar.position), xy, atol=1e-9)


def test_components_match_scipy():
    from scipy.sparse.csgraph import connected_components
    from sensornet.tracking.idpc import _components

    rng = np.random.default_rng(9)
    for k in (1, 2, 5, 12):
        a = rng.random((k, k)) < 0.15
        a = a | a.T
        _, ref = connected_components(a, directed=False)
        got = _components(a)
        # the same partition (labels may be named differently)
        assert (np.equal.outer(got, got) == np.equal.outer(ref, ref)).all()
