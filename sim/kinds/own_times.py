"""What a peer needs to take its plots at their own times (issue 34: ``lmb.time_slice``,
``filter.time_slice``), built from the scenario once for both kinds that do
(:mod:`sim.kinds.lmb`, :mod:`sim.kinds.gmphd`) and for the asynchronous centralised reference
(:mod:`sim.studies.traffic.asynchronous`): a rotating radar's sector ``Pd`` and the clutter
inside the sector its beam sweeps."""

from __future__ import annotations

from sensornet.peers.lmb_own_times import OwnTimes
from sensornet.sim.scenario import Scenario
from sensornet.sim.world.birth import beam_of
from sensornet.sim.world.build import clutter_intensity, sensor_params, sweep_fraction
from sensornet.tracking.elapsed import ElapsedMotion

MIN_CLUTTER_INTENSITY = 1e-12
"""``kappa`` of a sensor without clutter (per m^2 or m rad): the LMB needs ``kappa > 0``."""


def sector_clutter(scn: Scenario, name: str) -> float:
    """Clutter intensity inside a rotating radar's swept sector (the per-tick intensity over
    the circle divided by the share swept), floored for the LMB's division."""
    spec = scn.sensor(name)
    return max(clutter_intensity(scn, spec) / sweep_fraction(scn, spec), MIN_CLUTTER_INTENSITY)


def own_times(scn: Scenario, name: str, slice_s: float) -> OwnTimes | None:
    """Sensor ``name``'s plots at their own times in slices of ``slice_s`` s (> 0; else None):
    a rotating radar's sector ``Pd`` (:meth:`sim.world.birth.Beam.sector`) and the clutter
    inside its swept sector (:func:`sector_clutter`), as the asynchronous centralised
    reference; a sensor without a rotation its ``detection_probability`` and its filter's
    clutter."""
    if slice_s <= 0:
        return None
    spec = scn.sensor(name)
    beam = beam_of(scn, spec)
    clutter = (sector_clutter(scn, name) if beam is not None
               else max(sensor_params(scn, name).clutter_intensity, MIN_CLUTTER_INTENSITY))
    return OwnTimes(slice_s, scn.scan_period,
                    ElapsedMotion(scn.scan_period, scn.sigma_w), scn.survival_probability,
                    clutter, None if beam is None else beam.sector,
                    max(spec.detection_probability, 1e-12))


__all__ = ["MIN_CLUTTER_INTENSITY", "own_times", "sector_clutter"]
