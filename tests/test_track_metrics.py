"""Track-level metrics (tracking.track_metrics, tracking.tgospa) against independent computations:
OSPA(2) by its definition with loops, trajectory GOSPA against the paper's full linear programme
and against brute-force enumeration of assignment sequences, CLEAR MOT / IDF1 against
py-motmetrics, HOTA (TrackEval) and switch counts on hand-built cases."""

from __future__ import annotations

from itertools import permutations, product

import motmetrics as mm
import numpy as np
import pytest
from scipy.optimize import linprog
from sensornet.tracking.tgospa import trajectory_gospa
from sensornet.tracking.track_metrics import (
    TrackTable,
    clear_match,
    clear_mot,
    hota,
    idf1,
    label_agreement,
    ospa2,
    ospa2_dense,
    tables_by_peer,
    track_report,
)


def table(rows):
    """``rows``: (scan, id, x, y) tuples."""
    a = np.array(rows, dtype=float).reshape(-1, 4)
    return TrackTable(a[:, 0], a[:, 1], a[:, 2:])


def random_dense(rng, T, n, box=6.0, absent=0.25, d=2):
    X = rng.uniform(0, box, size=(T, n, d))
    X[rng.random((T, n)) < absent] = np.nan
    return X


def random_run(rng, T=12, m=3, labels=3, gate=3.0):
    """Truth random walks with gaps; estimates: noisy copies under changing labels, some
    dropped, plus clutter — tables with switches, fragments and false tracks."""
    rows_t, rows_e = [], []
    for j in range(m):
        x = rng.uniform(0, 20, 2)
        alive = rng.random(T) < 0.85
        for t in range(T):
            x = x + rng.normal(0, 1, 2)
            if alive[t]:
                rows_t.append((t, j, *x))
                if rng.random() < 0.8:
                    lab = 10 * j + int(rng.integers(0, labels))
                    rows_e.append((t, lab, *(x + rng.normal(0, gate / 2, 2))))
    for t in range(T):
        if rng.random() < 0.3:
            rows_e.append((t, 99, *rng.uniform(0, 20, 2)))
    return table(rows_t), table(rows_e)


# ------------------------------------------------------------------------------ OSPA(2)


def ospa2_by_definition(E, Y, c, p, start, end):
    """Beard, Vo & Vo 2020: base distance = mean over scans in [start, end) where either track
    exists of min(c, d) (both) or c (one); OSPA of order p over the tracks present, by trying
    every injection."""
    def present(Z, i):
        return [t for t in range(start, end) if not np.isnan(Z[t, i]).any()]

    xs = [i for i in range(E.shape[1]) if present(E, i)]
    ys = [j for j in range(Y.shape[1]) if present(Y, j)]

    def base(i, j):
        total, count = 0.0, 0
        for t in range(start, end):
            a, b = not np.isnan(E[t, i]).any(), not np.isnan(Y[t, j]).any()
            if a and b:
                total += min(c, float(np.linalg.norm(E[t, i] - Y[t, j])))
            elif a or b:
                total += c
            count += a or b
        return total / count

    n, m = len(xs), len(ys)
    if n == 0 and m == 0:
        return 0.0
    if n == 0 or m == 0:
        return c
    small, large, flip = (xs, ys, False) if n <= m else (ys, xs, True)
    best = min(sum((base(b, a) if flip else base(a, b)) ** p
                   for a, b in zip(small, perm, strict=False))
               for perm in permutations(large, len(small)))
    return ((best + c**p * abs(n - m)) / max(n, m)) ** (1 / p)


@pytest.mark.parametrize("seed", range(6))
def test_ospa2_matches_definition(seed):
    rng = np.random.default_rng(seed)
    T, c, p, L = 7, 4.0, [1.0, 2.0][seed % 2], 3
    E, Y = random_dense(rng, T, 4), random_dense(rng, T, 3)
    curve = ospa2_dense(E, Y, c, p, window=L)
    want = [ospa2_by_definition(E, Y, c, p, max(0, k + 1 - L), k + 1) for k in range(T)]
    np.testing.assert_allclose(curve, want, rtol=1e-12, atol=1e-12)
    whole = ospa2_dense(E, Y, c, p)
    np.testing.assert_allclose(whole, [ospa2_by_definition(E, Y, c, p, 0, T)], rtol=1e-12)


def test_ospa2_metric_properties():
    rng = np.random.default_rng(7)
    E, Y = random_dense(rng, 9, 4), random_dense(rng, 9, 3)
    np.testing.assert_allclose(ospa2_dense(E, E, 5.0, 2.0, 4), 0.0, atol=1e-12)
    np.testing.assert_allclose(ospa2_dense(E, Y, 5.0, 2.0, 4), ospa2_dense(Y, E, 5.0, 2.0, 4))
    assert np.all(ospa2_dense(E, Y, 5.0, 2.0, 4) <= 5.0 + 1e-12)


def test_ospa2_on_tables_hand_case():
    # one truth 4 scans at 0; an estimate 1 away for the first 2 scans only: the base distance
    # over 4 scans is (1 + 1 + c + c) / 4 = 3 with c = 5; one track each: OSPA(2) = 3
    truth = table([(t, 0, 0.0, 0.0) for t in range(4)])
    est = table([(t, 7, 1.0, 0.0) for t in range(2)])
    np.testing.assert_allclose(ospa2(truth, est, c=5.0, p=2.0), [3.0])
    np.testing.assert_allclose(ospa2(truth, est, c=5.0, p=2.0, window=2), [1, 1, 3, 5])


def _random_tracks(rng, n_ids: int, T: int, first_id: int = 0) -> TrackTable:
    """Tracks with random lives inside ``T`` scans, each present 90 % of its life."""
    rows = []
    for i in range(n_ids):
        s0 = int(rng.integers(0, T))
        for k in range(s0, min(T, s0 + int(rng.integers(1, 40)))):
            if rng.random() < 0.9:
                rows.append((k, first_id + 7 * i, *rng.normal(0.0, 30.0, 2)))
    return table(rows) if rows else TrackTable(np.zeros(0), np.zeros(0), np.zeros((0, 2)))


@pytest.mark.parametrize("seed", range(20))
def test_ospa2_in_chunks_equals_dense(seed):
    # limit=1 forces the chunked paths (a scan at a time for the whole run; 4 windows for
    # the curve): the same numbers as the dense evaluation, up to summation order
    rng = np.random.default_rng(seed)
    T = int(rng.integers(5, 80))
    truth, est = _random_tracks(rng, 4, T), _random_tracks(rng, 9, T, 1000)
    grid = np.arange(T)
    for window in (None, 3, 10):
        dense = ospa2(truth, est, 40.0, 2.0, window, grid)
        chunked = ospa2(truth, est, 40.0, 2.0, window, grid, limit=1)
        np.testing.assert_allclose(chunked, dense, rtol=1e-12, atol=1e-9)


def test_ospa2_of_a_long_run_with_thousands_of_ids_stays_small():
    # 3,000 scans, 2,000 short-lived track ids, 60 truths: dense pair distances would be
    # 3.6e8 cells (2.9 GB an array, several arrays); chunked the peak stays under 300 MB
    import tracemalloc

    rng = np.random.default_rng(0)
    truth, est = _random_tracks(rng, 60, 3000), _random_tracks(rng, 2000, 3000, 10_000)
    tracemalloc.start()
    try:
        curve = ospa2(truth, est, 200.0, 2.0, 10)
        run = ospa2(truth, est, 200.0, 2.0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 300e6
    assert curve.shape == (len(np.unique(np.concatenate([truth.scan, est.scan]))),)
    assert np.all((curve >= 0) & (curve <= 200.0)) and 0 < run[0] <= 200.0


# ------------------------------------------------------------------------ trajectory GOSPA


def pair_costs(E, Y, c, p):
    """The paper's D^t: (T, n+1, m+1), last row/column the dummy."""
    T, n, m = E.shape[0], E.shape[1], Y.shape[1]
    D = np.zeros((T, n + 1, m + 1))
    for t in range(T):
        for i in range(n + 1):
            for j in range(m + 1):
                a = i < n and not np.isnan(E[t, i]).any()
                b = j < m and not np.isnan(Y[t, j]).any()
                if a and b:
                    D[t, i, j] = min(float(np.linalg.norm(E[t, i] - Y[t, j])), c) ** p
                elif a or b:
                    D[t, i, j] = c**p / 2
    return D


def full_lp(E, Y, c, p, gamma):
    """The paper's LP (Sec. IV) with every W^t (n+1) x (m+1) and h_ij(t) >= |W^{t+1} - W^t|."""
    T, n, m = E.shape[0], E.shape[1], Y.shape[1]
    D = pair_costs(E, Y, c, p)
    nW = (n + 1) * (m + 1)
    nh = n * m * (T - 1)

    def w(t, i, j):
        return t * nW + i * (m + 1) + j

    def h(t, i, j):
        return T * nW + t * n * m + i * m + j

    N = T * nW + nh
    f = np.concatenate([D.reshape(-1), np.full(nh, gamma**p / 2)])
    Aeq, beq, Aub = [], [], []
    for t in range(T):
        for j in range(m):
            row = np.zeros(N)
            row[[w(t, i, j) for i in range(n + 1)]] = 1
            Aeq.append(row)
        for i in range(n):
            row = np.zeros(N)
            row[[w(t, i, j) for j in range(m + 1)]] = 1
            Aeq.append(row)
    beq = np.ones(len(Aeq))
    for t in range(T - 1):
        for i in range(n):
            for j in range(m):
                for s in (1, -1):
                    row = np.zeros(N)
                    row[w(t + 1, i, j)], row[w(t, i, j)], row[h(t, i, j)] = s, -s, -1
                    Aub.append(row)
    res = linprog(f, A_ub=np.array(Aub) if Aub else None, b_ub=np.zeros(len(Aub)) if Aub
                  else None, A_eq=np.array(Aeq), b_eq=beq, bounds=(0, None), method="highs")
    assert res.status == 0
    return res.fun ** (1 / p)


def brute_force(E, Y, c, p, gamma):
    """Definition 2 of the paper: minimum over every sequence of assignments pi^t (estimate i
    -> truth pi_i or unassigned, -1) of sum_t [paired costs + c^p/2 per unpaired present
    trajectory] + gamma^p sum_t sum_i s_i, s_i = 0 same, 1 both assigned and different,
    1/2 otherwise."""
    T, n, m = E.shape[0], E.shape[1], Y.shape[1]
    D = pair_costs(E, Y, c, p)
    assigns = [a for a in product(range(-1, m), repeat=n)
               if len([x for x in a if x >= 0]) == len({x for x in a if x >= 0})]
    A = len(assigns)
    step = np.zeros((T, A))
    for t in range(T):
        for k, a in enumerate(assigns):
            used = {x for x in a if x >= 0}
            step[t, k] = (sum(D[t, i, a[i]] if a[i] >= 0 else D[t, i, m] for i in range(n))
                          + sum(D[t, n, j] for j in range(m) if j not in used))
    sw = np.zeros((A, A))
    for k, a in enumerate(assigns):
        for q, b in enumerate(assigns):
            sw[k, q] = sum(0 if x == y else (1 if x >= 0 and y >= 0 else 0.5)
                           for x, y in zip(a, b, strict=True))
    seqs = np.array(list(product(range(A), repeat=T)))  # every sequence of assignments
    total = step[np.arange(T), seqs].sum(axis=1)
    total += gamma**p * sw[seqs[:, :-1], seqs[:, 1:]].sum(axis=1)
    return total.min() ** (1 / p)


def close_pair_case(rng, T, n, m):
    """Truths on a small grid, estimates near truths under swapped labels, with absences."""
    Y = rng.uniform(0, 4, size=(T, m, 2))
    E = np.empty((T, n, 2))
    for t in range(T):
        E[t] = Y[t, rng.integers(0, m, n)] + rng.normal(0, 0.7, (n, 2))
    E[rng.random((T, n)) < 0.2] = np.nan
    Y[rng.random((T, m)) < 0.2] = np.nan
    return E, Y


@pytest.mark.parametrize("seed", range(8))
def test_tgospa_equals_full_paper_lp(seed):
    rng = np.random.default_rng(100 + seed)
    E, Y = close_pair_case(rng, 5, 3, 3)
    c, p, gamma = 2.0, [1.0, 2.0][seed % 2], [0.5, 1.5, 3.0, 6.0][seed % 4]
    got = trajectory_gospa(E, Y, c, p, gamma)
    assert got.distance == pytest.approx(full_lp(E, Y, c, p, gamma), rel=1e-7, abs=1e-9)


@pytest.mark.parametrize("seed", range(10))
def test_tgospa_against_brute_force(seed):
    rng = np.random.default_rng(200 + seed)
    shape = [(4, 2, 2), (3, 3, 2), (3, 2, 3)][seed % 3]
    E, Y = close_pair_case(rng, shape[0], shape[1], shape[2])
    c, p, gamma = 2.0, [1.0, 2.0][seed % 2], [0.5, 1.5, 3.0][seed % 3]
    integer_value = brute_force(E, Y, c, p, gamma)
    lp = trajectory_gospa(E, Y, c, p, gamma)
    exact = trajectory_gospa(E, Y, c, p, gamma, integer=True)
    assert exact.distance == pytest.approx(integer_value, rel=1e-7, abs=1e-9)
    assert lp.distance <= integer_value + 1e-9  # the relaxation never exceeds the integer form
    if lp.integral:
        assert lp.distance == pytest.approx(integer_value, rel=1e-7, abs=1e-9)


def test_tgospa_relaxation_below_integer_form():
    """A case (found by search) where the LP optimum is fractional: the relaxation is strictly
    below the assignment form, which the mixed-integer programme still matches exactly."""
    rng = np.random.default_rng(1445)
    shape = rng.integers(3, 7), rng.integers(2, 5), rng.integers(2, 5)
    assert tuple(int(s) for s in shape) == (4, 2, 4)
    E, Y = close_pair_case(rng, 4, 2, 4)
    lp = trajectory_gospa(E, Y, 2.0, 2.0, 0.8)
    exact = trajectory_gospa(E, Y, 2.0, 2.0, 0.8, integer=True)
    brute = brute_force(E, Y, 2.0, 2.0, 0.8)
    assert not lp.integral and exact.integral
    assert lp.distance < brute - 1e-5
    assert exact.distance == pytest.approx(brute, rel=1e-9)
    assert lp.distance == pytest.approx(full_lp(E, Y, 2.0, 2.0, 0.8), rel=1e-7)


def test_tgospa_hand_cases_and_parts():
    T = 4
    x = np.zeros((T, 1, 2))
    y = x + [1.0, 0.0]
    r = trajectory_gospa(x, y, c=5.0, p=2.0, gamma=3.0)
    assert r.distance == pytest.approx(2.0)  # sqrt(4 scans * 1^2)
    assert (r.localisation, r.missed, r.false, r.switches) == pytest.approx((4, 0, 0, 0))
    # two estimates, truths swap labels after scan 2: two full switches, gamma^p each
    x = np.zeros((T, 2, 2))
    x[:, 1, 0] = 10.0
    y = x.copy()
    y[2:] = y[2:, ::-1]
    r = trajectory_gospa(x, y, c=5.0, p=2.0, gamma=3.0)
    assert r.distance**2 == pytest.approx(18.0) and r.switches == pytest.approx(2.0)
    # a missed truth for 3 scans and a false estimate for 1: c^p/2 each
    x = np.full((T, 1, 2), np.nan)
    x[0] = 50.0
    y = np.full((T, 1, 2), np.nan)
    y[1:] = 0.0
    r = trajectory_gospa(x, y, c=5.0, p=2.0, gamma=3.0)
    assert (r.missed, r.false) == pytest.approx((3, 1))
    assert r.distance**2 == pytest.approx(25 / 2 * 4)
    rng = np.random.default_rng(3)
    E, Y = close_pair_case(rng, 6, 3, 2)
    a, b = trajectory_gospa(E, Y, 2.0, 2.0, 1.0), trajectory_gospa(Y, E, 2.0, 2.0, 1.0)
    assert a.distance == pytest.approx(b.distance)  # symmetric
    assert trajectory_gospa(E, E, 2.0, 2.0, 1.0).distance == pytest.approx(0.0, abs=1e-9)
    total = a.localisation + 2.0**2 / 2 * (a.missed + a.false) + a.switching
    assert a.distance**2 == pytest.approx(total)
    assert a.per_scan.sum() + a.switch_per_scan.sum() == pytest.approx(total)


def test_tgospa_bad_input():
    with pytest.raises(ValueError, match="est"):
        trajectory_gospa(np.zeros((3, 2)), np.zeros((3, 1, 2)))
    with pytest.raises(ValueError, match="differ"):
        trajectory_gospa(np.zeros((3, 1, 2)), np.zeros((4, 1, 2)))


# ---------------------------------------------------------------- CLEAR MOT, IDF1, HOTA


def test_switches_and_fragments_hand_built():
    truth = table([(t, 1, 0.0, 0.0) for t in range(8)] + [(t, 2, 50.0, 0.0) for t in range(8)])
    # truth 1: label a, a, b, b, -, b, a, a -> switches at 2 and 6, one fragment (4 -> 5)
    labels = ["a", "a", "b", "b", None, "b", "a", "a"]
    ids = {"a": 10, "b": 11}
    rows = [(t, ids[lab], 0.1, 0.0) for t, lab in enumerate(labels) if lab]
    # truth 2: tracked by 20 except scans 3, 4 (one fragment, no switch)
    rows += [(t, 20, 50.0, 0.2) for t in range(8) if t not in (3, 4)]
    cl = clear_match(truth, table(rows), gate=1.0)
    r = clear_mot(cl)
    assert r["switches"] == 2 and r["fragmentations"] == 2
    pt = r["per_truth"]
    assert pt["switches"].tolist() == [2, 0] and pt["fragmentations"].tolist() == [1, 1]
    np.testing.assert_allclose(pt["continuity"], [4 / 8, 6 / 8])  # a 4 of 8; 20 six of 8
    assert r["misses"] == 3 and r["false"] == 0
    assert r["mota"] == pytest.approx(1 - (3 + 0 + 2) / 16)
    assert r["motp"] == pytest.approx((7 * 0.1 + 6 * 0.2) / 13)


def test_estimate_kept_while_within_gate():
    # CLEAR MOT keeps an established pair within the gate even when another is closer
    truth = table([(0, 1, 0, 0), (1, 1, 0, 0)])
    est = table([(0, 5, 0.5, 0), (1, 5, 0.9, 0), (1, 6, 0.0, 0)])
    r = clear_mot(clear_match(truth, est, gate=1.0))
    assert r["switches"] == 0 and r["false"] == 1


@pytest.mark.parametrize("seed", range(6))
def test_clear_and_idf1_equal_motmetrics(seed):
    rng = np.random.default_rng(300 + seed)
    gate = 3.0
    truth, est = random_run(rng, T=15, m=3, labels=3, gate=gate)
    r = clear_mot(clear_match(truth, est, gate))
    i = idf1(truth, est, gate)
    acc = mm.MOTAccumulator(auto_id=False)
    for t in np.unique(np.concatenate([truth.scan, est.scan])):
        a, b = truth.scan == t, est.scan == t
        oi, hi = np.argsort(truth.id[a]), np.argsort(est.id[b])
        D = np.linalg.norm(truth.pos[a][oi][:, None] - est.pos[b][hi][None], axis=-1)
        D[D > gate] = np.nan
        acc.update(truth.id[a][oi], est.id[b][hi], D, frameid=int(t))
    ref = mm.metrics.create().compute(
        acc, metrics=["idf1", "idtp", "mota", "motp", "num_switches", "num_fragmentations",
                      "num_misses", "num_false_positives"], name="run").iloc[0]
    assert r["switches"] > 0 or seed > 2  # the cases do exercise switches
    assert i["idf1"] == pytest.approx(ref.idf1) and i["idtp"] == ref.idtp
    assert r["mota"] == pytest.approx(ref.mota) and r["motp"] == pytest.approx(ref.motp)
    assert (r["switches"], r["fragmentations"], r["misses"], r["false"]) == (
        ref.num_switches, ref.num_fragmentations, ref.num_misses, ref.num_false_positives)


def test_idf1_hand_case():
    truth = table([(t, 1, 0, 0) for t in range(4)])
    est = table([(0, 5, 0, 0), (1, 5, 0, 0), (2, 6, 0, 0), (3, 6, 0, 0)])
    assert idf1(truth, est, 1.0)["idf1"] == pytest.approx(2 * 2 / (4 + 4))


def test_hota_closed_forms():
    truth = table([(t, 1, 0, 0) for t in range(4)] + [(t, 2, 9, 0) for t in range(4)])
    assert hota(truth, table([(t, i + 10, x, 0) for t, i, x, _ in
                              [(t, 1, 0, 0) for t in range(4)] + [(t, 2, 9, 0)
                                                                  for t in range(4)]]),
                gate=1.0)["hota"] == pytest.approx(1.0)
    # one truth, two frames, the label changes halfway: DetA 1, AssA 1/2
    one = table([(0, 1, 0, 0), (1, 1, 0, 0)])
    r = hota(one, table([(0, 5, 0, 0), (1, 6, 0, 0)]), gate=1.0)
    assert (r["hota"], r["deta"], r["assa"]) == pytest.approx((np.sqrt(0.5), 1.0, 0.5))
    # similarity 1 - 0.45 = 0.55 matches at thresholds 0.05 .. 0.55: 11 of 19, HOTA 1 there
    r = hota(one, table([(0, 5, 0.45, 0), (1, 5, 0.45, 0)]), gate=1.0)
    assert r["hota"] == pytest.approx(11 / 19) and r["loca"] == pytest.approx(
        (11 * 0.55 + 8 * 1.0) / 19)  # TrackEval's LocA is 1 at thresholds with no match
    # seen once of two frames: DetA 1/2 (TP 1, FN 1), AssA 1/2 (TPA 1, FNA 1)
    r = hota(one, table([(0, 5, 0, 0)]), gate=1.0)
    assert r["hota"] == pytest.approx(0.5)


# -------------------------------------------------------------------- report, agreement


def test_report_identical_runs_are_perfect():
    rng = np.random.default_rng(11)
    truth, _ = random_run(rng, T=10, m=3)
    est = TrackTable(truth.scan, truth.id + 100, truth.pos)
    r = track_report(truth, est, c=5.0, window=3)
    assert r["ospa2"] == pytest.approx(0.0, abs=1e-12) and np.allclose(r["ospa2_curve"], 0)
    assert r["tgospa"] == pytest.approx(0.0, abs=1e-9)
    assert (r["mota"], r["idf1"], r["hota"], r["switches"]) == pytest.approx((1, 1, 1, 0))
    assert np.allclose(r["per_truth"]["continuity"], 1.0)


def test_report_switch_rate():
    truth = table([(t, 1, 0, 0) for t in range(10)] + [(t, 2, 20, 0) for t in range(10)])
    est = table([(t, 5 if t < 5 else 6, 0, 0) for t in range(10)]
                + [(t, 7, 20, 0) for t in range(10)])
    r = track_report(truth, est, c=5.0, gamma=2.0, window=4)
    assert r["switches"] == 1 and r["switches_per_1000"] == pytest.approx(1000 / 20)
    assert r["tgospa_switches"] == pytest.approx(1.0)  # 5 -> 6 on truth 1: two half switches
    assert r["idf1"] == pytest.approx(2 * 15 / 40)


def test_label_agreement_hand_case():
    truth = table([(t, 1, 0, 0) for t in range(4)] + [(t, 2, 30, 0) for t in range(4)])
    flat = {"peer": [], "scan": [], "id": [], "x": [], "y": []}
    for peer, rows in {"a": [(t, 7, 0, 0) for t in range(4)] + [(t, 8, 30, 0) for t in range(4)],
                       "b": [(t, 7 if t != 2 else 9, 0, 0) for t in range(4)]
                       + [(t, 8, 30, 0) for t in range(3)]}.items():
        for s, i, x, y in rows:
            for k, v in zip(("peer", "scan", "id", "x", "y"), (peer, s, i, x, y), strict=True):
                flat[k].append(v)
    by_peer = tables_by_peer({k: np.array(v) for k, v in flat.items()})
    assert sorted(by_peer) == ["a", "b"]
    r = label_agreement(by_peer, truth, gate=1.0)
    # matched at both peers: 4 + 3 = 7 pairs, 6 agree; matched at either: 8
    assert (r["confirmed"], r["agreeing"], r["confirmed_any"]) == (7, 6, 8)
    assert r["agreement"] == pytest.approx(6 / 7) and r["agreement_any"] == pytest.approx(6 / 8)


def test_bad_tables():
    with pytest.raises(ValueError, match="twice"):
        table([(0, 1, 0, 0), (0, 1, 1, 1)])
    with pytest.raises(ValueError, match="length"):
        TrackTable(np.arange(3), np.arange(2), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="non-finite"):
        table([(0, 1, np.nan, 0)])
