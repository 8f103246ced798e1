"""From a scenario to a peer: estimator, fuser, consensus, scorer and the sans-I/O core.

The one place where a scenario's ``[network]``, ``[fusion]`` and ``[filter]`` settings become a
:class:`peers.core.PeerCore`, so the Zenoh runtime, the twin and the experiments build the same
peer from the same file.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from sensornet.peers.consensus import Consensus, ConsensusOptions
from sensornet.peers.core import CoreConfig, PeerCore
from sensornet.peers.labelling import settle_scans
from sensornet.peers.scoring import Scorer
from sensornet.peers.trust import TrustConfig
from sensornet.sim.kinds import kind_of
from sensornet.sim.run.lies import LyingCore, make_lie
from sensornet.sim.scenario import Scenario, ScenarioError
from sensornet.sim.world import generate_truth, truth_rng
from sensornet.sim.world.build import adjacency


def consensus_options(scn: Scenario, name: str, **changes) -> ConsensusOptions:
    """How the peer of sensor ``name`` exchanges and fuses, from the scenario's network."""
    names, A = adjacency(scn)
    if name not in names:
        raise ScenarioError(f"{scn.name}: no sensor named {name!r} "
                            f"(sensors: {', '.join(names)})")
    i = names.index(name)
    nb = np.flatnonzero(A[i])
    deg = A.sum(axis=1)
    net = scn.network
    kind = kind_of(scn)
    single = kind.same_scan  # fuse estimates of the scan at hand only
    opts = ConsensusOptions(
        name=name,
        neighbours=tuple(names[j] for j in nb),
        degrees=tuple((names[j], int(deg[j])) for j in [i, *nb]),
        rounds=net.rounds,
        omega=net.omega if net.omega in ("metropolis", "uniform") else "metropolis",
        max_age=0 if single else net.max_age,
        policy="drop-late" if single else net.policy,
        feedback=net.feedback and not single,
        round_deadlines=kind.round_deadlines,
        trust=(TrustConfig(detection_probability=min(
            scn.sensor(n).detection_probability for n in [name, *(names[j] for j in nb)]),
            register=scn.fusion.trust_register, repair=scn.fusion.trust_repair)
            if scn.fusion.trust and kind.trust else None),
        confirm_settle=settle_scans(A, i),
        support_inputs=scn.fusion.support,
        existence_prior=scn.fusion.existence_prior,
        existence_young=scn.fusion.existence_young,
        support_scans=scn.fusion.support_scans,
    )
    return replace(opts, **changes)


def truth_function(scn: Scenario, run: int):
    """``k -> (n, d)`` true states of scan ``k`` of run ``run`` (None outside the run): what
    the world will publish, regenerated from the scenario, so scoring needs no truth message."""
    gen = generate_truth(scn, truth_rng(scn, run))
    states, ids = gen.states, gen.ids

    def truth(k: int) -> np.ndarray | None:
        return np.asarray(states[k - 1]) if 1 <= k <= len(states) else None

    def truth_ids(k: int) -> np.ndarray | None:
        """The true target ids of scan ``k`` (rows of ``truth(k)``), for the results table."""
        return np.asarray(ids[k - 1]) if 1 <= k <= len(ids) else None

    truth.ids = truth_ids  # read by peers.scoring.Scorer.truth_ids
    return truth


def make_parts(scn: Scenario, name: str, run: int = 0):
    """The estimator and fuser of sensor ``name``'s peer, built by the scenario's peer kind
    (:mod:`sim.kinds`); :class:`ScenarioError` for a fusion rule the kind does not take (the
    loader refuses it first; this catches scenarios changed after loading)."""
    kind = kind_of(scn)
    if scn.fusion.rule not in kind.rules:
        raise ScenarioError(f"{scn.name}: fusion.rule {scn.fusion.rule!r} is not one that "
                            f"{kind.name!r} peers take ({', '.join(kind.rules)})")
    return kind.build(scn, name, run)


def make_peer(scn: Scenario, name: str, run: int = 0, *, network: str = "twin",
              speed: float | None = None, score_truth: bool = True, **changes) -> PeerCore:
    """The sans-I/O peer of sensor ``name`` for Monte Carlo run ``run`` on ``network``.

    ``speed``: scans per scan period (default the scenario's). ``changes`` override
    :class:`peers.consensus.ConsensusOptions` fields. ``score_truth``: score against the truth
    regenerated from the scenario (default); False scores against ``Truth`` messages instead.
    """
    est, fuser = make_parts(scn, name, run)
    consensus = Consensus(consensus_options(scn, name, **changes), est, fuser)
    scorer = Scorer(scn.metrics.ospa_cutoff, scn.metrics.ospa_order, est.position_index,
                    truth_function(scn, run) if score_truth else None)
    cfg = CoreConfig(name=name, sensor=name, network=network,
                     interval=scn.scan_period / (speed or scn.network.speed),
                     deadline=scn.network.deadline, last_scan=scn.num_scans)
    core = PeerCore(cfg, consensus, scorer)
    liar, _, lie = scn.fusion.lie.partition(":")
    if liar == name:  # the test hook fusion.lie (sim.studies.lying.study)
        core = LyingCore(core, make_lie(lie, scn, est.position_index))
    return core
