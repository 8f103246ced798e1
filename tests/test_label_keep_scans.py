"""``fusion.label_keep_scans`` (issue 34, tracking.held_ids.ReportedIds): ``label_keep``'s veto
over the labels a peer reported in its last N scans, so a reported track not extracted for one
scan keeps its label. By hand on the traced case (paris-8's training hour, aircraft 392af3 at
CDG, ticks 773-775: reported under ``AIRCRAFT``, not reported at 774, at 775 an en-route radar's
remnant ``REMNANT`` of another aircraft's label, born 289 scans earlier, paired with its row),
the store's memory, and the option's wiring."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from sensornet.peers.consensus import Consensus, ConsensusOptions
from sensornet.peers.fusers import HybridFuser
from sensornet.peers.labelling import label_fused
from sensornet.sim.kinds import kind
from sensornet.sim.run.peers import consensus_options
from sensornet.sim.scenario import ScenarioError, load_scenario
from sensornet.tracking.held_ids import ReportedIds
from sensornet.tracking.label_keys import keys_isin, label_keys
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.reduction import Reducer

from tests.test_fusion_batch import _Echo

COV = np.diag([100.0**2, 10.0**2, 100.0**2, 10.0**2])
AIRCRAFT = (0, 525, 1)
"""The aircraft's fused label, reported at 773, held by seven of the eight inputs."""
REMNANT = (4, 236, 2)
"""A far radar's own confirmed track on the aircraft under another aircraft's old label."""
OTHER = (0, 700, 5)
"""Another aircraft's label, reported every scan (so the last scan's set is never empty)."""


def _mix(means) -> GaussianMixture:
    means = np.atleast_2d(np.asarray(means, dtype=float))
    return GaussianMixture(np.ones(len(means)), means, np.repeat(COV[None], len(means), 0))


def _label_at_775(keep: np.ndarray | None) -> tuple:
    """The fused row's label at 775: two inputs hold it under AIRCRAFT, the remnant radar's
    own track (150 m off) under REMNANT, born long before (the earliest-birth rule's winner)."""
    x = [0.0, 230.0, 0.0, 0.0]
    inputs = [(_mix([x]), np.array([AIRCRAFT])), (_mix([x]), np.array([AIRCRAFT])),
              (_mix([[150.0, 230.0, 0.0, 0.0]]), np.array([REMNANT]))]
    return tuple(label_fused(_mix([x]), inputs, 3, 775, keep=keep, settle=3).labels[0])


def _reported(scans: dict[int, list]) -> tuple[np.ndarray, ReportedIds | None]:
    """Replays ``scans`` ``{k: reported labels}`` in order as the consensus does (the last
    scan's keys, and with ``label_keep_scans`` the store); the keep set at the next scan."""
    store, last = ReportedIds(3), label_keys(np.zeros((0, 3), np.int64))
    for k, ids in scans.items():
        ids = np.array(ids, dtype=np.int64).reshape(-1, 3)
        last = np.unique(label_keys(ids))
        store.remember(k, ids)
    return last, store


def test_a_one_scan_drop_ends_the_veto_of_the_scan_before_but_not_over_three_scans():
    """Reported at 773, not at 774: ``label_keep`` of the scan before keeps only OTHER and
    the remnant takes the aircraft's row at 775 (the traced switch); over the last 3 scans
    AIRCRAFT is still kept and the row keeps it. Reported at 774 too, both keep it."""
    last, store = _reported({773: [AIRCRAFT, OTHER], 774: [OTHER]})
    assert _label_at_775(None) == REMNANT
    assert _label_at_775(last) == REMNANT
    assert _label_at_775(store.union(775, last)) == AIRCRAFT
    last, store = _reported({773: [AIRCRAFT, OTHER], 774: [AIRCRAFT, OTHER]})
    assert _label_at_775(last) == AIRCRAFT == _label_at_775(store.union(775, last))


def test_a_label_not_reported_for_more_than_n_scans_is_no_longer_kept():
    """Reported at 771 (4 scans before 775) only: not kept with N = 3, kept with N = 4."""
    for n, want in ((3, REMNANT), (4, AIRCRAFT)):
        store = ReportedIds(n)
        store.remember(771, np.array([AIRCRAFT]))
        for k in (772, 773, 774):
            store.remember(k, np.array([OTHER]))
        last = np.unique(label_keys(np.array([OTHER])))
        assert _label_at_775(store.union(775, last)) == want


def test_the_store_remembers_each_id_by_its_last_report_and_forgets_old_ones():
    store = ReportedIds(2)
    store.remember(10, np.array([AIRCRAFT, OTHER]))
    store.remember(11, np.array([OTHER]))
    np.testing.assert_array_equal(store.recent(12), np.unique(label_keys(np.array(
        [AIRCRAFT, OTHER]))))  # scans 10-11: AIRCRAFT 2 scans before 12
    store.remember(12, np.zeros((0, 3), dtype=np.int64))
    np.testing.assert_array_equal(store.recent(13), label_keys(np.array([OTHER])))
    assert len(store.keys) == 1  # AIRCRAFT forgotten
    got = store.union(13, label_keys(np.array([AIRCRAFT])))
    np.testing.assert_array_equal(got, np.unique(label_keys(np.array([AIRCRAFT, OTHER]))))


@pytest.mark.parametrize("bad", [0, -1, 2.5, True])
def test_bad_memories_are_refused_in_one_line(bad):
    with pytest.raises(ValueError, match="memory must be an integer >= 1"):
        ReportedIds(bad)


def test_the_option_reaches_the_peers_and_their_consensus():
    """``fusion.label_keep_scans`` (0, off, by default) is each peer's ``label_keep_scans``;
    a labelled peer with ``label_keep`` keeps a store of that many scans, none without."""
    for v in (0, 3):
        scn = load_scenario("paris-8", overrides={"fusion.label_keep_scans": v})
        assert consensus_options(scn, scn.sensor_names[0]).label_keep_scans == v
    assert load_scenario("paris-8").fusion.label_keep_scans == 0
    with pytest.raises(ValueError, match="label_keep_scans"):
        ConsensusOptions("a", ("b",), (("a", 1), ("b", 1)), label_keep_scans=-1)

    def kept(origin, keep, scans):
        est = _Echo()
        est.origin = origin
        opts = ConsensusOptions("a", ("b",), (("a", 1), ("b", 1)), label_keep=keep,
                                label_keep_scans=scans)
        return Consensus(opts, est, HybridFuser(Reducer())).kept_ids

    assert kept(0, True, 3).scans == 3
    assert kept(0, True, 0) is None and kept(0, False, 3) is None and kept(None, True, 3) is None


@pytest.mark.parametrize("bad", [-1, "abc", 1.5, True])
def test_bad_scenario_values_are_one_line_errors(bad):
    """``--set fusion.label_keep_scans=...``: a negative, a string, a fraction or a boolean is
    refused when the scenario loads, in one line naming the key."""
    with pytest.raises(ScenarioError, match="label_keep_scans") as e:
        load_scenario("paris-8", overrides={"fusion.label_keep_scans": bad})
    assert "\n" not in str(e.value)


def test_a_peer_s_label_problem_keeps_what_it_reported_in_its_last_n_scans():
    """Through the peer: an LMB consensus reports AIRCRAFT and OTHER at 773, OTHER only at 774;
    its label problem at 775 keeps AIRCRAFT with ``label_keep_scans = 3`` (the store its
    extraction fed), not with 0 (the scan before's only)."""
    def mix(xs):
        m = np.zeros((len(xs), 4))
        m[:, 0] = xs
        return GaussianMixture(np.full(len(xs), 0.9), m,
                               np.tile(np.eye(4) * 100.0, (len(xs), 1, 1)))

    both = np.array([AIRCRAFT, OTHER])
    for scans, kept in ((0, [False, True]), (3, [True, True])):
        est, _ = kind("lmb").build(load_scenario("seed000", {"network.filter": "lmb"}), "s1", 0)
        peer = Consensus(ConsensusOptions("s1", ("s2",), (("s1", 1), ("s2", 1)), label_keep=True,
                                          label_keep_scans=scans), est, HybridFuser(Reducer()))
        (m1,) = peer._tracks(773, mix([0.0, 5000.0]), 0.0, both)
        (m2,) = peer._tracks(774, mix([5000.0]), 0.0, np.array([OTHER]))
        assert len(m1.ids) == 2 and m2.ids.tolist() == [list(OTHER)]
        fused = mix([0.0, 5000.0])
        st = SimpleNamespace(inputs=None, current=fused, labels=both, k=775, round=0)
        keep = peer.label_problem(st, fused).keep
        assert keys_isin(label_keys(both), keep).tolist() == kept
