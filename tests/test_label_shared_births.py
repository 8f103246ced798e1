"""Ids made alike at birth (issue 33, design A): GM-PHD births at fixed birth points every peer
shares are labelled ``(SHARED_ORIGIN, k, i)`` and stamped ``(SHARED_ORIGIN, k', PUBLISHED_BASE +
i)`` at first publication, so peers that start a target's track from the same birth component
in the same scan give it one id without exchanging labels. The stamp rule is checked against a
loop over the labels (one stamp per track, the earliest birth keeps it), the estimators on a
target seen by two peers with their own noise and clutter."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.estimators import GmphdEstimator
from sensornet.sim.kinds.gmphd import build
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.labels import PUBLISHED_BASE as PB
from sensornet.tracking.labels import SHARED_ORIGIN, Publication
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.reduction import Reducer
from sensornet.tracking.reidentify import Reidentification
from sensornet.tracking.track_metrics import label_agreement

from tests.labelled_tables import twin_tables

S = SHARED_ORIGIN


def reference_stamp(labels, weights, threshold, k, origin):
    """The stamp of a first publication, a label at a time (nothing published before)."""
    labels = [tuple(int(v) for v in row) for row in labels]
    on = {lab for lab, w in zip(labels, weights, strict=True) if w > threshold}
    shared = sorted(lab for lab in on if lab[0] == S and lab[2] < PB)  # by birth, then index
    taken = {lab for lab in labels if lab not in on or not (
        lab[0] in (S, origin) and lab[2] < PB)}
    out, own = {}, []
    for lab in shared:
        stamp = (S, k, PB + lab[2])
        if stamp in out.values() or stamp in taken:
            own.append(lab)
        else:
            out[lab] = stamp
    own += [lab for lab in on if lab[0] == origin and lab[2] < PB]
    for j, lab in enumerate(sorted(own)):
        out[lab] = (origin, k, PB + j)
    return np.array([out.get(lab, lab) for lab in labels], dtype=np.int64).reshape(-1, 3)


def test_first_publication_stamps_shared_births_alike_one_stamp_per_track():
    rng = np.random.default_rng(3)
    collisions = 0
    for _ in range(300):
        n = int(rng.integers(1, 9))
        labels = np.column_stack((rng.choice([S, 2, 4], n), rng.integers(5, 9, n),
                                  rng.integers(0, 3, n)))
        labels[rng.random(n) < 0.15, 2] += PB  # some stamped already (held by the network)
        weights = rng.random(n)
        got = Publication(2, shared=S).stamp(labels, weights, 0.5, 9)
        want = reference_stamp(labels, weights, 0.5, 9, 2)
        np.testing.assert_array_equal(got, want)
        # one track per label: distinct old labels never share a new one
        old = {tuple(a): tuple(b) for a, b in zip(labels.tolist(), got.tolist(), strict=True)}
        assert len(set(old.values())) == len(old)
        collisions += len({lab[2] for lab in old if lab[0] == S}) < sum(
            lab[0] == S for lab in old)
    assert collisions > 20  # the earliest-birth rule was exercised


def test_two_peers_publish_one_target_under_one_id():
    """Each peer sees the target with its own noise and clutter; the first label each
    publishes is the same shared one (own births: each its origin, two ids to reconcile)."""
    motion = ConstantVelocity(1.0, 2.0)
    reducer = Reducer(prune_threshold=1e-5, merge_threshold=4.0, max_components=20)
    points = np.array([[0.0, 0.0, 0.0, 0.0], [500.0, 0.0, 500.0, 0.0]])
    birth = GaussianMixture(np.full(2, 0.1), points,
                            np.tile(np.diag([100.0, 25, 100, 25]), (2, 1, 1)))

    def first_ids(shared: bool, seed: int) -> list:
        rng = np.random.default_rng(seed)
        ests = [GmphdEstimator(GMPHDFilter(motion, [SensorParams(LinearPosition(5.0), 0.99,
                                                                 2.5e-7)], birth, 0.99, reducer),
                               origin=o, shared_births=shared) for o in (1, 2)]
        first = [None, None]
        for k in range(1, 9):
            x = points[1, [0, 2]] + (k - 4) * np.array([3.0, -2.0])  # appears at scan 4
            for j, e in enumerate(ests):
                z = rng.uniform(-1000, 1500, (3, 2))
                if k >= 4:
                    z = np.vstack((z, x + rng.normal(0, 5.0, 2)))
                out = e.step(1, z)
                pub = out.labels["posterior"]
                near = np.hypot(*(out.published["posterior"].means[:, [0, 2]] - x).T) < 30
                if first[j] is None and k >= 4 and near.any():
                    first[j] = pub[near][0].tolist()
        return first

    for seed in range(5):
        a, b = first_ids(True, seed)
        assert a == b and a[0] == S and a[2] == PB + 1, (seed, a, b)
        a, b = first_ids(False, seed)
        assert a[0] == 1 and b[0] == 2


def test_peers_that_never_fuse_agree_on_ids_with_shared_births_only():
    """Seed 000's three peers, no fusion (no label ever travels): with shared births the local
    ids of a target agree across the peers (measured 98 % of target-scans, run 0, 40 scans);
    with own births never."""
    got = {}
    for ids in ("shared", "own"):
        scn = load_scenario("seed000", overrides={"fusion.rule": "none", "scenario.num_scans": 40,
                                                  "network.birth_ids": ids})
        tabs, truth = twin_tables(run_twin(scn, 0), scn.sensor_names, "local")
        got[ids] = label_agreement(tabs, truth, gate=scn.metrics.ospa_cutoff)
    assert got["shared"]["confirmed"] > 40 and got["shared"]["agreement"] >= 0.95
    assert got["own"]["agreement"] == 0.0


def test_a_shared_origin_is_no_peer_origin():
    f = GMPHDFilter(ConstantVelocity(1.0, 2.0), [SensorParams(LinearPosition(5.0), 0.9, 1e-6)],
                    None, 0.99, Reducer())
    with pytest.raises(ValueError, match="shared births"):
        GmphdEstimator(f, origin=S, shared_births=True)


def test_the_scenario_key_picks_the_scheme():
    for ids, origins, births in (("shared", [1, 2, 3], [S] * 3), ("own", [0, 1, 2], [0, 1, 2])):
        scn = load_scenario("seed000", overrides={"network.birth_ids": ids})
        ests = [build(scn, n)[0] for n in scn.sensor_names]
        assert [e.origin for e in ests] == origins and [e.birth_origin for e in ests] == births
    scn = load_scenario("seed000", overrides={"birth.model": "measurements"})
    assert build(scn, scn.sensor_names[1])[0].birth_origin == 1  # plots differ: own births
    with pytest.raises(ValueError, match="birth_ids"):
        load_scenario("seed000", overrides={"network.birth_ids": "alike"})


def test_a_reborn_track_stamped_shared_takes_its_lost_label():
    cv = ConstantVelocity(sigma_w=2.0)
    old = [1, 3, PB + 4]
    cov = np.eye(4) * 25.0

    def mix(x):
        return GaussianMixture(np.array([0.9]), np.asarray(x, float)[None], cov[None])

    for shared, back in ((S, True), (None, False)):
        reid = Reidentification(cv, 1, shared=shared)
        for k in range(1, 4):
            reid.apply(np.array([old]), mix([10.0 * k, 10.0, 0.0, 0.0]), 0.5, k)
        new = [S, 5, PB + 0]
        out = reid.apply(np.array([new]), mix([50.0, 10.0, 0.0, 0.0]), 0.5, 5)
        assert out.tolist() == [old if back else new]
