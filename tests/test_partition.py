"""Distance partitioning: MST thresholds give the same partitions as every pairwise distance."""

import numpy as np
import pytest

from tracking.partition import (
    DistancePartitioner,
    ScanTooLarge,
    all_pairs_partitions,
    canonical,
)


def _scan(rng, n_targets=4, per=6, clutter=10, sigma=20.0):
    centres = rng.uniform(-1000, 1000, (n_targets, 2))
    pts = [c + sigma * rng.standard_normal((rng.poisson(per), 2)) for c in centres]
    pts.append(rng.uniform(-1000, 1000, (rng.poisson(clutter), 2)))
    return np.concatenate(pts)


def _keys(parts):
    return {canonical(p).tobytes() for p in parts}


@pytest.mark.parametrize("seed", range(25))
def test_mst_thresholds_give_the_all_pairs_partitions(seed):
    rng = np.random.default_rng(seed)
    z = _scan(rng, sigma=20.0 * (1 + seed % 3))
    part = DistancePartitioner(sigma=20.0)
    got = part(z)
    want = all_pairs_partitions(z, 20.0, *part.bounds)
    assert len(got) == len(_keys(got))  # no duplicates
    assert _keys(got) == _keys(want)


def test_small_scans_and_no_threshold_in_range():
    part = DistancePartitioner(sigma=20.0)
    assert [p.tolist() for p in part(np.zeros((0, 2)))] == [[]]
    assert [p.tolist() for p in part(np.array([[1.0, 2.0]]))] == [[0]]
    far = np.array([[0.0, 0.0], [900.0, 0.0]])
    assert [canonical(p).tolist() for p in part(far)] == [[0, 1]]
    near = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert [canonical(p).tolist() for p in part(near)] == [[0, 0]]


def test_parameters_and_cap_fail_in_one_line():
    with pytest.raises(ValueError, match="p_lower"):
        DistancePartitioner(p_lower=0.9, p_upper=0.5)
    with pytest.raises(ScanTooLarge, match="cap 100"):
        DistancePartitioner(max_measurements=100)(np.zeros((101, 2)))
