"""From a scenario's ``[extended]`` table to the seed-002 parts: partitioner and ET-GM-PHD.

The one place where the extended-target settings become :mod:`tracking.partition` and
:mod:`tracking.etgmphd` objects, so the peers, the twin and the Monte Carlo experiment
(:mod:`sim.studies.seed002.montecarlo`) build the same filter from the same file.
"""

from __future__ import annotations

import dataclasses

from sensornet.sim.scenario import Scenario, ScenarioError
from sensornet.sim.world.build import birth_mixture, clutter_intensity, make_reducer, motion_model
from sensornet.tracking.etgmphd import ETGMPHDFilter, ExtendedSensor
from sensornet.tracking.partition import DistancePartitioner, GridSpectralPartitioner


def _extended(scn: Scenario):
    if scn.extended is None:
        raise ScenarioError(f"{scn.name}: extended targets need an [extended] table")
    return scn.extended


def make_partitioner(scn: Scenario, name: str, partition: str | None = None):
    """The partitioner of sensor ``name`` (``partition`` overrides ``extended.partition``)."""
    ext = _extended(scn)
    sigma = scn.sensor(name).sigma_r
    which = partition or ext.partition
    if which == "distance":
        return DistancePartitioner(sigma, ext.p_lower, ext.p_upper, ext.max_measurements)
    if which == "grid-spectral":
        return GridSpectralPartitioner(
            sigma=sigma, compression=ext.compression, cell_factor=ext.cell_factor,
            core_level=ext.core_level, rho=ext.rho,
            k_rule=ext.k_rule, k_spread=ext.k_spread, units=ext.units,
            max_measurements=ext.max_measurements)
    raise ScenarioError(f"{scn.name}: unknown partition {which!r} "
                        f"(expected 'distance' or 'grid-spectral')")


def extended_sensor(scn: Scenario, name: str) -> ExtendedSensor:
    """Sensor ``name`` as the ET-GM-PHD sees it (linear position sensors only)."""
    spec = scn.sensor(name)
    if spec.kind != "linear":
        raise ScenarioError(f"{scn.name}: sensors.{name}.kind is {spec.kind!r}; the ET-GM-PHD "
                            f"filter takes 'linear' sensors only")
    return ExtendedSensor(sigma=spec.sigma_r, detection_probability=spec.detection_probability,
                          clutter_intensity=clutter_intensity(scn, spec),
                          rate=_extended(scn).rate)


def make_et_filter(scn: Scenario, name: str, partition: str | None = None) -> ETGMPHDFilter:
    """The ET-GM-PHD filter of sensor ``name`` (Granström et al. 2012; seed 002)."""
    return ETGMPHDFilter(
        motion=motion_model(scn),
        sensor=extended_sensor(scn, name),
        birth=birth_mixture(scn),
        partitioner=make_partitioner(scn, name, partition),
        survival_probability=scn.survival_probability,
        reducer=make_reducer(scn),
        extraction_threshold=scn.filter.extraction_threshold,
        extraction=scn.filter.extraction,
    )


def with_partition(scn: Scenario, partition: str) -> Scenario:
    """The same scenario with ``extended.partition = partition``."""
    return dataclasses.replace(scn, extended=dataclasses.replace(_extended(scn),
                                                                 partition=partition))


__all__ = ["extended_sensor", "make_et_filter", "make_partitioner", "with_partition"]
