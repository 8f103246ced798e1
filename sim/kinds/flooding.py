"""Flooding peers (seed 004): every peer floods its scans for ``network.rounds`` iterations and
estimates from the pooled scans by density-peaks clustering (IDPC), DBSCAN + k-means (FTC) or
the iterated-corrector GM-PHD (IC) (``[clustering]`` table)."""

from __future__ import annotations

import zlib

import numpy as np
from sensornet.peers.flood_parts import ScanBound, poisson_bound
from sensornet.peers.flooding import (
    FloodEstimator,
    FloodFuser,
    IcFloodEstimator,
    IcFloodFuser,
    corrector_order,
)
from sensornet.peers.labelling import origin_of
from sensornet.peers.point_ids import EXTRACTED, PointIds
from sensornet.sim.kinds import PeerKind
from sensornet.sim.scenario import FUSION_RULES, Scenario
from sensornet.sim.world.build import adjacency, make_filter, measurement_box, sensor_model
from sensornet.tracking.idpc import ClusterParams

MARGIN_SIGMAS = 6.0
"""A target's return may fall this many noise standard deviations outside the sensor's field."""


def scan_bounds(scn: Scenario) -> dict[str, ScanBound]:
    """Per sensor, what its scans can plausibly hold (:class:`peers.flood_parts.ScanBound`):
    returns inside its measurement box widened by :data:`MARGIN_SIGMAS` noise deviations, and
    at most the Poisson(clutter rate + the scenario's target count) bound at tail 1e-9."""
    out = {}
    for s in scn.sensors:
        low, high = measurement_box(scn, s)
        pad = MARGIN_SIGMAS * np.array([s.sigma_r, s.sigma_r] if s.kind == "linear"
                                       else [s.sigma_r, s.sigma_theta])
        out[s.name] = ScanBound(tuple(map(float, low - pad)), tuple(map(float, high + pad)),
                                poisson_bound(s.clutter_rate + len(scn.targets)))
    return out


def build(scn: Scenario, name: str, run: int = 0):
    est, fuser = _parts(scn, name, run)
    est.point_tracks = PointIds(origin_of(scn.sensor_names, name), EXTRACTED,
                                est.position_index)
    return est, fuser


def _parts(scn: Scenario, name: str, run: int):
    net, c = scn.network, scn.clustering
    bounds = scan_bounds(scn)
    if c.estimator == "ic":  # the iterated-corrector GM-PHD over the pooled scans
        names, A = adjacency(scn)
        order = [names[i] for i in corrector_order(A)]
        est = IcFloodEstimator(name, make_filter(scn, order), order)
        return est, IcFloodFuser(name, scn.sensor_names, net.rounds, est, bounds)
    pds = {s.detection_probability for s in scn.sensors}
    params = ClusterParams(c.cutoff, c.zeta, c.radius_factor, c.split_factor,
                           detection_probability=float(np.mean(sorted(pds))))
    roster = {s.name: sensor_model(s) for s in scn.sensors}
    est = FloodEstimator(name, roster, params, c.assumed_scans,
                         seed=zlib.crc32(f"{scn.seed}/{run}".encode()), method=c.estimator)
    return est, FloodFuser(name, scn.sensor_names, net.rounds, bounds)


FLOODING = PeerKind("flooding", "scans flooded over the graph, clustered per peer (seed 004)",
                    build, FUSION_RULES, same_scan=True,  # fusion.rule: not used
                    round_deadlines=True, trust=False)
