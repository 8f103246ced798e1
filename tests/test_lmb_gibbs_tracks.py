"""Auto association's bound on Gibbs sampling (tracking.lmb_association.GIBBS_TRACKS): a loopy
cluster beyond ``exact_limit`` with more tracks than ``gibbs_tracks`` keeps LBP's marginals
(no Gibbs call, so a host behind cannot pay 70-190 ms for one); up to it, or with None, Gibbs
as before; the filter and a host's stacked steps pass the setting on."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sensornet.tracking import lmb_association
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.lmb_association import (
    EXACT_LIMIT,
    GIBBS_TRACKS,
    hypothesis_count,
    marginals,
    marginals_lbp,
)
from sensornet.tracking.lmb_batch import step_many
from sensornet.tracking.models import ConstantVelocity, LinearPosition


def _ring(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``n`` tracks in a ring over ``n`` measurements, each linked strongly to 3 of them: one
    loopy cluster, nothing for the thinning to drop, beyond ``exact_limit``."""
    rng = np.random.default_rng(seed)
    miss = rng.uniform(0.3, 1.0, n)
    detect = np.zeros((n, n))
    for i in range(n):
        detect[i, [i, (i + 1) % n, (i + 2) % n]] = rng.uniform(0.5, 3.0, 3)
    return miss, detect


def _counting(monkeypatch) -> list[int]:
    calls: list[int] = []
    gibbs = lmb_association.marginals_gibbs

    def counted(miss, detect, *args, **kw):
        calls.append(detect.shape[0])
        return gibbs(miss, detect, *args, **kw)

    monkeypatch.setattr(lmb_association, "marginals_gibbs", counted)
    return calls


def test_a_cluster_beyond_gibbs_tracks_keeps_lbp_and_one_within_is_sampled(monkeypatch):
    calls = _counting(monkeypatch)
    n = GIBBS_TRACKS + 2
    miss, detect = _ring(n)
    assert hypothesis_count(n, n) > EXACT_LIMIT and 4.0**n > EXACT_LIMIT
    lm, lp = marginals_lbp(miss, detect)
    am, ap = marginals(miss, detect)  # the default bound
    assert calls == []
    np.testing.assert_allclose(am, lm, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ap, lp, rtol=1e-12, atol=1e-15)
    gm, gp = marginals(miss, detect, gibbs_tracks=None)  # no bound: Gibbs, as before
    assert calls == [n]
    assert np.abs(gm - lm).max() > 1e-4  # LBP is not Gibbs' answer here (the check can fail)
    wm, wp = marginals(miss, detect, gibbs_tracks=n)  # within the bound: Gibbs
    assert calls == [n, n]
    np.testing.assert_array_equal(wm, gm)
    np.testing.assert_array_equal(wp, gp)


def test_the_filter_and_a_hosts_stacked_steps_pass_gibbs_tracks_on(monkeypatch):
    """Two filters' steps on a scan whose tracks form one large cluster: with the default
    bound no Gibbs call, with ``gibbs_tracks=None`` one per step, own or stacked alike."""
    calls = _counting(monkeypatch)
    n = GIBBS_TRACKS + 4
    f = LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(10.0), 0.9, 1e-7),
                  adaptive_birth=True)
    xs = 15.0 * np.arange(n)  # tracks 15 m apart on a line, plots between them
    z0 = np.column_stack([xs, np.zeros(n)])
    state = f.step(f.initial(), z0, 0)
    for k in range(1, 4):  # existence up, so the tracks compete for the plots
        state = f.step(state, z0 + np.random.default_rng(k).normal(0, 2.0, z0.shape), k)
    z = z0 + np.array([7.5, 0.0])
    unbounded = dataclasses.replace(f, gibbs_tracks=None)
    calls.clear()
    f.step(state, z, 4)
    assert calls == []
    unbounded.step(state, z, 4)
    assert len(calls) == 1 and calls[0] > GIBBS_TRACKS
    calls.clear()
    g1, g2 = dataclasses.replace(f), dataclasses.replace(unbounded)
    got = step_many([g1, g2], [state, state], [z, z], [4, 4])
    assert all(r is not None for r in got)
    assert len(calls) == 1 and calls[0] > GIBBS_TRACKS  # only the unbounded problem's


def test_a_negative_gibbs_tracks_is_a_one_line_error():
    with pytest.raises(ValueError, match="gibbs_tracks must be >= 0 or None, got -1"):
        LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(10.0), 0.9, 1e-7),
                  gibbs_tracks=-1)
