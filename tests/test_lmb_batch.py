"""Stacked LMB local steps (tracking.lmb_batch) against each filter's own step: the same
states to the bit, the same Gibbs stream, on random filters, priors and scans; and a peer's
estimator using a prepared step only when it is the step it makes."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.tracking.gaussian import inv_det_spd
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import SHARED_ORIGIN
from sensornet.tracking.lmb import EDGE_FLAG, LmbFilter, LmbState
from sensornet.tracking.lmb_batch import (
    _own_quad,
    _quad,
    _quad_in_order,
    _reduce,
    batch_key,
    step_many,
)
from sensornet.tracking.lmb_sets import LabelledBernoulliSet, reduce_components
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition, RangeBearing

MOTION = ConstantVelocity(1.0, 2.0)
CENTRES = np.array([[0.0, 3.0, 0.0, 1.0], [150.0, -2.0, 80.0, 0.0], [-90.0, 0.0, 40.0, -3.0],
                    [60.0, 1.0, -120.0, 2.0], [5.0, 0.0, 15.0, 0.0]])


def _filter(rng, p: int, radar: bool = False) -> LmbFilter:
    model = (RangeBearing(position=(0.0, 0.0)) if radar
             else LinearPosition(float(rng.uniform(5, 30)), (float(rng.uniform(0, 9)), 0.0)))
    sensor = SensorParams(model, float(rng.uniform(0.7, 0.99)), float(rng.uniform(1e-7, 1e-5)))
    birth = None
    if p % 3 == 0:
        birth = GaussianMixture(np.full(2, 0.05), CENTRES[:2],
                                np.tile(np.diag([400.0, 25, 400, 25]), (2, 1, 1)))
    method = ("gibbs", "lbp", "auto", "auto", "auto")[p % 5]
    return LmbFilter(MOTION, sensor, birth=birth, adaptive_birth=not radar, method=method,
                     seed=p, origin=p + 1, shared_origin=SHARED_ORIGIN if p % 2 else None,
                     birth_edge=20.0 if p % 4 == 1 else 0.0, gibbs_samples=300,
                     gate=25.0 if p % 6 == 5 else None)


def _scan(rng, k: int, m_max: int = 9) -> np.ndarray:
    targets = CENTRES[:, [0, 2]] + k * CENTRES[:, [1, 3]]
    seen = targets[rng.random(len(targets)) < 0.8] + rng.normal(0, 8, (1, 2))
    clutter = rng.uniform(-300, 300, (int(rng.integers(0, m_max)), 2))
    return np.concatenate((seen, clutter))[rng.permutation(len(seen) + len(clutter))]


def _same(a: LmbState, b: LmbState) -> None:
    assert a.k == b.k
    for f in ("labels", "existence", "weights", "means", "covs", "owner"):
        np.testing.assert_array_equal(getattr(a.tracks, f), getattr(b.tracks, f), err_msg=f)
    for f in ("weights", "means", "covs"):
        np.testing.assert_array_equal(getattr(a.pending, f), getattr(b.pending, f), err_msg=f)
    np.testing.assert_array_equal(a.hits, b.hits)


def test_step_many_equals_each_filter_step_to_the_bit():
    rng = np.random.default_rng(33)
    stacked = checked = 0
    for trial in range(8):
        n = int(rng.integers(2, 9))
        filters = [_filter(rng, p, radar=(trial % 4 == 3 and p == 0)) for p in range(n)]
        states = [f.initial() for f in filters]
        for k in range(6):
            ks = [s.k + (2 if (trial + p + k) % 7 == 0 else 1) if k else 0
                  for p, s in enumerate(states)]
            scans = [_scan(rng, kk, 1 if p == 1 else 9) for p, kk in enumerate(ks)]
            if k == 3:
                scans[0] = scans[0][:0]  # no plots
            keys = [batch_key(f, kk - s.k if s.k >= 0 else 1)
                    for f, s, kk in zip(filters, states, ks, strict=True)]
            stacked += sum(1 for key in keys if key is not None and keys.count(key) > 1)
            twins = [copy.deepcopy(f) for f in filters]
            got = step_many(filters, states, scans, ks)
            for f, t, s, z, kk, g in zip(filters, twins, states, scans, ks, got, strict=True):
                assert f._rng.bit_generator.state == t._rng.bit_generator.state  # untouched
                want = t.step(s, z, kk)
                _same(g[0], want)
                assert g[1] == t._rng.bit_generator.state  # the draws its own step made
                checked += 1
            states = [g[0] for g in got]
            for f, g in zip(filters, got, strict=True):  # on, as if the steps were taken
                f._rng.bit_generator.state = g[1]
    assert stacked > 150 and checked > 200  # most problems went through the stack
    assert sum(len(s.tracks) for s in states) > 20  # tracks to associate, not empty sets


@pytest.mark.parametrize("layout", ["C", "F"])
def test_the_written_out_quadratic_form_sums_as_the_updates_einsum(layout):
    """The rule of :func:`_quad_in_order` against NumPy: on every shape it calls in order,
    :func:`_quad` is the update's ``einsum`` to the bit (the others are recomputed as the
    update computes them; one of them needs it on either layout)."""
    model, rng = LinearPosition(20.0), np.random.default_rng(3)
    cols = list(model.selected)
    for c in (*range(1, 9), 33, 64, 65, 107, 201):
        for m in (*range(1, 9), 15, 44):
            same = True
            for _ in range(8):
                mean = rng.normal(0.0, 100.0, (c, 4))
                A = rng.normal(0.0, 3.0, (c, 4, 4))
                P = A @ A.swapaxes(1, 2) + np.eye(4)
                scan = np.array(rng.normal(0.0, 100.0, (m, 2)), order=layout)
                S_inv = inv_det_spd(P[:, :, cols][:, cols, :] + model.R)[0]
                nu = model.residual(scan[None, :, :], mean[:, cols][:, None, :])
                same &= np.array_equal(_quad(nu, S_inv), _own_quad(model, mean, P, model.R,
                                                                   scan))
            assert same or not _quad_in_order(c, m, layout), (c, m)
            if (c, m) == (1, 1):
                assert not same


def test_the_stacked_reduction_is_each_problems_own():
    """Tracks of many components, some close (merged), problems above and below the 200
    pairs where the merge's inverses change method, one whose pairs are all far apart."""
    rng = np.random.default_rng(11)
    sets = []
    for p in range(7):
        n = (1, 3, 30, 6, 2, 25, 4)[p]
        sizes = rng.integers(1, 13, n)
        c = int(sizes.sum())
        spread = 1e4 if p == 6 else 3.0
        centre = np.repeat(rng.normal(0, 500, (n, 4)), sizes, axis=0)
        A = rng.normal(0, 2, (c, 4, 4))
        w = rng.uniform(0, 1, c) * np.where(rng.random(c) > 0.1, 1.0, 1e-6)  # some pruned
        sets.append(LabelledBernoulliSet.trusted(
            np.zeros((n, 3), np.int64), rng.uniform(0, 1, n), w,
            centre + rng.normal(0, spread, (c, 4)), A @ A.swapaxes(1, 2) + 4 * np.eye(4),
            np.repeat(np.arange(n), sizes)))
    n_lens = np.array([len(t) for t in sets])
    owner = np.concatenate([t.owner + o for t, o in zip(sets, np.cumsum(n_lens) - n_lens,
                                                       strict=True)])
    prob_t = np.repeat(np.arange(len(sets)), n_lens)
    w, m, P, own = _reduce(np.concatenate([t.weights for t in sets]),
                           np.concatenate([t.means for t in sets]),
                           np.concatenate([t.covs for t in sets]), owner, prob_t, len(sets),
                           1e-4, 4.0, 5)
    rows = np.bincount(prob_t[own], minlength=len(sets))
    at, t0 = 0, 0
    for t, r, n in zip(sets, rows, n_lens, strict=True):
        want = reduce_components(t, 1e-4, 4.0, 5)
        np.testing.assert_array_equal(w[at:at + r], want.weights)
        np.testing.assert_array_equal(m[at:at + r], want.means)
        np.testing.assert_array_equal(P[at:at + r], want.covs)
        np.testing.assert_array_equal(own[at:at + r] - t0, want.owner)
        at, t0 = at + r, t0 + n
    assert len(w) < len(owner)  # something pruned or merged


def test_birth_labels_alike_in_cells_near_edges_and_two_in_a_cell():
    """Pending births placed by hand: two plots in one 200 m cell (the likelier keeps the
    cell's label), plots within the edge band, cells of two widths, shared and own origins
    side by side: the stacked labels are each filter's own."""
    rng = np.random.default_rng(12)
    plots = np.array([[10.0, 10.0], [150.0, 30.0], [199.0, 50.0], [401.0, -3.0],
                      [-250.0, 90.0], [-260.0, 95.0]])
    filters, states = [], []
    for p in range(6):
        f = _filter(rng, p)
        f.shared_origin = SHARED_ORIGIN if p != 2 else None
        f.birth_edge, f.birth_cell = (15.0, 200.0) if p % 2 else (0.0, 100.0 if p == 4 else 200.0)
        means = np.zeros((len(plots), 4))
        means[:, [0, 2]] = plots + rng.normal(0, 0.5, plots.shape)
        pend = GaussianMixture(rng.uniform(0.01, 0.1, len(plots)), means,
                               np.tile(np.eye(4) * 100.0, (len(plots), 1, 1)))
        filters.append(f)
        states.append(LmbState(f.initial().tracks, np.zeros(0, np.int64), 4, pend))
    scans = [_scan(rng, 5) for _ in filters]
    twins = [copy.deepcopy(f) for f in filters]
    got = step_many(filters, states, scans, [5] * len(filters))
    labels = []
    for t, s, z, g in zip(twins, states, scans, got, strict=True):
        want = t.predict(s, 5).tracks.labels
        _same(g[0], t.step(s, z, 5))
        labels.append(want)
    edge = np.concatenate(labels)[:, 2] >= EDGE_FLAG
    assert edge.any() and not edge.all()  # some flagged
    assert any((lab[:, 0] != SHARED_ORIGIN).any() and (lab[:, 0] == SHARED_ORIGIN).any()
               for lab in labels)  # a cell's second plot took an own label


def test_bad_problems_are_left_to_their_own_step():
    rng = np.random.default_rng(4)
    filters = [_filter(rng, p) for p in range(3)]
    states = [f.initial() for f in filters]
    scans = [_scan(rng, 0), np.array([[np.nan, 1.0]]), _scan(rng, 0)]
    got = step_many(filters, states, scans, [0, 0, -1])
    assert got[1] is None and got[2] is None  # a bad plot; a scan not after the state's
    _same(got[0][0], copy.deepcopy(filters[0]).step(states[0], scans[0], 0))


def test_a_problem_whose_association_raises_is_not_prepared_the_others_are(monkeypatch):
    import sensornet.tracking.lmb as lmb
    import sensornet.tracking.lmb_batch as lmb_batch

    rng = np.random.default_rng(8)
    filters = [_filter(rng, p) for p in range(3)]
    states = [f.initial() for f in filters]
    for k in range(3):
        got = step_many(filters, states, [_scan(rng, k) for _ in filters], [k] * 3)
        states = [g[0] for g in got]
    real = lmb_batch.marginals

    def refuse(miss, detect, *args, rng=None, **kw):
        if rng is filters[1]._rng:
            raise ValueError("too many hypotheses")
        return real(miss, detect, *args, rng=rng, **kw)

    monkeypatch.setattr(lmb_batch, "marginals", refuse)
    scans = [_scan(rng, 3) for _ in filters]
    twins = [copy.deepcopy(f) for f in filters]
    got = step_many(filters, states, scans, [3] * 3)
    assert got[1] is None
    for p in (0, 2):
        _same(got[p][0], twins[p].step(states[p], scans[p], 3))
    # alone (not stacked: a group of one) it is not prepared either, and nothing raises
    monkeypatch.setattr(lmb, "marginals", refuse)
    assert step_many(filters[1:2], states[1:2], scans[1:2], [3]) == [None]


def _estimators(rng, n: int) -> list[LmbEstimator]:
    return [LmbEstimator(_filter(rng, p), origin=p + 1) for p in range(n)]


def test_the_estimator_uses_a_prepared_step_only_when_it_matches():
    ests = _estimators(np.random.default_rng(5), 4)
    plain = [LmbEstimator(copy.deepcopy(e.filter), origin=e.origin) for e in ests]
    rng = np.random.default_rng(6)
    for k in range(1, 9):
        scans = [_scan(rng, k) for _ in ests]
        LmbEstimator.prepare_many(ests, [1, 1, 1, 1], scans)
        # estimator 1 steps 2 scans ahead, estimator 2 sees another scan: both not prepared
        steps = [1, 2, 1, 1]
        seen = [scans[0], scans[1], scans[2][:1], scans[3]]
        for e, q, s, z in zip(ests, plain, steps, seen, strict=True):
            kk = e.k + s
            e.begin_scan(kk)
            q.begin_scan(kk)
            a, b = e.step(s, z), q.step(s, z)
            _same(e.state, q.state)
            np.testing.assert_array_equal(a.published["posterior"].means,
                                          b.published["posterior"].means)
            np.testing.assert_array_equal(a.labels["posterior"], b.labels["posterior"])
            assert e.filter._rng.bit_generator.state == q.filter._rng.bit_generator.state
        assert ests[0].prepared_hits == k and ests[3].prepared_hits == k
        assert ests[1].prepared_hits == 0 and ests[2].prepared_hits == 0


def test_a_failing_stack_prepares_nothing(monkeypatch):
    """A stacked step that raises prepares nothing and leaves every Generator where it was:
    each peer's own step runs as if nothing had been tried."""
    import sensornet.tracking.lmb_batch as lmb_batch

    rng = np.random.default_rng(7)
    ests = _estimators(rng, 3)
    plain = [LmbEstimator(copy.deepcopy(e.filter), origin=e.origin) for e in ests]
    scans = [_scan(rng, 1) for _ in ests]

    def broken(*args):
        raise FloatingPointError("stack")

    monkeypatch.setattr(lmb_batch, "_update", broken)
    with pytest.raises(FloatingPointError):
        LmbEstimator.prepare_many(ests, [1, 1, 1], scans)
    for e, q, z in zip(ests, plain, scans, strict=True):
        e.step(1, z)
        q.step(1, z)
        _same(e.state, q.state)
        assert e.prepared_hits == 0


@pytest.mark.network
def test_two_hosts_of_three_lmb_peers_prepare_their_steps_and_equal_the_twin(tmp_path):
    """Real processes: six LMB peers in two hosts stack their local steps (the summaries count
    the prepared steps taken) and every scan's tracks are the twin's, where each steps alone."""
    from sensornet.sim.run.twin import run_twin
    from sensornet.sim.world.graphs import network_scenario

    from tests.test_network_faults import _assert_tracks_equal_the_twin, _run

    names = [f"p{i:02d}" for i in range(6)]
    source = tmp_path / "six.toml"
    source.write_text(network_scenario(6, 2, scans=30, rounds=1, speed=5.0, deadline=1.0))
    sets = ["network.filter=lmb"]
    scn, codes, summaries = _run(str(source), tmp_path / "run", sets, rerun=False,
                                 per_process=3, peer_args={n: ["--save-tracks"] for n in names})
    assert all(c == 0 for c in codes.values()), codes
    assert set(summaries) == set(names)
    assert all(s["internal_errors"] == {} for s in summaries.values())
    assert sum(s["prepared_steps"] for s in summaries.values()) > 0
    _assert_tracks_equal_the_twin(tmp_path / "run", scn, summaries, run_twin(scn, 0))
