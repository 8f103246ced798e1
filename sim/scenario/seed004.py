"""Seed 004's file (``[scenario] study = "seed004"``, ``sim/scenarios/seed004.toml``): its keys
declared once (:func:`sim.scenario.options.option`, each with its table as the key's prefix)
and read by :func:`read_seed004` with the scenario's readers, so a mistake is the scenario's
one-line ``ScenarioError`` naming the dotted key. The file parametrises what the network
scenario derives (sensors on a random geometric graph, the targets at the birth means):
:mod:`sim.studies.seed004.scenario` builds the offline model and the network document from a
:class:`Seed004File`; docs/scenario.md documents its tables."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from sensornet.sim.bounds import MAX_COORDINATE, MAX_ROUNDS, MAX_SENSORS
from sensornet.sim.scenario.common import ASSUMED_SCANS, FLOOD_ESTIMATORS, Matrix
from sensornet.sim.scenario.options import (
    NONNEGATIVE,
    POSITIVE,
    PROBABILITY,
    Bound,
    at_least,
    keys,
    option,
)
from sensornet.sim.scenario.reading import read
from sensornet.sim.scenario.tables import Context, Table, brief
from sensornet.tracking.gci_product import CARDINALITY_RULES

VARIANTS = ("linear", "range-bearing", "mixed")
"""Seed 004's sensor kinds: all linear, all range-bearing, or even sensors linear."""
TABLES = ("scenario", "truth", "sensors", "filter", "clustering", "flooding", "consensus",
          "metrics")
"""The file's tables, in order (``[network]``, ``[faults]``, ``[security]`` and ``[fusion]``
are the network scenario's own, passed to it)."""
ROUNDS = Bound(1, MAX_ROUNDS)


@dataclass(frozen=True)
class Seed004File:
    """The settings of a seed-004 file (docs/seed004.md); positions and states as tuples."""

    seed: int = option(4, doc="Base seed; Monte Carlo run `r` draws from `(seed, r)`.",
                       key="scenario.seed", check=NONNEGATIVE)
    scan_period: float = option(1.0, doc="`T`.", unit="s", key="scenario.scan_period",
                                check=POSITIVE)
    num_scans: int = option(60, doc="Scans in a run.", key="scenario.num_scans",
                            check=at_least(1))
    region: tuple[tuple[float, float], tuple[float, float]] = option(
        ((-1000.0, 1000.0), (-1000.0, 1000.0)), doc="`[[xmin, xmax], [ymin, ymax]]`, "
        "non-empty; clutter is uniform over it.", unit="m", key="scenario.region",
        custom="`[[-1000, 1000], [-1000, 1000]]`")
    variant: str = option("linear", doc="Sensor kinds: `\"linear\"`, `\"range-bearing\"` or "
                                        "`\"mixed\"` (even sensors linear).",
                          key="scenario.variant", choices=VARIANTS)
    truth_sigma_w: float = option(0.0, doc="Process noise of the truth; 0: straight lines.",
                                  unit="m/s^2", key="truth.sigma_w", check=NONNEGATIVE)
    starts: Matrix = option((), doc="Each target's state `[px, vx, py, vy]` at scan 1 (every "
                                    "target lives the whole run; also the birth means).",
                            unit="m, m/s", key="truth.starts", custom="none")
    detection_probability: float = option(0.95, doc="`Pd` of every sensor.",
                                          key="sensors.detection_probability",
                                          check=PROBABILITY)
    clutter_rate: float = option(10.0, doc="Poisson mean of clutter per sensor and scan, "
                                           "uniform over the region.",
                                 key="sensors.clutter_rate", check=NONNEGATIVE)
    sigma: float = option(10.0, doc="Linear sensors: noise per axis.", unit="m",
                          key="sensors.sigma", check=POSITIVE)
    sigma_range: float = option(10.0, doc="Range-bearing sensors: range noise.", unit="m",
                                key="sensors.sigma_range", check=POSITIVE)
    sigma_bearing_deg: float = option(0.5, doc="Range-bearing sensors: bearing noise.",
                                      unit="deg", key="sensors.sigma_bearing_deg",
                                      check=POSITIVE)
    radius: float = option(800.0, doc="Sensors within this distance are linked; the graph must "
                                      "be connected.", unit="m", key="sensors.radius",
                           check=POSITIVE)
    positions: tuple[tuple[float, float], ...] = option(
        (), doc=f"The sensors `[[x, y], ...]` (`s1`, `s2`, ... in the network), at most "
                f"{MAX_SENSORS}.", unit="m", key="sensors.positions", custom="none")
    sigma_w: float = option(2.0, doc="The GM-PHD filters' CV process noise.", unit="m/s^2",
                            key="filter.sigma_w", check=NONNEGATIVE)
    survival_probability: float = option(0.98, doc="`Ps`.", key="filter.survival_probability",
                                         check=PROBABILITY)
    birth_weight: float = option(0.05, doc="Weight of the birth component at each start.",
                                 key="filter.birth_weight", check=NONNEGATIVE)
    birth_cov_diag: tuple[float, ...] = option(
        (100.0, 25.0, 100.0, 25.0), doc="Diagonal of each birth component's covariance.",
        unit="m^2, m^2/s^2", key="filter.birth_cov_diag", custom="`[100, 25, 100, 25]`")
    prune_threshold: float = option(1e-5, doc="GM-PHD pruning threshold.",
                                    key="filter.prune_threshold", check=NONNEGATIVE)
    merge_threshold: float = option(4.0, doc="GM-PHD merge threshold.",
                                    key="filter.merge_threshold", check=NONNEGATIVE)
    max_components: int = option(100, doc="GM-PHD component cap.", key="filter.max_components",
                                 check=at_least(1))
    publish_threshold: float = option(0.01, doc="Components lighter than this are not sent.",
                                      key="filter.publish_threshold", check=NONNEGATIVE)
    cardinality: str = option("separate", doc="GCI target number (`fusion.cardinality`).",
                              key="filter.cardinality", choices=CARDINALITY_RULES)
    cutoff: float = option(25.0, doc="IDPC/FTC `d_c`.", unit="m", key="clustering.cutoff",
                           check=POSITIVE)
    zeta: float = option(0.3, doc="IDPC `zeta`.", key="clustering.zeta", check=POSITIVE)
    radius_factor: float = option(1.25, doc="IDPC `L`.", key="clustering.radius_factor",
                                  check=POSITIVE)
    split_factor: float = option(1.6, doc="IDPC split factor.", key="clustering.split_factor",
                                 check=POSITIVE)
    iterations: int = option(4, doc="Flooding iterations (the diameter: complete on a loss-free "
                                    "network).", key="flooding.iterations", check=ROUNDS)
    assumed_scans: str = option("held", doc="`S` in IDPC after incomplete flooding: the scans "
                                            "a peer holds or every sensor's.",
                                key="flooding.assumed_scans", choices=ASSUMED_SCANS)
    estimator: str = option("idpc", doc="The flooding peers' estimator (`clustering."
                                        "estimator`).", key="flooding.estimator",
                            choices=FLOOD_ESTIMATORS)
    rounds: tuple[int, ...] = option((1, 2, 3, 4), doc="GCI and AA consensus rounds compared, "
                                                       f"each in 1..{MAX_ROUNDS}.",
                                     key="consensus.rounds", custom="`[1, 2, 3, 4]`")
    ospa_cutoff: float = option(100.0, doc="OSPA `c`.", unit="m", key="metrics.ospa_cutoff",
                                check=POSITIVE)
    ospa_order: float = option(2.0, doc="OSPA `p`.", key="metrics.ospa_order",
                               check=at_least(1))


def read_seed004(doc: dict, label: str, overridden: Iterable[str] = ()) -> Seed004File:
    """The settings of seed-004 document ``doc`` (``[network]``, ``[faults]``, ``[security]``,
    ``[fusion]`` left out by the caller), each key checked as declared; ``overridden``: the
    dotted keys an override wrote (their errors say ``(overrides)``)."""
    ctx = Context(label, set(overridden))
    top = Table(doc, "", ctx, TABLES)
    t = {name: Table(top.raw(name, {}), name, ctx,
                     [*keys(Seed004File, name), *(("name", "study") if name == "scenario"
                                                   else ())])
         for name in TABLES}
    values = {k: v for name in TABLES for k, v in read(t[name], Seed004File, name).items()}
    positions = _points(t["sensors"], "positions", 2)
    if len(positions) > MAX_SENSORS:
        raise t["sensors"].fail("positions", f"lists {len(positions):,} sensors, over the "
                                             f"limit of {MAX_SENSORS}")
    rounds = t["consensus"].raw("rounds", [1, 2, 3, 4])
    if not (isinstance(rounds, list) and rounds and all(
            isinstance(r, int) and not isinstance(r, bool) and ROUNDS.problem(r) is None
            for r in rounds)):
        raise t["consensus"].fail("rounds", f"must be integers in 1..{MAX_ROUNDS}, got "
                                            f"{brief(rounds)}")
    cov = Seed004File().birth_cov_diag
    if t["filter"].has("birth_cov_diag"):
        cov = t["filter"].vector("birth_cov_diag", 4)
        if min(cov) <= 0:
            raise t["filter"].fail("birth_cov_diag", f"must be 4 numbers > 0, got {cov}")
    return Seed004File(**values, region=_region(t["scenario"]), positions=positions,
                       starts=_points(t["truth"], "starts", 4), rounds=tuple(rounds),
                       birth_cov_diag=cov)


def _points(t: Table, name: str, dim: int) -> tuple[tuple[float, ...], ...]:
    """A list of ``dim``-number lists, finite and within :data:`MAX_COORDINATE`."""
    raw = t.raw(name, [])
    what = "[x, y] pairs" if dim == 2 else f"lists of {dim} numbers"
    if not isinstance(raw, list) or not all(isinstance(p, list) and len(p) == dim
                                            for p in raw):
        raise t.fail(name, f"must be a list of {what}, got {brief(raw)}")
    out = tuple(tuple(t._number(name, x, f"a list of {what}") for x in p) for p in raw)
    if any(abs(x) > MAX_COORDINATE for p in out for x in p):
        raise t.fail(name, f"must be finite and within +-{MAX_COORDINATE:g} m")
    return out


def _region(t: Table) -> tuple[tuple[float, float], tuple[float, float]]:
    raw = t.raw("region", None)
    if raw is None:
        return Seed004File().region
    if not isinstance(raw, list) or len(raw) != 2 or not all(
            isinstance(r, list) and len(r) == 2 and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in r) for r in raw):
        raise t.fail("region", f"must be [[xmin, xmax], [ymin, ymax]] (m), got {brief(raw)}")
    (x0, x1), (y0, y1) = ((float(a), float(b)) for a, b in raw)
    if not all(math.isfinite(v) and abs(v) <= MAX_COORDINATE for v in (x0, x1, y0, y1)):
        raise t.fail("region", f"must be finite and within +-{MAX_COORDINATE:g} m")
    if not (x0 < x1 and y0 < y1):
        raise t.fail("region", "must have xmin < xmax and ymin < ymax (a non-empty area)")
    return (x0, x1), (y0, y1)
