"""The sections of a scenario about what is there and how it is seen and filtered: targets,
sensors, births, the GM-PHD filter, recorded traffic and the metrics (re-exported by
:mod:`sim.scenario.model`). Each option is declared once in its field
(:func:`sim.scenario.options.option`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from sensornet.sim.choices import BIRTH_MODELS
from sensornet.sim.scenario.common import SENSOR_KINDS, Matrix, _diag
from sensornet.sim.scenario.options import (
    NONNEGATIVE,
    POSITIVE,
    PROBABILITY,
    at_least,
    option,
)
from sensornet.tracking.gmphd import EXTRACTION_RULES
from sensornet.tracking.reduction import MERGE_RULES


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
    corroborate_scans: int = option(0, doc="Labelled GM-PHD peers: scans after its first "
                                           "publication in which an own label that no "
                                           "neighbour's track was paired with "
                                           "(uncorroborated) moves a scan later, every scan, "
                                           "and going dark makes it be stamped anew on return "
                                           "(`peers.stamp_moves`); 1: only the move in the scan "
                                           "of its first publication; 0: 2 with births alike at "
                                           "every peer (`network.birth_ids` `\"shared\"`, fixed "
                                           "birth points), else 1 (issue 33: a clutter track at "
                                           "a birth point scans before a target no longer gives "
                                           "the target its id; training runs, 20 peers, Pd "
                                           "0.99: fused OSPA(2) 17.4 -> 12.0 and 21.8 -> 15.0 m "
                                           "on the two runs it acts on).",
                                    unit="scans", check=NONNEGATIVE)
    time_slice: float = option(0.0, doc="GM-PHD peers: plots at their own times (issue 34, "
                                        "recorded traffic, measurement births): the peer takes "
                                        "a rotating radar's plots in slices of this length at "
                                        "the slice's midpoint (sector `Pd` with soft edges and "
                                        "sector clutter, as `lmb.time_slice`; "
                                        "`peers.gmphd_own_times`), then predicts to the tick; "
                                        "divides `scenario.scan_period`. 0: every plot at its "
                                        "tick.", unit="s", check=NONNEGATIVE)


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
