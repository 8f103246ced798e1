"""peers.labelling.label_fused ``fallback`` and ``keep`` (issue 34, docs/real-traffic.md "The
switches traced"): a fused row that loses the label it won to a heavier row takes the next
label it was paired with, not a fresh one, and its own track is released to that label; a row
paired with a label the peer reported the scan before keeps it against an earlier-born one;
batched equals one by one to the bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sensornet.peers.labelling import FRESH_BASE, label_fused, next_labels
from sensornet.peers.labelling_batch import label_fused_many
from sensornet.tracking.label_matching import RELEASE, adopt_labels
from sensornet.tracking.labels import label_keys
from sensornet.tracking.mixture import GaussianMixture

from tests.test_labelling_batch import _problem, _same

COV = np.diag([100.0**2, 10.0**2, 100.0**2, 10.0**2])
OLD, YOUNG = (0, 160, 3), (0, 200, 4)  # 3949f7's label, 506d8e's (CDG, Orly, Pontoise)


def _mix(means, weights=None):
    means = np.atleast_2d(np.asarray(means, dtype=float))
    w = np.ones(len(means)) if weights is None else np.asarray(weights, dtype=float)
    return GaussianMixture(w, means, np.repeat(COV[None], len(means), axis=0))


A = [0.0, 0.0, 0.0, 0.0]  # the older aircraft (heavier fused row)
B = [2200.0, 0.0, 0.0, 0.0]  # the young aircraft 2.2 km away


def _scan(fallback: bool, own_labels: np.ndarray, k: int = 202):
    """South's view at the incident: its own track OLD has moved onto B; three neighbours
    hold A under OLD and B under YOUNG. Fused rows: A (heavier), B."""
    fused = _mix([A, B], [0.99, 0.9])
    own = (_mix([B]), own_labels)
    nbrs = [(_mix([A, B]), np.array([OLD, YOUNG])) for _ in range(3)]
    return label_fused(fused, [own, *nbrs], origin=7, k=k, fallback=fallback, copies=True)


def test_a_row_that_loses_its_label_takes_the_next_paired_label_not_a_fresh_one():
    before = _scan(False, np.array([OLD]))
    assert tuple(before.labels[0]) == OLD
    assert tuple(before.labels[1][:2]) == (7, 202) and before.labels[1][2] >= FRESH_BASE
    assert before.fresh == 1
    got = _scan(True, np.array([OLD]))
    np.testing.assert_array_equal(got.labels, [OLD, YOUNG])
    assert got.fresh == 0
    # south's own track on B is released to YOUNG (it takes it though it is the later label)
    assert len(got.own) == 1 and got.own.cost[0] == RELEASE
    np.testing.assert_array_equal(got.own.own, [OLD])
    np.testing.assert_array_equal(got.own.nbr, [YOUNG])
    np.testing.assert_array_equal(adopt_labels(np.array([OLD]), got.own), [YOUNG])


def test_the_reported_label_survives_the_sequence_and_peers_agree():
    """Scans 200-204: the young row is reported under YOUNG from 200; at 202 south's track
    OLD moves onto it. With the fallback every peer's fused label of B stays YOUNG; without
    it, it changes to a fresh label at 202 (the switch of docs/real-traffic.md)."""
    for fallback, want in ((True, {YOUNG}), (False, None)):
        south = np.array([YOUNG])
        seen = []
        for k in range(200, 205):
            if k == 202:
                south = np.array([OLD])  # its track of A wandered onto B
            got = _scan(fallback, south, k)
            seen.append(tuple(got.labels[1]))
            # a neighbour (CDG) fuses the same scan's densities, south's among them
            cdg = label_fused(_mix([A, B], [0.99, 0.9]),
                              [(_mix([A, B]), np.array([OLD, YOUNG])), (_mix([B]), south),
                               (_mix([A, B]), np.array([OLD, YOUNG]))],
                              origin=2, k=k, fallback=fallback, copies=True)
            if fallback:
                assert tuple(cdg.labels[1]) == seen[-1]
            south = adopt_labels(south, got.own)
        if want is not None:
            assert set(seen) == want
        else:
            assert len(set(seen)) > 1 and seen[2][2] >= FRESH_BASE


def test_copies_within_the_gate_keep_a_fresh_label():
    """Under AA a row within the gate of the row that kept its label is the same target's
    copy (peers.labelling.copy_rows): no fallback, it stays marked a copy."""
    fused = _mix([A, [30.0, 0, 0, 0]], [0.99, 0.3])
    inputs = [(_mix([[30.0, 0, 0, 0]]), np.array([OLD])),
              (_mix([A, [30.0, 0, 0, 0]]), np.array([OLD, YOUNG]))]
    got = label_fused(fused, inputs, 1, 5, fallback=True, copies=True)
    assert got.labels[1][2] >= FRESH_BASE and got.copies[1]


def test_next_labels_heavier_row_first_and_taken_labels_skipped():
    labels = np.array([[0, 1, 0], [0, 1, 0], [0, 1, 0], [9, 9, 9]])
    won = np.array([True, False, False, True])
    pending = np.array([False, True, True, False])
    # rows 1 and 2 both lost (0,1,0); next: row 1 -> (9,9,9) (taken) then (0,2,0);
    # row 2 -> (0,2,0) too, heavier -> row 2 wins it at rank 1, row 1 at rank 2 gets (0,3,0)
    Jo = np.array([1, 1, 1, 2, 2])
    Lo = np.array([[0, 1, 0], [9, 9, 9], [0, 2, 0], [0, 1, 0], [0, 2, 0]])
    Jo, Lo = np.r_[Jo, 1], np.r_[Lo, [[0, 3, 0]]]
    by = np.argsort(Jo, kind="stable")
    out, won2 = next_labels(labels, won, pending, Jo[by], Lo[by],
                            np.array([1.0, 0.2, 0.5, 1.0]), np.zeros(4, dtype=np.int64))
    np.testing.assert_array_equal(out[2], [0, 2, 0])
    np.testing.assert_array_equal(out[1], [0, 3, 0])
    assert won2.all()


def test_a_reported_label_is_kept_against_one_born_settle_scans_before_it():
    """392af3 at tick 528: its row is reported under (0, 527) (two inputs hold it); north's
    track (4, 524), born 3 scans earlier, is paired with the row too. Without ``keep`` the
    earlier birth wins (a switch); with (0, 527) reported the scan before and a settle of 1-3
    scans, it stays; with a settle of 4 (a label born 3 scans before may still be the same
    target's on its way) the earlier one wins as before; a label not reported does not
    count."""
    young, north = (0, 527, 1), (4, 524, 2)
    fused = _mix([B])
    inputs = [(_mix([B]), np.array([young])), (_mix([B]), np.array([young])),
              (_mix([[B[0] + 150.0, 0, 0, 0]]), np.array([north]))]
    assert tuple(label_fused(fused, inputs, 3, 528).labels[0]) == north
    keep = np.unique(label_keys(np.array([young, (5, 1, 1)])))
    for settle in (0, 1, 3):
        got = label_fused(fused, inputs, 3, 528, keep=keep, settle=settle)
        assert tuple(got.labels[0]) == young and len(got.own) == 0
    assert tuple(label_fused(fused, inputs, 3, 528, keep=keep, settle=4).labels[0]) == north
    other = np.unique(label_keys(np.array([(5, 1, 1)])))
    assert tuple(label_fused(fused, inputs, 3, 528, keep=other).labels[0]) == north
    # north itself (its own track first) reports young too: its own track keeps its label
    # (the rule adopts only earlier labels), the fused row keeps the reported one
    at_north = label_fused(fused, [inputs[2], *inputs[:2]], 4, 528, keep=keep)
    assert tuple(at_north.labels[0]) == young
    np.testing.assert_array_equal(adopt_labels(np.array([north]), at_north.own), [north])


def test_kept_first_vetoes_only_labels_born_settle_scans_before_the_earliest_kept():
    from sensornet.peers.labelling import kept_first

    J = np.array([0, 0, 0, 1, 1])
    L = np.array([(1, 10, 0), (2, 7, 0), (3, 8, 0), (1, 10, 0), (2, 3, 0)])
    keep = np.unique(label_keys(np.array([(1, 10, 0)])))
    # row 0: kept birth 10, settle 3: 7 vetoed, 8 not; row 1: 3 vetoed
    np.testing.assert_array_equal(kept_first(J, L, 2, keep, np.full(5, 3)), [0, 1, 0, 0, 1])
    np.testing.assert_array_equal(kept_first(J, L, 2, None, np.full(5, 3)), [0] * 5)


def test_batched_equals_one_by_one_with_the_fallback_and_keep():
    rng = np.random.default_rng(3403)
    changed = kept = 0
    for _ in range(150):
        problems = []
        for _ in range(int(rng.integers(1, 9))):
            pr = _problem(rng)
            keep = None
            if rng.random() < 0.5:
                labs = [np.asarray(lab) for _, lab in pr.inputs if lab is not None and len(lab)]
                if labs:
                    pool = np.concatenate(labs)
                    pick = pool[rng.random(len(pool)) < 0.3]
                    keep = np.unique(label_keys(pick))
            problems.append(dataclasses.replace(pr, fallback=bool(rng.random() < 0.7),
                                                keep=keep, settle=int(rng.integers(0, 3))))
        for pr, g in zip(problems, label_fused_many(problems), strict=True):
            ref = pr.alone()
            _same(g, ref)
            if pr.fallback:
                plain = dataclasses.replace(pr, fallback=False).alone()
                changed += int((ref.labels != plain.labels).any(axis=1).sum())
            if pr.keep is not None:
                plain = dataclasses.replace(pr, keep=None).alone()
                kept += int((ref.labels != plain.labels).any(axis=1).sum())
    assert changed > 10 and kept > 10  # the random cases do fall back and keep


def test_the_options_default_per_peer_kind():
    """Auto (-1, the default) resolves per kind where the peers are built
    (``sim.run.peers.consensus_options``): on for LMB peers with rotating radars (paris-8),
    off for GM-PHD peers (whose switches rose on real traffic) and for LMB peers of a
    synchronous scenario (seed 000: label agreement fell on an evaluation run); an explicit
    0 turns each off for LMB peers, 1 on for the others, each key on its own."""
    from sensornet.sim.run.peers import consensus_options
    from sensornet.sim.scenario import load_scenario

    def got(scenario="paris-8", **sets):
        scn = load_scenario(scenario, overrides={f"network.{k}" if k == "filter"
                                                 else f"fusion.{k}": v
                                                 for k, v in sets.items()})
        o = consensus_options(scn, scn.sensor_names[0])
        return o.label_fallback, o.label_keep

    assert got("seed000", filter="lmb") == (False, False)
    assert got("seed000", filter="lmb", label_fallback=1, label_keep=1) == (True, True)

    assert load_scenario("paris-8").fusion.label_fallback == -1
    assert load_scenario("paris-8").fusion.label_keep == -1
    assert got(filter="lmb") == (True, True)
    assert got(filter="gmphd") == (False, False)
    assert got(filter="lmb", label_fallback=0) == (False, True)
    assert got(filter="lmb", label_keep=0) == (True, False)
    assert got(filter="gmphd", label_fallback=1) == (True, False)
    assert got(filter="gmphd", label_keep=1) == (False, True)
    assert got(filter="lmb", label_fallback=1, label_keep=1) == (True, True)


def test_true_false_and_out_of_range_are_one_line_errors():
    """The keys are integers now (-1 auto, 0 off, 1 on): ``--set fusion.label_keep=true`` (the
    old boolean form) and a value outside [-1, 1] fail at load in one line naming the key."""
    from sensornet.sim.scenario import ScenarioError, load_scenario
    from sensornet.sim.scenario.overrides import parse_overrides

    for item in ("fusion.label_keep=true", "fusion.label_fallback=false",
                 "fusion.existence_revisit=true", "fusion.label_keep=2"):
        key = item.partition("=")[0]
        with pytest.raises(ScenarioError, match=key.replace(".", r"\.")) as err:
            load_scenario("paris-8", overrides=parse_overrides([item]))
        assert "\n" not in str(err.value)
