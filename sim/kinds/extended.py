"""ET-GM-PHD peers (seed 002): extended targets, the GM-PHD's mixtures and fusers."""

from __future__ import annotations

from sensornet.peers.extended import EtGmphdEstimator
from sensornet.peers.labelling import origin_of
from sensornet.peers.point_ids import EXTRACTED, PointIds
from sensornet.sim.kinds import PeerKind
from sensornet.sim.kinds.gmphd import MIXTURE_RULES, mixture_fuser
from sensornet.sim.scenario import Scenario
from sensornet.sim.world.extended import make_et_filter


def build(scn: Scenario, name: str, run: int = 0):
    filt = make_et_filter(scn, name)
    est = EtGmphdEstimator(filt, scn.fusion.level2_pruning, scn.fusion.level2_threshold)
    est.point_tracks = PointIds(origin_of(scn.sensor_names, name), EXTRACTED, est.position_index)
    return est, mixture_fuser(scn, filt.reducer)


def check(scn: Scenario) -> str | None:
    if scn.extended is None:
        return ("network.filter", "key 'network.filter' is 'et-gmphd', which needs an "
                "[extended] table")
    return None


ET_GMPHD = PeerKind("et-gmphd", "extended-target GM-PHD per sensor (seed 002)", build,
                    MIXTURE_RULES, check=check)
