"""An LMB peer's labels back on the network after a gap (peers/lmb_estimator.py,
``lmb.republish_gap`` / ``lmb.tentative_gap``), worked by hand: a label unpublished for more
than the gap is stamped anew at its return (own origin, the return scan), one within it keeps
its stamp, a label only ever tentative has its own gap; without the gaps a label keeps its
first stamp for the track's life (the rule before)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.lmb_estimator import PUBLISHED_BASE, LmbEstimator
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.lmb import LmbFilter, LmbState
from sensornet.tracking.lmb_sets import LabelledBernoulliSet
from sensornet.tracking.models import ConstantVelocity, LinearPosition

ORIGIN = 2


def _estimator(**kw) -> LmbEstimator:
    f = LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(20.0), 0.95, 2.5e-6),
                  origin=ORIGIN)
    return LmbEstimator(f, origin=ORIGIN, tentative_threshold=0.1, tentative_scans=2, **kw)


def _set(est: LmbEstimator, labels: np.ndarray, r: list[float]) -> None:
    """Two one-component tracks with ``labels (2, 3)`` and existences ``r``."""
    n = len(r)
    est.state = LmbState(LabelledBernoulliSet.trusted(
        labels, np.array(r), np.ones(n), np.zeros((n, 4)), np.tile(np.eye(4), (n, 1, 1)),
        np.arange(n)), np.zeros(n, np.int64), 0, None)


# existences per scan: A tentative at 1 (age 0), gone at 2, tentative again at 3 (age 2);
# B above 0.5 at 1, unpublished at 2-5 (below the tentative threshold, then old and below
# 0.5), back above 0.5 at 6
SCANS = {1: [0.2, 0.7], 2: [0.05, 0.05], 3: [0.3, 0.05], 4: [0.05, 0.3], 5: [0.05, 0.3],
         6: [0.05, 0.7]}


def _run(**kw) -> dict[int, np.ndarray]:
    est = _estimator(**kw)
    labels = np.array([[ORIGIN, 1, 0], [ORIGIN, 1, 1]], dtype=np.int64)
    out = {}
    for k, r in SCANS.items():
        _set(est, labels, r)
        est._stamp_first_publication(k)
        labels = est.state.tracks.labels.copy()
        out[k] = labels
    return out


def test_no_gap_keeps_the_first_stamp():
    out = _run()
    assert out[1][:, 1].tolist() == [1, 1] and (out[1][:, 2] >= PUBLISHED_BASE).all()
    for k in SCANS:
        np.testing.assert_array_equal(out[k], out[1])


def test_tentative_gap_restamps_a_tentative_label_after_one_dark_scan():
    out = _run(tentative_gap=0)
    assert out[3][0, 1] == 3 and out[3][0, 0] == ORIGIN and out[3][0, 2] >= PUBLISHED_BASE
    np.testing.assert_array_equal(out[6][1], out[1][1])  # B was above 0.5: no gap of its own


def test_republish_gap_restamps_a_label_dark_longer_than_the_gap():
    out = _run(republish_gap=3)  # B dark at 2-5 (4 scans > 3): a new stamp at 6
    np.testing.assert_array_equal(out[5], out[1])
    assert out[6][1, 1] == 6 and out[6][1, 2] >= PUBLISHED_BASE
    np.testing.assert_array_equal(out[3][0], out[1][0])  # A dark 1 scan: within 3
    out = _run(republish_gap=4)  # within the gap: kept
    np.testing.assert_array_equal(out[6], out[1])


def test_bad_gap():
    with pytest.raises(ValueError, match="republish_gap"):
        _estimator(republish_gap=-1)
    with pytest.raises(ValueError, match="tentative_gap"):
        _estimator(tentative_gap=-2)
