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

import copy
import dataclasses
import difflib
import math
import re
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from protocol.keys import check_name
from sim.faultplan import (
    Constant,
    Delay,
    Exponential,
    FaultPlan,
    LinkLayer,
    MultiStep,
    OneStep,
    PlanConflict,
    Scans,
    ShortDelay,
    Uniform,
)
from sim.formats import adapt_document
from sim.kinds import kind as peer_kind
from sim.kinds import names as kind_names
from sim.truths import names as truth_names
from tracking.reduction import MERGE_RULES

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
MAX_SENSORS = 256
"""Sensors (= peers) a scenario may list: a flooding forward carries at most this many scans
(protocol.codec.Limits.max_entries), and a peer's work per scan grows with its neighbours."""
MAX_ROUNDS = 16
"""``network.rounds``: consensus (or flooding) rounds per scan. Every round is a message per
peer and link held until the scan is done, so the twin's memory grows with it."""
MAX_RUNS = 100_000
"""Monte Carlo runs one command or campaign cell may ask for (``--runs``, ``campaign.runs``):
each run's results are held until the table is written."""
MAX_COORDINATE = 1e7
"""Largest ``|x|`` or ``|y|`` in metres of the region (and of sensor and target positions):
10,000 km, well past any surveillance area; areas and distances stay far from overflow."""

Matrix = tuple[tuple[float, ...], ...]


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

    config: dict
    """The seed-003 tables the PDA filters and the world's draws read (``scenario``, ``sensors``,
    ``clutter``, ``filters``, ``detector``, ``fuzzy``, ``metrics``: :mod:`sim.seed003`)."""
    mode: str = "meas"
    """``"meas"``: measurement sharing with the sequential update (the paper's scheme);
    ``"ci"``: estimate sharing fused by covariance intersection."""
    method: str = "fuzzy IMM"
    """The filter: ``"PDAF"``, ``"IMM-PDAF"``, ``"fuzzy PDA"`` or ``"fuzzy IMM"``."""
    pregate: float = 4.0
    """Measurement sharing publishes the returns inside ``pregate`` x the gate threshold."""


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
    (:mod:`sim.faultplan`); injected by :mod:`peers.faults`. Its delays in scans are bound to
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
            f"{scn.name}: unknown birth model {model!r} (expected one of {_choices(BIRTH_MODELS)})"
        )
    return dataclasses.replace(scn, birth=dataclasses.replace(scn.birth, model=model))


# --------------------------------------------------------------------------------------------
# Built-in scenarios
# --------------------------------------------------------------------------------------------


def _builtin_dir():
    return resources.files("sim").joinpath("scenarios")


def builtin_scenarios() -> list[str]:
    """Names of the scenarios shipped in ``sim/scenarios/`` (``["seed000", ...]``)."""
    return sorted(
        p.name[: -len(".toml")] for p in _builtin_dir().iterdir() if p.name.endswith(".toml")
    )


def scenario_text(name: str) -> str:
    """The text of a built-in scenario file (for ``scenario show`` and for copying)."""
    key = name[: -len(".toml")] if name.endswith(".toml") else name
    if key not in builtin_scenarios():
        raise ScenarioError(
            f"no built-in scenario {name!r} (built-in: {', '.join(builtin_scenarios())})"
        )
    return _builtin_dir().joinpath(f"{key}.toml").read_text(encoding="utf-8")


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------


def load_scenario(source: str | Path, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Read and validate a scenario from a ``.toml`` path or a built-in name (``"seed000"``).

    ``overrides`` changes values before validation, so they are checked like the file. Keys are
    dotted paths (``{"filter.gate": 9.21}``, ``{"sensors[1].clutter_rate": 20}``; a list entry
    is picked by index, by its ``name`` (``"sensors.s2.sigma_r"``) or all at once with ``*``
    (``"sensors.*.clutter_rate"``)) or nested tables (``{"filter": {"gate": 9.21}}``).
    """
    path = Path(source)
    if path.is_file():
        label, origin, stem = (path.name if path.parent == Path() else str(path), str(path),
                               path.stem)
        text = path.read_text(encoding="utf-8")
    else:
        key = str(source)
        key = key[: -len(".toml")] if key.endswith(".toml") else key
        if key not in builtin_scenarios():
            raise ScenarioError(
                f"{source}: no such scenario file or built-in scenario "
                f"(built-in: {', '.join(builtin_scenarios())})"
            )
        label, origin, stem = f"{key}.toml", f"builtin:{key}", key
        text = scenario_text(key)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{label}: invalid TOML: {exc}") from None
    offline = data.get("scenario", {}).get("offline") if isinstance(data.get("scenario"),
                                                                    dict) else None
    if offline:  # e.g. seed003.toml: read by its own study, no network peers yet
        raise ScenarioError(f"{label}: an offline study, not a network scenario; run '{offline}'")
    ctx = _Context(label)
    if overrides:
        ctx.override_paths = _apply_overrides(data, overrides, label)
    study = data.get("scenario", {}).get("study") if isinstance(data.get("scenario"),
                                                                dict) else None
    if study is not None:  # a study's own format: the network scenario is built from it
        try:
            data = adapt_document(study, data, label)
        except KeyError as exc:
            raise ScenarioError(str(exc.args[0])) from None
    return _parse(data, ctx, default_name=stem, origin=origin)


def parse_overrides(items: Iterable[str]) -> dict[str, Any]:
    """``["filter.gate=9.21", "fusion.rule=aa"]`` → ``{"filter.gate": 9.21, ...}`` (for CLIs).

    The value is read as a TOML value (``20``, ``1e-4``, ``true``, ``[1, 2]``, ``"s2"``); text that
    is not valid TOML is taken as a bare string, so ``fusion.rule=aa`` works unquoted.
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key, raw = key.strip(), raw.strip()
        if not sep or not key:
            raise ScenarioError(f"override {item!r}: expected KEY=VALUE, e.g. filter.gate=9.21")
        try:
            out[key] = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = raw
    return out


# --------------------------------------------------------------------------------------------
# Overrides
# --------------------------------------------------------------------------------------------

_TOKEN = re.compile(r"\[([^\]]*)\]|([^.\[\]]+)")


def _flatten(overrides: Mapping[str, Any], prefix: str = "") -> Iterable[tuple[str, Any]]:
    for key, value in overrides.items():
        path = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, Mapping):
            yield from _flatten(value, path)
        else:
            yield path, value


def _apply_overrides(data: dict, overrides: Mapping[str, Any], label: str) -> set[str]:
    """Write ``overrides`` into the raw TOML ``data``; return the normalised paths written."""
    written: set[str] = set()
    for key, value in _flatten(overrides):
        tokens = [m.group(1) if m.group(1) is not None else m.group(2)
                  for m in _TOKEN.finditer(key)]
        if not tokens or "".join(_TOKEN.sub("", key).split(".")):
            raise ScenarioError(f"{label} (overrides): malformed key {key!r}")
        for path in _set_path(data, tokens, copy.deepcopy(value), "", key, label):
            written.add(path)
    return written


def _set_path(node: Any, tokens: list[str], value: Any, path: str, key: str,
              label: str) -> list[str]:
    head, rest = tokens[0], tokens[1:]
    if isinstance(node, list):
        if head == "*":
            picks = list(range(len(node)))
        elif head.lstrip("-").isdigit():
            picks = [int(head)]
        else:
            picks = [i for i, e in enumerate(node) if isinstance(e, dict) and e.get("name") == head]
        if not picks or not all(0 <= i < len(node) for i in picks):
            raise ScenarioError(
                f"{label} (overrides): key {key!r}: no entry {head!r} in '{path}' "
                f"(it has {len(node)} entries)"
            )
        if not rest:
            for i in picks:
                node[i] = value
            return [f"{path}[{i}]" for i in picks]
        return [p for i in picks
                for p in _set_path(node[i], rest, value, f"{path}[{i}]", key, label)]
    if not isinstance(node, dict):
        raise ScenarioError(f"{label} (overrides): key {key!r}: '{path}' is not a table")
    here = f"{path}.{head}" if path else head
    if not rest:
        node[head] = value
        return [here]
    child = node.setdefault(head, {})
    return _set_path(child, rest, value, here, key, label)


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------

_REQUIRED = object()


def _choices(options: Iterable[str]) -> str:
    return ", ".join(repr(o) for o in options)


def _short(value: Any) -> str:
    """A value for an error message, TOML-spelled where it differs, at most 60 characters."""
    text = ("true" if value else "false") if isinstance(value, bool) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


@dataclass
class _Context:
    """Where errors point: the file label, and which keys came from overrides."""

    label: str
    override_paths: set[str] = dataclasses.field(default_factory=set)

    def fail(self, path: str, problem: str) -> ScenarioError:
        overridden = any(
            path == p or path.startswith((p + ".", p + "[")) or p.startswith((path + ".",
                                                                              path + "["))
            for p in self.override_paths
        )
        where = f"{self.label} (overrides)" if overridden else self.label
        return ScenarioError(f"{where}: {problem}")


class _Table:
    """One TOML table being read: typed getters; keys outside ``known`` are errors."""

    def __init__(self, data: Any, path: str, ctx: _Context, known: Iterable[str]):
        self.path, self.ctx = path, ctx
        if not isinstance(data, dict):
            raise ctx.fail(path, f"'{path}' must be a table, got {_short(data)}")
        self.data = data
        known = list(known)
        for key in data:
            if key not in known:
                close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
                hint = f" (did you mean '{self.key(close[0])}'?)" if close else ""
                raise ctx.fail(self.key(key), f"unknown key '{self.key(key)}'{hint}")

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, problem: str) -> ScenarioError:
        return self.ctx.fail(self.key(name), f"key '{self.key(name)}' {problem}")

    def raw(self, name: str, default: Any = _REQUIRED) -> Any:
        if name in self.data:
            return self.data[name]
        if default is _REQUIRED:
            raise self.ctx.fail(self.key(name), f"missing required key '{self.key(name)}'")
        return default

    def has(self, name: str) -> bool:
        return name in self.data

    # typed getters ---------------------------------------------------------------------------
    def integer(self, name: str, default: Any = _REQUIRED, minimum: int | None = None,
                maximum: int | None = None) -> int:
        v = self.raw(name, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(name, f"must be an integer, got {_short(v)}")
        if minimum is not None and v < minimum:
            raise self.fail(name, f"must be >= {minimum}, got {v}")
        if maximum is not None and v > maximum:
            raise self.fail(name, f"must be <= {maximum}, got {_short(v)}")
        return v

    def number(self, name: str, default: Any = _REQUIRED, minimum: float | None = None,
              positive: bool = False, probability: bool = False) -> float:
        v = self.raw(name, default)
        v = self._number(name, v)
        if probability and not 0.0 <= v <= 1.0:
            raise self.fail(name, f"must be a probability in [0, 1], got {v:g}")
        if positive and v <= 0:
            raise self.fail(name, f"must be > 0, got {v:g}")
        if minimum is not None and v < minimum:
            raise self.fail(name, f"must be >= {minimum:g} (no negative values), got {v:g}")
        return v

    def _number(self, name: str, v: Any, what: str = "a number") -> float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(name, f"must be {what}, got {_short(v)}")
        if not math.isfinite(v):
            raise self.fail(name, f"must be finite, got {v}")
        return float(v)

    def flag(self, name: str, default: Any = _REQUIRED) -> bool:
        v = self.raw(name, default)
        if not isinstance(v, bool):
            raise self.fail(name, f"must be true or false, got {_short(v)}")
        return v

    def text(self, name: str, default: Any = _REQUIRED) -> str:
        v = self.raw(name, default)
        if not isinstance(v, str) or not v:
            raise self.fail(name, f"must be a non-empty string, got {_short(v)}")
        return v

    def choice(self, name: str, options: Iterable[str], default: Any = _REQUIRED) -> str:
        options = tuple(options)
        v = self.raw(name, default)
        if v not in options:
            close = difflib.get_close_matches(str(v), options, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise self.fail(name, f"is {_short(v)}, expected one of {_choices(options)}{hint}")
        return v

    def vector(self, name: str, length: int, default: Any = _REQUIRED) -> tuple[float, ...]:
        v = self.raw(name, default)
        if not isinstance(v, list | tuple) or len(v) != length:
            raise self.fail(name, f"must be a list of {length} numbers, got {_short(v)}")
        return tuple(self._number(name, x, f"a list of {length} numbers") for x in v)

    def position(self, name: str) -> tuple[float, float]:
        """``[x, y]`` in metres, each within :data:`MAX_COORDINATE`."""
        x, y = self.vector(name, 2)
        if max(abs(x), abs(y)) > MAX_COORDINATE:
            raise self.fail(name, f"is [{x:g}, {y:g}] m, beyond +-{MAX_COORDINATE:g} m")
        return x, y

    def tables(self, name: str, default: Any = _REQUIRED) -> list[Any]:
        v = self.raw(name, default)
        if not isinstance(v, list):
            raise self.fail(name, f"must be an array of tables ([[{self.key(name)}]]), "
                                  f"got {_short(v)}")
        return v

    def covariance(self, dim: int, default: Matrix | None = None) -> Matrix:
        """``cov_diag = [d...]`` or ``cov = [[...]]`` (not both): symmetric positive definite."""
        if self.has("cov_diag") and self.has("cov"):
            raise self.fail("cov", "and 'cov_diag' are both given; use one")
        if self.has("cov"):
            rows = self.raw("cov")
            if not isinstance(rows, list) or len(rows) != dim or not all(
                isinstance(r, list) and len(r) == dim for r in rows
            ):
                raise self.fail("cov", f"must be a {dim} x {dim} list of lists, got {_short(rows)}")
            P = np.array([[self._number("cov", x, "a matrix of numbers") for x in r]
                          for r in rows])
            if not np.allclose(P, P.T, rtol=1e-9, atol=1e-12):
                raise self.fail("cov", "must be symmetric")
            name = "cov"
        elif self.has("cov_diag") or default is None:
            diag = self.vector("cov_diag", dim)
            P = np.diag(diag)
            name = "cov_diag"
        else:
            return default
        eig = np.linalg.eigvalsh(P)
        if eig.min() <= 1e-12 * max(1.0, float(np.abs(eig).max())):
            raise self.fail(name, f"must be positive definite (smallest eigenvalue {eig.min():g})")
        return tuple(tuple(float(x) for x in row) for row in P)


def _diag(values: Iterable[float]) -> Matrix:
    return tuple(tuple(float(x) for x in row) for row in np.diag(list(values)))


PAPER_BIRTH = (
    BirthComponent(0.1, (250.0, 0.0, 250.0, 0.0), _diag([100, 25, 100, 25])),
    BirthComponent(0.1, (-250.0, 0.0, -250.0, 0.0), _diag([100, 25, 100, 25])),
)
"""Seed 000's printed births (§10), the default of ``[[birth.paper]]``."""
TRUTH_BIRTH_COV = _diag([100, 2500, 100, 2500])
"""Default covariance of the ``"truth"`` birth components (§10)."""


def _parse(data: dict, ctx: _Context, default_name: str, origin: str) -> Scenario:
    top = _Table(data, "", ctx, ["scenario", "motion", "targets", "sensors", "birth", "filter",
                                 "fusion", "metrics", "network", "faults", "extended",
                                 "security", "clustering", "pda"])
    sc = _Table(top.raw("scenario"), "scenario", ctx,
                ["name", "seed", "scan_period", "num_scans", "region", "truth", "truth_sigma_w"])
    num_scans = sc.integer("num_scans", minimum=1)
    region = _region(sc)
    mo = _Table(top.raw("motion", {}), "motion", ctx, ["model", "sigma_w", "survival_probability"])
    targets = tuple(
        _target(_Table(t, f"targets[{i}]", ctx, ["birth_scan", "death_scan", "start", "end"]))
        for i, t in enumerate(top.tables("targets", []))
    )
    sensors = _sensors(top, ctx)
    names = [s.name for s in sensors]
    scn = Scenario(
        name=sc.text("name", default_name),
        seed=sc.integer("seed", 0, minimum=0),
        scan_period=sc.number("scan_period", 1.0, positive=True),
        num_scans=num_scans,
        region=region,
        targets=targets,
        sensors=sensors,
        truth=sc.choice("truth", TRUTH_MODELS, "straight"),
        truth_sigma_w=sc.number("truth_sigma_w", 0.0, minimum=0.0),
        motion_model=mo.choice("model", MOTION_MODELS, "cv"),
        sigma_w=mo.number("sigma_w", 2.0, minimum=0.0),
        survival_probability=mo.number("survival_probability", 0.99, probability=True),
        birth=_birth(_Table(top.raw("birth", {}), "birth", ctx, ["model", "paper", "truth"])),
        filter=_filter(_Table(top.raw("filter", {}), "filter", ctx, [
            "prune_threshold", "merge_threshold", "merge_rule", "max_components",
            "extraction_threshold", "extraction", "gate", "refit"])),
        fusion=_fusion(_Table(top.raw("fusion", {}), "fusion", ctx, [
            "rule", "omega", "level2_pruning", "level2_threshold", "fusing_sensor",
            "cardinality", "trust"]), names),
        metrics=_metrics(_Table(top.raw("metrics", {}), "metrics", ctx,
                                ["ospa_cutoff", "ospa_order"])),
        network=_network(_Table(top.raw("network", {}), "network", ctx, [
            "topology", "edges", "rounds", "omega", "max_age", "policy", "feedback", "speed",
            "deadline", "filter", "router"]), names),
        source=origin,
    )
    if top.has("extended"):
        scn = dataclasses.replace(scn, extended=_extended(_Table(
            top.raw("extended"), "extended", ctx, [f.name for f in
                                                   dataclasses.fields(ExtendedSpec)])))
    if top.has("clustering"):
        t = _Table(top.raw("clustering"), "clustering", ctx,
                   [f.name for f in dataclasses.fields(ClusteringSpec)])
        scn = dataclasses.replace(scn, clustering=ClusteringSpec(
            cutoff=t.number("cutoff", 25.0, positive=True),
            zeta=t.number("zeta", 0.3, positive=True),
            radius_factor=t.number("radius_factor", 1.25, positive=True),
            split_factor=t.number("split_factor", 1.6, positive=True),
            assumed_scans=t.choice("assumed_scans", ("held", "all"), "held"),
            estimator=t.choice("estimator", FLOOD_ESTIMATORS, "idpc")))
    if top.has("pda"):
        t = _Table(top.raw("pda"), "pda", ctx, ["config", "mode", "method", "pregate"])
        config = t.raw("config", {})
        if not isinstance(config, dict):
            raise t.fail("config", f"must be a table, got {_short(config)}")
        scn = dataclasses.replace(scn, pda=PdaSpec(
            config=config, mode=t.choice("mode", PDA_MODES, "meas"),
            method=t.choice("method", PDA_METHODS, "fuzzy IMM"),
            pregate=t.number("pregate", 4.0, positive=True)))
    kind = peer_kind(scn.network.filter)
    if scn.fusion.rule not in kind.rules:
        raise ctx.fail("fusion.rule", f"key 'fusion.rule' is {scn.fusion.rule!r}, which "
                       f"{kind.name!r} peers do not take (they take: {', '.join(kind.rules)})")
    if kind.check is not None and (bad := kind.check(scn)) is not None:
        raise ctx.fail(*bad)
    if top.has("security"):
        sec = _Table(top.raw("security"), "security", ctx, ["keys"])
        keys = Path(sec.text("keys"))
        if not keys.is_absolute() and not origin.startswith("builtin:"):
            keys = Path(origin).parent / keys
        scn = dataclasses.replace(scn, security=str(keys))
    raw_faults = top.raw("faults", {})
    if raw_faults != {}:
        faults = _faults(_Table(raw_faults, "faults", ctx, ["default", "peers", "links"]),
                         names, scn.scan_period / scn.network.speed)
        scn = dataclasses.replace(scn, faults=faults)
    return scn


def _region(sc: _Table) -> tuple[tuple[float, float], tuple[float, float]]:
    raw = sc.raw("region")
    if not isinstance(raw, list) or len(raw) != 2:
        raise sc.fail("region", f"must be [[xmin, xmax], [ymin, ymax]], got {_short(raw)}")
    out = []
    for axis, row in zip("xy", raw, strict=True):
        if not isinstance(row, list) or len(row) != 2 or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in row
        ):
            raise sc.fail("region", f"must be [[xmin, xmax], [ymin, ymax]], got {_short(raw)}")
        lo, hi = float(row[0]), float(row[1])
        if max(abs(lo), abs(hi)) > MAX_COORDINATE:
            raise sc.fail("region", f"has {axis} = {max(lo, hi, key=abs):g} m, beyond "
                                    f"+-{MAX_COORDINATE:g} m")
        if not lo < hi:
            raise sc.fail("region", f"has {axis}min {lo:g} >= {axis}max {hi:g} (an empty area)")
        out.append((lo, hi))
    return out[0], out[1]


def _target(t: _Table) -> TargetSpec:
    birth = t.integer("birth_scan", minimum=1)
    death = t.integer("death_scan")
    if death < birth:
        raise t.fail("death_scan", f"is {death}, before birth_scan {birth}")
    start, end = t.position("start"), t.position("end")
    return TargetSpec(birth, death, (start[0], start[1]), (end[0], end[1]))


def _sensors(top: _Table, ctx: _Context) -> tuple[SensorSpec, ...]:
    raw = top.tables("sensors")
    if not raw:
        raise top.fail("sensors", "must list at least one sensor ([[sensors]])")
    if len(raw) > MAX_SENSORS:
        raise top.fail("sensors", f"lists {len(raw):,} sensors, over the limit of "
                                  f"{MAX_SENSORS} (one peer each)")
    out: list[SensorSpec] = []
    seen: dict[str, int] = {}
    for i, entry in enumerate(raw):
        s = _Table(entry, f"sensors[{i}]", ctx, [
            "name", "kind", "position", "sigma_r", "sigma_theta_deg", "detection_probability",
            "clutter_rate"])
        name = s.raw("name")
        try:
            check_name(name, "sensor name", peer=True)
        except ValueError as exc:
            raise ctx.fail(s.key("name"), f"key '{s.key('name')}': {exc}") from None
        if name.lower() in seen:  # a set: linear in the number of sensors
            first = out[seen[name.lower()]].name
            if first == name:
                raise s.fail("name", f"repeats the sensor name {name!r}")
            raise s.fail("name", f"is {name!r}, which differs from sensor {first!r} only in "
                                 f"case (one log file on a case-insensitive file system)")
        seen[name.lower()] = i
        kind = s.choice("kind", SENSOR_KINDS)
        if kind == "range-bearing":
            if not s.has("sigma_theta_deg"):
                raise ctx.fail(s.key("sigma_theta_deg"), f"missing required key "
                               f"'{s.key('sigma_theta_deg')}' (kind 'range-bearing' needs it)")
            sigma_theta = s.number("sigma_theta_deg", minimum=0.0)
        elif s.has("sigma_theta_deg"):
            raise s.fail("sigma_theta_deg", "is only for kind 'range-bearing'")
        else:
            sigma_theta = None
        px, py = s.position("position")
        out.append(SensorSpec(
            name=name,
            kind=kind,
            position=(px, py),
            sigma_r=s.number("sigma_r", 20.0, minimum=0.0),
            sigma_theta_deg=sigma_theta,
            detection_probability=s.number("detection_probability", 0.99, probability=True),
            clutter_rate=s.number("clutter_rate", 10.0, minimum=0.0),
        ))
    return tuple(out)


def _birth(b: _Table) -> BirthSpec:
    model = b.choice("model", BIRTH_MODELS, "paper")
    if b.has("paper"):
        paper = []
        for i, entry in enumerate(b.tables("paper")):
            c = _Table(entry, f"birth.paper[{i}]", b.ctx, ["weight", "mean", "cov_diag", "cov"])
            paper.append(BirthComponent(
                weight=c.number("weight", minimum=0.0),
                mean=c.vector("mean", STATE_DIM),
                cov=c.covariance(STATE_DIM),
            ))
        paper_t = tuple(paper)
    else:
        paper_t = PAPER_BIRTH
    tr = _Table(b.raw("truth", {}), "birth.truth", b.ctx, ["weight", "cov_diag", "cov"])
    return BirthSpec(
        model=model,
        paper=paper_t,
        truth_weight=tr.number("weight", 0.1, minimum=0.0),
        truth_cov=tr.covariance(STATE_DIM, default=TRUTH_BIRTH_COV),
    )


def _filter(f: _Table) -> FilterSpec:
    gate = f.number("gate", positive=True) if f.has("gate") else None
    return FilterSpec(
        prune_threshold=f.number("prune_threshold", 1e-5, minimum=0.0),
        merge_threshold=f.number("merge_threshold", 5.0, minimum=0.0),
        merge_rule=f.choice("merge_rule", MERGE_RULES, "vo-ma"),
        max_components=f.integer("max_components", 100, minimum=1),
        extraction_threshold=f.number("extraction_threshold", 0.5, minimum=0.0),
        extraction=f.choice("extraction", EXTRACTION_RULES, "cardinality"),
        gate=gate,
        refit=f.flag("refit", False),
    )


def _fusion(f: _Table, sensor_names: list[str]) -> FusionSpec:
    fuser = f.choice("fusing_sensor", sensor_names, sensor_names[0])
    return FusionSpec(
        rule=f.choice("rule", FUSION_RULES, "hybrid"),
        omega=f.choice("omega", OMEGA_RULES, "uniform"),
        level2_pruning=f.flag("level2_pruning", True),
        level2_threshold=f.number("level2_threshold", 0.5, minimum=0.0),
        fusing_sensor=fuser,
        cardinality=f.choice("cardinality", CARDINALITY_RULES, "separate"),
        trust=f.flag("trust", False),
    )


def _network(t: _Table, sensor_names: list[str]) -> NetworkSpec:
    topology = t.choice("topology", TOPOLOGIES, "full")
    edges: list[tuple[str, str]] = []
    raw = t.raw("edges", [])
    if not isinstance(raw, list):
        raise t.fail("edges", f"must be a list of [name, name] pairs, got {_short(raw)}")
    for i, e in enumerate(raw):
        if (not isinstance(e, list) or len(e) != 2 or not all(isinstance(x, str) for x in e)
                or e[0] == e[1]):
            raise t.fail("edges", f"entry {i} must be a pair of two different sensor names, "
                                  f"got {_short(e)}")
        for x in e:
            if x not in sensor_names:
                raise t.fail("edges", f"entry {i} names unknown sensor {x!r} "
                                      f"(sensors: {', '.join(sensor_names)})")
        edges.append((e[0], e[1]))
    if topology == "custom" and not edges:
        raise t.fail("edges", "topology 'custom' needs at least one edge")
    if topology != "custom" and edges:
        raise t.fail("edges", f"only used with topology 'custom' (topology is {topology!r})")
    deadline = t.number("deadline", 0.5, positive=True)
    if deadline > 1.0:
        raise t.fail("deadline", f"must be in (0, 1] of a scan interval, got {deadline:g}")
    return NetworkSpec(
        topology=topology,
        edges=tuple(edges),
        rounds=t.integer("rounds", 1, minimum=1, maximum=MAX_ROUNDS),
        omega=t.choice("omega", NETWORK_OMEGA_RULES, "metropolis"),
        max_age=t.integer("max_age", 5, minimum=0),
        policy=t.choice("policy", OOS_POLICIES, "nale"),
        feedback=t.flag("feedback", False),
        speed=t.number("speed", 10.0, positive=True),
        deadline=deadline,
        filter=t.choice("filter", kind_names(), "gmphd"),
        router=t.flag("router", False),
    )


def _extended(t: _Table) -> ExtendedSpec:
    from tracking.partition import DistancePartitioner, GridSpectralPartitioner

    spec = ExtendedSpec(
        rate=t.number("rate", 10.0, positive=True),
        partition=t.choice("partition", PARTITIONS, "distance"),
        p_lower=t.number("p_lower", 0.3, probability=True),
        p_upper=t.number("p_upper", 0.8, probability=True),
        compression=t.number("compression", 0.5, positive=True),
        cell_factor=t.number("cell_factor", 4.0, positive=True),
        core_level=t.number("core_level", 0.5, probability=True),
        rho=t.number("rho", 2.0, positive=True),
        k_rule=t.choice("k_rule", ("eigengap", "core-regions"), "eigengap"),
        k_spread=t.integer("k_spread", 0, minimum=0),
        units=t.choice("units", ("sigma", "unit-box"), "sigma"),
        max_measurements=t.integer("max_measurements", 2000, minimum=1),
    )
    try:
        DistancePartitioner(20.0, spec.p_lower, spec.p_upper)
    except ValueError:
        raise t.fail("p_upper", f"must be >= p_lower and both in (0, 1), got p_lower "
                                f"{spec.p_lower:g}, p_upper {spec.p_upper:g}") from None
    if spec.rho <= 1:
        raise t.fail("rho", f"must be > 1, got {spec.rho:g}")
    if spec.compression > 2:
        raise t.fail("compression", f"must be in (0, 2], got {spec.compression:g}")
    GridSpectralPartitioner(compression=spec.compression, cell_factor=spec.cell_factor,
                            core_level=spec.core_level, rho=spec.rho, k_rule=spec.k_rule,
                            k_spread=spec.k_spread, units=spec.units)
    return spec


def _metrics(m: _Table) -> MetricsSpec:
    order = m.number("ospa_order", 2.0)
    if order < 1:
        raise m.fail("ospa_order", f"must be >= 1, got {order:g}")
    return MetricsSpec(ospa_cutoff=m.number("ospa_cutoff", 200.0, positive=True), ospa_order=order)



# --------------------------------------------------------------------------------------------
# [faults]: the link-fault plan
# --------------------------------------------------------------------------------------------


def parse_faults(table: Mapping[str, Any], interval: float, peers: Iterable[str],
                 label: str = "[faults]") -> FaultPlan:
    """The fault plan of a ``[faults]`` table, checked like a scenario file's (for code that
    builds plans without a file). ``interval`` is the scan interval (s) delays in scans are
    multiples of; ``peers`` the peer names. Errors are :class:`ScenarioError` naming the key
    (``faults.links[0].loss``), prefixed by ``label``.
    """
    if not (isinstance(interval, int | float) and math.isfinite(interval) and interval > 0):
        raise ScenarioError(f"{label}: scan interval must be > 0 s, got {interval!r}")
    ctx = _Context(label)
    return _faults(_Table(dict(table), "faults", ctx, ["default", "peers", "links"]),
                   list(peers), float(interval))


def _faults(f: _Table, names: list[str], interval: float) -> FaultPlan:
    """``faults.default``, ``faults.peers.<name>``, ``faults.links[i]`` -> the resolved plan."""
    ctx = f.ctx
    default = _fault_layer(_Table(f.raw("default", {}), "faults.default", ctx, FAULT_KEYS),
                           interval)
    peers: dict[str, LinkLayer] = {}
    raw = f.raw("peers", {})
    for name in raw if isinstance(raw, dict) else ():
        if name not in names:
            raise ctx.fail(f"faults.peers.{name}", f"key 'faults.peers.{name}' names no peer "
                                                   f"(peers: {', '.join(names)})")
    raw_peers = _Table(raw, "faults.peers", ctx, names)
    for name in raw_peers.data:
        peers[name] = _fault_layer(
            _Table(raw_peers.raw(name), raw_peers.key(name), ctx, FAULT_KEYS), interval)
    links: dict[tuple[str, str], LinkLayer] = {}
    first: dict[tuple[str, str], str] = {}
    for i, entry in enumerate(f.tables("links", [])):
        t = _Table(entry, f"faults.links[{i}]", ctx, ["from", "to", *FAULT_KEYS])
        pair = (t.choice("from", names), t.choice("to", names))
        if pair[0] == pair[1]:
            raise t.fail("to", f"is {pair[1]!r} like 'from': a link joins two different peers")
        if pair in links:
            raise ctx.fail(t.path, f"key '{t.path}' repeats the link {pair[0]} -> {pair[1]} "
                                   f"of '{first[pair]}'")
        links[pair], first[pair] = _fault_layer(t, interval), t.path
    try:
        return FaultPlan.layered(names, interval, default, peers, links)
    except PlanConflict as exc:
        raise ctx.fail(exc.key, str(exc)) from None


def _fault_layer(t: _Table, interval: float) -> LinkLayer:
    """One ``default`` / ``peers.<name>`` / ``links[i]`` table: the keys it sets."""
    kw: dict[str, Any] = {}
    for name in ("loss", "duplicate", "reorder"):
        if t.has(name):
            kw[name] = t.number(name, probability=True)
    for name in ("delay", "reorder_delay"):
        if t.has(name):
            kw[name] = _delay(t, name, interval)
    if t.has("partitions"):
        kw["partitions"] = _partitions(t, "partitions")
    return LinkLayer(**kw, where=t.path)


def _delay(t: _Table, name: str, interval: float) -> Delay:
    """Seconds (a number), a parameterless kind (``"short"``, ``"one-step"``) or a table
    ``{kind = ..., <its parameters>}`` (:data:`DELAY_KINDS`)."""
    v = t.raw(name)
    if isinstance(v, bool) or not isinstance(v, int | float | str | dict):
        raise t.fail(name, f"must be seconds, a delay kind or a table with 'kind', "
                           f"got {_short(v)}")
    if isinstance(v, int | float):
        if not (math.isfinite(v) and v >= 0):
            raise t.fail(name, f"must be a delay >= 0 s, got {_short(v)}")
        return Constant(float(v))
    path = t.key(name)
    if isinstance(v, str):
        kind = t.choice(name, DELAY_KINDS)
        if DELAY_KINDS[kind]:
            raise t.fail(name, f"is {kind!r}, which needs a table: {{kind = \"{kind}\", "
                               + ", ".join(f"{p} = ..." for p in DELAY_KINDS[kind]) + "}")
        d = _Table({"kind": kind}, path, t.ctx, ["kind"])
    else:
        kind = v.get("kind")
        params = DELAY_KINDS[kind] if isinstance(kind, str) and kind in DELAY_KINDS else sorted(
            {p for ps in DELAY_KINDS.values() for p in ps})
        d = _Table(v, path, t.ctx, ["kind", *params])
        kind = d.choice("kind", DELAY_KINDS)
    if kind == "constant":
        return Constant(d.number("value", minimum=0.0))
    if kind == "uniform":
        low, high = d.number("low", minimum=0.0), d.number("high", minimum=0.0)
        if high < low:
            raise d.fail("high", f"must be >= low ({low:g}), got {high:g}")
        return Uniform(low, high)
    if kind == "exponential":
        return Exponential(d.number("mean", positive=True))
    if kind == "scans":
        low, high = d.integer("low", minimum=0), d.integer("high", minimum=0)
        if high < low:
            raise d.fail("high", f"must be >= low ({low}), got {high}")
        return Scans(low, high, interval)
    if kind == "short":
        return ShortDelay(interval)
    if kind == "one-step":
        return OneStep(interval)
    return MultiStep(d.integer("max_steps", minimum=1), interval)


def _partitions(t: _Table, name: str) -> tuple[tuple[float, float], ...]:
    """``[[start, end], ...]``: run-clock seconds, ``0 <= start < end``."""
    raw = t.raw(name)
    if not isinstance(raw, list):
        raise t.fail(name, f"must be a list of [start, end] pairs (s), got {_short(raw)}")
    out = []
    for i, part in enumerate(raw):
        where = f"{t.key(name)}[{i}]"
        ok = isinstance(part, list) and len(part) == 2 and all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
            for x in part)
        if not ok:
            raise t.ctx.fail(where, f"key '{where}' must be [start, end] (s), got {_short(part)}")
        start, end = float(part[0]), float(part[1])
        if start < 0:
            raise t.ctx.fail(where, f"key '{where}' starts before 0 s: {_short(part)}")
        if not end > start:
            raise t.ctx.fail(where, f"key '{where}' must end after it starts, got {_short(part)}")
        out.append((start, end))
    return tuple(out)


__all__ = [
    "BIRTH_MODELS",
    "FUSION_RULES",
    "OMEGA_RULES",
    "SENSOR_KINDS",
    "BirthComponent",
    "BirthSpec",
    "ExtendedSpec",
    "FilterSpec",
    "FusionSpec",
    "MetricsSpec",
    "NetworkSpec",
    "Scenario",
    "ScenarioError",
    "SensorSpec",
    "TargetSpec",
    "builtin_scenarios",
    "load_scenario",
    "parse_faults",
    "parse_overrides",
    "scenario_text",
    "with_birth_model",
]
