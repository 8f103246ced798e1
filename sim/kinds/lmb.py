"""LMB peers (issue 33): a labelled multi-Bernoulli filter per sensor (tracking.lmb), its PHD
mixture fused by the mixture rules (hybrid, GCI, AA) with the tracks' labels beside it.

Built from the scenario: the motion model and ``Ps``; the sensor model, ``Pd`` and the clutter
intensity ``kappa = lambda_c / V`` (:func:`sim.world.build.sensor_params`, floored at
:data:`MIN_CLUTTER_INTENSITY` since the LMB update divides by it); births measurement-driven
(Reuter et al. 2014, Sec. IV-C) for linear sensors, the scenario's birth components (weights
clipped to 1) for range-bearing ones; ``filter.gate`` and ``filter.extraction_threshold``; the
adaptive birth's ``lambda_B``, ``r_B,max`` and velocity spread from ``[lmb]``
(:class:`sim.scenario.network.LmbSpec`); with ``network.birth_ids = "shared"`` births labelled
alike at every peer (fixed ones by component, adaptive ones by the ``lmb.birth_cell`` grid cell
of their plot; own origins from 1). The LMB's other settings (association, per-track
``J``, confirmation) are :class:`tracking.lmb.LmbFilter`'s defaults.
"""

from __future__ import annotations

import numpy as np
from sensornet.peers.fusers import AaFuser
from sensornet.peers.labelling import origin_of, settle_scans
from sensornet.peers.lmb_estimator import LmbEstimator
from sensornet.sim.choices import MIXTURE_RULES
from sensornet.sim.kinds import PeerKind
from sensornet.sim.kinds.gmphd import mixture_fuser
from sensornet.sim.kinds.own_times import MIN_CLUTTER_INTENSITY, own_times
from sensornet.sim.scenario import Scenario
from sensornet.sim.world.build import (
    adjacency,
    birth_mixture,
    make_reducer,
    motion_model,
    sensor_params,
)
from sensornet.tracking.elapsed import slices_per_tick
from sensornet.tracking.gmphd import SensorParams
from sensornet.tracking.label_keys import SHARED_ORIGIN
from sensornet.tracking.lmb import LmbFilter
from sensornet.tracking.mixture import GaussianMixture


def birth_edge(scn: Scenario, sensor: SensorParams) -> float:
    """``lmb.birth_edge``, or if negative (auto) the sensor's position noise (the largest
    standard deviation of ``R``, below half a cell) for LMB peers that publish tentative tracks,
    else 0 (off: the real-traffic scenarios, which publish none, are unchanged)."""
    if scn.lmb.birth_edge >= 0:
        return scn.lmb.birth_edge
    if scn.lmb.tentative_threshold <= 0 or sensor.model.selected is None:
        return 0.0
    sd = float(np.sqrt(np.max(np.diag(sensor.model.R))))
    return min(sd, 0.49 * scn.lmb.birth_cell)


def make_lmb_filter(scn: Scenario, name: str, origin: int = 0,
                    shared_origin: int | None = None) -> LmbFilter:
    """The LMB filter of sensor ``name`` (module docstring); ``shared_origin``: births
    labelled alike at every peer (``network.birth_ids = "shared"``, cells of
    ``lmb.birth_cell``), None: own."""
    sp = sensor_params(scn, name)
    sensor = SensorParams(sp.model, sp.detection_probability,
                          max(sp.clutter_intensity, MIN_CLUTTER_INTENSITY))
    adaptive = sensor.model.selected is not None
    birth = None
    if not adaptive:
        b = birth_mixture(scn)
        birth = GaussianMixture(np.minimum(b.weights, 1.0), b.means, b.covs) if len(b) else None
    return LmbFilter(motion=motion_model(scn), sensor=sensor,
                     survival_probability=scn.survival_probability, birth=birth,
                     adaptive_birth=adaptive, birth_rate=scn.lmb.birth_rate,
                     birth_max_existence=scn.lmb.birth_max_existence,
                     birth_velocity_std=scn.lmb.birth_velocity_std, gate=scn.filter.gate,
                     extraction_threshold=scn.filter.extraction_threshold, origin=origin,
                     shared_origin=shared_origin, birth_cell=scn.lmb.birth_cell,
                     birth_edge=birth_edge(scn, sensor))


LMB_CORROBORATE_SCANS = 3
"""``lmb.corroborate_scans`` "auto" (0) for LMB peers that publish tentative tracks: an
uncorroborated label moves in the first 3 scans after its first publication (decided on the
labelled study's training runs, docs/labelled-tracking.md "Uncorroborated LMB labels keep
moving")."""


def corroborate_scans(scn: Scenario) -> int:
    """``lmb.corroborate_scans``, or if 0 (auto) :data:`LMB_CORROBORATE_SCANS` with
    ``lmb.tentative_threshold`` on, else 1 (a label moves only in its first scan, as before:
    without tentative tracks, e.g. the real-traffic scenarios, nothing changes)."""
    n = scn.lmb.corroborate_scans
    return n if n > 0 else (LMB_CORROBORATE_SCANS if scn.lmb.tentative_threshold > 0 else 1)


def fused_extraction(scn: Scenario) -> str:
    """The extraction rule of an LMB peer's fused tracks: ``lmb.fused_extraction``, or
    ``filter.extraction`` when it is ``"filter"``; ``"auto"``: ``"round"`` (an existence test
    per track), but ``filter.extraction`` under the GCI rule, whose fused weights are a PHD's
    (a target's mass split over components, one at 0.34-0.49 while every input holds it at
    0.99: docs/labelled-tracking.md, "The GCI and AA rules under the LMB defaults")."""
    rule = scn.lmb.fused_extraction
    if rule == "auto":
        rule = "filter" if scn.fusion.rule == "gci" else "round"
    return scn.filter.extraction if rule == "filter" else rule


AA_LABEL_STATE = "mean"
"""``lmb.aa_label_existence`` "auto": the copies' weighted mean (chosen over ``"heaviest"`` and
off on training runs 100-102 of full3 and circ20, evaluated once on runs 0-7 / 0-2:
docs/labelled-tracking.md "Per-label existence over the AA copies")."""


def aa_label_existence(scn: Scenario) -> str | None:
    """The state rule of the AA fuser's per-label existence (``lmb.aa_label_existence``,
    :attr:`peers.fusers.AaFuser.label_state`), None for off; ``"auto"``:
    :data:`AA_LABEL_STATE`."""
    rule = scn.lmb.aa_label_existence
    return AA_LABEL_STATE if rule == "auto" else None if rule == "off" else rule


def adopt_states(scn: Scenario, name: str) -> int:
    """Peer ``name``'s feedback of states only (``lmb.adopt_states``, LmbEstimator
    ``adopt_states``; > 0 turns feedback on, sim.run.peers.consensus_options): the value if
    set, else (-1, auto) ``fusion.existence_young`` for a peer with a peer 2 hops or more away
    under the hybrid rule with sensors that scan every tick, else 0. Why (issue 33,
    docs/labelled-tracking.md): on 20 peers of degree 4 the diffused states lower the fused
    OSPA(2) (training 25.5 -> 24.9, 33.3 -> 32.2 m); on the 3-peer full mesh one round fuses
    every input already and the fused tracks outlived their targets a little more (31.3 ->
    31.7); the AA and GCI rules and rotating radars were not measured."""
    v = scn.lmb.adopt_states
    if v >= 0:
        return v
    names, A = adjacency(scn)
    spec = scn.sensor(name)
    auto = (scn.network.filter == "lmb" and scn.fusion.rule == "hybrid"
            and spec.rotation_period is None and scn.lmb.time_slice == 0
            and settle_scans(A, names.index(name), margin=0) > 1)
    return scn.fusion.existence_young if auto else 0


def build(scn: Scenario, name: str, run: int = 0):
    shared = SHARED_ORIGIN if scn.network.birth_ids == "shared" else None
    origin = origin_of([s.name for s in scn.sensors], name) + (0 if shared is None else 1)
    reducer = make_reducer(scn)
    f = scn.fusion
    est = LmbEstimator(make_lmb_filter(scn, name, origin, shared), reducer,
                       f.level2_threshold if f.level2_pruning else None,
                       scn.filter.extraction_threshold, fused_extraction(scn), origin=origin,
                       tentative_threshold=scn.lmb.tentative_threshold or None,
                       tentative_scans=scn.lmb.tentative_scans,
                       republish_gap=None if scn.lmb.republish_gap < 0 else scn.lmb.republish_gap,
                       tentative_gap=None if scn.lmb.tentative_gap < 0 else scn.lmb.tentative_gap,
                       corroborate_scans=corroborate_scans(scn),
                       own_times=own_times(scn, name, scn.lmb.time_slice),
                       adopt_states=adopt_states(scn, name))
    fuser = mixture_fuser(scn, reducer)
    if isinstance(fuser, AaFuser):
        fuser.label_state = aa_label_existence(scn)
    return est, fuser


def check(scn: Scenario) -> tuple[str, str] | None:
    """``(key, message)`` if the scenario cannot run LMB peers: extended targets, or
    range-bearing sensors (no adaptive birth) without birth components."""
    if scn.extended is not None:
        return ("network.filter", "key 'network.filter' is 'lmb', whose peers track point "
                "targets ([extended] is for 'et-gmphd')")
    if scn.lmb.time_slice > 0:
        try:
            slices_per_tick(scn.scan_period, scn.lmb.time_slice)
        except ValueError:
            return ("lmb.time_slice", f"key 'lmb.time_slice' ({scn.lmb.time_slice:g} s) must "
                    f"divide scenario.scan_period ({scn.scan_period:g} s)")
    rb = [s.name for s in scn.sensors if s.kind != "linear"]
    if rb and len(birth_mixture(scn)) == 0:
        return ("birth.model", f"'lmb' peers with range-bearing sensors ({', '.join(rb)}) need "
                f"birth components (birth.model 'paper' with [[birth.paper]], or 'truth')")
    return None


LMB = PeerKind("lmb", "LMB filter per sensor (labelled tracks); its PHD mixture fused", build,
               MIXTURE_RULES, check=check)
