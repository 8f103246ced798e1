"""A peer host's trust tests run together (peers/trust_batch.py) give each peer's own numbers.

``weigh_together`` runs several peers' rounds of :meth:`Trust.weigh` in lockstep and computes
their divergences, offsets and charts in stacked computations; every peer's weights, records
and trust states must be those of its own ``weigh``, to the bit, over scans with lying,
quarantined, registered, repaired and late neighbours. The stacked primitives are held to
the one-at-a-time functions, and a twin with a liar publishes the same fused states and trust
summaries whichever way its host tests.
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import numpy as np
import pytest
from sensornet.peers.batching import FusionBatch
from sensornet.peers.trust import Trust, TrustConfig
from sensornet.peers.trust_batch import TOGETHER, run_together, weigh_together
from sensornet.peers.trust_checks import (
    ALONE,
    centred,
    divergence_test,
    divergence_tests,
    information_sums,
    neighbour_statistics_steps,
    segment_sums,
    target_mass,
)
from sensornet.peers.trust_record import NeighbourTrust, push_window, stacked_window
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.divergence import (
    cs_from_log_overlaps,
    log_overlaps,
    log_overlaps_many,
)
from sensornet.tracking.mixture import GaussianMixture

from benchmarks import trust_before
from benchmarks.bench_network import scenario_text
from tests.trust_twin import run_with_batch


def _mixture(rng: np.random.Generator, size: int, d: int = 4,
             side: float = 2000.0) -> GaussianMixture:
    """``size`` components over a square of ``side`` m (positions at 0 and 2), some heavy."""
    if size == 0:
        return GaussianMixture.empty(d)
    A = rng.normal(0, 1, (size, d, d)) * rng.uniform(1, 40, (size, 1, 1))
    return GaussianMixture(rng.uniform(0.05, 1.0, size),
                           rng.uniform(-side / 2, side / 2, (size, d)),
                           A @ A.transpose(0, 2, 1) + np.eye(d))


def test_log_overlaps_many_is_each_groups_log_overlaps_to_the_bit():
    rng = np.random.default_rng(3)
    for _ in range(60):
        groups = []
        for _ in range(int(rng.integers(1, 12))):
            mixes = [_mixture(rng, int(rng.integers(0, 13))) for _ in range(rng.integers(1, 7))]
            if rng.random() < 0.3:
                mixes.append(mixes[0])  # identical inputs
            if rng.random() < 0.2:  # one component each (or none)
                mixes = [_mixture(rng, int(rng.integers(0, 2))) for _ in range(4)]
            if rng.random() < 0.05:
                mixes = [_mixture(rng, 2, d=2)]  # another dimension: on its own
            groups.append(mixes)
        for mixes, L in zip(groups, log_overlaps_many(groups), strict=True):
            assert np.array_equal(L, log_overlaps(mixes))


def _requests(rng: np.random.Generator, op: str) -> list[tuple]:
    """Random arguments of a stacked request kind, as the trust generators make them."""
    if op == "overlaps":
        return [([_mixture(rng, int(rng.integers(0, 6))) for _ in range(5)],)
                for _ in range(int(rng.integers(2, 9)))]
    if op == "relative":  # 2-7 offsets, some singular, some left out of the median
        out = []
        for _ in range(int(rng.integers(2, 12))):
            infos = {}
            for i in range(int(rng.integers(2, 8))):
                B = rng.normal(0, 1, (2, 2))
                infos[f"n{i}"] = (B @ B.T * (rng.random() < 0.85), rng.normal(0, 30, 2))
            among = [s for s in infos if rng.random() < 0.85]
            out.append((infos, among))
        return out
    if op == "withheld":  # 2-6 inputs, any references (own's column always among them)
        out = []
        for _ in range(int(rng.integers(2, 12))):
            n = int(rng.integers(2, 7))
            U = rng.uniform(0, 2, (n, n)) * (rng.random((n, n)) < 0.5)
            refs = (rng.random((n, n)) < 0.7) & ~np.eye(n, dtype=bool)
            out.append((U, rng.uniform(0, 3, n), refs, 0.9, 0.99, 4.47))
        return out
    if op == "masses":  # mixtures shared between requests, as a host's estimates are
        pool = [_mixture(rng, int(rng.integers(0, 6))) for _ in range(6)]
        return [([pool[i] for i in rng.integers(0, 6, int(rng.integers(1, 6)))],
                 float(rng.choice([0.3, 0.5]))) for _ in range(int(rng.integers(2, 9)))]
    if op in ("unmatched", "offsets"):  # near enough for the gates to pair some
        out = []
        for _ in range(int(rng.integers(2, 9))):
            mixes = [_mixture(rng, int(rng.integers(0, 6)), side=300.0)
                     for _ in range(int(rng.integers(1, 6)))]
            chi2 = [None, 13.8][int(rng.integers(0, 2))]
            if op == "unmatched":
                out.append((mixes, [0, 2], 0.3, 50.0, chi2))
            else:
                ref = _mixture(rng, int(rng.integers(0, 6)), side=300.0)
                out.append((ref, mixes, [0, 2], 0.3, 60.0, chi2))
        return out
    out = []
    for _ in range(int(rng.integers(2, 9))):
        infos = []
        for _ in range(int(rng.integers(1, 6))):  # per neighbour: a window of (I, y)
            window = []
            for _ in range(int(rng.integers(1, 20))):
                B = rng.normal(0, 1, (2, 2))
                I = B @ B.T * (rng.random() < 0.8)  # some scans matched nothing
                window.append((I, rng.normal(0, 3, 2)))
            infos.append(window)
        if op == "chi2":  # the windows as trust_record.stacked_window gives them
            out.append(([(np.array([i for i, _ in w]), np.array([v for _, v in w]))
                         for w in infos], (3, 16)))
        else:
            g = np.maximum(0.0, rng.normal(0, 5, (len(infos), 8)))
            out.append((g, [w[0] for w in infos], 30.0, np.eye(2)[[0, 1, 0, 1, 0, 1, 0, 1]]))
    return out


@pytest.mark.parametrize("op", sorted(set(TOGETHER) - {"tests", "own_tests"}))  # below
def test_each_stacked_request_equals_its_own_computation(op):
    rng = np.random.default_rng(len(op))
    for _ in range(30):
        args = _requests(rng, op)
        for a, got in zip(args, TOGETHER[op](args), strict=True):
            want = ALONE[op](*a)
            if op == "relative":  # per neighbour (I, y)
                assert got.keys() == want.keys()
                for s in want:
                    assert np.array_equal(got[s][0], want[s][0])
                    assert np.array_equal(got[s][1], want[s][1])
            elif op == "offsets":  # per mixture (I, y)
                assert len(got) == len(want)
                for (I, y), (I0, y0) in zip(got, want, strict=True):
                    assert np.array_equal(I, I0) and np.array_equal(y, y0)
            elif isinstance(want, np.ndarray):
                assert np.array_equal(got, want)
            else:
                assert got == want


TEST_CONFIGS = [
    TrustConfig(),
    TrustConfig(detection_probability=0.9),
    TrustConfig(detection_probability=0.9, location_only=True),
    TrustConfig(detection_probability=0.9, median_test=False),
    TrustConfig(majority=False),
]


def _tests_request(cfg: TrustConfig, rng: np.random.Generator) -> tuple:
    """The ``"tests"`` request :func:`neighbour_statistics_steps` makes of random inputs
    (0-8 neighbours: empty, single, copied and near copies of own; zero weights and
    quarantined ones)."""
    own = _mixture(rng, int(rng.integers(0, 5)), side=600.0)
    inputs = {}
    for i in range(int(rng.integers(0, 9))):
        kind = rng.integers(0, 4)
        if kind == 0 and inputs:
            inputs[f"n{i}"] = inputs[sorted(inputs)[0]]
        elif kind == 1:
            inputs[f"n{i}"] = GaussianMixture(own.weights.copy(), own.means + rng.normal(
                0, 5, own.means.shape), own.covs.copy())
        else:
            inputs[f"n{i}"] = _mixture(rng, int(rng.integers(0, 5)), side=600.0)
    weights = {"": float(rng.uniform(0.1, 1))}
    weights.update({s: float(rng.choice([0.0, rng.uniform(0.05, 1)], p=[0.15, 0.85]))
                    for s in inputs})
    quarantined = {s for s in inputs if rng.random() < 0.2}
    steps = neighbour_statistics_steps(cfg, own, inputs, weights, quarantined)
    request = next(steps)
    while request[0] != "tests":
        request = steps.send(ALONE[request[0]](*request[1:]))
    return request[1:]


def test_neighbour_tests_together_are_each_ones_to_the_bit():
    """Every config the tests branch on, 0-8 neighbours, requests of several sizes and
    configs mixed in one call (grouped inside)."""
    rng = np.random.default_rng(11)
    seen = 0
    for _ in range(40):
        args = [_tests_request(TEST_CONFIGS[int(rng.integers(0, len(TEST_CONFIGS)))], rng)
                for _ in range(int(rng.integers(2, 30)))]
        for a, got in zip(args, TOGETHER["tests"](args), strict=True):
            want = ALONE["tests"](*a)
            assert got == want
            seen += sum(v > 0 for v in want)
    assert seen > 100


def test_own_tests_together_are_each_ones_and_the_old_scalar_tests():
    """The ``"own_tests"`` request (each input against own alone: the test-once guard and a
    late estimate's test) of several peers at once is each one's, and each value the old
    scalar :func:`divergence_test` with the guard's shape (``max(0, D_CS)`` of the centred
    overlaps) to the bit."""
    rng = np.random.default_rng(12)
    seen = 0
    for _ in range(40):
        args = []
        for _ in range(int(rng.integers(2, 20))):
            cfg, L, L0, mass, tm, _, _ = _tests_request(
                TEST_CONFIGS[int(rng.integers(0, len(TEST_CONFIGS)))], rng)
            args.append((cfg, L, L0, mass.tolist(), tm.tolist()))
        for (cfg, L, L0, mass, tm), got in zip(args, TOGETHER["own_tests"](args), strict=True):
            assert got == ALONE["own_tests"](cfg, L, L0, mass, tm)
            for j in range(1, len(mass)):
                shape = 0.0 if L0 is None else max(0.0, float(
                    cs_from_log_overlaps(L0[j, 0], L0[j, j], L0[0, 0])))
                assert got[j - 1] == trust_before.divergence_test(
                    cfg, L[j, j], L[j, 0], L[0, 0], mass[j], mass[0], tm[j], tm[0],
                    shape=shape)
                seen += got[j - 1] > 0
    assert seen > 100


def test_divergence_tests_are_the_old_scalar_tests_to_the_bit():
    """:func:`divergence_tests` elementwise, and :func:`divergence_test` on floats, are the old
    scalar test on every branch: empty
    sides, no overlap (``-inf``), empty mixtures (NaN), ``-0.0``, shapes, the unmatched and
    miss bounds, and masses whose ``** 2`` is not ``x * x`` to the bit."""
    rng = np.random.default_rng(13)
    pick = [0.0, -0.0, 1e-10, 0.3, 1.0, 2.5, -np.inf, np.inf, np.nan]
    n = 4000
    def draw(spread):
        v = rng.normal(0, spread, n)
        special = rng.random(n) < 0.15
        v[special] = rng.choice(pick, int(special.sum()))
        return v
    l_jj, l_jr, l_rr = draw(10), draw(10), draw(10)
    n_j, n_r = np.abs(draw(3)), np.abs(draw(3))
    n_j[: n // 4] = rng.uniform(0, 20, n // 4)  # x ** 2 != x * x for some of these
    t_j, t_r, u = np.abs(draw(2)), np.abs(draw(2)), np.abs(draw(2))
    shape = np.where(rng.random(n) < 0.5, 0.0, np.abs(draw(2)))
    for cfg in (TrustConfig(), TrustConfig(detection_probability=0.9)):
        for with_u in (False, True):
            got = divergence_tests(cfg, l_jj, l_jr, l_rr, n_j, n_r, t_j, t_r,
                                   u if with_u else None, shape)
            for i in range(n):
                want = trust_before.divergence_test(
                    cfg, l_jj[i], l_jr[i], l_rr[i], float(n_j[i]), float(n_r[i]),
                    float(t_j[i]), float(t_r[i]), float(u[i]) if with_u else None,
                    float(shape[i]))
                assert got[i] == want or (np.isnan(got[i]) and np.isnan(want)), (i, want)
                assert np.signbit(got[i]) == np.signbit(want)
                one = divergence_test(  # the same formula on floats (a peer alone)
                    cfg, l_jj[i], l_jr[i], l_rr[i], n_j[i], n_r[i], t_j[i], t_r[i],
                    u[i] if with_u else None, shape[i])
                assert one == want or (np.isnan(one) and np.isnan(want))
                assert np.signbit(one) == np.signbit(want)


NAMES = ("a", "b", "c", "d")


def _round(rng: np.random.Generator, own: GaussianMixture, liar: str, k: int,
           rnd: int) -> dict[str, GaussianMixture]:
    """One round's inputs: honest ones near own; the liar per ``liar`` (``empty``, moved
    ``200`` m, ``biased`` 30 m, ``random``); an honest neighbour sometimes losing a track."""
    out = {}
    for s in NAMES:
        means = own.means + rng.normal(0, 3, own.means.shape)
        mix = GaussianMixture(own.weights.copy(), means, own.covs.copy())
        if s == "a" and rng.random() < 0.15 and len(mix):
            mix = GaussianMixture(mix.weights[1:], mix.means[1:], mix.covs[1:])
        out[s] = mix
    m = out["c"]
    if liar == "empty" and k > 3:
        out["c"] = GaussianMixture.empty(4)
    elif liar == "moved" and k > 3:
        out["c"] = GaussianMixture(m.weights, m.means + 200.0, m.covs)
    elif liar == "biased":
        shift = np.zeros(4)
        shift[[0, 2]] = 30.0
        out["c"] = GaussianMixture(m.weights, m.means + shift, m.covs)
    elif liar == "random" and k > 5:
        out["c"] = _mixture(rng, int(rng.integers(0, 5)))
    if liar == "repeat" and k > 4 and rnd == 0:
        out["c"] = GaussianMixture(np.full(2, 0.9), np.zeros((2, 4)),
                                   np.broadcast_to(np.eye(4) * 30, (2, 4, 4)))
    return out


CONFIGS = [
    TrustConfig(detection_probability=0.9),
    TrustConfig(detection_probability=0.9, test_once=False),
    TrustConfig(detection_probability=0.95, repair=False, register=False),
    TrustConfig(),
    TrustConfig(detection_probability=0.9, location_only=True, renormalise=False),
]
LIARS = ("none", "empty", "moved", "biased", "random", "repeat")


@pytest.mark.parametrize("c", range(len(CONFIGS)))
def test_rounds_weighed_together_are_each_peers_own(c):
    """Six peers (one per kind of liar among its neighbours), 14 scans of 2 rounds, some
    round-0 inputs late (made a scan before): weights, records and the trust states of
    every peer the same, to the bit, as its own weigh's."""
    cfg = CONFIGS[c]
    rng = np.random.default_rng(40 + c)
    alone = [Trust(cfg, NAMES) for _ in LIARS]
    for t in alone:
        t.history = []  # every round's raw statistic (floats: compared to the bit)
    together = copy.deepcopy(alone)
    prev: list[dict] = [{} for _ in LIARS]
    changes = 0
    for k in range(1, 15):
        owns = [_mixture(rng, int(rng.integers(1, 5))) if k % 4 == 1 or k == 1 else None
                for _ in LIARS]
        for rnd in (0, 1):
            calls = []
            for p, liar in enumerate(LIARS):
                own = owns[p] if owns[p] is not None else _drift(alone[p].own_at, k, rng)
                owns[p] = own
                inputs = _round(rng, own, liar, k, rnd)
                late = None
                if rnd == 0 and prev[p] and rng.random() < 0.3:  # b's estimate a scan old
                    late = {"b": (k - 1, prev[p]["b"])}
                if rnd == 0:
                    prev[p] = inputs
                w = list(rng.uniform(0.1, 0.3, len(NAMES) + 1))
                calls.append((k, rnd, own, inputs, w, bool(p % 2), late))
            want = [t.weigh(*call) for t, call in zip(alone, calls, strict=True)]
            got = weigh_together([(t, *call) for t, call in zip(together, calls, strict=True)])
            assert got == want, (k, rnd)
            for a, b in zip(alone, together, strict=True):
                assert a.drain_records() == b.drain_records()
                assert a.fused_in.keys() == b.fused_in.keys()
                assert [a.n[s].last_statistic for s in NAMES] == [
                    b.n[s].last_statistic for s in NAMES]
    for a, b in zip(alone, together, strict=True):
        a.finish()
        b.finish()
        assert a.summary() == b.summary()
        assert a.history == b.history
        changes += len(a.summary()["changes"])
        for s in NAMES:
            ra, rb = a.n[s], b.n[s]
            assert (ra.score, ra.withheld, ra.last_offset_chi2) == (
                rb.score, rb.withheld, rb.last_offset_chi2)
            assert np.array_equal(ra.cusum, rb.cusum)
            assert (ra.registered is None) == (rb.registered is None)
            if ra.registered is not None:
                assert np.array_equal(ra.registered, rb.registered)
    assert changes > 0  # the liars were caught: the states moved


def test_a_late_estimates_test_goes_with_the_hosts_requests(monkeypatch):
    """A late estimate with new evidence (made at a scan not tested before) is tested against
    own of its scan through the batch's stacked overlaps, not alone, and its statistic is
    the divergence test of the two computed directly (log overlaps, masses)."""
    cfg = TrustConfig(detection_probability=0.9, location_only=True)
    rng = np.random.default_rng(5)
    trusts = [Trust(cfg, NAMES) for _ in range(3)]
    for t in trusts:
        t.history = []  # every round's raw statistic
    own1, own2 = _mixture(rng, 3), _mixture(rng, 3)
    late_b = GaussianMixture(own1.weights, own1.means + 40.0, own1.covs)
    for t in trusts:  # scan 1 without b: b is never tested at scan 1
        t.weigh(1, 0, own1, {s: own1 for s in NAMES if s != "b"}, [0.25] * 4)
    pairs: list[int] = []
    stacked = TOGETHER["overlaps"]

    def counted(args):
        pairs.extend(len(a[0]) == 2 for a in args)
        return stacked(args)

    monkeypatch.setitem(TOGETHER, "overlaps", counted)
    alone = copy.deepcopy(trusts[0])
    calls = [(t, 2, 0, own2, {s: own2 for s in NAMES} | {"b": late_b}, [0.2] * 5, False,
              {"b": (1, late_b)}) for t in trusts]
    got = weigh_together(calls)
    assert got == [alone.weigh(*calls[0][1:])] * 3
    assert sum(pairs) == 6  # each peer's late test: plain and centred overlaps, stacked
    L, L0 = log_overlaps([own1, late_b]), log_overlaps(centred([own1, late_b]))
    w = cfg.repeat_weight
    want = divergence_test(cfg, L[1, 1], L[1, 0], L[0, 0], late_b.mass, own1.mass,
                           target_mass(late_b, w), target_mass(own1, w),
                           shape=max(0.0, float(cs_from_log_overlaps(L0[1, 0], L0[1, 1],
                                                                     L0[0, 0]))))
    assert want > 0
    for t in trusts:
        assert t.n["b"].tested == 1
        assert [raw for k, s, raw, *_ in t.history if (k, s) == (2, "b")] == [want]


def _drift(own_at: dict, k: int, rng: np.random.Generator) -> GaussianMixture:
    """Own's density of the scan before, moved a little (the targets move)."""
    last = own_at[max(own_at)] if own_at else _mixture(rng, 3)
    return GaussianMixture(last.weights, last.means + rng.normal(0, 2, last.means.shape),
                           last.covs)


def test_a_generator_that_raises_has_its_exception_and_the_others_go_on():
    def good():
        L = yield ("overlaps", [GaussianMixture.empty(4)])
        return L.shape

    def bad():
        yield ("overlaps", [GaussianMixture.empty(4)])
        raise ValueError("broken")

    out = run_together([good(), bad(), good()])
    assert out[0] == out[2] == (1, 1)
    assert isinstance(out[1], ValueError)


@pytest.fixture(scope="module")
def twin_runs():
    """A twin of 8 GM-PHD peers with a shifted liar, its host testing each round on its own
    and together."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "twin.toml"
        path.write_text(scenario_text(8, 4, 12, rounds=2, speed=10.0))
        scn = load_scenario(str(path), overrides={"network.filter": "gmphd",
                                                   "fusion.trust": True,
                                                   "fusion.lie": "p02:shifted"})
        for together in (False, True):
            peers = {q: make_peer(scn, q, 0, network="twin") for q in scn.sensor_names}
            made: list[FusionBatch] = []

            def batch(together=together, made=made):
                made.append(FusionBatch(trust_together=together))
                return made[-1]

            res, summaries = run_with_batch(scn, peers, batch)
            out[together] = (res, summaries, made[0])
    return out


def test_a_twins_host_tests_together_with_the_same_results(twin_runs):
    (one, sum_one, _), (many, sum_many, batch) = twin_runs[False], twin_runs[True]
    assert batch.stacked > 0  # the rounds did go through the batch
    assert one.tracks.keys() == many.tracks.keys()
    for q in one.tracks:
        assert one.tracks[q].keys() == many.tracks[q].keys()
        for k in one.tracks[q]:
            assert np.array_equal(one.tracks[q][k], many.tracks[q][k])
    assert sum_one == sum_many
    assert any(v["changes"] for v in sum_many.values())  # the liar was noticed


def test_stacked_window_is_the_window_made_anew():
    """The arrays kept of the offset window, updated per push, equal the window's; a push
    they did not see (here: two in a row) makes them anew."""
    rng = np.random.default_rng(8)
    rec = NeighbourTrust()
    rebuilt = 0
    for k in range(40):
        B = rng.normal(0, 1, (2, 2))
        y = rng.normal(0, 3, 2)
        if k % 7 == 3:
            y[k % 2] = np.nan if k % 14 == 3 else -0.0  # kept as they are, sign too
        push_window(rec.offsets, (B @ B.T, y), 16)
        if k in (5, 20):
            push_window(rec.offsets, (np.eye(2), np.zeros(2)), 16)
        before = rec.stacked
        I, y = stacked_window(rec)
        rebuilt += before is not None and before[2] is not rec.offsets[1]
        assert np.array_equal(I, np.array([i for i, _ in rec.offsets]))
        want = np.array([v for _, v in rec.offsets])
        assert np.array_equal(y, want, equal_nan=True)
        assert np.array_equal(np.signbit(y), np.signbit(want))
        assert I.dtype == y.dtype == np.float64
    assert len(rec.offsets) == 16 and rebuilt == 2


def test_segment_sums_are_each_segments_sum_to_the_bit():
    """Every segment's sum at once (padded with -0.0) is ``X[segment].sum(axis=0)`` bit for
    bit, ``-0.0`` sums kept; the per-pair products summed so are the old per-segment
    ``einsum`` (what :func:`information_sums` replaced)."""
    rng = np.random.default_rng(11)
    for _ in range(300):
        counts = rng.integers(1, 40, int(rng.integers(1, 9))).tolist()
        X = rng.normal(0, 1, (sum(counts), 2, 2)) * 10.0 ** rng.uniform(-8, 4, (sum(counts), 1, 1))
        if rng.random() < 0.2:
            X[:, 0, 1] = -0.0  # diagonal covariances: an all -0.0 entry stays -0.0
        d = rng.normal(0, 50, (sum(counts), 2))
        got = segment_sums(X, counts)
        infos = information_sums(X @ X.transpose(0, 2, 1) + np.eye(2), d, counts)
        lo = 0
        for n, c in enumerate(counts):
            want = X[lo:lo + c].sum(axis=0)
            assert np.array_equal(got[n], want)
            assert np.array_equal(np.signbit(got[n]), np.signbit(want))
            S = np.linalg.inv(X[lo:lo + c] @ X[lo:lo + c].transpose(0, 2, 1) + np.eye(2))
            assert np.array_equal(infos[n][0], S.sum(axis=0))
            assert np.array_equal(infos[n][1], np.einsum("pij,pj->i", S, d[lo:lo + c]))
            lo += c
