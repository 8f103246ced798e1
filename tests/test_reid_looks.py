"""GM-PHD re-identification remembered in looks of the peer's radar, not in scans (issue 34):
a 10 s radar at a 2 s tick looks once in 5 scans, so 3 scans forgot a lost track before the
radar could see its aircraft again."""

import numpy as np
import pytest
from sensornet.sim.kinds.gmphd import build, revisit_scans
from sensornet.sim.scenario import load_scenario
from sensornet.tracking.label_keys import PUBLISHED_BASE
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.models import ConstantVelocity
from sensornet.tracking.reidentify import REID_SCANS, Reidentification

CV = ConstantVelocity(T=2.0, sigma_w=10.0)


def _at(k):
    """One aircraft flying east at 150 m/s, seen at scan ``k`` (a tight component)."""
    m = np.array([[300.0 * k, 150.0, 0.0, 0.0]])
    return GaussianMixture(np.array([0.9]), m, np.diag([100.0**2, 20.0**2] * 2)[None])


@pytest.mark.parametrize(("scans", "back"), [(REID_SCANS, False), (REID_SCANS * 5, True)])
def test_a_track_lost_for_two_looks_of_a_10s_radar_gets_its_label_back_only_in_looks(
        scans, back):
    reid = Reidentification(CV, origin=2, scans=scans)
    old = np.array([[2, 1, PUBLISHED_BASE]])
    for k in range(1, 6):  # published 5 scans in a row
        assert reid.apply(old, _at(k), 0.5, k).tolist() == old.tolist()
    for k in range(6, 15):  # two missed looks: nothing published
        reid.apply(np.zeros((0, 3), np.int64), GaussianMixture.empty(4), 0.5, k)
    new = np.array([[2, 15, PUBLISHED_BASE]])  # re-born and stamped new at scan 15
    got = reid.apply(new, _at(15), 0.5, 15)
    assert got.tolist() == (old if back else new).tolist()


def test_paris8_gmphd_peers_remember_three_looks():
    scn = load_scenario("paris-8")
    for n in scn.sensor_names:
        assert build(scn, n)[0].reid.scans == REID_SCANS * revisit_scans(scn, n)
