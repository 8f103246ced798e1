"""sim.studies.traffic.ospa2_parts: OSPA(2)'s localisation, gap and cardinality parts add up
to OSPA(2)^p as tracking.track_metrics.ospa2_dense computes it (the independent reference)."""

import numpy as np
import pytest
from sensornet.sim.studies.traffic.ospa2_parts import ospa2_parts, ospa2_parts_dense, summary
from sensornet.tracking.track_metrics import TrackTable, ospa2_dense

from tests.dense_tracks import random_dense


@pytest.mark.parametrize("seed", range(5))
def test_parts_add_up_to_ospa2_of_the_reference(seed):
    rng = np.random.default_rng(seed)
    E, Y = random_dense(rng, 30, 5, 0.3), random_dense(rng, 30, 4, 0.2)
    parts = ospa2_parts_dense(E, Y, 1000.0, 2.0, 10)
    ref = ospa2_dense(E, Y, 1000.0, 2.0, 10)
    np.testing.assert_allclose(parts[:, 4], ref, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(parts[:, :4].sum(axis=1), ref**2, rtol=1e-9, atol=1e-6)
    assert (parts[:, :4] >= 0).all()
    assert not (parts[:, 2] * parts[:, 3]).any()  # missing and extra never both


def test_a_switch_is_charged_to_the_track_count_and_an_offset_to_localisation():
    T = 10
    truth = TrackTable(np.arange(1, T + 1), np.zeros(T, int), np.zeros((T, 2)))
    off = TrackTable(np.arange(1, T + 1), np.zeros(T, int), np.full((T, 2), 100.0))
    sw = TrackTable(np.arange(1, T + 1), (np.arange(T) >= 5).astype(int), np.zeros((T, 2)))
    grid = np.arange(1, T + 1)
    a = summary(ospa2_parts(truth, off, grid, 1000.0, 2.0, 10), 2.0)
    assert a["loc"] == pytest.approx(1.0) and a["missing"] == a["extra"] == 0.0
    b = ospa2_parts(truth, sw, grid, 1000.0, 2.0, 10)
    # the last window holds both ids: one pair half present (gap), one id without partner
    assert b[-1, 3] == pytest.approx(1000.0**2 / 2) and b[-1, 2] == 0.0
    assert b[-1, 1] == pytest.approx(500.0**2 / 2)
    assert b[:5, :4].sum() == 0.0


def test_chunked_equals_whole():
    rng = np.random.default_rng(7)
    T = 50
    rows = [(k, i, rng.normal(0, 500, 2)) for k in range(1, T + 1) for i in range(4)
            if rng.random() < 0.8]
    est = TrackTable(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                     np.array([r[2] for r in rows]))
    truth = TrackTable(np.repeat(np.arange(1, T + 1), 2), np.tile([0, 1], T),
                       rng.normal(0, 500, (2 * T, 2)))
    grid = np.arange(1, T + 1)
    whole = ospa2_parts(truth, est, grid, 1000.0, 2.0, 10, chunk=T)
    np.testing.assert_allclose(ospa2_parts(truth, est, grid, 1000.0, 2.0, 10, chunk=7), whole)
