"""tracking.reidentify: a track stamped new within a few scans of a loss, inside the gate of
the lost track predicted forward, takes the lost label back; checked against the gate computed
by a loop (F^dt as a matrix power, Q_dt as the sum of F^t Q F^t^T) and, with several
candidates, against every assignment enumerated."""

from __future__ import annotations

import itertools

import numpy as np
from sensornet.tracking.labels import PUBLISHED_BASE
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity
from sensornet.tracking.reidentify import Reidentification

CV = ConstantVelocity(sigma_w=2.0)
OWN = 1


def _mix(means, w=None, var=25.0):
    means = np.asarray(means, float).reshape(-1, 4)
    n = len(means)
    return GaussianMixture(np.full(n, 0.9) if w is None else np.asarray(w, float), means,
                           np.tile(np.eye(4) * var, (n, 1, 1)))


def _new(k, i=0):
    return [OWN, k, PUBLISHED_BASE + i]


def reference_cost(m_new, P_new, m_old, P_old, dt):
    F = np.linalg.matrix_power(CV.F, dt)
    Q = sum(np.linalg.matrix_power(CV.F, t) @ CV.Q @ np.linalg.matrix_power(CV.F, t).T
            for t in range(dt))
    d = m_new - F @ m_old
    return float(d @ np.linalg.inv(P_new + F @ P_old @ F.T + Q) @ d)


def _lose(reid, old, x0, k_last, var=25.0):
    """Publish ``old`` at ``x0`` on scans 1..k_last (moving at its velocity)."""
    for k in range(1, k_last + 1):
        x = np.asarray(x0, float) + (k - 1) * np.array([x0[1], 0, x0[3], 0])
        reid.apply(np.array([old]), _mix(x, var=var), 0.5, k)
    return x


def test_a_reborn_track_takes_its_lost_label_inside_the_gate_only():
    old = [0, 1, PUBLISHED_BASE + 3]
    for dt, offset in itertools.product((1, 2, 3, 4), (0.0, 15.0, 25.0, 40.0)):
        reid = Reidentification(CV, OWN, scans=3, gate=26.0)
        x_last = _lose(reid, old, [0.0, 10.0, 0.0, -5.0], 3)
        k = 3 + dt
        for j in range(4, k):  # dark scans: only a light component left
            reid.apply(np.array([old]), _mix(x_last, w=[0.1]), 0.5, j)
        x_new = np.linalg.matrix_power(CV.F, dt) @ x_last + [offset, 0, offset, 0]
        out = reid.apply(np.array([_new(k)]), _mix(x_new), 0.5, k)
        cost = reference_cost(x_new, np.eye(4) * 25, x_last, np.eye(4) * 25, dt)
        back = dt <= 3 and cost <= 26.0
        assert out.tolist() == [old if back else _new(k)], (dt, offset, cost)
    # a track published for fewer than `age` scans in a row is not remembered
    reid = Reidentification(CV, OWN, age=3)
    x = _lose(reid, old, [0.0, 0.0, 0.0, 0.0], 2)
    assert reid.apply(np.array([_new(3)]), _mix(x), 0.5, 3).tolist() == [_new(3)]
    # a label replaced by another on its track (the network rule) is not a lost track
    reid = Reidentification(CV, OWN)
    x = _lose(reid, old, [0.0, 0.0, 0.0, 0.0], 3)
    won = [0, 0, PUBLISHED_BASE]
    reid.apply(np.array([won]), _mix(x), 0.5, 4)
    out = reid.apply(np.array([won, _new(5)]), _mix([x + 300, x]), 0.5, 5)
    assert out.tolist() == [won, _new(5)]
    # a label that is still published is never handed out again
    reid = Reidentification(CV, OWN)
    _lose(reid, old, [0.0, 0.0, 0.0, 0.0], 3)
    out = reid.apply(np.array([old, _new(4)]), _mix([[0, 0, 0, 0], [1, 0, 1, 0]]), 0.5, 4)
    assert out.tolist() == [old, _new(4)]


def test_only_labels_stamped_new_this_scan_are_reidentified_and_all_their_rows_change():
    old = [2, 1, PUBLISHED_BASE]
    reid = Reidentification(CV, OWN)
    x = _lose(reid, old, [0.0, 0.0, 0.0, 0.0], 3)
    net = [3, 4, PUBLISHED_BASE]  # a network label, not stamped here: left alone
    far = x + [500, 0, 0, 0]
    out = reid.apply(np.array([net, _new(4), _new(4)]), _mix([far, x, x], w=[0.9, 0.8, 0.2]),
                     0.5, 4)
    assert out.tolist() == [net, old, old]


def test_several_candidates_take_the_least_total_cost_assignment():
    rng = np.random.default_rng(5)
    for _ in range(30):
        reid = Reidentification(CV, OWN, scans=3, gate=26.0)
        lost = rng.uniform(-20, 20, (3, 4))
        labs = [[0, 1, PUBLISHED_BASE + i] for i in range(3)]
        for k in (1, 2, 3):
            reid.apply(np.array(labs), _mix(lost @ np.linalg.matrix_power(CV.F, k - 1).T), 0.5, k)
        lost = lost @ np.linalg.matrix_power(CV.F, 2).T  # as last published, scan 3
        reid.apply(np.zeros((0, 3), dtype=np.int64), GaussianMixture.empty(4), 0.5, 4)
        new = lost[rng.permutation(3)][:2] @ np.linalg.matrix_power(CV.F, 2).T \
            + rng.normal(0, 6, (2, 4))
        out = reid.apply(np.array([_new(5, 0), _new(5, 1)]), _mix(new), 0.5, 5)
        C = np.array([[reference_cost(n, np.eye(4) * 25, o, np.eye(4) * 25, 2) for o in lost]
                      for n in new])
        Cc = np.minimum(C, 26.0)
        best = min(itertools.permutations(range(3), 2), key=lambda p: Cc[0, p[0]] + Cc[1, p[1]])
        want = [labs[j] if C[i, j] <= 26.0 else _new(5, i) for i, j in enumerate(best)]
        assert out.tolist() == want
