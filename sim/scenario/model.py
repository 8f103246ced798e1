"""The scenario as data: one frozen dataclass per section, each option declared once in its
field (:func:`sim.scenario.options.option`: default, doc, unit, choices, bounds)."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable
from dataclasses import dataclass

from sensornet.peers.faultplan import (
    FaultPlan,
)
from sensornet.sim.bounds import MAX_COORDINATE, MAX_ROUNDS, MAX_RUNS, MAX_SENSORS  # noqa: F401 (re-exported)
from sensornet.sim.choices import BIRTH_MODELS, FUSION_RULES, OMEGA_RULES, OOS_POLICIES
from sensornet.sim.kinds import names as kind_names
from sensornet.sim.scenario.options import (
    NONNEGATIVE,
    POSITIVE,
    PROBABILITY,
    Bound,
    at_least,
    option,
)
from sensornet.sim.truths import names as truth_names
from sensornet.tracking.gci_product import CARDINALITY_RULES
from sensornet.tracking.gmphd import EXTRACTION_RULES
from sensornet.tracking.reduction import MERGE_RULES

STATE_DIM = 4
"""State ``[px, vx, py, vy]``."""
TRUTH_MODELS = truth_names()
"""The shipped truth models (:mod:`sim.truths`; the loader asks the registry)."""
MOTION_MODELS = ("cv",)
SENSOR_KINDS = ("linear", "range-bearing")
NETWORK_OMEGA_RULES = OMEGA_RULES
"""The old name of :data:`OMEGA_RULES` (one set of weights for the network and the fusing
sensor)."""
PEER_FILTERS = kind_names()
"""The peer kinds known at import (:mod:`sim.kinds`; the loader asks the registry, which also
knows plug-ins registered later)."""
FLOOD_ESTIMATORS = ("idpc", "ftc", "ic")
"""What a flooding peer makes of its pooled scans (seed 004): density-peaks clustering, the
FTC baseline, or the iterated-corrector GM-PHD (``clustering.estimator``)."""
LIE_KINDS = ("empty", "shifted", "inflated", "phantoms", "biased", "stuck")
"""The lies ``fusion.lie`` names (the test hook; what each does: :mod:`sim.run.lies`)."""
PARTITIONS = ("distance", "grid-spectral")
K_RULES = ("eigengap", "core-regions")
DISTANCE_UNITS = ("sigma", "unit-box")
ASSUMED_SCANS = ("held", "all")
PDA_MODES = ("meas", "ci")
PDA_METHODS = ("PDAF", "IMM-PDAF", "fuzzy PDA", "fuzzy IMM")
TOPOLOGIES = ("full", "ring", "star", "line", "custom")
FAULT_KEYS = ("delay", "loss", "duplicate", "reorder", "reorder_delay", "partitions")
"""The keys of a ``[faults.default]``, ``[faults.peers.<name>]`` or ``faults.links`` entry."""
DELAY_KINDS = {"constant": ("value",), "uniform": ("low", "high"), "exponential": ("mean",),
               "scans": ("low", "high"), "short": (), "one-step": (), "multi-step": ("max_steps",)}
"""Delay kinds and the parameters each needs."""
Matrix = tuple[tuple[float, ...], ...]


def _diag(values: Iterable[float]) -> Matrix:
    """A diagonal matrix as nested tuples."""
    v = [float(x) for x in values]
    return tuple(tuple(x if i == j else 0.0 for j in range(len(v))) for i, x in enumerate(v))


def listing(options: Iterable[str]) -> str:
    """The choices of a key, quoted, for error messages."""
    return ", ".join(repr(o) for o in options)


class ScenarioError(ValueError):
    """A user error in a scenario file or override; the message is one line naming the key."""


# --------------------------------------------------------------------------------------------
# The scenario as data
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TargetSpec:
    """One true target moving in a straight line at constant velocity over its life."""

    birth_scan: int = option(doc="First scan (1-based; scan `k` is at time `k T`) at which the "
                                 "target exists.", unit="scan", check=at_least(1))
    death_scan: int = option(doc="Last scan (inclusive) at which the target exists; not before "
                                 "`birth_scan`.", unit="scan")
    start: tuple[float, float] = option(doc="Position `[x, y]` at `birth_scan`.", unit="m")
    end: tuple[float, float] = option(doc="Position `[x, y]` at `death_scan`.", unit="m")


@dataclass(frozen=True)
class SensorSpec:
    """One sensor: its measurement model, detection and clutter."""

    name: str = option(doc="Unique name, also the peer's name (`\"s1\"`); names differing only "
                           "in case are refused.", custom="required")
    kind: str = option(doc="`\"linear\"` (position with `R = sigma_r^2 I`) or "
                           "`\"range-bearing\"` (radar).", choices=SENSOR_KINDS)
    position: tuple[float, float] = option(doc="Sensor position `[x, y]` in the local frame; "
                                                 "not with `site`.", unit="m",
                                           custom="required unless `site` is given")
    sigma_r: float = option(20.0, doc="Position (linear, per axis) or range (range-bearing) "
                                      "noise standard deviation.", unit="m", check=NONNEGATIVE)
    sigma_theta_deg: float | None = option(
        None, doc="Bearing noise standard deviation; range-bearing only, where it is required "
                  "(and recorded traffic's radars, whatever their kind).",
        unit="deg", check=NONNEGATIVE, custom="none (linear); required for range-bearing")
    detection_probability: float = option(0.99, doc="`Pd`: probability that a target yields a "
                                                    "measurement in a scan.", check=PROBABILITY)
    clutter_rate: float = option(10.0, doc="`lambda_c`: Poisson mean of the number of clutter "
                                           "measurements per scan.", check=NONNEGATIVE)
    plot_sigma: float | None = option(
        None, doc="Recorded traffic, kind `\"linear\"` (required there): the filters' per-axis "
                  "noise of the x-y plots, whose true error is the radar's range-bearing error "
                  "at the plot's range (`sigma_r`, `sigma_theta_deg`) plus the time alignment "
                  "(docs/real-traffic.md); choose it from the cross-range error at the median "
                  "range.", unit="m", check=POSITIVE)
    site: tuple[float, float] | None = option(
        None, doc="`[latitude, longitude]` (degrees WGS84): the sensor stands there and "
                  "`position` is that point in the local east-north frame about "
                  "`traffic.centre` (which it needs).", unit="deg",
        custom="none: `position` is given")
    rotation_period: float | None = option(
        None, doc="Recorded traffic (`truth = \"recorded\"`): the radar's rotation period; its "
                  "plots are made as the beam crosses each aircraft and go to the fusion tick "
                  "`(t_(k-1), t_k]` they fall in, so the filters' `Pd` is `detection_probability "
                  "x min(1, scan_period / rotation_period)` (GM-PHD peers with `birth.model = "
                  "\"measurements\"`: per component, the beam's sector and the range curve, "
                  "`sim.world.birth.Beam`) and `clutter_rate` is per rotation. "
                  "Absent: a snapshot of every aircraft at each tick.", unit="s", check=POSITIVE)
    phase: float | None = option(
        None, doc="Recorded traffic: rotations start at `start + phase + j rotation_period`; "
                  "absent: a stable phase from the name (no two radars in step).", unit="s",
        check=NONNEGATIVE)
    max_range: float | None = option(
        None, doc="Recorded traffic (required there): the coverage radius; `Pd` falls with "
                  "slant range as a Swerling I target's, to half of `detection_probability` at "
                  "0.8 `max_range` and 0 beyond it (`sim.traffic.radar`); clutter is uniform "
                  "over the coverage disc.", unit="m", check=POSITIVE)

    @property
    def sigma_theta(self) -> float:
        """Bearing noise standard deviation in radians (0 for linear sensors)."""
        return math.radians(self.sigma_theta_deg or 0.0)


@dataclass(frozen=True)
class BirthComponent:
    """One Gaussian component ``w N(x; m, P)`` of a birth intensity."""

    weight: float = option(doc="`w`: expected number of births per scan from this component.",
                           check=NONNEGATIVE)
    mean: tuple[float, ...] = option(doc="`m` in `[px, vx, py, vy]`.", unit="m, m/s",
                                     custom="required (4 numbers)")
    cov: Matrix = option(doc="`P`, symmetric positive definite: `cov = [[...], ...]` (4 x 4) or "
                             "`cov_diag = [...]` (4 numbers).", custom="required")


PAPER_BIRTH = (
    BirthComponent(0.1, (250.0, 0.0, 250.0, 0.0), _diag([100, 25, 100, 25])),
    BirthComponent(0.1, (-250.0, 0.0, -250.0, 0.0), _diag([100, 25, 100, 25])),
)
"""Seed 000's printed births (§10), the default of ``[[birth.paper]]``."""
TRUTH_BIRTH_COV = _diag([100, 2500, 100, 2500])
"""Default covariance of the ``"truth"`` birth components (§10)."""


@dataclass(frozen=True)
class BirthSpec:
    """Birth intensity added at every prediction (§10 discusses why the choice matters)."""

    model: str = option("paper", doc="`\"paper\"` (the `[[birth.paper]]` components), "
                                     "`\"truth\"` (one at each true start) or "
                                     "`\"measurements\"` (at the previous scan's unexplained "
                                     "plots; GM-PHD peers).",
                        choices=BIRTH_MODELS)
    paper: tuple[BirthComponent, ...] = option(
        PAPER_BIRTH, doc="Components of the `\"paper\"` model (`[[birth.paper]]` entries).",
        custom="seed 000's two printed components (§10)")
    truth_weight: float = option(0.1, doc="Weight of each `\"truth\"` component.",
                                 key="truth.weight", check=NONNEGATIVE)
    truth_cov: Matrix = option(
        TRUTH_BIRTH_COV, doc="Covariance of each `\"truth\"` component (zero-velocity mean at a "
                             "target's start): `truth.cov` (4 x 4) or `truth.cov_diag`.",
        key="truth.cov", custom="diag(100, 2500, 100, 2500)")
    measurements_weight: float = option(
        0.05, doc="`\"measurements\"`: weight of the birth component at each plot of the "
                  "previous scan that no component explains (adaptive birth, after Ristic, "
                  "Clark, Vo & Vo 2012).", key="measurements.weight", check=NONNEGATIVE)
    measurements_speed: float = option(
        200.0, doc="`\"measurements\"`: standard deviation of each velocity component of a "
                   "birth (zero-velocity mean at the plot; position covariance the plot's).",
        unit="m/s", key="measurements.speed", check=POSITIVE)
    measurements_gate: float = option(
        13.8, doc="`\"measurements\"`: a plot whose squared Mahalanobis distance to every "
                  "predicted component heavier than 0.1 exceeds this gives a birth (13.8: the "
                  "0.999 point of chi-square with 2 degrees of freedom).",
        key="measurements.gate", check=POSITIVE)


@dataclass(frozen=True)
class FilterSpec:
    """GM-PHD filter settings: level-1 reduction (§4), extraction and gating (§2)."""

    prune_threshold: float = option(1e-5, doc="Components lighter than this are dropped "
                                              "(`Tp` / `W0`).", check=NONNEGATIVE)
    merge_threshold: float = option(5.0, doc="Merge threshold (`U` for `\"vo-ma\"`, `eta` for "
                                             "`\"weighted\"`).", check=NONNEGATIVE)
    merge_rule: str = option("vo-ma", doc="`\"vo-ma\"` (Mahalanobis, Vo & Ma 2006) or "
                                          "`\"weighted\"` (seed 000 §3.3).", choices=MERGE_RULES)
    max_components: int = option(100, doc="Cap on the number of components (`Jmax`).",
                                 check=at_least(1))
    extraction: str = option("cardinality", doc="Extraction rule: `\"round\"` (Vo-Ma `round(w)` "
                                                "copies) or `\"cardinality\"` (the `round` of "
                                                "the total mass heaviest components).",
                             choices=EXTRACTION_RULES)
    extraction_threshold: float = option(0.5, doc="Components heavier than this are reported "
                                                  "as targets.", check=NONNEGATIVE)
    gate: float | None = option(None, doc="Mahalanobis gate on `nu' S^-1 nu` in the update; "
                                          "absent: no gate.", check=POSITIVE)
    refit: bool = option(False, doc="Re-fit the reduced weights by minimising the integral "
                                    "squared error.")


@dataclass(frozen=True)
class FusionSpec:
    """How local estimates are fused (§3, §4 level 2)."""

    rule: str = option("hybrid", doc="`\"hybrid\"` (AA target weights, GCI locations: "
                                     "`tracking.fusion_rules.hybrid_fuse`), `\"gci\"`, `\"aa\"` "
                                     "(arithmetic average), `\"ratio\"` (the particle rule, IMM "
                                     "peers) or `\"none\"` (local filters only); each peer kind "
                                     "takes some.", choices=FUSION_RULES)
    fusing_omega: str = option("uniform", doc="The offline experiment's fusion weights at the "
                                              "fusing sensor: `\"uniform\"`, `\"metropolis\"` "
                                              "(of the star it forms with the others) or "
                                              "optimised `\"det\"` / `\"chernoff\"` (the peers' "
                                              "are `network.omega`).",
                               choices=OMEGA_RULES, was="omega")
    level2_pruning: bool = option(True, doc="Publish only components heavier than "
                                            "`level2_threshold`.")
    level2_threshold: float = option(0.5, doc="Level-2 pruning threshold.", check=NONNEGATIVE)
    fusing_sensor: str = option("", doc="The sensor that fuses in the offline experiment (seed "
                                        "000: `\"s2\"`), and the hub of a `\"star\"` network.",
                                custom="the first sensor")
    cardinality: str = option("separate", doc="GCI target number: `\"emd\"` (exact Poisson "
                                              "EMD, Uney 2013) or `\"separate\"` (location "
                                              "densities and cardinalities fused apart, "
                                              "Battistelli 2013).", choices=CARDINALITY_RULES)
    trust: bool = option(False, doc="Test each neighbour's density before fusing it and "
                                    "down-weight or quarantine the inconsistent ones "
                                    "(`peers.trust`).")
    trust_register: bool = option(True, doc="With `trust`: repair a neighbour the offset test "
                                             "fires on (registration, `TrustConfig.register`) "
                                             "instead of quarantining it.")
    trust_repair: bool = option(True, doc="With `trust`: fuse a failing neighbour's repaired "
                                          "density (its uncorroborated components dropped, its "
                                          "mass the others' median) where that passes the test "
                                          "(`TrustConfig.repair`).")
    lie: str = option("", doc="Test hook: `\"PEER:KIND\"` makes that peer publish lie KIND of "
                              "`sim.run.lies` in every estimate (a member lying with its own valid "
                              "key), in the twin and as a process.", custom="no lie")


@dataclass(frozen=True)
class NetworkSpec:
    """The peer network: one peer per sensor (same name), its graph, consensus and pacing."""

    topology: str = option("full", doc="`\"full\"`, `\"ring\"`, `\"star\"` (hub: "
                                       "`fusion.fusing_sensor`), `\"line\"` or `\"custom\"` "
                                       "(`edges`).", choices=TOPOLOGIES)
    edges: tuple[tuple[str, str], ...] = option(
        (), doc="Undirected edges between sensor names, `[[\"s1\", \"s2\"], ...]` (topology "
                "`\"custom\"` only).", custom="none")
    rounds: int = option(1, doc="Consensus (or flooding) rounds `L` per scan.",
                         check=Bound(1, MAX_ROUNDS))
    omega: str = option("metropolis", doc="The peers' fusion weights: `\"metropolis\"`, "
                                          "`\"uniform\"`, or each pair's optimised `\"det\"` / "
                                          "`\"chernoff\"` weight (GCI; consensus then "
                                          "Metropolis).", choices=OMEGA_RULES)
    max_age: int = option(5, doc="Neighbour estimates older than this are not fused.",
                          unit="scans", check=NONNEGATIVE)
    policy: str = option("nale", doc="Out-of-sequence policy: `\"nale\"`, `\"drop-late\"` or "
                                     "`\"as-is\"`.", choices=OOS_POLICIES)
    feedback: bool = option(False, doc="Peers use their fused density as the prior of the next "
                                       "scan.")
    speed: float = option(10.0, doc="Wall-clock speed factor: a scan every `scan_period / "
                                    "speed` seconds.", check=POSITIVE)
    filter: str = option("gmphd", doc="The peers' kind (`sim.kinds`): `\"gmphd\"`, "
                                      "`\"et-gmphd\"` (`[extended]`), for one target "
                                      "`\"imm-pf\"`/`\"imm-ekf\"`, `\"flooding\"` (seed 004, "
                                      "`[clustering]`) or `\"pda\"` (seed 003, `[pda]`).",
                         choices=kind_names)
    deadline: float = option(0.5, doc="Fusion deadline after a scan.", unit="scan interval",
                             check=Bound(0, 1, low_open=True))
    router: bool = option(False, doc="`sensornet run`/`demo`: every process a client of one "
                                     "Zenoh router the run starts (as `--router`), not peer to "
                                     "peer.")
    ros2: bool = option(False, doc="Each peer also publishes its tracks (and the world its "
                                   "detections) as ROS 2 messages in `rmw_zenoh`'s format "
                                   "(`--ros2`; docs/ros2.md; needs the `[ros2]` extra).")
    ros2_domain: int = option(0, doc="The ROS 2 domain (`ROS_DOMAIN_ID`) of those messages.",
                              check=Bound(0, 232))


@dataclass(frozen=True)
class ExtendedSpec:
    """Extended targets (seed 002, docs/seed002.md): returns per target and partitioning."""

    rate: float = option(10.0, doc="`gamma`: Poisson mean of the measurements of a detected "
                                   "target per scan.", check=POSITIVE)
    partition: str = option("distance", doc="`\"distance\"` (Granström, MST thresholds) or "
                                            "`\"grid-spectral\"` (the seed's method).",
                            choices=PARTITIONS)
    p_lower: float = option(0.3, doc="Distance partitioning: lower chi-square(2) probability of "
                                     "the thresholds on `d^2/2`.", check=PROBABILITY)
    p_upper: float = option(0.8, doc="Distance partitioning: upper chi-square(2) probability "
                                     "(at least `p_lower`).", check=PROBABILITY)
    compression: float = option(0.5, doc="Grid-spectral: compression rate `gamma` of the grid "
                                         "(seed 002 eq. 5).", check=Bound(0, 2, low_open=True))
    cell_factor: float = option(4.0, doc="Grid-spectral: `c0` in `ceil(N_z^(gamma/2) c0)` cells "
                                         "per axis (our reading).", check=POSITIVE)
    core_level: float = option(0.5, doc="Grid-spectral: core threshold `min + core_level (max "
                                        "- min)` of the cell counts.", check=PROBABILITY)
    rho: float = option(2.0, doc="Grid-spectral: density parameter of the edge length "
                                 "`rho^dist - 1`.", check=Bound(1, low_open=True))
    k_rule: str = option("eigengap", doc="Grid-spectral: number of clusters by `\"eigengap\"` "
                                         "or `\"core-regions\"`.", choices=K_RULES)
    k_spread: int = option(0, doc="Grid-spectral: also partitions for K +- 1..k_spread (0: one "
                                  "partition, the paper's).", check=NONNEGATIVE)
    units: str = option("sigma", doc="Grid-spectral: distances in `\"sigma\"` units or the "
                                     "paper's `\"unit-box\"` [0, 1].", choices=DISTANCE_UNITS)
    max_measurements: int = option(2000, doc="Scans with more points are not partitioned "
                                             "(counted, corrected as all-missed).",
                                   check=at_least(1))


@dataclass(frozen=True)
class ClusteringSpec:
    """Flooding peers' clustering (seed 004, ``tracking.idpc``; ``[clustering]`` table)."""

    cutoff: float = option(25.0, doc="`d_c`, the neighbourhood radius.", unit="m",
                           check=POSITIVE)
    zeta: float = option(0.3, doc="Target points have more than `zeta S` neighbours within "
                                  "`d_c`.", check=POSITIVE)
    radius_factor: float = option(1.25, doc="`L`: a cluster takes the points within `L d_c` of "
                                            "its seed.", check=POSITIVE)
    split_factor: float = option(1.6, doc="Clusters above `split_factor S Pd` points are split "
                                          "by k-means.", check=POSITIVE)
    assumed_scans: str = option("held", doc="`S`: the scans a peer holds (`\"held\"`) or every "
                                            "sensor (`\"all\"`).", choices=ASSUMED_SCANS)
    estimator: str = option("idpc", doc="The flooding peers' estimator from the pooled scans: "
                                        "`\"idpc\"` (density-peaks clustering), `\"ftc\"` "
                                        "(DBSCAN + k-means) or `\"ic\"` (the iterated-corrector "
                                        "GM-PHD, `[filter]`/`[birth]`, corrected with each "
                                        "pooled scan in turn; `peers.flooding."
                                        "IcFloodEstimator`). Seed 004's `flooding.estimator`.",
                            choices=FLOOD_ESTIMATORS)


@dataclass(frozen=True)
class PdaSpec:
    """Single-target PDA peers (seed 003, ``network.filter = "pda"``; ``[pda]`` table)."""

    tables: str = option("{}", doc="The seed-003 tables the PDA filters and the "
                                   "world's draws read (`scenario`, `sensors`, `clutter`, "
                                   "`filters`, `detector`, `fuzzy`, `metrics`: "
                                   "`sim.world.seed003`), held as canonical JSON so the "
                                   "scenario stays hashable.",
                         key="config", custom="an empty table")
    mode: str = option("meas", doc="`\"meas\"`: measurement sharing with the sequential update "
                                   "(the paper's scheme); `\"ci\"`: estimate sharing fused by "
                                   "covariance intersection.", choices=PDA_MODES)
    method: str = option("fuzzy IMM", doc="The filter: `\"PDAF\"`, `\"IMM-PDAF\"`, `\"fuzzy "
                                          "PDA\"` or `\"fuzzy IMM\"`.", choices=PDA_METHODS)
    pregate: float = option(4.0, doc="Measurement sharing publishes the returns inside "
                                     "`pregate` x the gate threshold.", check=POSITIVE)

    @property
    def config(self) -> dict:
        """A fresh copy of the seed-003 tables as nested dicts."""
        return json.loads(self.tables)


@dataclass(frozen=True)
class TrafficSpec:
    """Recorded aircraft as the truth (``truth = "recorded"``; ``[traffic]`` table,
    ``sim.traffic``): which OpenSky state-vector file, window and region."""

    file: str = option("", doc="OpenSky state vectors (`.json[.gz]`, `.csv[.gz]`, `.parquet`; "
                               "`sim.traffic.opensky`), relative to the scenario file.",
                       custom="the shipped excerpt (`sim/traffic/data/paris_excerpt.json.gz`)")
    start: float | str | None = option(
        None, doc="Time origin `t_0` of the run (tick `k` is at `t_0 + k scan_period`): an ISO "
                  "8601 time (no zone: UTC) or seconds after the file's first report.",
        unit="s", custom="the file's first report")
    end: float | str | None = option(
        None, doc="Reports after this are not read (ISO 8601 or seconds after the first "
                  "report); the run's last tick must not be later.", unit="s",
        custom="the file's last report")
    centre: tuple[float, float] | None = option(
        None, doc="`[latitude, longitude]` (degrees): the origin of the local east-north frame "
                  "(height 0) and of `radius`; sensors' `site`s need it.", unit="deg",
        custom="the middle of the reports' latitude/longitude box")
    radius: float | None = option(None, doc="Only reports within this geodesic distance of "
                                            "`centre` (which it needs).", unit="m",
                                  check=POSITIVE)
    max_gap: float = option(20.0, doc="An aircraft not reported for longer is absent over the "
                                      "gap, never extrapolated.", unit="s", check=POSITIVE)
    airborne_only: bool = option(True, doc="Drop reports flagged on the ground.")


@dataclass(frozen=True)
class MetricsSpec:
    """Error metric settings (§11)."""

    ospa_cutoff: float = option(200.0, doc="OSPA cut-off `c`.", unit="m", check=POSITIVE)
    ospa_order: float = option(2.0, doc="OSPA order `p`.", check=at_least(1))


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
    pda: PdaSpec | None = option(None, doc="PDA peers' settings (`[pda]`).",
                                 custom="no PDA settings")
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


