"""GM-PHD peers (seed 000): a GM-PHD filter per sensor, mixtures fused by GCI, AA or the hybrid."""

from __future__ import annotations

import math

from sensornet.peers.estimators import GmphdEstimator
from sensornet.peers.fusers import AaFuser, GciFuser, HybridFuser, NoFuser
from sensornet.peers.labelling import origin_of
from sensornet.sim.choices import MIXTURE_RULES
from sensornet.sim.kinds import PeerKind
from sensornet.sim.kinds.own_times import own_times
from sensornet.sim.scenario import Scenario
from sensornet.sim.world.build import make_filter
from sensornet.tracking.elapsed import slices_per_tick
from sensornet.tracking.label_keys import SHARED_ORIGIN


def mixture_fuser(scn: Scenario, reducer):
    """The fuser of ``fusion.rule`` for mixture peers (GM-PHD and ET-GM-PHD)."""
    rule = scn.fusion.rule
    if rule == "gci":
        return GciFuser(reducer, scn.fusion.cardinality, scn.network.omega)
    if rule == "aa":
        return AaFuser(reducer)
    if rule == "hybrid":
        return HybridFuser(reducer)
    return NoFuser()


def revisit_scans(scn: Scenario, name: str) -> int:
    """Scans between two looks of sensor ``name`` at a target: a rotating radar's rotation in
    scans, rounded up (its plots are spread over the scans its beam sweeps), else 1."""
    rotation = scn.sensor(name).rotation_period
    return max(1, math.ceil(rotation / scn.scan_period - 1e-9)) if rotation else 1


def corroborate_scans(scn: Scenario, shared: bool) -> int:
    """``filter.corroborate_scans``, its automatic value (0) resolved: 2 for births alike at
    every peer (the clutter tracks at fixed birth points it was chosen for, issue 33), else 1
    (measurement births, e.g. recorded traffic: not measured with more)."""
    return scn.filter.corroborate_scans or (2 if shared else 1)


def build(scn: Scenario, name: str, run: int = 0):
    filt = make_filter(scn, [name])
    origin = origin_of([s.name for s in scn.sensors], name)
    shared = (origin is not None and scn.network.birth_ids == "shared"
              and scn.birth.model != "measurements")
    est = GmphdEstimator(filt, scn.fusion.level2_pruning, scn.fusion.level2_threshold,
                         origin=SHARED_ORIGIN + 1 + origin if shared else origin,
                         shared_births=shared, revisit=revisit_scans(scn, name),
                         corroborate_scans=corroborate_scans(scn, shared),
                         own_times=own_times(scn, name, scn.filter.time_slice))
    return est, mixture_fuser(scn, filt.reducer)


def check(scn: Scenario) -> tuple[str, str] | None:
    """``(key, message)`` if ``filter.time_slice`` is on but does not divide the tick or the
    births are not measurement-driven (fixed birth components would enter at every slice)."""
    s = scn.filter.time_slice
    if s <= 0:
        return None
    if scn.birth.model != "measurements":
        return ("filter.time_slice", f"key 'filter.time_slice' ({s:g} s) needs birth.model "
                f"'measurements', got {scn.birth.model!r}")
    try:
        slices_per_tick(scn.scan_period, s)
    except ValueError:
        return ("filter.time_slice", f"key 'filter.time_slice' ({s:g} s) must divide "
                f"scenario.scan_period ({scn.scan_period:g} s)")
    return None


GMPHD = PeerKind("gmphd", "GM-PHD filter per sensor; mixtures fused (seed 000)", build,
                 MIXTURE_RULES, check=check)
