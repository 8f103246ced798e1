"""A fresh stamp of an LMB peer's first publication at scan k must not take the label a stamp
moved to scan k holds (peers.labelling.take_moves): the two tracks would share a label, and the
own-times step's label map then counts both rows for the one that survives (IndexError in
LmbFilter.settle every later scan; paris-8 with tentative tracks, docs/real-traffic.md "The
remaining gap taken apart")."""

import numpy as np
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.labels import PUBLISHED_BASE as PB
from sensornet.tracking.lmb import LmbFilter, LmbState
from sensornet.tracking.lmb_sets import LabelledBernoulliSet
from sensornet.tracking.models import ConstantVelocity, LinearPosition


def test_a_fresh_stamp_skips_the_index_a_moved_stamp_holds():
    f = LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(5.0), 0.99, 2.5e-7),
                  origin=1)
    e = LmbEstimator(f, origin=1)
    k = 5
    labels = np.array([[1, k, PB], [1, k - 1, 0]])  # moved here last scan; own-born, unpublished
    tr = LabelledBernoulliSet.trusted(labels, np.array([0.9, 0.9]), np.ones(2),
                                      np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1)),
                                      np.arange(2))
    e.state = LmbState(tr, np.zeros(2, np.int64), k, e.state.pending)
    e._stamp_first_publication(k)
    got = e.state.tracks.labels
    assert len({tuple(x) for x in got.tolist()}) == 2, got
    assert got[0].tolist() == [1, k, PB] and got[1, :2].tolist() == [1, k]
