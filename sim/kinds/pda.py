"""Single-target PDA peers (seed 003): a PDA-family filter (PDAF, IMM-PDAF, fuzzy PDA, fuzzy
IMM) per position sensor in dense clutter, sharing measurements (the sequential update) or
estimates (covariance intersection) by ``pda.mode``."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from sensornet.peers.labelling import origin_of
from sensornet.peers.pda_parts import CiFuser, PdaEstimator, SequentialFuser, SequentialPdaEstimator
from sensornet.peers.point_ids import PointIds, single_target
from sensornet.sim.kinds import PeerKind, View
from sensornet.sim.kinds.pda_filters import initial_state, make_filter
from sensornet.sim.scenario import FUSION_RULES, Scenario, pda_tables
from sensornet.sim.world import seed003 as world
from sensornet.tracking.imm import POS

MODES = ("meas", "ci")
METHOD = "fuzzy IMM"
"""The peers' filter (the paper's; with the detector silent it is the IMM-PDAF)."""
PREGATE = 4.0
"""Measurement sharing publishes the returns inside ``PREGATE`` x the gate threshold of the
predicted estimate: a later sensor's gate (on the estimate after the earlier sensors' update)
lies inside it unless that update moved the estimate by more than a gate's size."""


def draws(cfg: Mapping, run: int):
    """Truth ``(K + 1, 6)``, sensors, target returns, region clutter and the initial estimate
    of run ``run`` (the draws of :func:`sim.studies.seed003.peers.run_once`)."""
    rng = np.random.default_rng([int(cfg["scenario"]["seed"]), int(run)])
    X = world.truth(cfg)
    sens = world.sensors(cfg)
    target = world.target_returns(X, sens, rng)
    m0, P0 = initial_state(cfg, X[0], rng)
    region = world.region_clutter(cfg, X, sens, rng)
    return X, sens, target, region, m0, P0


def make_parts(cfg: Mapping, name: str, mode: str, run: int = 0, *, method: str = METHOD,
               pregate: float = PREGATE):
    """The estimator and fuser of the PDA peer of sensor ``name`` in ``mode``, from the run's
    one initial estimate (every peer starts from it)."""
    names = [s["name"] for s in cfg["sensors"]]
    if name not in names:
        raise ValueError(f"seed003: no sensor named {name!r} (sensors: {', '.join(names)})")
    _, sens, _, _, m0, P0 = draws(cfg, run)
    by_name = dict(zip(names, sens, strict=True))
    filt = make_filter(cfg, method, m0, P0)
    if mode == "meas":
        est = SequentialPdaEstimator(filt, by_name, names, name, POS, pregate)
        return est, SequentialFuser(est)
    if mode == "ci":
        return PdaEstimator(filt, by_name[name], POS, feedback=False), CiFuser()
    raise ValueError(f"seed003: unknown peer mode {mode!r}; expected one of {MODES}")


def build(scn: Scenario, name: str, run: int = 0):
    p = scn.pda
    est, fuser = make_parts(pda_tables(scn), name, p.mode, run, method=p.method,
                            pregate=p.pregate)
    est.point_tracks = PointIds(origin_of(scn.sensor_names, name), single_target(True),
                                est.position_index)
    return est, fuser


def check(scn: Scenario):
    if scn.pda is None:
        return ("network.filter", "key 'network.filter' is 'pda', which needs the seed-003 "
                "tables ([scenario] study = \"seed003\": sim/scenarios/seed003.toml)")
    return None


PDA = PeerKind("pda", "PDA-family filter per position sensor, one target in clutter (seed 003)",
               build, FUSION_RULES, same_scan=True, trust=False,  # pda.mode decides the fusion
               view=View(single_target=True), check=check)
