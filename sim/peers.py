"""From a scenario to a peer: estimator, fuser, consensus, scorer and the sans-I/O core.

The one place where a scenario's ``[network]``, ``[fusion]`` and ``[filter]`` settings become a
:class:`peers.core.PeerCore`, so the Zenoh runtime, the twin and the experiments build the same
peer from the same file.
"""

from __future__ import annotations

import zlib
from dataclasses import replace

import numpy as np

from peers.consensus import Consensus, ConsensusOptions
from peers.core import CoreConfig, PeerCore
from peers.estimators import GmphdEstimator, ImmEstimator, SingleTargetConfig
from peers.fusers import AaFuser, GciFuser, HybridFuser, ImmFuser, NoFuser
from peers.scoring import Scorer
from peers.trust import TrustConfig
from sim.build import adjacency, make_filter, sensor_model
from sim.scenario import Scenario, ScenarioError
from sim.world import generate_truth, truth_rng


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
    single = net.filter not in ("gmphd", "et-gmphd")  # and flooding: scans of the same k only
    opts = ConsensusOptions(
        name=name,
        neighbours=tuple(names[j] for j in nb),
        degrees=tuple((names[j], int(deg[j])) for j in [i, *nb]),
        rounds=net.rounds,
        omega=net.omega if net.omega in ("metropolis", "uniform") else "metropolis",
        max_age=0 if single else net.max_age,
        policy="drop-late" if single else net.policy,
        feedback=net.feedback and not single,
        round_deadlines=net.filter == "flooding",
        trust=TrustConfig() if scn.fusion.trust and net.filter != "flooding" else None,
    )
    return replace(opts, **changes)


def truth_function(scn: Scenario, run: int):
    """``k -> (n, d)`` true states of scan ``k`` of run ``run`` (None outside the run): what
    the world will publish, regenerated from the scenario, so scoring needs no truth message."""
    states = generate_truth(scn, truth_rng(scn, run)).states

    def truth(k: int) -> np.ndarray | None:
        return np.asarray(states[k - 1]) if 1 <= k <= len(states) else None

    return truth


def make_parts(scn: Scenario, name: str, run: int = 0):
    """The estimator and fuser of sensor ``name``'s peer."""
    net, fus = scn.network, scn.fusion
    rule = fus.rule
    if net.filter == "flooding":  # seed 004: flood the scans, cluster the pooled set
        from peers.flooding import FloodEstimator, FloodFuser
        from tracking.idpc import ClusterParams

        c = scn.clustering
        if c.estimator == "ic":  # or run the iterated-corrector GM-PHD over it
            from peers.flooding import IcFloodEstimator, IcFloodFuser, corrector_order

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
    if net.filter in ("gmphd", "et-gmphd"):
        if rule == "ratio":
            raise ScenarioError(f"{scn.name}: fusion.rule 'ratio' needs single-target peers "
                                f"(network.filter 'imm-pf' or 'imm-ekf')")
        if net.filter == "et-gmphd":  # seed 002: extended targets, same mixtures and fusers
            from peers.extended import EtGmphdEstimator
            from sim.extended import make_et_filter

            filt = make_et_filter(scn, name)
            est = EtGmphdEstimator(filt, fus.level2_pruning, fus.level2_threshold)
        else:
            filt = make_filter(scn, [name])
            est = GmphdEstimator(filt, fus.level2_pruning, fus.level2_threshold)
        if rule == "gci":
            fuser = GciFuser(filt.reducer, fus.cardinality, net.omega)
        elif rule == "aa":
            fuser = AaFuser(filt.reducer)
        elif rule == "hybrid":
            fuser = HybridFuser(filt.reducer)
        else:
            fuser = NoFuser()
        return est, fuser
    if rule in ("aa", "hybrid"):
        raise ScenarioError(f"{scn.name}: single-target peers fuse by 'gci', 'ratio' or "
                            f"'none', not {rule!r}")
    from sim.seed001 import Seed001Scenario, truth

    cfg = SingleTargetConfig()
    s1 = Seed001Scenario(T=scn.scan_period, seed=scn.seed)
    rng = np.random.default_rng(np.random.SeedSequence([scn.seed, run,
                                                        zlib.crc32(name.encode())]))
    m0 = truth(s1)[0] + rng.standard_normal(6) @ np.linalg.cholesky(s1.init_cov).T
    rng_local, rng_fused = rng.spawn(2)
    est = ImmEstimator(net.filter, cfg.imm, cfg.particle, sensor_model(scn.sensor(name)), m0,
                       s1.init_cov, rng_local, cfg.cov_floor, with_prediction=rule == "ratio")
    if rule == "none":
        return est, NoFuser()
    return est, ImmFuser(rule, est, m0, s1.init_cov, rng_fused, cfg.gci_omega, cfg.ratio)


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
                     deadline=scn.network.deadline)
    return PeerCore(cfg, consensus, scorer)
