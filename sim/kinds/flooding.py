"""Flooding peers (seed 004): every peer floods its scans for ``network.rounds`` iterations and
estimates from the pooled scans by density-peaks clustering (IDPC), DBSCAN + k-means (FTC) or
the iterated-corrector GM-PHD (IC) (``[clustering]`` table)."""

from __future__ import annotations

import zlib

import numpy as np

from peers.flooding import (
    FloodEstimator,
    FloodFuser,
    IcFloodEstimator,
    IcFloodFuser,
    corrector_order,
)
from sim.build import adjacency, make_filter, sensor_model
from sim.kinds import PeerKind
from sim.scenario import FUSION_RULES, Scenario
from tracking.idpc import ClusterParams


def build(scn: Scenario, name: str, run: int = 0):
    net, c = scn.network, scn.clustering
    if c.estimator == "ic":  # the iterated-corrector GM-PHD over the pooled scans
        names, A = adjacency(scn)
        order = [names[i] for i in corrector_order(A)]
        est = IcFloodEstimator(name, make_filter(scn, order), order)
        return est, IcFloodFuser(name, scn.sensor_names, net.rounds, est)
    pds = {s.detection_probability for s in scn.sensors}
    params = ClusterParams(c.cutoff, c.zeta, c.radius_factor, c.split_factor,
                           detection_probability=float(np.mean(sorted(pds))))
    roster = {s.name: sensor_model(s) for s in scn.sensors}
    est = FloodEstimator(name, roster, params, c.assumed_scans,
                         seed=zlib.crc32(f"{scn.seed}/{run}".encode()), method=c.estimator)
    return est, FloodFuser(name, scn.sensor_names, net.rounds)


FLOODING = PeerKind("flooding", "scans flooded over the graph, clustered per peer (seed 004)",
                    build, FUSION_RULES, same_scan=True,  # fusion.rule: not used
                    round_deadlines=True, trust=False)
