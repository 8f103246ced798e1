"""tracking.label_twins (issue 33): a young fused row whose moved stamp's first (same origin and
index, a scan earlier) the peer held a scan before is held back; two real targets side by side,
old rows and other indices are reported; the option reaches a peer only 2 hops or more from
some other peer."""

import numpy as np
import pytest
from sensornet.peers.consensus_types import ConsensusOptions
from sensornet.sim.run.peers import consensus_options
from sensornet.sim.studies.labelled.ospa2_floor import GRAPHS
from sensornet.sim.studies.labelled.study import RULES, scenario_of
from sensornet.tracking.label_twins import StampTwins

COV = np.diag([100.0, 25.0, 100.0, 25.0])  # 10 m, 5 m/s a side
STAMP = (1 << 36) + (1 << 34) + 4242  # a shared stamp of birth cell 4242


def density(xs, births, index=STAMP, weights=None):
    """Fused density components at positions ``xs`` (x, y), 10 m/s east, shared labels
    ``(0, birth, index)``: (labels, weights, means, covs)."""
    n = len(xs)
    means = np.array([[x, 10.0, y, 0.0] for x, y in xs], dtype=float).reshape(n, 4)
    idx = index if np.ndim(index) else [index] * n
    labels = np.array([[0, b, i] for b, i in zip(births, idx, strict=True)],
                      dtype=np.int64).reshape(n, 3)
    w = np.full(n, 0.9) if weights is None else np.asarray(weights, dtype=float)
    return labels, w, means, np.repeat(COV[None], n, axis=0)


def held(rule, k, rows, dens):
    """``rule.held`` of the extracted ``rows`` (a density's tuple) given the density ``dens``."""
    labels, _, means, covs = rows
    return rule.held(k, labels, means, covs, *dens).tolist()


def test_moved_stamp_held_while_its_first_may_come():
    """Scan 21: the density holds (0, 21, c) at 0.08 (a neighbour's, not extracted); scan 22:
    the mover's (0, 22, c) 8 m away is extracted alone: held back (scans = 1); at scan 23 (its
    first not seen at 22, the memory of 1 scan over) it is reported; off: reported at once."""
    rule = StampTwins(1, 1)
    first = density([(1000.0, 500.0)], [21], weights=[0.08])
    empty = density([], [])
    assert held(rule, 21, empty, first) == []
    moved = density([(1008.0, 500.0)], [22], weights=[0.6])
    assert held(rule, 22, moved, moved) == [True]
    moved23 = density([(1018.0, 500.0)], [22], weights=[0.8])
    assert held(rule, 23, moved23, moved23) == [False]
    # the first stamp back at 23 in the same density, extracted: the moved row is held, the
    # first reported (23 - 22 <= 1 scan old)
    both = density([(1018.0, 500.0), (1019.0, 500.0)], [21, 22], weights=[0.7, 0.3])
    rule = StampTwins(1, 1)
    rule.held(21, *empty[:1], *empty[2:], *first)
    assert held(rule, 23, both, both) == [False, True]


def test_two_real_targets_and_other_labels_reported():
    """Held back only beside a twin: another index (another birth cell), a twin 100 m away
    (d2 = 100^2 / 200 = 50 > 26), a row older than ``young`` scans, or a twin born the same
    scan (a same-scan tie, the label rule's) leave the row reported."""
    here = [(0.0, 0.0)]
    for twin, row, k in [(density(here, [21], index=STAMP + 1), density(here, [22]), 22),
                         (density(here, [21]), density([(100.0, 0.0)], [22]), 22),
                         (density(here, [10]), density(here, [20]), 22),
                         (density(here, [22]), density(here, [22]), 22)]:
        rule = StampTwins(1, 1)
        rule.held(k - 1, *twin[:1], *twin[2:], *twin)
        assert held(rule, k, row, row) == [False]
    # two targets 300 m apart, each a moved stamp of its own cell: each held by its own twin;
    # one first stamp beside two moved rows of its cell: one row held (assignment, one to one)
    rule = StampTwins(1, 1)
    twins = density([(0.0, 0.0), (300.0, 0.0)], [21, 21], index=[STAMP, STAMP + 7])
    rule.held(21, *twins[:1], *twins[2:], *twins)
    rows = density([(3.0, 0.0), (302.0, 0.0)], [22, 22], index=[STAMP, STAMP + 7])
    assert held(rule, 22, rows, rows) == [True, True]
    rule = StampTwins(1, 1)
    rule.held(21, *twins[:1], *twins[2:], *twins)
    rows = density([(3.0, 0.0), (1.0, 0.0)], [22, 22], index=[STAMP, STAMP])
    assert held(rule, 22, rows, rows) == [False, True]


def test_memory_forgets_after_its_scans():
    """With ``memory = 2`` a first stamp seen at scan 20 still holds a row at 22, not at 23."""
    first = density([(0.0, 0.0)], [20], weights=[0.1])
    for k, expect in [(22, [True]), (23, [False])]:
        rule = StampTwins(2, 2)
        rule.held(20, *first[:1], *first[2:], *first)
        row = density([(1.0, 0.0)], [k - 1])
        assert held(rule, k, row, row) == expect


def test_bad_input_is_one_line_error():
    with pytest.raises(ValueError, match="young"):
        StampTwins(0, 1)
    with pytest.raises(ValueError, match="gate"):
        StampTwins(1, 1, gate=np.inf)
    rows = density([(0.0, 0.0)], [22])
    with pytest.raises(ValueError, match="covs"):
        StampTwins(1, 1).held(22, rows[0], rows[2], rows[3][:0], *rows)
    with pytest.raises(ValueError, match="stamp_twins"):
        ConsensusOptions(name="a", stamp_twins=-1)


def test_option_reaches_peers_two_hops_from_another():
    """``fusion.stamp_twins`` at 20 peers of degree 4 (eccentricity 5); not at 3 peers linked
    to each other (every stamp reaches every peer at the next fusion: nothing to wait for)."""
    for graph, expect in [("circ20", 1), ("full3", 0)]:
        scn = scenario_of(GRAPHS[graph], "lmb", 0.9, 10.0, 5,
                          {**RULES["hybrid"], "fusion.stamp_twins": 1})
        assert {consensus_options(scn, s).stamp_twins for s in scn.sensor_names} == {expect}


def test_default_is_one_scan_for_lmb_peers_and_off_for_gmphd():
    """The auto default (-1): 1 scan at LMB peers two hops from another, off at GM-PHD peers
    (not evaluated there) and on a full graph; an explicit 0 turns it off for LMB."""
    for kind, graph, sets, expect in [("lmb", "circ20", {}, 1), ("gmphd", "circ20", {}, 0),
                                      ("lmb", "full3", {}, 0),
                                      ("lmb", "circ20", {"fusion.stamp_twins": 0}, 0)]:
        scn = scenario_of(GRAPHS[graph], kind, 0.9, 10.0, 5, {**RULES["hybrid"], **sets})
        assert scn.fusion.stamp_twins == sets.get("fusion.stamp_twins", -1)
        assert {consensus_options(scn, s).stamp_twins for s in scn.sensor_names} == {expect}
