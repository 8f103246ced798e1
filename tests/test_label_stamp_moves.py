"""Stamps that stay young while uncorroborated (issue 33, docs/labelled-tracking.md, "Stamps
corroborated within 2 scans"; peers.stamp_moves): with ``corroborate_scans`` 2 a GM-PHD peer's
label that no neighbour corroborates moves a scan later every scan for 2 scans after its first
stamp, and one that goes dark in that time is stamped anew when it returns, so a clutter track
two scans before a target, or one that returns onto a new target's track, does not give the
target an earlier id than the one the other peers stamp."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.estimators import GmphdEstimator
from sensornet.peers.labelling import label_fused, take_moves
from sensornet.peers.stamp_moves import RESTAMP_BASE, MovingStamps
from sensornet.sim.kinds.gmphd import GMPHD
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.gmphd import GMPHDFilter, SensorParams
from sensornet.tracking.labels import PUBLISHED_BASE as PB
from sensornet.tracking.labels import SHARED_ORIGIN as S
from sensornet.tracking.labels import adopt_labels
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition
from sensornet.tracking.reduction import Reducer


def _gm(means) -> GaussianMixture:
    means = np.asarray(means, float).reshape(-1, 4)
    return GaussianMixture(np.ones(len(means)), means, np.tile(np.eye(4) * 25.0,
                                                              (len(means), 1, 1)))


def _pair(corroborate_scans: int) -> list[GmphdEstimator]:
    motion = ConstantVelocity(1.0, 2.0)
    reducer = Reducer(prune_threshold=1e-5, merge_threshold=4.0, max_components=20)
    birth = GaussianMixture(np.full(1, 0.1), np.array([[0.0, 0.0, 0.0, 0.0]]),
                            np.diag([100.0, 25, 100, 25])[None])
    return [GmphdEstimator(GMPHDFilter(motion, [SensorParams(LinearPosition(5.0), 0.99, 2.5e-7)],
                                       birth, 0.99, reducer), origin=o, shared_births=True,
                           corroborate_scans=corroborate_scans) for o in (1, 2)]


def _run_pair(corroborate_scans: int) -> dict[int, set]:
    """Peer 1 sees a plot at the birth point at scans 2 and 3 (clutter), the target appears
    there at scan 4 at both peers; one consensus round a scan between the two (fused = own +
    neighbour, as in test_label_corroborated). Returns each peer's fused ids of the target."""
    a, b = _pair(corroborate_scans)
    ids: dict[int, set] = {0: set(), 1: set()}
    for k in range(1, 9):
        x = np.array([2.0 * (k - 4), 1.0 * (k - 4)])
        za = [x] if k >= 4 else ([[1.0, -1.0]] if k in (2, 3) else [])
        zb = [x] if k >= 4 else []
        outs = []
        for e, z in ((a, za), (b, zb)):
            e.begin_scan(k)
            outs.append(e.step(1, np.asarray(z, float).reshape(-1, 2)))
        for j, (e, mine, theirs) in enumerate(((a, outs[0], outs[1]), (b, outs[1], outs[0]))):
            own = (mine.published["posterior"], mine.labels["posterior"])
            nbr = (theirs.published["posterior"], theirs.labels["posterior"])
            fused = own[0] if len(own[0]) else nbr[0]
            lab = label_fused(fused, [own, nbr], e.origin, k, bump=e.fresh_stamps())
            e.relabel(lab.own)
            if k >= 4 and len(fused):
                near = np.argmin(np.hypot(*(fused.means[:, [0, 2]] - x).T))
                ids[j].add(tuple(lab.labels[near].tolist()))
    return ids


def test_a_clutter_track_two_scans_early_takes_the_targets_stamp_with_two_scans():
    old = _run_pair(1)  # moved once (to scan 3): still the earliest, the target's id at both
    assert old[0] == old[1] == {(S, 3, PB)}
    new = _run_pair(2)  # moved again at scan 3 (to 4): the stamp both peers give the target
    assert new[0] == new[1] == {(S, 4, PB)}


def test_a_moved_label_that_returns_after_a_dark_scan_is_stamped_anew():
    """The 114 case at the labels' level: own birth stamp (S, 2, PB + 1) moved to scan 3 (no
    neighbour), dark at scan 3, back at scan 4 on the track a neighbour names (S, 4, PB + 3).
    Without the memory it is the earliest label there and takes the target's id; with it the
    own label is (1, 4, RESTAMP_BASE) and the neighbour's stamp wins at both."""
    for scans in (1, 2):
        m = MovingStamps(scans)
        lab2 = np.array([[S, 2, PB + 1]])
        f2 = label_fused(_gm([[0, 0, 0, 0]]), [(_gm([[0, 0, 0, 0]]), lab2)], 1, 2, bump=lab2)
        moved, rest = take_moves(lab2, f2.own, lab2)
        m.note(lab2, moved, 2)
        assert moved.tolist() == [[S, 3, PB + 1]] and len(rest) == 0
        lab3, new3 = m.returning(moved, np.array([False]), 1, 3)  # unpublished at scan 3
        assert lab3.tolist() == moved.tolist() and len(new3) == 0
        lab4, new4 = m.returning(lab3, np.array([True]), 1, 4)  # back at scan 4
        nbr = (_gm([[1, 0, 1, 0]]), np.array([[S, 4, PB + 3]]))
        f4 = label_fused(_gm([[0, 0, 0, 0]]), [(_gm([[0, 0, 0, 0]]), lab4), nbr], 1, 4,
                         bump=new4)
        own_after = adopt_labels(lab4, f4.own)
        if scans == 1:
            assert new4.shape == (0, 3) and f4.labels.tolist() == [[S, 3, PB + 1]]
        else:
            assert new4.tolist() == [[1, 4, RESTAMP_BASE]]
            assert f4.labels.tolist() == [[S, 4, PB + 3]]
            assert own_after.tolist() == [[S, 4, PB + 3]]


def test_moves_stop_after_the_scans_and_labels_are_forgotten_when_gone():
    m = MovingStamps(2)
    a = np.array([[S, 5, PB]])
    m.note(a, np.array([[S, 6, PB]]), 5)
    assert m.offer(6, np.array([[S, 6, PB]])).tolist() == [[S, 6, PB]]
    m.note(np.array([[S, 6, PB]]), np.array([[S, 7, PB]]), 6)
    assert m.first.tolist() == [5]  # its first stamp kept through the moves
    assert m.offer(7, np.array([[S, 7, PB]])).shape == (0, 3)  # 2 scans after its stamp
    m.returning(np.array([[S, 9, 0]]), np.array([True]), 1, 7)  # no row carries it
    assert len(m.labels) == 0
    one = MovingStamps(1)  # the rule of af0ecdb: nothing remembered
    one.note(a, np.array([[S, 6, PB]]), 5)
    assert len(one.labels) == 0 and one.offer(6, np.array([[S, 6, PB]])).shape == (0, 3)


def test_bad_scans_is_a_clear_error():
    with pytest.raises(ValueError, match="MovingStamps.scans"):
        MovingStamps(0)


def test_the_automatic_value_is_two_with_shared_births_else_one():
    def scans(**over) -> int:
        scn = load_scenario("seed000", overrides=over)
        est, _ = GMPHD.build(scn, scn.sensor_names[0])
        return est.moving.scans

    assert scans() == 2  # seed 000: fixed birth points, births alike at every peer
    assert scans(**{"network.birth_ids": "own"}) == 1
    assert scans(**{"filter.corroborate_scans": 3, "network.birth_ids": "own"}) == 3
