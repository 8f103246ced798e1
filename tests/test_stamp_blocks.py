"""tracking.stamp_blocks (issue 33): a shared label is reported as its block of scans and birth
cells, so one target's stamps a scan apart or in neighbouring cells show one id; stamps across
a block edge, own labels and two rows of one block are left as they are; the option reaches a
peer's reported tracks and nothing else."""

import numpy as np
import pytest
from sensornet.sim.run.peers import consensus_options, make_peer
from sensornet.sim.studies.labelled.ospa2_floor import GRAPHS
from sensornet.sim.studies.labelled.study import RULES, scenario_of
from sensornet.tracking.label_keys import CELL_BASE, PUBLISHED_BASE, cell_index
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.stamp_blocks import BLOCK_FLAG, block_ids


def stamp(scan, x, y, size=200.0):
    """The shared stamp ``(0, scan, PUBLISHED_BASE + cell_index)`` of a birth plot at (x, y)."""
    return [0, scan, PUBLISHED_BASE + int(cell_index(np.array([[x, y]]), size)[0])]


def test_stamps_of_one_block_show_one_id():
    """Cells 200 m, blocks of 4: (410, 90) and (390, 90) are cells 2 and 1 on x (one 800 m
    block, 0-799 m), scans 41 and 42 one 4-scan block (40-43): all four stamps show one id,
    scan 40, the block's cell (0, 0), flagged; a stamp at scan 44 or at x = 810 m (cell 4, the
    next block) shows another."""
    ids = np.array([stamp(41, 410, 90), stamp(41, 390, 90), stamp(42, 410, 90),
                    stamp(42, 390, 90)])
    out = np.array([block_ids(ids[i:i + 1], 4)[0] for i in range(4)])
    assert (out == out[0]).all()
    want = [0, 40, PUBLISHED_BASE + BLOCK_FLAG + int(cell_index(np.array([[0.0, 0.0]]),
                                                                200.0)[0])]
    assert out[0].tolist() == want
    for other in (stamp(44, 410, 90), stamp(41, 810, 90), stamp(41, 410, 810)):
        assert block_ids(np.array([other]), 4)[0].tolist() != want
    # negative coordinates: cells -1 and -4 on x are in two blocks (-800..-1 is -4..-1)
    a, b = block_ids(np.array([stamp(41, -10, 90)]), 4), block_ids(np.array([stamp(41, -790,
                                                                                   90)]), 4)
    c = block_ids(np.array([stamp(41, -810, 90)]), 4)
    assert (a == b).all() and not (a == c).all()


def test_own_labels_and_clashes_keep_their_labels():
    """Own labels (origin > 0: splits, fresh fusion labels) are reported as they are; a fixed
    birth component's stamp (small index) takes the scan block only; two rows of one scan that
    would share a block (two targets) both keep their labels; block 1 changes only the flag."""
    own = np.array([[3, 41, 7], [5, 42, (1 << 32) + 1]])
    assert (block_ids(own, 4) == own).all()
    fixed = np.array([[0, 42, PUBLISHED_BASE + 2]])
    assert block_ids(fixed, 4).tolist() == [[0, 40, PUBLISHED_BASE + BLOCK_FLAG + 2]]
    two = np.array([stamp(41, 410, 90), stamp(42, 390, 90), stamp(41, 2000, 90)])
    out = block_ids(two, 4)
    assert (out[:2] == two[:2]).all() and out[2, 1] == 40
    one = np.array([stamp(41, 410, 90)])
    assert block_ids(one, 1).tolist() == [[0, 41, one[0, 2] + BLOCK_FLAG]]
    assert CELL_BASE + (1 << 32) < BLOCK_FLAG < PUBLISHED_BASE


def test_bad_input_is_one_line_error():
    """Wrong shapes, non-integer labels, a block below 1 or a fraction: ValueError."""
    ok = np.array([stamp(41, 410, 90)])
    for args in [(np.zeros((2, 2), dtype=np.int64), 4), (np.zeros((1, 3)), 4), (ok, 0),
                 (ok, 2.5), (ok, -1)]:
        with pytest.raises(ValueError):
            block_ids(*args)
    with pytest.raises(ValueError):
        block_ids(ok, 4, axes=5)
    assert block_ids(np.zeros((0, 3), dtype=np.int64), 4).shape == (0, 3)


def test_option_reaches_the_reported_tracks_only():
    """``fusion.id_blocks`` reaches every peer's options (0 by default); a peer's Tracks of a
    fused density with two stamps (scans 41 and 42, 2 km apart: two blocks) report the blocks,
    flagged; with the option off, the labels."""
    for sets, expect in [({}, 0), ({"fusion.id_blocks": 4}, 4)]:
        scn = scenario_of(GRAPHS["circ20"], "lmb", 0.9, 10.0, 5, {**RULES["hybrid"], **sets})
        assert {consensus_options(scn, s).id_blocks for s in scn.sensor_names} == {expect}
    scn = scenario_of(GRAPHS["circ20"], "lmb", 0.9, 10.0, 5,
                      {**RULES["hybrid"], "fusion.id_blocks": 4})
    c = make_peer(scn, scn.sensor_names[0], 0).consensus
    labels = np.array([stamp(41, 410, 90), stamp(42, 2410, 90)], dtype=np.int64)
    means = np.array([[400.0, 0.0, 90.0, 0.0], [2400.0, 0.0, 90.0, 0.0]])
    fused = GaussianMixture(np.array([0.9, 0.9]), means,
                            np.repeat(np.diag([100.0, 25.0, 100.0, 25.0])[None], 2, axis=0))
    msg = c._tracks(45, fused, 0.0, labels.copy())[0]
    assert np.asarray(msg.ids).tolist() == block_ids(labels, 4).tolist()
    assert (np.asarray(msg.ids)[:, 2] & BLOCK_FLAG).all()
    c.o = type(c.o)(**{**c.o.__dict__, "id_blocks": 0})
    assert np.asarray(c._tracks(46, fused, 0.0, labels.copy())[0].ids).tolist() \
        == labels.tolist()
