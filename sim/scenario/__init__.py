"""Scenario files: TOML in, frozen dataclasses out (annotated: sim/scenarios/seed000.toml).

A scenario file says everything a run needs that is not code: the truth (targets as start →
end positions over their lives), the sensors, the motion and birth models, the filter's
reduction settings, the fusion rule and the metrics. ``sim/scenarios/seed000.toml`` is the
annotated reference; users copy and edit it.

Every mistake a user can make in a file (or in a command-line override) is a
:class:`ScenarioError` with a one-line message naming the file and the dotted key, e.g.
``seed000.toml: unknown key 'filter.merge_treshold' (did you mean 'filter.merge_threshold'?)``.
Array-of-table entries are named by 0-based index: ``sensors[1].sigma_r``.

The dataclasses hold tuples, not arrays, so a :class:`Scenario` is immutable, hashable,
comparable and cheap to pickle to worker processes.
"""

from __future__ import annotations

from sensornet.sim.scenario.faults import parse_faults
from sensornet.sim.scenario.loader import (
    builtin_scenarios,
    load_document,
    load_scenario,
    scenario_text,
)
from sensornet.sim.scenario.model import (
    BIRTH_MODELS,
    CARDINALITY_RULES,
    DELAY_KINDS,
    EXTRACTION_RULES,
    FAULT_KEYS,
    FLOOD_ESTIMATORS,
    FUSION_RULES,
    MAX_COORDINATE,
    MAX_ROUNDS,
    MAX_RUNS,
    MAX_SENSORS,
    MOTION_MODELS,
    NETWORK_OMEGA_RULES,
    OMEGA_RULES,
    OOS_POLICIES,
    PARTITIONS,
    PDA_METHODS,
    PDA_MODES,
    PEER_FILTERS,
    SENSOR_KINDS,
    STATE_DIM,
    TOPOLOGIES,
    TRUTH_MODELS,
    BirthComponent,
    BirthSpec,
    ClusteringSpec,
    ExtendedSpec,
    FilterSpec,
    FusionSpec,
    LmbSpec,
    ManoeuvreSpec,
    Matrix,
    MetricsSpec,
    NetworkSpec,
    PdaSpec,
    Scenario,
    ScenarioError,
    SensorSpec,
    TargetSpec,
    pda_tables,
    with_birth_model,
)
from sensornet.sim.scenario.overrides import apply_overrides, parse_overrides

__all__ = [
    "BIRTH_MODELS",
    "BirthComponent",
    "BirthSpec",
    "CARDINALITY_RULES",
    "ClusteringSpec",
    "DELAY_KINDS",
    "EXTRACTION_RULES",
    "ExtendedSpec",
    "FAULT_KEYS",
    "FLOOD_ESTIMATORS",
    "FUSION_RULES",
    "FilterSpec",
    "FusionSpec",
    "LmbSpec",
    "MAX_COORDINATE",
    "MAX_ROUNDS",
    "MAX_RUNS",
    "MAX_SENSORS",
    "MOTION_MODELS",
    "Matrix",
    "MetricsSpec",
    "NETWORK_OMEGA_RULES",
    "NetworkSpec",
    "OMEGA_RULES",
    "OOS_POLICIES",
    "PARTITIONS",
    "PDA_METHODS",
    "PDA_MODES",
    "PEER_FILTERS",
    "ManoeuvreSpec",
    "PdaSpec",
    "pda_tables",
    "SENSOR_KINDS",
    "STATE_DIM",
    "Scenario",
    "ScenarioError",
    "SensorSpec",
    "TOPOLOGIES",
    "TRUTH_MODELS",
    "TargetSpec",
    "apply_overrides",
    "builtin_scenarios",
    "load_document",
    "load_scenario",
    "parse_faults",
    "parse_overrides",
    "scenario_text",
    "with_birth_model",
]
