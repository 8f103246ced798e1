"""``fusion.label_hold`` (issue 34, tracking.held_ids): a young fused label does not replace the
id a peer reported a target under a scan or two before. By hand on :class:`HeldIds` (the
paris-8 case traced: aircraft 4401d1 at ticks 319-321), and the option's wiring."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.run.peers import consensus_options
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.held_ids import HeldIds

OLD = [0, 315, 7]
"""The aircraft's label, three radars' own tracks (its AA weight 0.3-0.5)."""
NEW = [0, 321, 9]
"""A label born at 321 from two far radars' one-plot tracks, pooled to 0.55."""


def _cov(sd: float) -> np.ndarray:
    return np.diag([sd**2, 50.0**2, sd**2, 50.0**2])


def _state(x: float, y: float) -> np.ndarray:
    return np.array([x, 200.0, y, 0.0])


def _scan(held: HeldIds | None, k: int, rows: list, fused: list) -> np.ndarray:
    """Reported ids at ``k`` of extracted ``rows`` ``[(label, state, sd)]``, the fused density
    ``fused`` ``[(label, state, sd)]`` (every row of it, extracted or not)."""
    ids = np.array([r[0] for r in rows], dtype=np.int64).reshape(-1, 3)
    X = np.array([r[1] for r in rows]).reshape(-1, 4)
    P = np.array([_cov(r[2]) for r in rows]).reshape(-1, 4, 4)
    L = np.array([f[0] for f in fused], dtype=np.int64).reshape(-1, 3)
    M = np.array([f[1] for f in fused]).reshape(-1, 4)
    S = np.array([_cov(f[2]) for f in fused]).reshape(-1, 4, 4)
    return ids if held is None else held.ids(k, ids, X, P, L, M, S)


def _ticks(held: HeldIds | None, gap: int = 1) -> list[list[tuple]]:
    """Ticks 319..322 of the traced case: OLD reported at 319, extracted at no tick after
    (its AA weight below the threshold); at 319 + gap + 1 the new row NEW, 500 m from OLD's
    fused row, is reported, and a scan later again."""
    out = []
    old_row = (OLD, _state(0.0, 0.0), 400.0)
    out.append(_scan(held, 319, [old_row], [old_row]).tolist())
    for k in range(320, 319 + gap + 1):
        out.append(_scan(held, k, [], [old_row]).tolist())
    new_row = (NEW, _state(500.0, 0.0), 300.0)
    k = 320 + gap
    out.append(_scan(held, k, [new_row], [old_row, new_row]).tolist())
    out.append(_scan(held, k + 1, [(NEW, _state(900.0, 0.0), 250.0)],
                     [(OLD, _state(400.0, 0.0), 400.0), (NEW, _state(900.0, 0.0), 250.0)]
                     ).tolist())
    return out


def test_the_traced_case_switches_without_the_rule_and_not_with_it():
    """Without the rule the aircraft is reported under OLD, then under NEW (a switch); with
    it (memory 3 scans: OLD reported 2 scans before) under OLD throughout."""
    off = _ticks(None)
    on = _ticks(HeldIds(memory=3, young=2))
    assert off == [[OLD], [], [NEW], [NEW]]
    assert on == [[OLD], [], [OLD], [OLD]]


def test_a_label_not_reported_for_longer_than_the_memory_is_not_taken():
    """OLD last reported 4 scans before NEW comes: memory 3 lets NEW stand, memory 4 not
    (and the row keeps OLD a scan later, when NEW is no longer young, as OLD is not
    reported under its own label)."""
    assert _ticks(HeldIds(memory=3, young=2), gap=3)[-2:] == [[NEW], [NEW]]
    assert _ticks(HeldIds(memory=4, young=2), gap=3)[-2:] == [[OLD], [OLD]]


def test_only_young_rows_beside_an_unreported_earlier_label_take_it():
    """Each condition alone keeps the row's own label: the remembered label is reported this
    scan (a second aircraft), its row is outside the gate (30 km away), the row's label is
    older than ``young``, or the remembered label was born after the row's."""
    old_row = (OLD, _state(0.0, 0.0), 400.0)
    new_row = (NEW, _state(500.0, 0.0), 300.0)

    def run(rows: list, fused: list, k: int = 321, young: int = 2) -> list:
        h = HeldIds(memory=3, young=young)
        _scan(h, 319, [old_row], [old_row])
        return _scan(h, k, rows, fused).tolist()

    assert run([new_row], [old_row, new_row]) == [OLD]  # all conditions met
    assert run([old_row, new_row], [old_row, new_row]) == [OLD, NEW]
    far = (NEW, _state(30000.0, 0.0), 300.0)
    assert run([far], [old_row, far]) == [NEW]
    assert run([new_row], [old_row, new_row], k=324) == [NEW]  # NEW 3 scans old, young 2
    late = ([0, 320, 1], _state(0.0, 0.0), 400.0)
    h = HeldIds(memory=3, young=2)
    _scan(h, 319, [late], [late])
    assert _scan(h, 321, [([0, 319, 9], _state(500.0, 0.0), 300.0)],
                 [late, ([0, 319, 9], _state(500.0, 0.0), 300.0)]).tolist() == [[0, 319, 9]]


def test_two_young_rows_beside_one_label_one_takes_it():
    """Two young rows within the gate of one remembered label: the nearer takes it (an
    assignment: one id, one row)."""
    h = HeldIds(memory=3, young=2)
    old_row = (OLD, _state(0.0, 0.0), 400.0)
    _scan(h, 319, [old_row], [old_row])
    a = (NEW, _state(300.0, 0.0), 300.0)
    b = ([0, 321, 10], _state(-900.0, 0.0), 300.0)
    assert _scan(h, 321, [a, b], [old_row, a, b]).tolist() == [OLD, [0, 321, 10]]


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="memory"):
        HeldIds(memory=0)
    with pytest.raises(ValueError, match="gate"):
        HeldIds(gate=np.inf)


def test_the_option_reaches_the_peers():
    """``fusion.label_hold`` (0, off, by default) is each peer's ``label_hold``."""
    for v in (0, 3):
        scn = load_scenario("seed000", overrides={"network.filter": "lmb",
                                                  "fusion.label_hold": v})
        assert consensus_options(scn, scn.sensor_names[0]).label_hold == v
    assert load_scenario("seed000").fusion.label_hold == 0
