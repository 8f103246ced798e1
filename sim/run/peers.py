"""From a scenario to a peer: estimator, fuser, consensus, scorer and the sans-I/O core.

The one place where a scenario's ``[network]``, ``[fusion]`` and ``[filter]`` settings become a
:class:`peers.core.PeerCore`, so the Zenoh runtime, the twin and the experiments build the same
peer from the same file.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from sensornet.peers.consensus import Consensus, ConsensusOptions
from sensornet.peers.core import CoreConfig, PeerCore
from sensornet.peers.label_support import reach_by_name
from sensornet.peers.labelling import origin_of, settle_scans
from sensornet.peers.scoring import Scorer
from sensornet.peers.trust import TrustConfig
from sensornet.sim.kinds import kind_of
from sensornet.sim.kinds.lmb import adopt_states as lmb_adopt_states
from sensornet.sim.run.lies import LyingCore, make_lie
from sensornet.sim.scenario import Scenario, ScenarioError
from sensornet.sim.world import generate_truth, truth_rng
from sensornet.sim.world.build import adjacency, clutter_intensity, sweep_fraction
from sensornet.tracking.support import MAJORITY


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
        feedback=(net.feedback or (net.filter == "lmb" and lmb_adopt_states(scn, name) > 0))
        and not single,  # an LMB peer's feedback of states (sim.kinds.lmb.adopt_states)
        round_deadlines=kind.round_deadlines,
        trust=(trust_config(scn, [name, *(names[j] for j in nb)], kind.view.single_target)
               if scn.fusion.trust and kind.trust else None),
        confirm_settle=settle_scans(A, i),
        support_inputs=support_inputs(scn),
        support_scans=scn.fusion.support_scans,
        existence_prior=existence_prior(scn),
        existence_young=scn.fusion.existence_young,
        existence_mature=existence_mature(scn),
        existence_absent=existence_absent(scn),
        existence_keep=scn.fusion.existence_keep,
        existence_own=existence_own(scn, name),
        existence_revisit=existence_revisit(scn),
        # a stamp from 2 hops or more can reach a peer after its neighbours' (label_twins)
        stamp_twins=stamp_twins(scn) if settle_scans(A, i) > 1 else 0,
        label_hold=scn.fusion.label_hold,
        id_blocks=scn.fusion.id_blocks,
        # LMB peers only: their adaptive births tie between neighbouring cells; a GM-PHD's
        # fixed births do not (its numbers were equal to the digit) and the masks cost it
        # ~40 % of its CPU at 50 peers (docs/labelled-tracking.md)
        label_support=net.label_support and net.filter == "lmb",
        label_reach=(reach_by_name(names, A, label_origins(scn, names), i)
                     if net.label_support and net.filter == "lmb" else ()),
        label_fallback=lmb_auto(scn, scn.fusion.label_fallback),
        label_keep=lmb_auto(scn, scn.fusion.label_keep),
        label_keep_scans=scn.fusion.label_keep_scans,
    )
    return replace(opts, **changes)


def label_origins(scn: Scenario, names: list[str]) -> list[int]:
    """The label origin of each of ``names`` as an LMB peer takes it (sim.kinds.lmb.build):
    its index in the sorted sensor names, plus 1 with shared births."""
    shift = 1 if scn.network.birth_ids == "shared" else 0
    return [origin_of([s.name for s in scn.sensors], n) + shift for n in names]


SUPPORT_AUTO = -2
"""``fusion.support`` "auto": resolved by :func:`support_inputs`."""


def support_inputs(scn: Scenario) -> int:
    """``fusion.support``, its automatic value (:data:`SUPPORT_AUTO`) resolved: the majority
    (``tracking.support.MAJORITY``) for GM-PHD peers whose births are alike at every peer
    (``network.birth_ids`` "shared", fixed birth points: the condition of
    ``filter.corroborate_scans`` auto, sim.kinds.gmphd), else 2 (docs/labelled-tracking.md,
    "Fused false tracks need a majority of the inputs")."""
    s = scn.fusion.support
    if s != SUPPORT_AUTO:
        return s
    shared = scn.network.birth_ids == "shared" and scn.birth.model != "measurements"
    return MAJORITY if scn.network.filter == "gmphd" and shared else 2


LMB_EXISTENCE_PRIOR = 0.01
"""``fusion.existence_prior`` "auto" (-1) for LMB peers that publish tentative tracks: about the
adaptive births' existence (docs/labelled-tracking.md, "Design B")."""


def existence_prior(scn: Scenario) -> float:
    """The pooling prior of fused extraction: ``fusion.existence_prior``, or if negative
    (auto) :data:`LMB_EXISTENCE_PRIOR` for LMB peers with ``lmb.tentative_threshold`` on, else
    0 (off: the GM-PHD's fused tracks are worse pooled, docs/labelled-tracking.md)."""
    r0 = scn.fusion.existence_prior
    if r0 >= 0:
        return r0
    return (LMB_EXISTENCE_PRIOR if scn.network.filter == "lmb" and scn.lmb.tentative_threshold > 0
            else 0.0)


def existence_mature(scn: Scenario) -> float:
    """The survival probability of :class:`tracking.mature_existence.MatureExistence`'s prior,
    0 (off) unless ``fusion.existence_mature`` is 1, or -1 (auto) with young tracks pooled
    (:func:`existence_prior` on: LMB peers that publish tentative tracks; the real-traffic
    scenarios and GM-PHD peers are unchanged) and a rule other than GCI: its fused weights
    are a PHD's, not existences (a target's component above 1, which the pooled cap of at most
    1 cut, so the cardinality rule dropped a target: docs/labelled-tracking.md, "The GCI and AA
    rules under the LMB defaults")."""
    on = scn.fusion.existence_mature
    auto = on < 0 and existence_prior(scn) > 0 and scn.fusion.rule != "gci"
    return scn.survival_probability if on == 1 or auto else 0.0


def existence_own(scn: Scenario, name: str) -> tuple[float, float, float] | tuple[()]:
    """``(Pd, kappa, sigma)`` of peer ``name``'s own sensor for the own-scan term of young
    fused tracks (``fusion.existence_own``, :mod:`tracking.own_scan`): LMB peers that pool
    young tracks, with an x-y ``linear`` sensor scanning the whole region every scan; else
    ``()``, off."""
    spec = scn.sensor(name)
    if (not scn.fusion.existence_own or scn.network.filter != "lmb"
            or existence_prior(scn) <= 0 or spec.kind != "linear"
            or spec.rotation_period is not None):
        return ()
    return (float(spec.detection_probability), float(clutter_intensity(scn, spec)),
            float(spec.plot_sigma or spec.sigma_r))


def existence_absent(scn: Scenario) -> float:
    """The existence at which an input without a mature track counts in its pool
    (:class:`tracking.mature_existence.MatureExistence` ``absent``): ``fusion.existence_absent``
    if positive; -1 (auto): the LMB's ``lmb.tentative_threshold`` (what its inputs publish
    tracks from) when :func:`existence_mature` is on for LMB peers, else 0 (off)."""
    v = scn.fusion.existence_absent
    if existence_mature(scn) <= 0:
        return 0.0
    if v >= 0:
        return v
    return scn.lmb.tentative_threshold if scn.network.filter == "lmb" else 0.0


def stamp_twins(scn: Scenario) -> int:
    """``fusion.stamp_twins`` if set, else (-1, auto) 1 scan for LMB peers and 0 (off) for the
    others: evaluated once on the LMB cells only (docs/labelled-tracking.md, "One target, two
    stamps a scan apart"); a peer with every other one hop away never holds a row (the caller)."""
    v = scn.fusion.stamp_twins
    if v >= 0:
        return v
    return 1 if scn.network.filter == "lmb" else 0


def lmb_auto(scn: Scenario, value: int) -> bool:
    """A tri-state key of issue 34's fused labels and extraction (``fusion.label_fallback``,
    ``label_keep``, ``existence_revisit``) resolved: 1 on, 0 off, -1 (auto) on for LMB peers
    with rotating radars (a ``rotation_period``: scans confirmed out of step) only. On real
    traffic they cut the fused LMB's OSPA(2) and switches (held-out hours); the GM-PHD's
    switches rose 0.00 -> 0.72 per aircraft-hour (docs/real-traffic.md, "Young fused tracks
    keep their labels"); on the synchronous synthetic cells ``label_keep`` (each peer keeps
    what it reported) split a target's confirmed label between peers in one evaluation run
    (seed 000 Pd 0.99: agreement 100 -> 97.8 %; docs/labelled-tracking.md, "Issue 34's label
    keys: a default for LMB peers with rotating radars")."""
    return value == 1 or (value < 0 and scn.network.filter == "lmb"
                          and any(s.rotation_period is not None for s in scn.sensors))


def existence_revisit(scn: Scenario) -> tuple[tuple[str, float], ...]:
    """Each rotating sensor's revisit in scans (``rotation_period / scan_period``) when
    ``fusion.existence_revisit`` is on (:func:`lmb_auto`), else ``()``: from the shared
    scenario, so no member's message sets how much its absence counts
    (tracking.support.revisit_weights); without rotating radars it is ``()`` either way."""
    if not lmb_auto(scn, scn.fusion.existence_revisit):
        return ()
    return tuple((s.name, float(s.rotation_period) / scn.scan_period) for s in scn.sensors
                 if s.rotation_period is not None)


SINGLE_TARGET_WARMUP = 10.0
"""Seconds at the start in which single-target peers are not tested: their filters start
from independent draws about the target (seed 001's ``init_sigma``: 20 m, 2 m/s) and are
overconfident while they converge (training run 9001: positions 2-5 sd apart at scans 2-8,
under 2 from scan 9; runs 9000, 9002, 9003 under 2 sd throughout)."""


def trust_config(scn: Scenario, group: list[str], single_target: bool = False) -> TrustConfig:
    """The trust test of a peer whose own and neighbours' sensors are ``group``: their
    smallest detection probability per scan, as the filters take it (a rotating radar's
    times the share of its circle swept in a scan, :func:`sim.world.build.sweep_fraction`),
    and no test in the first two rotations of the slowest radar (a measurement-born
    target is shown after its second plot: before, an honest peer shows nothing while its
    neighbours' faster radars show every aircraft). ``single_target`` (IMM peers): each
    summary tested as its moment-matched position (its divergence the location part only),
    no offset test (filters' errors correlated over scans), no test in the first
    :data:`SINGLE_TARGET_WARMUP` seconds, and no registration or repair (the particle ratio
    rule fuses a neighbour's posterior over its prediction: a posterior moved without its
    prediction pulled the fused filter 100 m off in seed 001's second turn)."""
    specs = [scn.sensor(n) for n in group]
    rotation = max((s.rotation_period or 0.0) for s in specs)
    warmup = math.ceil(2.0 * rotation / scn.scan_period) if rotation > scn.scan_period else 0
    if single_target:
        warmup = max(warmup, math.ceil(SINGLE_TARGET_WARMUP / scn.scan_period))
    return TrustConfig(
        detection_probability=min(s.detection_probability * sweep_fraction(scn, s)
                                  for s in specs),
        warmup=warmup,
        single_target=single_target, location_only=single_target, bias=not single_target,
        register=scn.fusion.trust_register and not single_target,
        repair=scn.fusion.trust_repair and not single_target)


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
