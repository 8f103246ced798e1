"""The manoeuvring single-target truths of seeds 001 and 003, as :mod:`sim.truths` models."""

from __future__ import annotations

import numpy as np
from sensornet.sim.scenario import Scenario, pda_tables
from sensornet.sim.studies.seed001.montecarlo import Seed001Scenario, truth
from sensornet.sim.studies.seed003 import montecarlo as seed003
from sensornet.sim.studies.seed003 import network as seed003_net
from sensornet.sim.truths import TruthModel
from sensornet.sim.world import Truth


def _one_target(X: np.ndarray, num_scans: int, what: str) -> Truth:
    """``X (K + 1, d)`` (``X[k]`` at scan ``k``) as a one-target :class:`Truth` of ``num_scans``."""
    if num_scans > len(X) - 1:
        raise ValueError(f"the {what} trajectory has {len(X) - 1} scans, not {num_scans}")
    return Truth(states=[X[k][None, :] for k in range(1, num_scans + 1)],
                 ids=[np.array([1]) for _ in range(num_scans)])


def _seed001(scn: Scenario):
    return Seed001Scenario.of(scn)


def seed001_truth(scn: Scenario, rng=None) -> Truth:
    """The seed-001 ground target (6-D ``[px, vx, ax, py, vy, ay]``, constant-turn legs)."""
    return _one_target(truth(_seed001(scn)), scn.num_scans, "seed-001")


def seed001_initial(scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """The true state at time 0 and seed 001's initial spread."""
    s1 = _seed001(scn)
    return truth(s1)[0], s1.init_cov


SEED001 = TruthModel("seed001", "seed 001's manoeuvring ground target (one target, 6-D)",
                     seed001_truth, initial=seed001_initial)


def seed003_truth(scn: Scenario, rng=None) -> Truth:
    """The seed-003 target: straight, a coordinated 90-degree turn, straight (6-D)."""
    return _one_target(seed003.truth(pda_tables(scn)), scn.num_scans, "seed-003")


def seed003_run(scn: Scenario, run: int):
    """Seed 003 draws its returns itself (the offline study's draws, so the peers see what
    the published table's filters see): the target's return first, then region clutter."""
    return seed003_net.run_data(pda_tables(scn), run)


SEED003 = TruthModel("seed003", "seed 003's manoeuvring target in dense clutter (one target)",
                     seed003_truth, run=seed003_run)
