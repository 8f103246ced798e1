"""OSPA / GOSPA / cardinality error (tracking.metrics) against brute-force definitions."""

from __future__ import annotations

from itertools import combinations, permutations

import numpy as np
import pytest
from sensornet.tracking.metrics import cardinality_error, gospa, ospa, rmse


def random_set(rng, max_size=5, box=10.0, d=2):
    return rng.uniform(0, box, size=(int(rng.integers(0, max_size + 1)), d))


def brute_ospa(X, Y, c, p):
    """Schuhmacher, Vo & Vo 2008, by trying every injection of the smaller set."""
    n, m = len(X), len(Y)
    if n == 0 and m == 0:
        return 0.0
    if n > m:
        X, Y, n, m = Y, X, m, n
    best = np.inf
    for perm in permutations(range(m), n):
        s = sum(min(c, float(np.linalg.norm(X[i] - Y[j]))) ** p for i, j in enumerate(perm))
        best = min(best, s)
    return float(((best + c**p * (m - n)) / m) ** (1 / p))


def brute_gospa_assignment(X, Y, c, p):
    """GOSPA with alpha = 2 in assignment form (Rahmathullah et al. 2017, Prop. 1): minimum over
    all partial matchings of sum d^p over matched pairs + c^p / 2 per unmatched point."""
    n, m = len(X), len(Y)
    best = c**p / 2 * (n + m)  # nothing matched
    for k in range(1, min(n, m) + 1):
        for xs in combinations(range(n), k):
            for ys in permutations(range(m), k):
                s = sum(float(np.linalg.norm(X[i] - Y[j])) ** p for i, j in zip(xs, ys,
                                                                              strict=True))
                best = min(best, s + c**p / 2 * (n + m - 2 * k))
    return float(best ** (1 / p))


def brute_gospa_definition(X, Y, c, p, alpha):
    """GOSPA by its definition (Rahmathullah et al. 2017, eq. 1), any 0 < alpha <= 2:
    for |X| <= |Y|, min over injections of sum min(c, d)^p + c^p / alpha (|Y| - |X|)."""
    n, m = len(X), len(Y)
    if n > m:
        X, Y, n, m = Y, X, m, n
    best = 0.0 if n == 0 else np.inf
    for perm in permutations(range(m), n):
        s = sum(min(c, float(np.linalg.norm(X[i] - Y[j]))) ** p for i, j in enumerate(perm))
        best = min(best, s)
    return float((best + c**p / alpha * (m - n)) ** (1 / p))


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_ospa_equals_brute_force(p):
    rng = np.random.default_rng(int(p))
    for _ in range(120):
        X, Y = random_set(rng), random_set(rng)
        c = float(rng.choice([1.0, 3.0, 20.0]))
        assert ospa(X, Y, c=c, p=p) == pytest.approx(brute_ospa(X, Y, c, p), rel=1e-12, abs=1e-12)


def test_ospa_special_cases():
    X = np.array([[0.0, 0.0], [3.0, 4.0]])
    assert ospa(np.zeros((0, 2)), np.zeros((0, 2)), c=10) == 0.0
    assert ospa(X, np.zeros((0, 2)), c=10) == 10.0
    assert ospa(np.zeros((0, 2)), X, c=10) == 10.0
    assert ospa(X, X, c=10) == 0.0
    # one point at distance 5, one missing: ((5^2 + 10^2) / 2)^(1/2)
    assert ospa(X[:1] + [3.0, 4.0], X, c=10.0, p=2.0) == pytest.approx(
        np.sqrt((0.0 + 100.0) / 2)
    )
    assert ospa(X[:1], X[1:], c=10.0, p=2.0) == pytest.approx(5.0)
    assert ospa(X[:1], X[1:], c=2.0, p=2.0) == pytest.approx(2.0)  # cut off


@pytest.mark.parametrize("metric", ["ospa", "gospa"])
@pytest.mark.parametrize("p", [1.0, 2.0])
def test_metric_axioms(metric, p):
    fn = ospa if metric == "ospa" else gospa
    rng = np.random.default_rng(7 + int(p))
    for _ in range(150):
        X, Y, Z = random_set(rng), random_set(rng), random_set(rng)
        c = float(rng.choice([2.0, 5.0]))
        dxy, dyx = fn(X, Y, c=c, p=p), fn(Y, X, c=c, p=p)
        assert dxy == pytest.approx(dyx, rel=1e-12, abs=1e-12)
        assert fn(X, X, c=c, p=p) == 0.0
        if len(X) != len(Y) or len(X) and not np.allclose(np.sort(X, 0), np.sort(Y, 0)):
            assert dxy > 0
        assert dxy <= fn(X, Z, c=c, p=p) + fn(Z, Y, c=c, p=p) + 1e-9
        assert dxy >= 0


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_gospa_alpha2_equals_brute_force(p):
    rng = np.random.default_rng(30 + int(p))
    for _ in range(80):
        X, Y = random_set(rng), random_set(rng)
        c = float(rng.choice([1.0, 3.0, 20.0]))
        ref = brute_gospa_assignment(X, Y, c, p)
        assert gospa(X, Y, c=c, p=p, alpha=2.0) == pytest.approx(ref, rel=1e-12, abs=1e-12)
        # the definition with alpha = 2 agrees with the assignment form
        assert brute_gospa_definition(X, Y, c, p, 2.0) == pytest.approx(ref, rel=1e-12)


@pytest.mark.parametrize("alpha", [1.0, 1.5])
def test_gospa_other_alpha_equals_definition(alpha):
    rng = np.random.default_rng(int(alpha * 10))
    for _ in range(80):
        X, Y = random_set(rng), random_set(rng)
        c = float(rng.choice([1.0, 3.0]))
        ref = brute_gospa_definition(X, Y, c, 2.0, alpha)
        assert gospa(X, Y, c=c, p=2.0, alpha=alpha) == pytest.approx(ref, rel=1e-12, abs=1e-12)


def test_gospa_special_cases():
    X = np.array([[0.0, 0.0], [3.0, 4.0]])
    assert gospa(np.zeros((0, 2)), np.zeros((0, 2))) == 0.0
    # two missed targets: (2 c^p / 2)^(1/p)
    assert gospa(X, np.zeros((0, 2)), c=10.0, p=2.0) == pytest.approx(10.0)
    # one pair at distance 5 (kept: 25 < 100), one false target: (25 + 50)^(1/2)
    assert gospa(X[:1] + [3.0, 4.0], X, c=10.0, p=2.0) == pytest.approx(np.sqrt(0.0 + 50.0))
    assert gospa(X[:1], X[1:], c=10.0, p=2.0) == pytest.approx(5.0)
    # beyond the cut-off: one missed + one false = c^p
    assert gospa(X[:1], X[1:], c=2.0, p=2.0) == pytest.approx(2.0)


def test_cardinality_error():
    X = np.ones((3, 2))
    assert cardinality_error(X, np.ones((1, 2))) == 2
    assert cardinality_error(np.ones((1, 2)), X) == 2
    assert cardinality_error(X, X) == 0
    assert cardinality_error(np.zeros((0, 2)), X) == 3
    assert cardinality_error(X, np.zeros((0,))) == 3
    assert cardinality_error(np.zeros((0, 4)), np.zeros((0, 2))) == 0
    assert cardinality_error(np.array([1.0, 2.0]), np.zeros((0, 2))) == 1  # a single point


def test_rmse():
    e = np.array([[1.0, -2.0], [3.0, 2.0], [-1.0, 0.0]])
    np.testing.assert_allclose(rmse(e), np.sqrt([(1 + 9 + 1) / 3, (4 + 4) / 3]))
    np.testing.assert_allclose(rmse(e, axis=1), np.sqrt([2.5, 6.5, 0.5]))


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_gospa_parts_add_up_to_gospa_and_count_points(p):
    """The decomposition reproduces gospa() and its counts obey n - false = m - missed."""
    from sensornet.tracking.metrics import gospa_parts

    rng = np.random.default_rng(7)
    c = 20.0
    for _ in range(200):
        n, m = rng.integers(0, 5, size=2)
        X, Y = rng.uniform(0, 40, (n, 2)), rng.uniform(0, 40, (m, 2))
        total, loc, missed, false = gospa_parts(X, Y, c, p)
        assert total == pytest.approx(gospa(X, Y, c=c, p=p), rel=1e-12, abs=1e-12)
        assert total == pytest.approx((loc + c**p / 2 * (missed + false)) ** (1 / p), rel=1e-12)
        assert n - false == m - missed >= 0
        assert loc <= (n - false) * c**p


def test_gospa_parts_closed_form():
    """One estimate 3 m from a target and one far from the other target: loc 3^2, and the far
    pair counts as one missed target and one false estimate."""
    from sensornet.tracking.metrics import gospa_parts

    X = np.array([[0.0, 3.0], [500.0, 500.0]])
    Y = np.array([[0.0, 0.0], [100.0, 0.0]])
    total, loc, missed, false = gospa_parts(X, Y, c=10.0, p=2.0)
    assert (loc, missed, false) == (9.0, 1, 1)
    assert total == pytest.approx(np.sqrt(9.0 + 100.0 / 2 * 2))


def test_ospa_gospa_parts_equals_each_metric_bit_for_bit():
    """The shared assignment (and the solver-free single-point case) gives exactly what
    ospa and gospa_parts give apart, over random sets of 0-4 points with tied and cut pairs."""
    from sensornet.tracking.metrics import gospa_parts, ospa_gospa_parts

    rng = np.random.default_rng(7)
    for t in range(3000):
        n, m = rng.integers(0, 5, 2)
        X, Y = rng.normal(0, 150, (n, 2)), rng.normal(0, 150, (m, 2))
        if t % 3 == 0 and n and m:
            X[0] = Y[0]  # a zero distance
        if t % 5 == 0 and m > 1:
            Y[1] = Y[0] + 1000.0  # beyond the cut-off
        assert ospa_gospa_parts(X, Y, 200.0, 2.0) == (ospa(X, Y, 200.0, 2.0),
                                                      gospa_parts(X, Y, 200.0, 2.0))


def test_batched_scores_equal_one_by_one():
    """ospa_gospa_parts_many (every assignment tried at once for up to 6 points a side, the
    solver beyond) gives each problem's ospa_gospa_parts to rounding, for random batches with
    empty sides, cut and exactly cut-off pairs, p = 1 and 2, and problems too big to permute."""
    from sensornet.tracking.metrics import PERMUTED_UP_TO, ospa_gospa_parts, ospa_gospa_parts_many

    rng = np.random.default_rng(11)
    for p, c in ((2.0, 200.0), (1.0, 50.0)):
        problems = []
        for t in range(600):
            n, m = rng.integers(0, PERMUTED_UP_TO + 3, 2)
            X, Y = rng.normal(0, 150, (n, 2)), rng.normal(0, 150, (m, 2))
            if t % 4 == 0 and n and m:
                X[0] = Y[0] + [c, 0.0]  # exactly at the cut-off: not a close pair
            problems.append((X, Y))
        for i in range(0, len(problems), 25):  # batches as a host's pass makes them
            batch = problems[i:i + 25]
            for (X, Y), (o, parts) in zip(batch, ospa_gospa_parts_many(batch, c, p),
                                          strict=True):
                ro, rparts = ospa_gospa_parts(X, Y, c, p)
                assert o == pytest.approx(ro, rel=1e-12, abs=1e-12)
                assert parts[0] == pytest.approx(rparts[0], rel=1e-12, abs=1e-12)
                assert parts[1] == pytest.approx(rparts[1], rel=1e-12, abs=1e-9)
                assert parts[2:] == rparts[2:]  # missed and false counts: the same
