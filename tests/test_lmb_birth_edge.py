"""Stamps of plots near a cell edge take the next scan (issue 33, docs/labelled-tracking.md,
"Stamps near a cell edge"): an LMB peer's shared adaptive-birth label names the 200 m cell of
its plot, and a target's first plots at different peers fall in two cells when it is near an
edge; the lowest cell index won and spread, often a cell one peer held. With
``lmb.birth_edge`` a birth whose plot lies near an edge is flagged and stamped a scan later at
its first publication, so it loses the tie to a stamp of a plot well inside a cell."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.lmb_estimator import PUBLISHED_BASE as PB
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.sim.kinds.lmb import build
from sensornet.sim.scenario import load_scenario
from sensornet.sim.world.build import sensor_params
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import SHARED_ORIGIN as S
from sensornet.tracking.label_keys import cell_index
from sensornet.tracking.lmb import EDGE_FLAG, LmbFilter
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity, LinearPosition

from tests.lmb_pair import run_pair


def _filter(origin: int, edge: float) -> LmbFilter:
    return LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(5.0), 0.99, 2.5e-7),
                     origin=origin, shared_origin=S, birth_edge=edge)


def test_births_near_an_edge_are_flagged():
    plots = np.array([[190.0, 100.0], [500.0, 500.0], [100.0, 385.0], [230.0, 100.0]])
    pend = GaussianMixture(np.full(4, 0.1), np.column_stack((plots[:, 0], np.zeros(4),
                                                             plots[:, 1], np.zeros(4))),
                           np.tile(np.eye(4), (4, 1, 1)))
    cells = cell_index(plots, 200.0)
    flagged = _filter(1, 20.0)._shared_labels(pend, 5)
    np.testing.assert_array_equal(flagged[:, 2] - cells, [EDGE_FLAG, 0, EDGE_FLAG, 0])
    np.testing.assert_array_equal(_filter(1, 0.0)._shared_labels(pend, 5)[:, 2], cells)
    with pytest.raises(ValueError, match="birth_edge"):
        _filter(1, 100.0)


def _run(edge: float, scans: int = 6) -> dict[int, list[tuple]]:
    """Peers 1 (``a``) and 2 (``b``) see one target from scan 1 (``x = 210 + k``), with biases
    of +11 and -12 m: ``a``'s first plot lies 22 m inside the cell ``x`` in [200, 400), ``b``'s
    1 m across its lower edge (cell [0, 200), the lower index). One fusion round a scan between
    the two, as the consensus runs it. Returns the label each published, per scan."""
    a, b = (LmbEstimator(_filter(o, edge), origin=o, tentative_threshold=0.15) for o in (1, 2))
    return run_pair(a, b, lambda k: ([[210.0 + k + 11.0, 100.0]], [[210.0 + k - 12.0, 100.0]]),
                    scans)


def test_a_stamp_across_an_edge_yields_to_one_well_inside():
    inside = int(cell_index(np.array([[222.0, 100.0]]), 200.0)[0])
    across = int(cell_index(np.array([[199.0, 100.0]]), 200.0)[0])
    assert across < inside  # without the flag the stamp across the edge wins the tie
    seen = _run(20.0)
    assert set(seen[1]) == {(S, 2, PB + inside)}  # a's id never changes
    assert seen[2][0] == (S, 3, PB + across) and set(seen[2][1:]) == {(S, 2, PB + inside)}
    old = _run(0.0)
    assert old[1][0] == (S, 2, PB + inside) and set(old[1][1:]) == {(S, 2, PB + across)}
    assert set(old[2]) == {(S, 2, PB + across)}


def test_auto_is_the_sensors_noise_only_with_tentative_tracks_and_off_by_default():
    base = {"network.filter": "lmb"}

    def edge(over):
        est, _ = build(load_scenario("seed000", overrides={**base, **over}), "s1")
        return est.filter.birth_edge

    sd = float(np.sqrt(np.max(np.diag(sensor_params(load_scenario("seed000"), "s1").model.R))))
    auto = {"lmb.birth_edge": -1.0}
    assert edge(auto) == pytest.approx(sd) and sd > 0
    assert edge({**auto, "lmb.tentative_threshold": 0.0}) == 0.0
    assert edge({"lmb.birth_edge": 7.0}) == 7.0
    assert edge({}) == 0.0  # off by default
