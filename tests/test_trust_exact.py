"""The trust checks' cheaper code gives the old numbers to the bit (peers/trust_checks.py).

``benchmarks/trust_before.py`` keeps the module before the speed-up; its
``neighbour_statistics`` is compared with the new one on random inputs (empty mixtures, one
component, identical components and inputs, quarantined and zero-weight neighbours, every
setting the loop branches on), and the new helpers against numpy's own functions.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter, deque

import numpy as np
import pytest
from sensornet.peers.trust import Trust
from sensornet.peers.trust_checks import (
    _cs_scalar,
    _loo_medians,
    cusum_directions,
    gls_offset,
    gls_offsets,
    is_repeat,
    median_small,
    neighbour_statistics,
    offset_chi2,
    offset_chi2_many,
    offset_cusum,
    offset_cusums,
    offset_information,
    offset_information_many,
    relative_offsets,
    triu_indices,
    unmatched_weights,
)
from sensornet.peers.trust_config import TrustConfig
from sensornet.peers.trust_record import NeighbourTrust, add_offset, add_offsets
from sensornet.tracking.divergence import cs_from_log_overlaps
from sensornet.tracking.mixture import GaussianMixture

from benchmarks import trust_before


def _mixture(rng: np.random.Generator, size: int) -> GaussianMixture:
    """``size`` components in 4-d (positions at 0 and 2) over a 2 km square, some heavy."""
    if size == 0:
        return GaussianMixture.empty(4)
    means = rng.uniform(-1000, 1000, (size, 4))
    A = rng.normal(0, 1, (size, 4, 4)) * rng.uniform(1, 40, (size, 1, 1))
    covs = A @ A.transpose(0, 2, 1) + 1.0 * np.eye(4)
    return GaussianMixture(rng.uniform(0.05, 1.0, size), means, covs)


def _inputs(rng: np.random.Generator):
    """Own and 0-7 neighbours: random sizes (0 and 1 included), some copies of own or of
    each other, some near copies (the same targets a few metres off)."""
    own = _mixture(rng, int(rng.integers(0, 5)))
    inputs = {}
    for i in range(int(rng.integers(0, 8))):
        kind = rng.integers(0, 4)
        if kind == 0 and inputs:
            inputs[f"n{i}"] = inputs[sorted(inputs)[0]]  # identical to another
        elif kind == 1:
            inputs[f"n{i}"] = GaussianMixture(own.weights.copy(), own.means + rng.normal(
                0, 5, own.means.shape), own.covs.copy())
        else:
            inputs[f"n{i}"] = _mixture(rng, int(rng.integers(0, 5)))
    names = sorted(inputs)
    weights = {"": float(rng.uniform(0.1, 1))}
    weights.update({s: float(rng.choice([0.0, rng.uniform(0.05, 1)], p=[0.15, 0.85]))
                    for s in names})
    quarantined = {s for s in names if rng.random() < 0.2}
    return own, inputs, weights, quarantined


CONFIGS = [
    TrustConfig(),
    TrustConfig(detection_probability=0.9),
    TrustConfig(detection_probability=0.9, location_only=True),
    TrustConfig(detection_probability=0.9, median_test=False),
    TrustConfig(majority=False),
    TrustConfig(location_only=True, detection_probability=0.7, unmatched=False),
]


@pytest.mark.parametrize("c", range(len(CONFIGS)))
def test_neighbour_statistics_equal_old_to_the_bit(c):
    rng = np.random.default_rng(100 + c)
    cfg = CONFIGS[c]
    seen = 0
    for _ in range(150):
        own, inputs, weights, quarantined = _inputs(rng)
        new = neighbour_statistics(cfg, own, inputs, weights, quarantined)
        old = trust_before.neighbour_statistics(cfg, own, inputs, weights, quarantined)
        assert new.keys() == old.keys()
        for s in new:  # to the bit (NaN nowhere: both would be flagged as unequal)
            assert new[s] == old[s], (s, new[s], old[s])
        seen += sum(v > 0 for v in new.values())
    assert seen > 50  # the inputs disagree often enough for the tests to matter


def test_statistics_of_empty_and_single_inputs():
    cfg = TrustConfig(detection_probability=0.9)
    rng = np.random.default_rng(7)
    one = _mixture(rng, 1)
    empty = GaussianMixture.empty(4)
    for own, inputs in [(empty, {}), (empty, {"a": empty}), (one, {"a": empty, "b": one}),
                        (one, {"a": one, "b": one, "c": one, "d": empty})]:
        w = {"": 1.0, **{s: 1.0 for s in inputs}}
        new = neighbour_statistics(cfg, own, inputs, w, set())
        assert new == trust_before.neighbour_statistics(cfg, own, inputs, w, set())
    # identical inputs: no evidence against anyone
    same = neighbour_statistics(cfg, one, {"a": one, "b": one, "c": one},
                                {"": 1.0, "a": 1.0, "b": 1.0, "c": 1.0}, set())
    assert same == {"a": 0.0, "b": 0.0, "c": 0.0}


@pytest.mark.parametrize("n", range(0, 12))
def test_median_small_is_numpys_median(n):
    rng = np.random.default_rng(n)
    for values in [rng.normal(0, 10, n), np.round(rng.normal(0, 2, n)), np.full(n, 3.25),
                   rng.choice([0.0, 1e300, -1e300, np.inf, -0.0], n)]:
        got = median_small(values)
        want = float(np.median(values)) if n else math.nan
        assert got == want or (math.isnan(got) and math.isnan(want)), (values, got, want)


def test_triu_indices_cached_and_read_only():
    for n in range(0, 9):
        rows, cols = triu_indices(n)
        want = np.triu_indices(n, 1)
        assert np.array_equal(rows, want[0]) and np.array_equal(cols, want[1])
        assert triu_indices(n)[0] is rows  # made once
        with pytest.raises(ValueError):
            rows[:1] = 0


def test_cs_scalar_is_cs_from_log_overlaps():
    rng = np.random.default_rng(3)
    vals = list(rng.normal(-20, 10, 30)) + [-np.inf, np.inf, np.nan, 0.0, -0.0, -1e308]
    for lpq in vals:
        for lpp in vals[::3]:
            for lqq in vals[::4]:
                want = float(cs_from_log_overlaps(np.float64(lpq), np.float64(lpp),
                                                  np.float64(lqq)))
                got = _cs_scalar(float(lpq), float(lpp), float(lqq))
                assert got == want or (math.isnan(got) and math.isnan(want)), \
                    (lpq, lpp, lqq, got, want)


def test_reference_module_is_the_old_code():
    """The reference differs from the new code in the speed-up only: same statistic on a
    hand-made case where the majority term decides (a liar far from three agreeing inputs)."""
    cfg = dataclasses.replace(TrustConfig(), detection_probability=None)
    rng = np.random.default_rng(11)
    own = _mixture(rng, 3)
    near = GaussianMixture(own.weights, own.means + 1.0, own.covs)
    liar = GaussianMixture(own.weights, own.means + 500.0, own.covs)
    inputs = {"a": near, "b": near, "c": liar}
    w = {"": 1.0, "a": 1.0, "b": 1.0, "c": 1.0}
    for f in (neighbour_statistics, trust_before.neighbour_statistics):
        out = f(cfg, own, inputs, w, set())
        assert out["c"] > 10 * max(out["a"], out["b"], 1e-9)


def _near_copies(rng: np.random.Generator, ref: GaussianMixture, count: int):
    """Mixtures like a round's neighbours: ``ref`` itself, shifted copies (some beyond the
    gate), empty ones, one-component ones and fresh random ones."""
    out = []
    for _ in range(count):
        kind = rng.integers(0, 5)
        if kind == 0:
            out.append(ref)
        elif kind == 1:
            out.append(GaussianMixture(ref.weights * rng.uniform(0.5, 1.5), ref.means
                                       + rng.normal(0, rng.choice([3.0, 80.0]), ref.means.shape),
                                       ref.covs))
        elif kind == 2:
            out.append(GaussianMixture.empty(4))
        else:
            out.append(_mixture(rng, int(rng.integers(1, 6))))
    return out


@pytest.mark.parametrize("chi2", [None, 13.8])
def test_offset_information_many_is_one_at_a_time(chi2):
    rng = np.random.default_rng(5 if chi2 else 6)
    matched = 0
    for _ in range(200):
        ref = _mixture(rng, int(rng.integers(0, 6)))
        mixes = _near_copies(rng, ref, int(rng.integers(0, 7)))
        gate = float(rng.choice([10.0, 50.0, 300.0]))
        got = offset_information_many(ref, mixes, [0, 2], 0.3, gate, chi2)
        assert len(got) == len(mixes)
        for m, (I, y) in zip(mixes, got, strict=True):
            I0, y0 = offset_information(ref, m, [0, 2], 0.3, gate, chi2)
            assert np.array_equal(I, I0) and np.array_equal(y, y0)
            I1, y1 = trust_before.offset_information(ref, m, [0, 2], 0.3, gate, chi2)
            assert np.array_equal(I, I1) and np.array_equal(y, y1)  # the per-mixture einsum's
            matched += bool(I.any())
    assert matched > 100  # most of them have pairs within the gate


@pytest.mark.parametrize("chi2", [None, 13.8])
def test_unmatched_weights_equal_old(chi2):
    rng = np.random.default_rng(8)
    for _ in range(200):
        own = _mixture(rng, int(rng.integers(0, 6)))
        mixes = [own] + _near_copies(rng, own, int(rng.integers(0, 6)))
        U, (hit, w, owner) = unmatched_weights(mixes, [0, 2], 0.3, 50.0, chi2)
        U0, (hit0, w0, owner0) = trust_before.unmatched_weights(mixes, [0, 2], 0.3, 50.0, chi2)
        assert np.array_equal(U, U0) and np.array_equal(hit, hit0)
        assert np.array_equal(w, w0) and np.array_equal(owner, owner0)


def test_cusum_directions_cached_read_only():
    for n in (1, 4, 8):
        want = trust_before.cusum_directions(n)
        got = cusum_directions(n)
        assert np.array_equal(got, want) and cusum_directions(n) is got
        assert np.allclose(np.linalg.norm(got, axis=1), 1.0)
        with pytest.raises(ValueError):
            got[0, 0] = 0.0


def test_withheld_test_taking_the_statistics_unmatched_weights_changes_nothing():
    """A round's withheld-target test takes the unmatched weights its statistics made of the
    same inputs (``Trust.made``); a Trust that makes them again weighs every round the same,
    to the bit, over scans where neighbours lie (empty, moved 200 m, a random density)."""
    rng = np.random.default_rng(21)
    cfg = TrustConfig(detection_probability=0.9)
    names = ("a", "b", "c", "d")
    reuse, again = Trust(cfg, names), Trust(cfg, names)
    plain = Trust._statistics_steps  # what weigh's statistics run

    def no_keep(own, inputs, weights, left_out=frozenset(), keep=None):
        return plain(again, own, inputs, weights, left_out)

    again._statistics_steps = no_keep
    reused = 0
    for k in range(1, 16):
        own = _mixture(rng, 4)
        for rnd in (0, 1):
            inputs = {s: GaussianMixture(own.weights, own.means + rng.normal(0, 3, (4, 4)),
                                         own.covs) for s in names}
            inputs["b"] = GaussianMixture.empty(4) if k % 3 else inputs["b"]
            inputs["c"] = GaussianMixture(own.weights, own.means + 200.0, own.covs)
            inputs["d"] = _mixture(rng, 3) if k > 8 else inputs["d"]
            w = [0.2] * 5
            assert reuse.weigh(k, rnd, own, inputs, w) == again.weigh(k, rnd, own, inputs, w)
            reused += "unmatched" in reuse.made and not again.made
    reuse.finish()
    again.finish()
    assert reused > 10
    assert reuse.summary() == again.summary()
    assert [reuse.n[s].withheld for s in names] == [again.n[s].withheld for s in names]
    assert max(reuse.n[s].withheld for s in names) > 0  # the withheld test did fire


def test_offset_chi2_many_is_one_at_a_time():
    """Windows of different lengths, singular scans (nothing matched) among them."""
    rng = np.random.default_rng(31)
    windows = (1, 5, 20)
    for _ in range(50):
        offsets = []
        for _ in range(int(rng.integers(1, 6))):
            d = deque()
            for _ in range(int(rng.integers(1, 25))):
                if rng.random() < 0.3:
                    d.append((np.zeros((2, 2)), np.zeros(2)))
                else:
                    A = rng.normal(0, 0.1, (2, 2))
                    d.append((A @ A.T + 1e-3 * np.eye(2), rng.normal(0, 1, 2)))
            offsets.append(d)
        got = offset_chi2_many(offsets, windows)
        assert got == [offset_chi2(d, windows) for d in offsets]
        assert any(c > 0 for g in got for c in g) and all(type(c) is float for c in got[0])
    assert offset_chi2_many([], windows) == []



def test_offset_chi2_of_full_windows_is_one_at_a_time_nan_and_signed_zeros_too():
    """A host's steady state: every window as long as the longest (stacked by ``np.array``,
    one index per window), with NaN and ``-0.0`` offsets and singular scans: each window's
    chi-squares are :func:`offset_chi2`'s to the bit (NaN where it gives NaN)."""
    rng = np.random.default_rng(32)
    windows = (3, 16)
    for _ in range(60):
        n = int(rng.integers(1, 20))
        offsets = []
        for _ in range(int(rng.integers(1, 13))):
            d = deque()
            for _ in range(n):
                A = rng.normal(0, 0.1, (2, 2))
                I, y = A @ A.T + 1e-3 * np.eye(2), rng.normal(0, 1, 2)
                r = rng.random()
                if r < 0.1:
                    I, y = np.zeros((2, 2)), np.zeros(2)
                elif r < 0.15:
                    y[0] = np.nan
                elif r < 0.25:
                    y[rng.integers(0, 2)] = -0.0
                    I[0, 1] = I[1, 0] = -0.0
                d.append((I, y))
            offsets.append(d)
        got = offset_chi2_many(offsets, windows)
        want = [offset_chi2(d, windows) for d in offsets]
        assert np.array_equal(np.array(got), np.array(want), equal_nan=True)
        assert all(type(c) is float for g in got for c in g)


def test_gls_offsets_is_one_at_a_time():
    rng = np.random.default_rng(41)
    for n in range(0, 7):
        infos = []
        for _ in range(n):
            A = rng.normal(0, 0.1, (2, 2))
            infos.append((np.zeros((2, 2)), np.zeros(2)) if rng.random() < 0.3 else
                         (A @ A.T + 1e-4 * np.eye(2), rng.normal(0, 1, 2)))
        got = gls_offsets(infos)
        assert len(got) == n
        for info, g in zip(infos, got, strict=True):
            want = gls_offset([info])
            assert (g is None and want is None) or np.array_equal(g, want)


def test_relative_offsets_equal_old():
    """The determinants in one batch and the leave-one-out medians by sorting: the old
    numbers to the bit (singular scans, two to seven neighbours, repeated offsets)."""
    rng = np.random.default_rng(51)
    changed = 0
    for _ in range(300):
        infos = {}
        for i in range(int(rng.integers(0, 8))):
            A = rng.normal(0, 0.1, (2, 2))
            infos[f"n{i}"] = ((np.zeros((2, 2)), np.zeros(2)) if rng.random() < 0.2 else
                              (A @ A.T + 1e-3 * np.eye(2), rng.normal(0, 1, 2)))
            if i and rng.random() < 0.2:
                infos[f"n{i}"] = infos[f"n{i - 1}"]
        among = [s for s in infos if rng.random() < 0.9]
        new = relative_offsets(infos, among)
        old = trust_before.relative_offsets(infos, among)
        assert new.keys() == old.keys()
        for s in new:
            assert np.array_equal(new[s][0], old[s][0]) and np.array_equal(new[s][1], old[s][1])
            changed += new[s] is not infos[s]
    assert changed > 300


@pytest.mark.parametrize("n", range(2, 10))
def test_loo_medians_are_numpys(n):
    rng = np.random.default_rng(n)
    for b in [rng.normal(0, 5, (n, 2)), np.round(rng.normal(0, 1, (n, 3))),
              np.where(rng.random((n, 2)) < 0.2, np.nan, rng.normal(0, 1, (n, 2)))]:
        others = np.array([[h for h in range(n) if h != i] for i in range(n)])
        with np.errstate(invalid="ignore"):
            want = np.median(b[others], axis=1)
        assert np.array_equal(_loo_medians(b), want, equal_nan=True)


def test_offset_cusums_are_one_at_a_time():
    """Every neighbour's offset CUSUM in one batch: :func:`offset_cusum` per neighbour to the
    bit (singular scans, charts at 0 and above, offsets small and large)."""
    rng = np.random.default_rng(61)
    dirs = cusum_directions(8)
    for _ in range(500):
        r = int(rng.integers(1, 7))
        infos = []
        for _ in range(r):
            A = rng.normal(0, rng.choice([0.01, 1.0, 100.0]), (2, 2))
            infos.append((np.zeros((2, 2)), np.zeros(2)) if rng.random() < 0.2 else
                         (A @ A.T + 1e-6 * np.eye(2), rng.normal(0, rng.choice([0.1, 1e3]), 2)))
        g = np.abs(rng.normal(0, 5, (r, 8))) * (rng.random((r, 8)) < 0.5)
        want = np.array([offset_cusum(g[i], infos[i], 30.0, dirs) for i in range(r)])
        assert np.array_equal(offset_cusums(g, infos, 30.0, dirs), want)
    assert offset_cusums(np.zeros((0, 8)), [], 30.0, dirs).shape == (0, 8)


def test_add_offsets_is_add_offset_per_neighbour():
    """Windows of different lengths over 30 scans: the same chi-squares, charts and windows
    as :func:`add_offset` one neighbour at a time."""
    rng = np.random.default_rng(62)
    cfg = TrustConfig()
    batch = [NeighbourTrust() for _ in range(4)]
    single = [NeighbourTrust() for _ in range(4)]
    for k in range(30):
        idx = [i for i in range(4) if rng.random() < 0.8 or k == 0]
        infos = []
        for _ in idx:
            A = rng.normal(0, 0.1, (2, 2))
            infos.append((np.zeros((2, 2)), np.zeros(2)) if rng.random() < 0.2 else
                         (A @ A.T + 1e-3 * np.eye(2), rng.normal(0, 1, 2)))
        got = add_offsets(cfg, [batch[i] for i in idx], infos)
        want = [add_offset(cfg, single[i], info) for i, info in zip(idx, infos, strict=True)]
        assert got == want
        for i in idx:
            assert np.array_equal(batch[i].cusum, single[i].cusum)
            assert batch[i].last_offset_chi2 == single[i].last_offset_chi2
    assert max(max(c) for c in want) > 0


def test_is_repeat_is_the_old_test():
    """The first-weight shortcut answers as the three array comparisons did: copies, a
    first weight changed (also to NaN or to -0.0 from 0.0), a later entry changed."""
    rng = np.random.default_rng(21)
    kinds = Counter()
    for _ in range(400):
        prev = _mixture(rng, int(rng.integers(0, 4)))
        mix = GaussianMixture(prev.weights.copy(), prev.means.copy(), prev.covs.copy())
        kind = int(rng.integers(0, 6))
        if len(mix) and kind == 1:
            mix.weights[0] = rng.choice([np.nan, mix.weights[0] * 1.5])
        elif len(mix) and kind == 2:
            prev.weights[0], mix.weights[0] = 0.0, -0.0
        elif len(mix) and kind == 3:
            mix.covs[-1, 2, 2] += 1e-9
        elif len(mix) and kind == 4:
            mix.weights[-1] = 0.1
        got = is_repeat(prev, mix, 0.3)
        assert got == trust_before.is_repeat(prev, mix, 0.3)
        kinds[(kind, got)] += 1
    assert kinds[(0, True)] > 20 and kinds[(2, True)] > 0  # equal ones found, -0.0 == 0.0
