"""Labelled GM-PHD (Panta, Clark & Vo 2009 tag propagation) and network-wide label matching
(tracking.labels): the labelled path changes no number of the filter, the tags follow targets,
merging keeps the heaviest member's tag (against a plain sweep), matching recovers permutations."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.messages import Tracks
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams, update
from sensornet.tracking.labels import (
    Confirmation,
    LabelledGMPHD,
    LabelledMixture,
    adopt_labels,
    extract_tracks,
    match_labels,
    new_labels,
    precedes,
    predict_labelled,
    reduce_labelled,
    split_duplicates,
    update_labelled,
)
from sensornet.tracking.metrics import ospa
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.reduction import Reducer

STARTS = np.array([[-600.0, 8, -600, 4], [600, -6, -500, 7], [0, 3, 700, -9]])
AREA = 4e6  # clutter uniform on [-1000, 1000]^2


def make_filter(lam, pd, reducer=None, extraction="cardinality", gate=None):
    means = STARTS.copy()
    means[:, [1, 3]] = 0.0
    birth = GaussianMixture(np.full(3, 0.03), means,
                            np.tile(np.diag([2500.0, 400, 2500, 400]), (3, 1, 1)))
    return GMPHDFilter(motion=ConstantVelocity(T=1.0, sigma_w=1.0),
                       sensors=[SensorParams(LinearPosition(sigma_r=10.0), pd, lam / AREA)],
                       birth=birth, survival_probability=0.99,
                       reducer=reducer or Reducer(1e-5, 4.0, 100), extraction=extraction,
                       gate=gate)


def simulate(seed, scans, lam, pd):
    """True states (3, 4) and the scan (targets detected with ``pd``, Poisson clutter) per k."""
    rng = np.random.default_rng(seed)
    motion, model = ConstantVelocity(T=1.0, sigma_w=1.0), LinearPosition(sigma_r=10.0)
    x, out = STARTS.copy(), []
    for k in range(scans):
        if k:
            x = motion.sample(x, rng)
        z = model.measure(x[rng.random(3) < pd], rng)
        c = rng.uniform(-1000, 1000, size=(rng.poisson(lam), 2))
        Z = np.concatenate((z, c))
        out.append((x.copy(), Z[rng.permutation(len(Z))]))
    return out


# -- the labelled path changes no number --------------------------------------------------------
@pytest.mark.parametrize("variant", ["plain", "weighted-gate-round", "refit", "capped"])
def test_labelled_filter_numbers_identical_to_unlabelled(variant):
    reducer, extraction, gate, scans = None, "cardinality", None, 40
    if variant == "weighted-gate-round":
        reducer, extraction, gate = Reducer(1e-5, 2.0, 100, "weighted"), "round", 16.0
    elif variant == "refit":
        reducer, scans = Reducer(1e-4, 4.0, 30, refit=True), 8
    elif variant == "capped":
        reducer = Reducer(1e-6, 4.0, 6)
    filt = make_filter(10, 0.95, reducer, extraction, gate)
    lf = LabelledGMPHD(filt, origin=3)
    mix, lm = filt.initial(), lf.initial()
    o_plain, o_lab = [], []
    for k, (x, Z) in enumerate(simulate(11, scans, 10, 0.95)):
        mix, lm = filt.step(mix, Z), lf.step(lm, k, Z)
        for a, b in ((mix.weights, lm.mixture.weights), (mix.means, lm.mixture.means),
                     (mix.covs, lm.mixture.covs)):
            assert np.array_equal(a, b)
        states, labels = lf.extract(lm)
        assert np.array_equal(states, filt.extract(mix))
        assert labels.shape == (len(states), 3) and labels.dtype == np.int64
        o_plain.append(ospa(filt.extract(mix), x))
        o_lab.append(ospa(states, x))
    assert f"{np.mean(o_plain):.6f}" == f"{np.mean(o_lab):.6f}"
    assert o_plain == o_lab


# -- tags follow targets ------------------------------------------------------------------------
def label_history(seed, lam, pd, split):
    filt = make_filter(lam, pd)
    lf = LabelledGMPHD(filt, origin=5, split_duplicates=split)
    conf = Confirmation(scans=3, threshold=filt.extraction_threshold)
    lm, out = lf.initial(), []
    for k, (x, Z) in enumerate(simulate(seed, 50, lam, pd)):
        lm = lf.step(lm, k, Z)
        conf.observe(lm)
        states, labels = lf.extract(lm)
        out.append((x, states, labels, conf.status(labels)))
    return out


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("split,lam,pd", [(True, 2, 0.98), (False, 10, 0.95)])
def test_labels_follow_three_separated_targets_for_50_scans(seed, split, lam, pd):
    per_target: dict[int, set] = {0: set(), 1: set(), 2: set()}
    matched = 0
    for k, (x, states, labels, status) in enumerate(label_history(seed, lam, pd, split)):
        if k < 5 or len(states) == 0:
            continue
        d = np.linalg.norm(x[:, None, [0, 2]] - states[None, :, [0, 2]], axis=2)
        for t, j in zip(*linear_sum_assignment(d), strict=True):
            if d[t, j] < 50.0:
                per_target[t].add(tuple(labels[j]))
                assert status[j] == 1, f"scan {k}: a target's track is not confirmed"
                matched += 1
    assert matched >= 0.9 * 45 * 3
    assert all(len(s) == 1 for s in per_target.values()), per_target  # no switch
    ids = [next(iter(s)) for s in per_target.values()]
    assert len(set(ids)) == 3 and all(i[0] == 5 for i in ids)  # distinct, born here


# -- the single rules ---------------------------------------------------------------------------
def random_mixture(rng, n, d=4, spread=60.0):
    w = rng.uniform(0.01, 1.0, n)
    m = rng.normal(0.0, spread, (n, d))
    A = rng.normal(size=(n, d, d))
    P = A @ A.swapaxes(1, 2) * 20.0 + np.eye(d) * 30.0
    return GaussianMixture(w, m, P)


def test_predict_keeps_labels_and_labels_births():
    rng = np.random.default_rng(1)
    lm = LabelledMixture(random_mixture(rng, 4), new_labels(2, 7, 4))
    birth = random_mixture(rng, 3)
    out = predict_labelled(lm, ConstantVelocity(), 0.9, birth, k=9, origin=4)
    assert np.array_equal(out.labels[:4], lm.labels)
    assert out.labels[4:].tolist() == [[4, 9, 0], [4, 9, 1], [4, 9, 2]]


def test_update_terms_inherit_their_predicted_components_label():
    rng = np.random.default_rng(2)
    mix = random_mixture(rng, 5, spread=300.0)
    lm = LabelledMixture(mix, rng.integers(0, 50, (5, 3)))
    sensor = SensorParams(LinearPosition(sigma_r=5.0), 0.9, 1e-6)
    Z = mix.means[[1, 3]][:, [0, 2]] + rng.normal(0, 5, (2, 2))
    out = update_labelled(lm, Z, sensor)
    assert np.array_equal(out.mixture.weights, update(mix, Z, sensor).weights)
    assert np.array_equal(out.labels[:5], lm.labels)  # missed-detection terms
    # every detection term is the Kalman update of the component whose label it carries
    H = LinearPosition.H_MATRIX
    R = 25.0 * np.eye(2)
    for i in range(5, len(out)):
        z = Z[(i - 5) // 5]
        j = (i - 5) % 5  # update's order: for z, for j
        assert np.array_equal(out.labels[i], lm.labels[j])
        P = mix.covs[j]
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        np.testing.assert_allclose(out.mixture.means[i], mix.means[j] + K @ (z - H @ mix.means[j]),
                                   rtol=1e-9, atol=1e-9)


def plain_sweep(w, m, P, U, rule):
    """Vo & Ma 2006 Table II as a loop: take the heaviest remaining, absorb its neighbours.
    Returns (total weight, index of the heaviest member) per group."""
    left, out = list(range(len(w))), []
    while left:
        j = max(left, key=lambda i: (w[i], -i))
        group = []
        for i in left:
            x = m[i] - m[j]
            if rule == "vo-ma":
                close = x @ np.linalg.inv(P[i]) @ x <= U
            else:
                close = (i == j) or (w[i] * w[j] / (w[i] + w[j])) * (
                    x @ np.linalg.inv(P[j]) @ x) < U
            if close:
                group.append(i)
        out.append((sum(w[i] for i in group), j))
        left = [i for i in left if i not in group]
    return out


@pytest.mark.parametrize("rule", ["vo-ma", "weighted"])
@pytest.mark.parametrize("n", [2, 7, 30, 80])
def test_merge_keeps_the_heaviest_members_label_against_a_plain_sweep(rule, n):
    rng = np.random.default_rng(n)
    for trial in range(6):
        mix = random_mixture(rng, n, spread=25.0 + 10 * trial)
        labels = rng.permutation(n * 3).reshape(n, 3)  # every label distinct
        U = 4.0 if rule == "vo-ma" else 1.0
        out = reduce_labelled(Reducer(0.0, U, 10 * n, rule), LabelledMixture(mix, labels))
        ref = plain_sweep(mix.weights, mix.means, mix.covs, U, rule)
        got = sorted((lab.tolist(), round(float(w), 9))
                     for lab, w in zip(out.labels, out.mixture.weights, strict=True))
        want = sorted((labels[j].tolist(), round(float(w), 9)) for w, j in ref)
        assert got == want


def test_prune_and_cap_drop_labels_with_their_components():
    rng = np.random.default_rng(5)
    mix = random_mixture(rng, 12, spread=5000.0)  # nothing merges
    labels = new_labels(1, 0, 12)
    out = reduce_labelled(Reducer(0.3, 4.0, 4), LabelledMixture(mix, labels))
    keep = np.sort(np.argsort(-mix.weights)[:4])
    assert (mix.weights[keep] >= 0.3).all()
    assert sorted(out.labels.tolist()) == sorted(labels[keep].tolist())
    for lab, w in zip(out.labels, out.mixture.weights, strict=True):
        assert w == mix.weights[lab[2]]


def test_split_duplicates_heaviest_keeps_the_label_others_get_new_ones():
    w = np.array([0.9, 1.2, 0.3, 0.7, 0.8])
    mix = GaussianMixture(w, np.zeros((5, 4)), np.tile(np.eye(4), (5, 1, 1)))
    labels = np.array([[1, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0], [2, 3, 1]])
    out = split_duplicates(LabelledMixture(mix, labels), 0.5, origin=9, k=12, start=3)
    assert out.labels.tolist() == [[9, 12, 3], [1, 0, 0], [1, 0, 0], [9, 12, 4], [2, 3, 1]]
    assert out.mixture is mix


def test_confirmation_counts_scans_above_the_threshold_until_the_label_is_gone():
    conf = Confirmation(scans=3, threshold=0.5)
    eye = np.tile(np.eye(4), (2, 1, 1))
    a, b = [1, 0, 0], [1, 0, 1]
    seen = []
    # a: above, above, below (a miss), above -> confirmed at its third scan above; then gone
    for wa, present in ((0.9, True), (0.8, True), (0.05, True), (0.7, True), (0.9, True),
                        (None, False), (0.9, True)):
        if present:
            lm = LabelledMixture(GaussianMixture(np.array([wa, 0.2]), np.zeros((2, 4)), eye),
                                 np.array([a, b]))
        else:
            lm = LabelledMixture(GaussianMixture(np.array([0.2]), np.zeros((1, 4)), eye[:1]),
                                 np.array([b]))
        conf.observe(lm)
        seen.append(conf.status(np.array([a, b, [7, 7, 7]])).tolist())
    assert [s[0] for s in seen] == [0, 0, 0, 1, 1, 0, 0]
    assert all(s[1] == 0 and s[2] == 0 for s in seen)
    assert conf.count(np.array([a, b])).tolist() == [1, 0]


def test_bad_labels_are_one_line_errors():
    mix = GaussianMixture(np.ones(2), np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1)))
    with pytest.raises(ValueError, match=r"labels has shape \(2, 2\), expected \(2, 3\)"):
        LabelledMixture(mix, np.zeros((2, 2), dtype=int))
    with pytest.raises(ValueError, match="labels has dtype float64"):
        LabelledMixture(mix, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="nbr_labels repeats a label"):
        match_labels(np.array([[0, 0, 0]]), np.zeros((1, 4)), np.eye(4)[None],
                     np.zeros((2, 3), dtype=int), np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1)),
                     9.0)


# -- labels across peers ------------------------------------------------------------------------
def tracks(rng, n, spread=2000.0):
    m = rng.uniform(-spread, spread, (n, 4))
    A = rng.normal(size=(n, 4, 4))
    return m, A @ A.swapaxes(1, 2) * 10.0 + np.eye(4) * 50.0


@pytest.mark.parametrize("seed", range(5))
def test_match_recovers_a_random_permutation_of_labels(seed):
    rng = np.random.default_rng(seed)
    n = 8
    m, P = tracks(rng, n)
    own = new_labels(1, 4, n)
    perm = rng.permutation(n)
    nbr_labels = new_labels(2, 6, n)[perm]
    nbr_m = m[perm] + rng.normal(0, 3.0, (n, 4))
    match = match_labels(own, m, P, nbr_labels, nbr_m, P[perm], gate=30.0)
    assert len(match) == n
    mapping = match.as_dict()
    for i in range(n):  # neighbour row i is our target perm[i]
        assert mapping[tuple(nbr_labels[i].tolist())] == tuple(own[perm[i]].tolist())


def test_match_is_the_optimal_gated_assignment_by_brute_force():
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, b = (int(v) for v in rng.integers(1, 5, size=2))
        m1, P1 = tracks(rng, a, 40.0)
        m2, P2 = tracks(rng, b, 40.0)
        gate = 6.0
        match = match_labels(new_labels(0, 0, a), m1, P1, new_labels(1, 0, b), m2, P2, gate)
        C = np.array([[(m1[i] - m2[j]) @ np.linalg.solve(P1[i] + P2[j], m1[i] - m2[j])
                       for j in range(b)] for i in range(a)])
        Cg = np.minimum(C, gate)  # an out-of-gate pair costs what leaving both unmatched does
        if a <= b:
            best = min(sum(Cg[i, c[i]] for i in range(a))
                       for c in itertools.permutations(range(b), a))
        else:
            best = min(sum(Cg[r[j], j] for j in range(b))
                       for r in itertools.permutations(range(a), b))
        got = match.cost.sum() + gate * (min(a, b) - len(match))
        assert got == pytest.approx(best, rel=1e-9, abs=1e-9)
        assert (match.cost <= gate).all()


def test_far_tracks_stay_unmatched():
    rng = np.random.default_rng(4)
    m, P = tracks(rng, 3)
    far = m + 500.0
    match = match_labels(new_labels(0, 0, 3), m, P, new_labels(1, 0, 3), far, P, gate=20.0)
    assert len(match) == 0


def test_the_network_rule_picks_the_earliest_birth_then_lowest_origin():
    own = np.array([[3, 5, 0], [3, 2, 1], [1, 9, 0]])
    nbr = np.array([[2, 5, 7], [0, 4, 0], [4, 9, 0]])
    m = np.array([[0.0, 0, 0, 0], [1000, 0, 0, 0], [0, 0, 1000, 0]])
    P = np.tile(np.eye(4) * 10.0, (3, 1, 1))
    match = match_labels(own, m, P, nbr, m, P, gate=9.0)
    # same birth scan 5: origin 2 < 3; birth 2 < 4: ours; same birth 9: origin 1 < 4: ours
    assert adopt_labels(own, match).tolist() == [[2, 5, 7], [3, 2, 1], [1, 9, 0]]
    assert precedes(np.array([[9, 1, 0], [1, 1, 0], [1, 1, 3], [0, 1, 2]]),
                    np.array([[0, 2, 0], [2, 1, 0], [1, 1, 3], [0, 1, 3]])).tolist() == [
        True, True, False, True]


@pytest.mark.parametrize("seed", range(6))
def test_the_rule_is_symmetric_whichever_peer_fuses_first(seed):
    rng = np.random.default_rng(seed)
    n = 6
    m, P = tracks(rng, n)
    la = np.stack([np.full(n, 1), rng.integers(0, 4, n), np.arange(n)], axis=1)
    perm = rng.permutation(n)
    lb = np.stack([np.full(n, 2), rng.integers(0, 4, n), np.arange(n)], axis=1)
    mb, Pb = m[perm] + rng.normal(0, 2.0, (n, 4)), P[perm]

    def fuse(own_l, own_m, own_P, nbr_l, nbr_m, nbr_P):
        return adopt_labels(own_l, match_labels(own_l, own_m, own_P, nbr_l, nbr_m, nbr_P, 30.0))

    # A fuses B's tracks first, then B fuses A's (already adopted) ones; and the other order
    a1 = fuse(la, m, P, lb, mb, Pb)
    b1 = fuse(lb, mb, Pb, a1, m, P)
    b2 = fuse(lb, mb, Pb, la, m, P)
    a2 = fuse(la, m, P, b2, mb, Pb)
    assert np.array_equal(a1, a2) and np.array_equal(b1, b2)
    assert np.array_equal(a1, b1[np.argsort(perm)])  # one id per target on both peers
    lb_ours = lb[np.argsort(perm)]  # B's label of our target i
    want = np.where(precedes(lb_ours, la)[:, None], lb_ours, la)
    assert np.array_equal(a1, want)


def test_adoption_renames_every_component_of_a_label():
    own_tracks = np.array([[1, 3, 0], [1, 3, 1]])
    m = np.array([[0.0, 0, 0, 0], [1000, 0, 0, 0]])
    P = np.tile(np.eye(4) * 10.0, (2, 1, 1))
    match = match_labels(own_tracks, m, P, np.array([[0, 1, 0], [1, 3, 0]]), m, P, 9.0)
    # (1,3,0) -> (0,1,0); (1,3,1) -> (1,3,0), free once our first target leaves it
    components = np.array([[1, 3, 0], [1, 3, 1], [1, 3, 0], [5, 5, 5]])
    assert adopt_labels(components, match).tolist() == [[0, 1, 0], [1, 3, 0], [0, 1, 0],
                                                        [5, 5, 5]]


def test_adoption_skips_a_label_another_of_our_targets_holds():
    own_tracks = np.array([[1, 3, 0], [1, 3, 1]])
    m = np.array([[0.0, 0, 0, 0], [1000, 0, 0, 0]])
    P = np.tile(np.eye(4) * 10.0, (2, 1, 1))
    match = match_labels(own_tracks, m, P, np.array([[1, 3, 0]]), m[1:], P[1:], 9.0)
    assert match.as_dict() == {(1, 3, 0): (1, 3, 1)}
    # (1,3,1) -> (1,3,0) would give our two targets one label: left as it is
    assert np.array_equal(adopt_labels(own_tracks, match), own_tracks)


def test_extracted_tracks_travel_in_a_tracks_message():
    filt = make_filter(2, 0.98)
    lf = LabelledGMPHD(filt, origin=4)
    conf = Confirmation(scans=3)
    lm = lf.initial()
    for k, (_, Z) in enumerate(simulate(1, 12, 2, 0.98)):
        lm = lf.step(lm, k, Z)
        conf.observe(lm)
    ex = extract_tracks(lm, filt.extraction_threshold, filt.extraction, conf)
    states, labels = lf.extract(lm)
    assert np.array_equal(ex.states, states) and np.array_equal(ex.ids, labels)
    assert ex.status.tolist() == [1, 1, 1] and ((ex.existence > 0.5) & (ex.existence <= 1)).all()
    out = decode(encode(Tracks("s4", 11, ex.states, ids=ex.ids, covs=ex.covs,
                               existence=ex.existence, status=ex.status)))
    assert np.array_equal(out.ids, ex.ids) and np.array_equal(out.status, ex.status)
    np.testing.assert_allclose(out.covs, ex.covs, rtol=0, atol=1e-9)
