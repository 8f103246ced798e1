"""sim.studies.traffic.gap_causes: the causes of OSPA(2)^p add up to it (ospa2_dense, the
independent reference), and a late start, a lingering track, a duplicate and a false track are
each charged to their own cause and visit."""

import numpy as np
import pytest
from sensornet.sim.studies.traffic.gap_causes import (
    CAUSES,
    attribute,
    decompose,
    load,
    save,
    truth_rows,
)
from sensornet.tracking.track_metrics import TrackTable, ospa2_dense

from tests.dense_tracks import random_dense

C, P, W = 1000.0, 2.0, 10


@pytest.mark.parametrize("seed", range(4))
def test_causes_add_up_to_ospa2_squared(seed):
    rng = np.random.default_rng(seed)
    E, Y = random_dense(rng, 30, 6, 0.3), random_dense(rng, 30, 4, 0.2)
    per_t, per_e, tot = attribute(E, Y, truth_rows(Y, E, C), C, P, W)
    ref = ospa2_dense(E, Y, C, P, W)
    np.testing.assert_allclose(tot, ref**2, rtol=1e-9, atol=1e-6)
    assert per_t.sum() + per_e.sum() == pytest.approx((ref**2).mean(), rel=1e-9)
    assert (per_t >= 0).all() and (per_e >= 0).all()


def _table(rows):
    s, i, x = zip(*rows, strict=True)
    return TrackTable(np.array(s), np.array(i), np.array(x, float))


def test_each_cause_is_charged_where_it_happened():
    T = 40
    grid = np.arange(1, T + 1)
    a = [(k, 0, (0.0, 0.0)) for k in grid]  # aircraft 0 all along
    b = [(k, 1, (50e3, 0.0)) for k in grid[:20]]  # aircraft 1 leaves at 20
    truth = _table(a + b)
    est = _table([(k, 10, (100.0, 0.0)) for k in grid[5:]]  # 0: 5 ticks late, 100 m off
                 + [(k, 11, (50e3, 0.0)) for k in grid[:25]]  # 1: lingers 5 ticks
                 + [(k, 12, (0.0, 300.0)) for k in grid[30:33]]  # a duplicate of 0
                 + [(k, 13, (-30e3, 0.0)) for k in grid[35:37]])  # a false track
    dec = decompose({"truth": truth, "e": est}, grid, C, P, W)
    per, ix = dec["e"]["per_visit"], {c: j for j, c in enumerate(CAUSES)}
    assert dec["e"]["first"].tolist() == [5, 0]
    assert per[0, ix["late"]] > 0 and per[1, ix["late"]] == 0
    assert per[0, ix["loc"]] > 0
    assert per[1, ix["linger"]] > 0 and per[0, ix["linger"]] == 0
    assert per[0, ix["dup"]] > 0 and per[1, ix["dup"]] == 0
    assert dec["e"]["false"] > 0
    assert per[:, ix["drop"]].sum() == per[:, ix["ident"]].sum() == 0
    total = per.sum() + dec["e"]["false"]
    assert total == pytest.approx(dec["e"]["msq"], rel=1e-12)


def test_tables_round_trip(tmp_path):
    t = {"truth": _table([(1, 0, (0.0, 1.0)), (2, 0, (0.5, 1.5))]),
         "fused:a": _table([(2, 7, (3.0, 4.0))])}
    save(str(tmp_path / "t.npz"), t)
    back = load(str(tmp_path / "t.npz"))
    assert list(back) == list(t)
    for n in t:
        for f in ("scan", "id", "pos"):
            np.testing.assert_array_equal(getattr(back[n], f), getattr(t[n], f))
