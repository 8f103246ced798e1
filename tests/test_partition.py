"""Distance partitioning: MST thresholds give the same partitions as every pairwise distance."""

import numpy as np
import pytest
from sensornet.tracking.partition import (
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


from sensornet.tracking.partition import GridSpectralPartitioner, adjusted_rand_index  # noqa: E402


def _clusters(rng, centres, per=10, clutter=10, sigma=20.0):
    pts = [c + sigma * rng.standard_normal((per, 2)) for c in centres]
    labels = np.repeat(np.arange(len(centres)), per)
    cl = rng.uniform(-1000, 1000, (clutter, 2))
    return np.concatenate(pts + [cl]), np.concatenate([labels, 100 + np.arange(clutter)])


def test_adjusted_rand_index_known_values():
    assert adjusted_rand_index([0, 0, 1, 1], [5, 5, 7, 7]) == 1.0
    # Hubert & Arabie's example as computed by sklearn: ARI([0,0,1,1],[0,0,1,2]) = 0.5714...
    assert adjusted_rand_index([0, 0, 1, 1], [0, 0, 1, 2]) == pytest.approx(4 / 7)
    assert adjusted_rand_index([0, 0, 0, 0], [0, 1, 2, 3]) == 0.0


def test_grid_spectral_finds_separated_targets_and_removes_clutter():
    rng = np.random.default_rng(2)
    centres = np.array([[100.0, 450], [-450, -450], [450, -209], [-350, 300]])
    scores, removed = [], []
    for _ in range(20):
        z, truth = _clusters(rng, centres)
        parts, kept = GridSpectralPartitioner().partition(z)
        assert len(parts) == 1 and len(parts[0]) == len(z)
        on_targets = truth < 100
        scores.append(adjusted_rand_index(parts[0][kept & on_targets], truth[kept & on_targets]))
        removed.append(1 - kept[~on_targets].mean())
        # removed points are one-measurement cells
        lab = parts[0][~kept]
        assert len(np.unique(lab)) == len(lab) and not np.isin(lab, parts[0][kept]).any()
    assert np.mean(scores) > 0.95 and np.mean(removed) > 0.9


def test_unit_box_scaling_makes_the_eigengap_say_one_cluster():
    """docs/seed002.md: with the scan scaled to [0, 1] the similarity 1 / (D + 1) stays in
    [0.5, 1] and the eigengap picks K = 1; in units of sigma it picks the targets."""
    rng = np.random.default_rng(4)
    z, truth = _clusters(rng, np.array([[0.0, 0], [400, 0], [0, 400]]), clutter=0)
    for units, k in (("unit-box", 1), ("sigma", 3)):
        p = GridSpectralPartitioner(units=units, remove_clutter=False)
        assert len(np.unique(p(z)[0])) == k


def test_core_region_rule_and_spread():
    rng = np.random.default_rng(5)
    z, _ = _clusters(rng, np.array([[0.0, 0], [500, 0]]), clutter=3)
    parts = GridSpectralPartitioner(k_rule="core-regions", k_spread=1).partition(z)[0]
    assert 2 <= len(parts) <= 3


@pytest.mark.parametrize("kw", [dict(rho=1.0), dict(sigma=0), dict(k_rule="x"),
                                dict(units="m"), dict(compression=0)])
def test_grid_spectral_parameters_fail_in_one_line(kw):
    with pytest.raises(ValueError, match="grid-spectral partition needs"):
        GridSpectralPartitioner(**kw)


def test_grid_spectral_cap():
    with pytest.raises(ScanTooLarge):
        GridSpectralPartitioner(max_measurements=10)(np.zeros((11, 2)))


def test_core_level_keeps_a_sparse_target_beside_a_dense_one():
    """eps2 = (max + min) / 2 (core_level 0.5) is relative to the densest target: a target with
    a third of its points has no core cell and is removed; a lower core level keeps it."""
    rng = np.random.default_rng(11)
    kept = {0.5: [], 0.2: []}
    for _ in range(20):
        z = np.concatenate([rng.normal([0, 0], 20, (24, 2)), rng.normal([600, 600], 20, (8, 2)),
                            rng.uniform(-1000, 1000, (10, 2))])
        for level in kept:
            k = GridSpectralPartitioner(core_level=level).grid_keep(z)[0]
            kept[level].append(k[24:32].mean())
    assert np.mean(kept[0.5]) < 0.5 < 0.9 < np.mean(kept[0.2])
    with pytest.raises(ValueError, match="core_level"):
        GridSpectralPartitioner(core_level=1.5)
