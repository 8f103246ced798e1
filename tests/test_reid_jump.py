"""tracking.reidentify's distance bound (issue 34's handover): a label that went dark and comes
back published more than ``jump`` metres from its last published state predicted forward is
stamped new, and re-identification does not give a lost label to a track that far; the
constructed cases keep the old label without the bound (jump=None), so they fail without it."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.labels import PUBLISHED_BASE
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity
from sensornet.tracking.reidentify import REID_JUMP, REJECTED_BASE, Reidentification

CV = ConstantVelocity(T=2.0, sigma_w=10.0)
OWN = 1
A = [0, 1, PUBLISHED_BASE]  # the aircraft that leaves (an early label)
B = [OWN, 2, PUBLISHED_BASE + 1]  # the next aircraft on the same approach
VAR = 4.0e6  # (2 km)^2: a coasted track's prediction, wide enough for the chi-square gate


def _mix(means, w, var=2500.0):
    means = np.asarray(means, float).reshape(-1, 4)
    covs = np.tile(np.eye(4) * var, (len(means), 1, 1))
    return GaussianMixture(np.asarray(w, float), means, covs)


def _state(x0, k):
    """CV truth: ``x0 = [x, vx, y, vy]`` at scan 1, at scan ``k``."""
    return np.linalg.matrix_power(CV.F, k - 1) @ np.asarray(x0, float)


def _run(jump, offset, dark=5, with_b=False):
    """A published on scans 1-6 (heading east at 60 m/s), then only a light remnant of A for
    ``dark`` scans; at the next scan the remnant is published again ``offset`` metres north of
    A's prediction; with ``with_b``, B (4 km behind A on its path, published from scan 2 on)
    takes A's label instead (a remnant of A took B's plots and merged with B's track).
    Returns the last scan's labels and the scan."""
    reid = Reidentification(CV, OWN, scans=9, jump=jump)
    xa = [0.0, 60.0, 0.0, 0.0]
    xb = [-4000.0, 60.0, offset, 0.0]
    for k in range(1, 7 + dark):
        a_on = k <= 6
        means = [_state(xa, k)]
        w = [0.9 if a_on else 0.01]
        labels = [A]
        if with_b and k >= 2:
            means.append(_state(xb, k))
            w.append(0.9)
            labels.append(B)
        reid.apply(np.array(labels), _mix(means, w), 0.5, k)
    k = 7 + dark
    back = _state(xa, k) + [0.0, 0.0, offset, 0.0]
    if with_b:  # A's label on both of B's rows, B's gone
        return reid.apply(np.array([A, A]), _mix([_state(xb, k), _state(xb, k)], [0.9, 0.05]),
                          0.5, k), k
    return reid.apply(np.array([A]), _mix(back, [0.9], var=VAR), 0.5, k), k


def test_a_dark_label_returning_far_from_its_prediction_is_stamped_new():
    for offset in (500.0, 2500.0, 3500.0, 6000.0):
        out, k = _run(REID_JUMP, offset)
        far = offset > REID_JUMP
        expect = [OWN, k, PUBLISHED_BASE + REJECTED_BASE] if far else A
        assert out.tolist() == [expect], offset
        out, _ = _run(None, offset)  # without the bound the label returns wherever it is
        assert out.tolist() == [A], offset


def test_a_label_that_took_another_track_gives_that_track_its_label_back():
    for dark in (0, 1, 5):  # 0: A published at the last scan, its wide track merged into B's
        out, _ = _run(REID_JUMP, 0.0, dark=dark, with_b=True)  # B 4 km behind A's prediction
        assert out.tolist() == [B, B], dark
        out, _ = _run(None, 0.0, dark=dark, with_b=True)
        assert out.tolist() == [A, A], dark  # the handover: A's early label on the next aircraft


def test_a_published_label_moving_far_keeps_it_unless_it_took_a_track():
    out, k = _run(REID_JUMP, 6000.0, dark=0)  # no other track: the label's own track moved
    assert out.tolist() == [A]


def _reidentify(jump, offset):
    """A published on scans 1-4, lost (nothing left) for 3 scans, a new stamp at scan 8
    ``offset`` metres north of A's prediction with a wide covariance (the chi-square gate
    passes at every offset here)."""
    reid = Reidentification(CV, OWN, scans=9, jump=jump)
    x0 = [0.0, 80.0, 0.0, 10.0]
    for k in range(1, 5):
        reid.apply(np.array([A]), _mix(_state(x0, k), [0.9]), 0.5, k)
    for k in range(5, 8):
        reid.apply(np.zeros((0, 3), dtype=np.int64), _mix(np.zeros((0, 4)), []), 0.5, k)
    new = [OWN, 8, PUBLISHED_BASE]
    x = _state(x0, 8) + [0.0, 0.0, offset, 0.0]
    return reid.apply(np.array([new]), _mix(x, [0.9], var=VAR), 0.5, 8).tolist(), new


def test_reidentification_keeps_to_the_bound():
    for offset in (0.0, 1000.0, 2900.0, 3100.0, 5000.0):
        F = np.linalg.matrix_power(CV.F, 4)  # the reference: the prediction by matrix power
        pred = F @ np.linalg.matrix_power(CV.F, 3) @ np.array([0.0, 80.0, 0.0, 10.0])
        x = np.linalg.matrix_power(CV.F, 7) @ np.array([0.0, 80.0, 0.0, 10.0]) + [0, 0, offset, 0]
        near = np.hypot(*(x - pred)[[0, 2]]) <= REID_JUMP
        out, new = _reidentify(REID_JUMP, offset)
        assert out == [A if near else new], offset
        assert _reidentify(None, offset)[0] == [A]


def test_jump_must_be_positive():
    with pytest.raises(ValueError, match="jump"):
        Reidentification(CV, OWN, jump=0.0)


def test_a_label_back_after_the_memory_forgot_every_label_is_no_error():
    """A label published, then dark longer than the memory (which is left empty), then back:
    the distance bound has nothing to test against and leaves it (a frozen peer's catch-up hit
    an IndexError here: tests/test_catch_up.py)."""
    reid = Reidentification(CV, OWN, scans=2, jump=REID_JUMP)
    x = [0.0, 60.0, 0.0, 0.0]
    reid.apply(np.array([A]), _mix([_state(x, 1)], [0.9]), 0.5, 1)
    for k in range(2, 7):
        reid.apply(np.zeros((0, 3), np.int64), _mix(np.zeros((0, 4)), []), 0.5, k)
    out = reid.apply(np.array([A]), _mix([_state(x, 7)], [0.9]), 0.5, 7)
    assert len(out) == 1
