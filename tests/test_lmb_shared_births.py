"""LMB ids made alike at birth (issue 33): an adaptive birth is labelled ``(SHARED_ORIGIN, k,
CELL_BASE + cell)`` by the grid cell of its plot at every peer (two in one cell at one peer: the
likelier keeps it, the other an own label), and stamped ``(SHARED_ORIGIN, k', PUBLISHED_BASE +
index)`` at first publication as GM-PHD shared births are. Checked against brute-force loops
over cells and labels, and on estimators that see one target with their own noise."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.sim.kinds import kind
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import (
    CELL_BASE,
    PUBLISHED_BASE,
    SHARED_ORIGIN,
    cell_index,
    shared_births,
)
from sensornet.tracking.lmb import LmbFilter, LmbState
from sensornet.tracking.lmb_sets import LabelledBernoulliSet
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.track_metrics import label_agreement

from tests.labelled_tables import twin_tables

S, PB = SHARED_ORIGIN, PUBLISHED_BASE


def test_cell_index_is_one_index_per_cell_in_a_fixed_order():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1000, 1000, (400, 2))
    pts[:50] = np.round(pts[:50] / 200.0) * 200.0  # points on cell edges too
    got = cell_index(pts, 200.0)
    cells = [(int(np.floor(x / 200.0)), int(np.floor(y / 200.0))) for x, y in pts]
    for i in range(len(pts)):  # brute force: same index exactly when same cell
        same = np.array([c == cells[i] for c in cells])
        np.testing.assert_array_equal(got == got[i], same)
    by_cell = sorted(range(len(pts)), key=lambda i: cells[i])  # (x cell, y cell) order
    assert np.all(np.diff(got[by_cell]) >= 0) and got.min() >= CELL_BASE
    assert got.max() < PB
    far = cell_index(np.array([[1e12, -1e12], [2e12, -3e12]]), 200.0)
    assert far[0] == far[1] < PB  # beyond the packed range: the edge cell
    with pytest.raises(ValueError, match="cell size"):
        cell_index(pts, 0.0)
    with pytest.raises(ValueError, match="points has shape"):
        cell_index(np.zeros((3, 5)), 200.0)


def test_shared_births_one_label_per_cell_the_likelier_keeps_it():
    rng = np.random.default_rng(1)
    for _ in range(200):
        n = int(rng.integers(1, 8))
        index = CELL_BASE + rng.integers(0, 3, n)
        prio = rng.choice([0.05, 0.1], n)
        got = shared_births(index, prio, S, 4, 7, 2)
        assert len({tuple(r) for r in got.tolist()}) == n  # one label per birth
        for i in range(n):  # brute force: the first of the highest priority in its cell
            rivals = [j for j in range(n) if index[j] == index[i]]
            best = max(rivals, key=lambda j: (prio[j], -j))
            want = [S, 7, index[i]] if i == best else [4, 7, 2 + i]
            assert got[i].tolist() == want


def _filter(origin: int, shared: int | None = S) -> LmbFilter:
    return LmbFilter(ConstantVelocity(1.0, 2.0),
                     SensorParams(LinearPosition(5.0), 0.99, 2.5e-7), birth_rate=1.0,
                     birth_max_existence=0.5, origin=origin, shared_origin=shared)


def test_a_plot_in_one_cell_is_one_birth_label_at_every_peer():
    z1 = np.array([[330.0, 410.0], [370.0, 450.0], [1000.0, -20.0]])  # two in one cell
    z2 = np.array([[335.0, 405.0]])
    labs = []
    for origin, z in ((1, z1), (2, z2)):
        f = _filter(origin)
        st = f.predict(f.correct(f.predict(f.initial(), 1), z), 2)
        labs.append(st.tracks.labels)
    cell = cell_index(np.array([[330.0, 410.0]]), 200.0)[0]
    assert labs[1].tolist() == [[S, 2, cell]]
    assert [S, 2, cell] in labs[0].tolist() and len({tuple(r) for r in labs[0].tolist()}) == 3
    assert sum(r[0] == 1 for r in labs[0].tolist()) == 1  # the second in the cell: own
    f = _filter(1, None)
    st = f.predict(f.correct(f.predict(f.initial(), 1), z1), 2)
    assert (st.tracks.labels[:, 0] == 1).all()  # own births
    with pytest.raises(ValueError, match="shared_origin"):
        _filter(S)
    with pytest.raises(ValueError, match="birth_cell"):
        LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(5.0), 0.9, 1e-6),
                  birth_cell=-1.0)


def test_two_peers_publish_one_target_under_one_id():
    """Each peer sees the target with its own noise and clutter; the first label each
    publishes is the same shared stamp (own births: each its origin)."""
    x0 = np.array([512.0, 316.0])

    def first_ids(shared: int | None, seed: int) -> list:
        rng = np.random.default_rng(seed)
        ests = [LmbEstimator(_filter(o, shared), origin=o) for o in (1, 2)]
        first = [None, None]
        for k in range(1, 10):
            x = x0 + (k - 3) * np.array([3.0, -2.0])  # appears at scan 3
            for j, e in enumerate(ests):
                z = rng.uniform(-5000, 5000, (2, 2))
                if k >= 3:
                    z = np.vstack((z, x + rng.normal(0, 5.0, 2)))
                out = e.step(1, z)
                pub, mix = out.labels["posterior"], out.published["posterior"]
                near = np.hypot(*(mix.means[:, [0, 2]] - x).T) < 30
                if first[j] is None and near.any():
                    first[j] = pub[near][0].tolist()
        return first

    cell = cell_index(x0[None], 200.0)[0]
    for seed in range(5):
        a, b = first_ids(S, seed)
        assert a == b and a[0] == S and a[2] == PB + cell, (seed, a, b)
        a, b = first_ids(None, seed)
        assert a[0] == 1 and b[0] == 2 and a[2] >= PB


def test_a_stamp_held_goes_to_the_earliest_birth_the_other_takes_an_own_one():
    """Two tracks of one cell born at scans 2 and 3, both first published at scan 3: the scan-2
    birth takes ``(S, 3, PB + cell)``, the other an own stamp; a track holding the stamp of the
    third cell already keeps it, the birth of that cell an own one; stamps stay after."""
    e = LmbEstimator(_filter(1), origin=1)
    cell = cell_index(np.array([[100.0, 100.0]]), 200.0)[0]
    labels = np.array([[S, 3, cell], [S, 2, cell], [S, 3, cell + 1], [S, 3, PB + cell + 1]])
    n = len(labels)
    e.state = LmbState(LabelledBernoulliSet.trusted(
        labels, np.full(n, 0.9), np.ones(n), np.zeros((n, 4)), np.tile(np.eye(4), (n, 1, 1)),
        np.arange(n)), np.zeros(n, dtype=np.int64), 3, GaussianMixture.empty(4))
    e._stamp_first_publication(3)
    got = e.state.tracks.labels.tolist()
    assert got == [[1, 3, PB], [S, 3, PB + cell], [1, 3, PB + 1], [S, 3, PB + cell + 1]]
    e._stamp_first_publication(4)
    assert e.state.tracks.labels.tolist() == got


def test_scenario_keys():
    scn = load_scenario("seed000", {"network.filter": "lmb", "lmb.birth_cell": 100.0})
    est, _ = kind("lmb").build(scn, "s1", 0)
    assert est.filter.birth_cell == 100.0 and est.filter.shared_origin == S
    with pytest.raises(ScenarioError, match="birth_cell"):
        load_scenario("seed000", {"network.filter": "lmb", "lmb.birth_cell": 0.0})


def test_lmb_peers_that_never_fuse_agree_on_ids_with_shared_births_only():
    """Seed 000's three LMB peers, no fusion (no label travels): with shared births the local
    ids of a target agree across the peers in most target-scans (measured 65 %, run 0, 40
    scans: a target's plots fall in neighbouring cells, or it is first published a scan apart);
    with own births never."""
    got = {}
    for ids in ("shared", "own"):
        scn = load_scenario("seed000", overrides={
            "network.filter": "lmb", "fusion.rule": "none", "scenario.num_scans": 40,
            "network.birth_ids": ids})
        tabs, truth = twin_tables(run_twin(scn, 0), scn.sensor_names, "local")
        got[ids] = label_agreement(tabs, truth, gate=scn.metrics.ospa_cutoff)
    assert got["shared"]["confirmed"] > 40 and got["shared"]["agreement"] >= 0.5  # 65 %
    assert got["own"]["agreement"] == 0.0
