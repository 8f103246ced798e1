"""The scenario as data: one frozen dataclass per section, each option declared once in its
field (:func:`sim.scenario.options.option`: default, doc, unit, choices, bounds).

The sections live in :mod:`sim.scenario.sensing` (targets, sensors, births, filter, traffic,
metrics) and :mod:`sim.scenario.network` (fusion, network, peer kinds), the vocabularies and
:class:`ScenarioError` in :mod:`sim.scenario.common`; this module holds :class:`Scenario` and
re-exports every name, so ``from sensornet.sim.scenario.model import X`` keeps working."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from sensornet.peers.faultplan import FaultPlan
from sensornet.sim.bounds import MAX_COORDINATE, MAX_ROUNDS, MAX_RUNS, MAX_SENSORS  # noqa: F401 (re-exported)
from sensornet.sim.choices import (  # noqa: F401 (re-exported)
    BIRTH_MODELS,
    FUSION_RULES,
    OMEGA_RULES,
    OOS_POLICIES,
)
from sensornet.sim.scenario.common import (  # noqa: F401 (re-exported)
    ASSUMED_SCANS,
    DELAY_KINDS,
    DISTANCE_UNITS,
    FAULT_KEYS,
    FLOOD_ESTIMATORS,
    K_RULES,
    LIE_KINDS,
    MOTION_MODELS,
    NETWORK_OMEGA_RULES,
    PARTITIONS,
    PDA_METHODS,
    PDA_MODES,
    PEER_FILTERS,
    SENSOR_KINDS,
    STATE_DIM,
    TOPOLOGIES,
    TRUTH_MODELS,
    Matrix,
    ScenarioError,
    _diag,
    listing,
)
from sensornet.sim.scenario.manoeuvre import ManoeuvreSpec
from sensornet.sim.scenario.network import (  # noqa: F401 (re-exported)
    ClusteringSpec,
    ExtendedSpec,
    FusionSpec,
    LmbSpec,
    NetworkSpec,
)
from sensornet.sim.scenario.options import (
    NONNEGATIVE,
    POSITIVE,
    PROBABILITY,
    at_least,
    option,
)
from sensornet.sim.scenario.pda import GATE_PROBABILITY as PDA_GATE_PROBABILITY
from sensornet.sim.scenario.pda import (  # noqa: F401 (re-exported)
    PdaClutter,
    PdaDetector,
    PdaFilters,
    PdaFuzzy,
    PdaSpec,
    PdaTarget,
)
from sensornet.sim.scenario.sensing import (  # noqa: F401 (re-exported)
    PAPER_BIRTH,
    TRUTH_BIRTH_COV,
    BirthComponent,
    BirthSpec,
    FilterSpec,
    MetricsSpec,
    SensorSpec,
    TargetSpec,
    TrafficSpec,
)
from sensornet.sim.truths import names as truth_names
from sensornet.tracking.gci_product import CARDINALITY_RULES  # noqa: F401 (re-exported)
from sensornet.tracking.gmphd import EXTRACTION_RULES  # noqa: F401 (re-exported)
from sensornet.tracking.reduction import MERGE_RULES  # noqa: F401 (re-exported)


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """Everything a run needs that is not code. Load with :func:`load_scenario`."""

    name: str = option(doc="Short name, used in reports and file names.", key="scenario.name",
                       custom="the file's name without `.toml`")
    seed: int = option(0, doc="Base random seed; run `r` draws from `(seed, r)`.",
                       key="scenario.seed", check=NONNEGATIVE)
    scan_period: float = option(1.0, doc="`T`; scan `k` (1-based) is at time `k T`.", unit="s",
                                key="scenario.scan_period", check=POSITIVE)
    num_scans: int = option(doc="Number of scans `K` in a run.", key="scenario.num_scans",
                            check=at_least(1))
    region: tuple[tuple[float, float], tuple[float, float]] = option(
        doc="Surveillance region `[[xmin, xmax], [ymin, ymax]]`, non-empty, within "
            f"+-{MAX_COORDINATE:g} m.", unit="m", key="scenario.region", custom="required")
    truth: str = option("straight", doc="Truth model (`sim.truths`): `\"straight\"` is constant "
                                        "velocity from start to end (our reading); "
                                        "`\"recorded\"`: the aircraft of `[traffic]`.",
                        key="scenario.truth", choices=truth_names)
    truth_sigma_w: float = option(0.0, doc="Process noise added to the straight-line truth; 0: "
                                           "exact lines.", unit="m/s^2",
                                  key="scenario.truth_sigma_w", check=NONNEGATIVE)
    motion_model: str = option("cv", doc="Filter motion model: `\"cv\"` (nearly constant "
                                         "velocity, §1).", key="motion.model",
                               choices=MOTION_MODELS)
    sigma_w: float = option(2.0, doc="Filter process noise standard deviation.", unit="m/s^2",
                            key="motion.sigma_w", check=NONNEGATIVE)
    survival_probability: float = option(0.99, doc="`Ps`.", key="motion.survival_probability",
                                         check=PROBABILITY)
    targets: tuple[TargetSpec, ...] = option((), doc="The true targets (`[[targets]]`).",
                                             custom="none")
    sensors: tuple[SensorSpec, ...] = option(doc="The sensors, in file order (`[[sensors]]`), "
                                                 f"at least one and at most {MAX_SENSORS}.",
                                             custom="required")
    birth: BirthSpec = option(BirthSpec(), doc="Birth intensity (`[birth]`).",
                              custom="the defaults of `[birth]`")
    filter: FilterSpec = option(FilterSpec(), doc="GM-PHD settings (`[filter]`).",
                                custom="the defaults of `[filter]`")
    fusion: FusionSpec = option(FusionSpec(), doc="Fusion settings (`[fusion]`).",
                                custom="the defaults of `[fusion]`")
    metrics: MetricsSpec = option(MetricsSpec(), doc="Metric settings (`[metrics]`).",
                                  custom="the defaults of `[metrics]`")
    network: NetworkSpec = option(NetworkSpec(), doc="Peer network settings (`[network]`).",
                                  custom="the defaults of `[network]`")
    extended: ExtendedSpec | None = option(None, doc="Extended targets (`[extended]`).",
                                           custom="point targets (one return each)")
    clustering: ClusteringSpec = option(ClusteringSpec(), doc="Flooding peers' clustering "
                                                              "(`[clustering]`).",
                                        custom="the defaults of `[clustering]`")
    lmb: LmbSpec = option(LmbSpec(), doc="LMB peers' adaptive birth (`[lmb]`).",
                          custom="the defaults of `[lmb]`")
    pda: PdaSpec | None = option(None, doc="PDA peers' settings (`[pda]`).",
                                 custom="no PDA settings")
    manoeuvre: ManoeuvreSpec | None = option(
        None, doc="The manoeuvring target of truth `\"seed001\"` (`[manoeuvre]`).",
        custom="seed 001's target (the defaults of `[manoeuvre]`)")
    faults: FaultPlan | None = option(
        None, doc="Link faults (`[faults]`), resolved per link (`peers.faultplan`); injected by "
                  "`peers.faults`. Delays in scans are bound to the scan interval `scan_period "
                  "/ network.speed` at load: change the speed with an override, not with "
                  "`dataclasses.replace`.", custom="perfect links")
    traffic: TrafficSpec | None = option(
        None, doc="Recorded traffic (`[traffic]`), read by `truth = \"recorded\"`.",
        custom="the defaults of `[traffic]` with truth `\"recorded\"`, else none")
    security: str | None = option(
        None, doc="`[security] keys = \"DIR\"`: the network's keys folder (relative to the "
                  "scenario file); `run`/`demo`/`peer`/`world` then run in secure mode as with "
                  "`--secure DIR` (`peers.security`).", key="security.keys",
        custom="plain mode unless `--secure` is given")
    source: str = ""
    """Where the scenario was read from (a path or ``builtin:<name>``); informational."""

    @property
    def sensor_names(self) -> list[str]:
        """Sensor names in file order."""
        return [s.name for s in self.sensors]

    def sensor(self, name: str) -> SensorSpec:
        """The sensor called ``name``; :class:`ScenarioError` if there is none."""
        for s in self.sensors:
            if s.name == name:
                return s
        raise ScenarioError(
            f"{self.name}: no sensor named {name!r} (sensors: {', '.join(self.sensor_names)})"
        )


def with_birth_model(scn: Scenario, model: str) -> Scenario:
    """The same scenario with birth model ``model`` (``"paper"`` or ``"truth"``)."""
    if model not in BIRTH_MODELS:
        raise ScenarioError(
            f"{scn.name}: unknown birth model {model!r} (expected one of {listing(BIRTH_MODELS)})"
        )
    return dataclasses.replace(scn, birth=dataclasses.replace(scn.birth, model=model))


def pda_tables(scn: Scenario) -> dict:
    """Seed 003's settings of ``scn`` as the nested tables the seed-003 world and filters read
    (``scenario``, ``sensors``, ``clutter``, ``filters``, ``detector``, ``fuzzy``, ``metrics``:
    sim/scenarios/seed003.toml's layout); :class:`ScenarioError` if ``scn`` has no ``[pda]``."""
    p = scn.pda
    if p is None:
        raise ScenarioError(f"{scn.name}: no [pda] table (seed 003's settings)")
    gates = p.gate_probability or (PDA_GATE_PROBABILITY,) * len(scn.sensors)
    t, f = p.target, p.filters
    return {
        "scenario": {"name": scn.name, "seed": scn.seed, "scan_period": scn.scan_period,
                     "num_scans": scn.num_scans, "start": list(t.start), "speed": t.speed,
                     "turn_scans": list(t.turn_scans), "manoeuvre": t.manoeuvre},
        "sensors": [{"name": s.name, "sigma": s.sigma_r,
                     "detection_probability": s.detection_probability, "gate_probability": g}
                    for s, g in zip(scn.sensors, gates, strict=True)],
        "clutter": {"mode": p.clutter.mode, "in_gate": p.clutter.in_gate,
                    "halfwidth": p.clutter.halfwidth},
        "filters": {"model": f.model, "sigma_cv": f.sigma_cv, "sigma_ca": f.sigma_ca,
                    "turn_rate_deg": f.turn_rate_deg, "sigma_ct": f.sigma_ct,
                    "transition": [list(r) for r in f.transition],
                    "initial_probs": list(f.initial_probs), "init_sigma": list(f.init_sigma)},
        "detector": {"window": p.detector.window, "false_alarm": p.detector.false_alarm},
        "fuzzy": p.fuzzy.config(),
        "metrics": {"loss_bound": p.loss_bound, "loss_scans": p.loss_scans},
    }
