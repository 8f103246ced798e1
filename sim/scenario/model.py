"""The scenario as data: one frozen dataclass per section, the choices and the bounds."""

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
from sensornet.sim.kinds import names as kind_names
from sensornet.sim.truths import names as truth_names

STATE_DIM = 4
"""State ``[px, vx, py, vy]``."""
TRUTH_MODELS = truth_names()
"""The shipped truth models (:mod:`sim.truths`)."""
MOTION_MODELS = ("cv",)
SENSOR_KINDS = ("linear", "range-bearing")
BIRTH_MODELS = ("paper", "truth")
FUSION_RULES = ("gci", "aa", "hybrid", "ratio", "none")
PEER_FILTERS = kind_names()
"""The peer kinds known at import (:mod:`sim.kinds`; the loader asks the registry, which also
knows plug-ins registered later)."""
FLOOD_ESTIMATORS = ("idpc", "ftc", "ic")
LIE_KINDS = ("empty", "shifted", "inflated", "phantoms", "biased", "stuck")
"""The lies ``fusion.lie`` names (the test hook; what each does: :mod:`sim.lies`)."""
"""What a flooding peer makes of its pooled scans (seed 004): density-peaks clustering, the
FTC baseline, or the iterated-corrector GM-PHD (``clustering.estimator``)."""
PARTITIONS = ("distance", "grid-spectral")
OMEGA_RULES = ("uniform", "metropolis", "det", "chernoff")
CARDINALITY_RULES = ("emd", "separate")
EXTRACTION_RULES = ("round", "cardinality")
TOPOLOGIES = ("full", "ring", "star", "line", "custom")
NETWORK_OMEGA_RULES = ("metropolis", "uniform", "det", "chernoff")
OOS_POLICIES = ("nale", "drop-late", "as-is")
FAULT_KEYS = ("delay", "loss", "duplicate", "reorder", "reorder_delay", "partitions")
"""The keys of a ``[faults.default]``, ``[faults.peers.<name>]`` or ``faults.links`` entry."""
DELAY_KINDS = {"constant": ("value",), "uniform": ("low", "high"), "exponential": ("mean",),
               "scans": ("low", "high"), "short": (), "one-step": (), "multi-step": ("max_steps",)}
"""Delay kinds and the parameters each needs."""
Matrix = tuple[tuple[float, ...], ...]


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

    birth_scan: int
    """First scan (1-based; scan ``k`` is at time ``k T``) at which the target exists."""
    death_scan: int
    """Last scan (1-based, inclusive) at which the target exists."""
    start: tuple[float, float]
    """Position ``(x, y)`` in metres at ``birth_scan``."""
    end: tuple[float, float]
    """Position ``(x, y)`` in metres at ``death_scan``."""


@dataclass(frozen=True)
class SensorSpec:
    """One sensor: its measurement model, detection and clutter."""

    name: str
    """Unique name, also the peer's name (``"s1"``)."""
    kind: str
    """``"linear"`` (position with ``R = sigma_r^2 I``) or ``"range-bearing"`` (radar)."""
    position: tuple[float, float]
    """Sensor position ``(x, y)`` in metres."""
    sigma_r: float = 20.0
    """Position (linear, per axis) or range (range-bearing) noise standard deviation, metres."""
    sigma_theta_deg: float | None = None
    """Bearing noise standard deviation in degrees (range-bearing only)."""
    detection_probability: float = 0.99
    """``Pd``: probability that a target yields a measurement in a scan."""
    clutter_rate: float = 10.0
    """``lambda_c``: Poisson mean of the number of clutter measurements per scan."""

    @property
    def sigma_theta(self) -> float:
        """Bearing noise standard deviation in radians (0 for linear sensors)."""
        return math.radians(self.sigma_theta_deg or 0.0)


@dataclass(frozen=True)
class BirthComponent:
    """One Gaussian component ``w N(x; m, P)`` of a birth intensity."""

    weight: float
    """``w``: expected number of births per scan from this component."""
    mean: tuple[float, ...]
    """``m`` in ``[px, vx, py, vy]`` (metres, m/s)."""
    cov: Matrix
    """``P`` (4 x 4, symmetric positive definite)."""


@dataclass(frozen=True)
class BirthSpec:
    """Birth intensity added at every prediction (§10 discusses why the choice matters)."""

    model: str = "paper"
    """``"paper"`` (the printed components below) or ``"truth"`` (one at each true start)."""
    paper: tuple[BirthComponent, ...] = ()
    """Components of the ``"paper"`` model."""
    truth_weight: float = 0.1
    """Weight of each ``"truth"`` component."""
    truth_cov: Matrix = ()
    """Covariance of each ``"truth"`` component (zero-velocity mean at a target's start)."""


@dataclass(frozen=True)
class FilterSpec:
    """GM-PHD filter settings: level-1 reduction (§4), extraction and gating (§2)."""

    prune_threshold: float = 1e-5
    """Components lighter than this are dropped (``Tp`` / ``W0``)."""
    merge_threshold: float = 5.0
    """Merge threshold (``U`` for ``"vo-ma"``, ``eta`` for ``"weighted"``)."""
    merge_rule: str = "vo-ma"
    """``"vo-ma"`` (Mahalanobis, Vo & Ma 2006) or ``"weighted"`` (seed 000 §3.3)."""
    max_components: int = 100
    """Cap on the number of components (``Jmax``)."""
    extraction: str = "cardinality"
    """Extraction rule: ``"round"`` (Vo–Ma ``round(w)`` copies) or ``"cardinality"``."""
    extraction_threshold: float = 0.5
    """Components heavier than this are reported as targets."""
    gate: float | None = None
    """Mahalanobis gate on ``nu^T S^-1 nu`` in the update; ``None``: no gate."""
    refit: bool = False
    """Re-fit the reduced weights by minimising the integral squared error."""


@dataclass(frozen=True)
class FusionSpec:
    """How local estimates are fused (§3, §4 level 2)."""

    rule: str = "gci"
    """``"gci"``, ``"aa"`` (arithmetic average), ``"hybrid"`` (AA target weights, GCI
    locations: :func:`tracking.fusion.hybrid_fuse`) or ``"none"`` (local filters only)."""
    omega: str = "uniform"
    """Fusion weights: ``"uniform"``, ``"metropolis"``, or optimised ``"det"`` / ``"chernoff"``."""
    level2_pruning: bool = True
    """Publish only components heavier than ``level2_threshold``."""
    level2_threshold: float = 0.5
    """Level-2 pruning threshold."""
    fusing_sensor: str = ""
    """The sensor that fuses in the offline experiment (seed 000: ``"s2"``)."""
    cardinality: str = "separate"
    """GCI mass rule: ``"emd"`` (exact Poisson EMD) or ``"separate"`` (Battistelli 2013)."""
    trust: bool = False
    """Test each neighbour's density before fusing it and down-weight or quarantine the
    inconsistent ones (:mod:`peers.trust`)."""
    trust_register: bool = True
    """With :attr:`trust`: repair a neighbour the offset test fires on (registration,
    :attr:`peers.trust_config.TrustConfig.register`; on by default) instead of quarantining it."""
    trust_repair: bool = True
    """With :attr:`trust`: fuse a failing neighbour's repaired density (its uncorroborated
    components dropped, its mass the others' median) where that passes the test
    (:attr:`peers.trust_config.TrustConfig.repair`; on by default)."""
    lie: str = ""
    """Test hook: ``"PEER:KIND"`` makes that peer publish lie KIND of :mod:`sim.lying` in
    every estimate (a member lying with its own valid key), in the twin and as a process."""


@dataclass(frozen=True)
class NetworkSpec:
    """The peer network: one peer per sensor (same name), its graph, consensus and pacing."""

    topology: str = "full"
    """``"full"``, ``"ring"``, ``"star"`` (hub: the fusing sensor), ``"line"`` or ``"custom"``."""
    edges: tuple[tuple[str, str], ...] = ()
    """Undirected edges between sensor names (``topology = "custom"`` only)."""
    rounds: int = 1
    """Consensus rounds ``L`` per scan."""
    omega: str = "metropolis"
    """Fusion weights in the network: ``"metropolis"``, ``"uniform"``, ``"det"``, ``"chernoff"``."""
    max_age: int = 5
    """Neighbour estimates older than this many scans are not fused."""
    policy: str = "nale"
    """Out-of-sequence policy: ``"nale"``, ``"drop-late"`` or ``"as-is"``."""
    feedback: bool = False
    """Peers use their fused density as the prior of the next scan."""
    speed: float = 10.0
    """Wall-clock speed factor: a scan every ``scan_period / speed`` seconds."""
    filter: str = "gmphd"
    """Local filter of every peer: ``"gmphd"``, for one target ``"imm-pf"``/``"imm-ekf"``, or
    ``"flooding"`` (seed 004: peers flood their scans for ``rounds`` iterations and cluster the
    pooled set, ``[clustering]`` table)."""
    deadline: float = 0.5
    """Fusion deadline after a scan, as a fraction of the (wall-clock) scan interval."""
    router: bool = False
    """``sensornet run``/``demo``: every process a client of one Zenoh router the run starts
    (as ``--router``), not peer to peer."""


@dataclass(frozen=True)
class ExtendedSpec:
    """Extended targets (seed 002, docs/seed002.md): returns per target and partitioning."""

    rate: float = 10.0
    """``gamma``: Poisson mean of the measurements of a detected target per scan."""
    partition: str = "distance"
    """``"distance"`` (Granström, MST thresholds) or ``"grid-spectral"`` (the seed's method)."""
    p_lower: float = 0.3
    """Distance partitioning: lower chi-square(2) probability of the thresholds on d^2/2."""
    p_upper: float = 0.8
    """Distance partitioning: upper chi-square(2) probability."""
    compression: float = 0.5
    """Grid-spectral: compression rate ``gamma`` of the grid (seed 002 eq. 5)."""
    cell_factor: float = 4.0
    """Grid-spectral: ``c0`` in ``ceil(N_z^(gamma/2) c0)`` cells per axis (our reading)."""
    core_level: float = 0.5
    """Grid-spectral: core threshold ``min + core_level (max - min)`` of the cell counts."""
    rho: float = 2.0
    """Grid-spectral: density parameter ``rho > 1`` of the edge length ``rho^dist - 1``."""
    k_rule: str = "eigengap"
    """Grid-spectral: number of clusters by ``"eigengap"`` or ``"core-regions"``."""
    k_spread: int = 0
    """Grid-spectral: also partitions for K +- 1..k_spread (0: one partition, the paper's)."""
    units: str = "sigma"
    """Grid-spectral: distances in ``"sigma"`` units or the paper's ``"unit-box"`` [0, 1]."""
    max_measurements: int = 2000
    """Scans with more points are not partitioned (counted, corrected as all-missed)."""


@dataclass(frozen=True)
class ClusteringSpec:
    """Flooding peers' clustering (seed 004, ``tracking.idpc``; ``[clustering]`` table)."""

    cutoff: float = 25.0
    """``d_c`` in metres."""
    zeta: float = 0.3
    """Target points have more than ``zeta S`` neighbours within ``d_c``."""
    radius_factor: float = 1.25
    """``L``: a cluster takes the points within ``L d_c`` of its seed."""
    split_factor: float = 1.6
    """Clusters above ``split_factor S Pd`` points are split by k-means."""
    assumed_scans: str = "held"
    """``S``: the scans a peer holds (``"held"``) or every sensor (``"all"``)."""
    estimator: str = "idpc"
    """The flooding peers' estimator from the pooled scans: ``"idpc"`` (density-peaks
    clustering), ``"ftc"`` (DBSCAN + k-means) or ``"ic"`` (the iterated-corrector GM-PHD, one
    ``[filter]``/``[birth]`` GM-PHD corrected with each pooled scan in turn, carried from scan
    to scan; ``peers.flooding.IcFloodEstimator``). Seed 004's ``flooding.estimator``."""


@dataclass(frozen=True)
class PdaSpec:
    """Single-target PDA peers (seed 003, ``network.filter = "pda"``; ``[pda]`` table)."""

    tables: str
    """The seed-003 tables the PDA filters and the world's draws read (``scenario``, ``sensors``,
    ``clutter``, ``filters``, ``detector``, ``fuzzy``, ``metrics``: :mod:`sim.seed003`), as
    canonical JSON, so the scenario stays immutable and hashable; :attr:`config` reads them."""
    mode: str = "meas"
    """``"meas"``: measurement sharing with the sequential update (the paper's scheme);
    ``"ci"``: estimate sharing fused by covariance intersection."""
    method: str = "fuzzy IMM"
    """The filter: ``"PDAF"``, ``"IMM-PDAF"``, ``"fuzzy PDA"`` or ``"fuzzy IMM"``."""
    pregate: float = 4.0
    """Measurement sharing publishes the returns inside ``pregate`` x the gate threshold."""

    @property
    def config(self) -> dict:
        """A fresh copy of the seed-003 tables as nested dicts."""
        return json.loads(self.tables)


PDA_MODES = ("meas", "ci")
PDA_METHODS = ("PDAF", "IMM-PDAF", "fuzzy PDA", "fuzzy IMM")


@dataclass(frozen=True)
class MetricsSpec:
    """Error metric settings (§11)."""

    ospa_cutoff: float = 200.0
    """OSPA cut-off ``c`` in metres."""
    ospa_order: float = 2.0
    """OSPA order ``p``."""


@dataclass(frozen=True)
class Scenario:
    """Everything a run needs that is not code. Load with :func:`load_scenario`."""

    name: str
    """Short name, used in reports and file names."""
    seed: int
    """Base random seed; run ``r`` draws from ``(seed, r)``."""
    scan_period: float
    """``T`` in seconds; scan ``k`` (1-based) is at time ``k T``."""
    num_scans: int
    """Number of scans ``K`` in a run."""
    region: tuple[tuple[float, float], tuple[float, float]]
    """Surveillance region ``((xmin, xmax), (ymin, ymax))`` in metres."""
    targets: tuple[TargetSpec, ...]
    """The true targets."""
    sensors: tuple[SensorSpec, ...]
    """The sensors, in file order."""
    truth: str = "straight"
    """Truth model: ``"straight"`` (constant velocity from start to end; our reading)."""
    truth_sigma_w: float = 0.0
    """Process noise (m/s^2) added to the straight-line truth; 0: exact lines."""
    motion_model: str = "cv"
    """Filter motion model: ``"cv"`` (nearly constant velocity, §1)."""
    sigma_w: float = 2.0
    """Filter process noise standard deviation in m/s^2."""
    survival_probability: float = 0.99
    """``Ps``."""
    birth: BirthSpec = BirthSpec()
    """Birth intensity."""
    filter: FilterSpec = FilterSpec()
    """GM-PHD settings."""
    fusion: FusionSpec = FusionSpec()
    """Fusion settings."""
    metrics: MetricsSpec = MetricsSpec()
    """Metric settings."""
    network: NetworkSpec = NetworkSpec()
    """Peer network settings."""
    extended: ExtendedSpec | None = None
    """Extended targets (``[extended]`` table); ``None``: point targets (one return each)."""
    clustering: ClusteringSpec = ClusteringSpec()
    """Flooding peers' clustering (``network.filter = "flooding"``)."""
    pda: PdaSpec | None = None
    """PDA peers' settings (``network.filter = "pda"``)."""
    faults: FaultPlan | None = None
    """Link faults from the ``[faults]`` table (``None``: perfect links), resolved per link
    (:mod:`peers.faultplan`); injected by :mod:`peers.faults`. Its delays in scans are bound to
    the scan interval ``scan_period / network.speed`` at load: change the speed with an
    override, not with ``dataclasses.replace``."""
    security: str | None = None
    """The network's keys folder from ``[security] keys = "DIR"`` (relative to the scenario
    file): ``run``/``demo``/``peer``/``world`` then run in secure mode as with ``--secure DIR``
    (:mod:`peers.security`). ``None``: plain mode unless ``--secure`` is given."""
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


