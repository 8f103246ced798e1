"""Single-target IMM peers (seed 001): an IMM particle filter or IMM-EKF on one radar, fused by
GCI or the particle ratio rule (:class:`peers.fusers.ImmFuser`)."""

from __future__ import annotations

import zlib

import numpy as np
from sensornet.peers.estimators import ImmEstimator, SingleTargetConfig
from sensornet.peers.fusers import ImmFuser, NoFuser
from sensornet.peers.labelling import origin_of
from sensornet.peers.point_ids import PointIds, single_target
from sensornet.sim.kinds import PeerKind, View
from sensornet.sim.scenario import Scenario
from sensornet.sim.world import initial_state
from sensornet.sim.world.build import sensor_model


def _builder(filter_name: str):
    def build(scn: Scenario, name: str, run: int = 0):
        rule = scn.fusion.rule
        cfg = SingleTargetConfig()
        x0, cov = initial_state(scn)
        rng = np.random.default_rng(np.random.SeedSequence([scn.seed, run,
                                                            zlib.crc32(name.encode())]))
        m0 = x0 + rng.standard_normal(len(x0)) @ np.linalg.cholesky(cov).T
        rng_local, rng_fused = rng.spawn(2)
        est = ImmEstimator(filter_name, cfg.imm, cfg.particle, sensor_model(scn.sensor(name)),
                           m0, cov, rng_local, cfg.cov_floor, with_prediction=rule == "ratio")
        est.point_tracks = PointIds(origin_of(scn.sensor_names, name),
                                    single_target(rule != "none"), est.position_index)
        if rule == "none":
            return est, NoFuser()
        return est, ImmFuser(rule, est, m0, cov, rng_fused, cfg.gci_omega, cfg.ratio)
    return build


RULES = ("gci", "ratio", "none")
IMM_PF = PeerKind("imm-pf", "IMM particle filter on one radar, one target (seed 001)",
                  _builder("imm-pf"), RULES, same_scan=True,
                  view=View(single_target=True, imm=True))
IMM_EKF = PeerKind("imm-ekf", "IMM-EKF on one radar, one target (seed 001)",
                   _builder("imm-ekf"), RULES, same_scan=True,
                   view=View(single_target=True, imm=True))
