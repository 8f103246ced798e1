"""LMB labels that stay uncorroborated keep moving (issue 33, docs/labelled-tracking.md,
"Uncorroborated LMB labels keep moving"): an own label that no neighbour's track was paired
with moves a scan later in each of the first ``corroborate_scans`` scans after its first
publication, so a track one peer alone published scans before the others (on 20 peers: a
clutter track at a birth point that then took the target's first plots) meets the others'
labels with their scan, not an earlier one, and the id most peers hold wins instead of
spreading one peer's early label over the graph."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.peers.lmb_estimator import PUBLISHED_BASE as PB
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.sim.kinds.lmb import LMB_CORROBORATE_SCANS, build, corroborate_scans
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.models import ConstantVelocity, LinearPosition

from tests.lmb_pair import run_pair


def _peer(origin: int, corroborate_scans: int) -> LmbEstimator:
    f = LmbFilter(ConstantVelocity(1.0, 2.0), SensorParams(LinearPosition(5.0), 0.99, 2.5e-7),
                  origin=origin)
    return LmbEstimator(f, origin=origin, tentative_threshold=0.15,
                        corroborate_scans=corroborate_scans)


def _run(corroborate_scans: int, b_from: int = 3, scans: int = 8) -> dict[int, list[tuple]]:
    """Peers 2 (``a``) and 1 (``b``): one target moving at 2 m/s along x, ``a`` sees it from
    scan 1, ``b`` from scan ``b_from`` on (so its track is born and first published a scan
    later). One fusion round a scan between the two, as the consensus runs it (labels of
    ``a``'s / ``b``'s published PHD, own first, with the estimator's fresh stamps). Returns
    the label each peer published for the target, per scan (from its first publication)."""
    a, b = _peer(2, corroborate_scans), _peer(1, corroborate_scans)

    def plots(k: int) -> tuple:
        x = np.array([[2.0 * k, 0.0]])
        return x, (x if k >= b_from else np.zeros((0, 2)))

    return run_pair(a, b, plots, scans)


def test_an_uncorroborated_label_moves_until_a_neighbour_holds_the_track():
    seen = _run(2)
    # a's track, first published (stamped) at scan 2 and alone until b's first publication at
    # scan 4, moved to scans 3 and 4 and then lost the tie to b's (origin 1 < 2): b's id never
    # changed, a's took it
    assert set(seen[1]) == {(1, 4, PB)}
    assert seen[2][:3] == [(2, 2, PB), (2, 3, PB), (2, 4, PB)]
    assert set(seen[2][3:]) == {(1, 4, PB)}


def test_with_one_move_only_the_early_label_takes_the_later_peers_track():
    seen = _run(1)
    # the rule before: a's label moved once, to scan 3, and beat b's of scan 4 at b
    assert seen[1][0] == (1, 4, PB) and set(seen[1][1:]) == {(2, 3, PB)}
    assert seen[2][0] == (2, 2, PB) and set(seen[2][1:]) == {(2, 3, PB)}


def test_the_moves_stop_after_corroborate_scans():
    # b first publishes at scan 5: a's label needs three moves (at scans 2, 3, 4) to tie
    for scans, winner in ((2, (2, 4, PB)), (3, (1, 5, PB))):
        seen = _run(scans, b_from=4)
        assert seen[1][0] == (1, 5, PB) and seen[2][-1] == seen[1][-1] == winner


def test_corroborate_scans_must_be_positive():
    with pytest.raises(ValueError, match="corroborate_scans"):
        _peer(1, 0)


def test_auto_moves_three_scans_only_with_tentative_tracks():
    base = {"network.filter": "lmb"}
    assert corroborate_scans(load_scenario("seed000", overrides=base)) == LMB_CORROBORATE_SCANS
    assert corroborate_scans(load_scenario(
        "seed000", overrides={**base, "lmb.tentative_threshold": 0.0})) == 1
    assert corroborate_scans(load_scenario(
        "seed000", overrides={**base, "lmb.corroborate_scans": 2})) == 2
    est, _ = build(load_scenario("seed000", overrides=base), "s1")
    assert est.corroborate_scans == LMB_CORROBORATE_SCANS
