"""A scenario document to a :class:`Scenario`: each section read and checked."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from sensornet.protocol.keys import check_name
from sensornet.sim.kinds import kind as peer_kind
from sensornet.sim.kinds import names as kind_names
from sensornet.sim.scenario.faults import _faults
from sensornet.sim.scenario.model import (
    BIRTH_MODELS,
    CARDINALITY_RULES,
    EXTRACTION_RULES,
    FLOOD_ESTIMATORS,
    FUSION_RULES,
    LIE_KINDS,
    MAX_COORDINATE,
    MAX_ROUNDS,
    MAX_SENSORS,
    MOTION_MODELS,
    NETWORK_OMEGA_RULES,
    OMEGA_RULES,
    OOS_POLICIES,
    PARTITIONS,
    PDA_METHODS,
    PDA_MODES,
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
    Matrix,
    MetricsSpec,
    NetworkSpec,
    PdaSpec,
    Scenario,
    SensorSpec,
    TargetSpec,
    listing,
)
from sensornet.sim.scenario.tables import Context, Table, brief
from sensornet.tracking.reduction import MERGE_RULES


def _diag(values: Iterable[float]) -> Matrix:
    return tuple(tuple(float(x) for x in row) for row in np.diag(list(values)))


PAPER_BIRTH = (
    BirthComponent(0.1, (250.0, 0.0, 250.0, 0.0), _diag([100, 25, 100, 25])),
    BirthComponent(0.1, (-250.0, 0.0, -250.0, 0.0), _diag([100, 25, 100, 25])),
)
"""Seed 000's printed births (§10), the default of ``[[birth.paper]]``."""
TRUTH_BIRTH_COV = _diag([100, 2500, 100, 2500])
"""Default covariance of the ``"truth"`` birth components (§10)."""


def parse_document(data: dict, ctx: Context, default_name: str, origin: str) -> Scenario:
    top = Table(data, "", ctx, ["scenario", "motion", "targets", "sensors", "birth", "filter",
                                 "fusion", "metrics", "network", "faults", "extended",
                                 "security", "clustering", "pda"])
    sc = Table(top.raw("scenario"), "scenario", ctx,
                ["name", "seed", "scan_period", "num_scans", "region", "truth", "truth_sigma_w"])
    num_scans = sc.integer("num_scans", minimum=1)
    region = _region(sc)
    mo = Table(top.raw("motion", {}), "motion", ctx, ["model", "sigma_w", "survival_probability"])
    targets = tuple(
        _target(Table(t, f"targets[{i}]", ctx, ["birth_scan", "death_scan", "start", "end"]))
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
        birth=_birth(Table(top.raw("birth", {}), "birth", ctx, ["model", "paper", "truth"])),
        filter=_filter(Table(top.raw("filter", {}), "filter", ctx, [
            "prune_threshold", "merge_threshold", "merge_rule", "max_components",
            "extraction_threshold", "extraction", "gate", "refit"])),
        fusion=_fusion(Table(top.raw("fusion", {}), "fusion", ctx, [
            "rule", "omega", "level2_pruning", "level2_threshold", "fusing_sensor",
            "cardinality", "trust", "trust_register", "trust_repair", "lie"]), names),
        metrics=_metrics(Table(top.raw("metrics", {}), "metrics", ctx,
                                ["ospa_cutoff", "ospa_order"])),
        network=_network(Table(top.raw("network", {}), "network", ctx, [
            "topology", "edges", "rounds", "omega", "max_age", "policy", "feedback", "speed",
            "deadline", "filter", "router"]), names),
        source=origin,
    )
    if top.has("extended"):
        scn = dataclasses.replace(scn, extended=_extended(Table(
            top.raw("extended"), "extended", ctx, [f.name for f in
                                                   dataclasses.fields(ExtendedSpec)])))
    if top.has("clustering"):
        t = Table(top.raw("clustering"), "clustering", ctx,
                   [f.name for f in dataclasses.fields(ClusteringSpec)])
        scn = dataclasses.replace(scn, clustering=ClusteringSpec(
            cutoff=t.number("cutoff", 25.0, positive=True),
            zeta=t.number("zeta", 0.3, positive=True),
            radius_factor=t.number("radius_factor", 1.25, positive=True),
            split_factor=t.number("split_factor", 1.6, positive=True),
            assumed_scans=t.choice("assumed_scans", ("held", "all"), "held"),
            estimator=t.choice("estimator", FLOOD_ESTIMATORS, "idpc")))
    if top.has("pda"):
        t = Table(top.raw("pda"), "pda", ctx, ["config", "mode", "method", "pregate"])
        config = t.raw("config", {})
        if not isinstance(config, dict):
            raise t.fail("config", f"must be a table, got {brief(config)}")
        scn = dataclasses.replace(scn, pda=PdaSpec(
            tables=json.dumps(config, sort_keys=True), mode=t.choice("mode", PDA_MODES, "meas"),
            method=t.choice("method", PDA_METHODS, "fuzzy IMM"),
            pregate=t.number("pregate", 4.0, positive=True)))
    kind = peer_kind(scn.network.filter)
    if scn.fusion.rule not in kind.rules:
        raise ctx.fail("fusion.rule", f"key 'fusion.rule' is {scn.fusion.rule!r}, which "
                       f"{kind.name!r} peers do not take (they take: {', '.join(kind.rules)})")
    if kind.check is not None and (bad := kind.check(scn)) is not None:
        raise ctx.fail(*bad)
    if top.has("security"):
        sec = Table(top.raw("security"), "security", ctx, ["keys"])
        keys = Path(sec.text("keys"))
        if not keys.is_absolute() and not origin.startswith("builtin:"):
            keys = Path(origin).parent / keys
        scn = dataclasses.replace(scn, security=str(keys))
    raw_faults = top.raw("faults", {})
    if raw_faults != {}:
        faults = _faults(Table(raw_faults, "faults", ctx, ["default", "peers", "links"]),
                         names, scn.scan_period / scn.network.speed)
        scn = dataclasses.replace(scn, faults=faults)
    return scn


def _region(sc: Table) -> tuple[tuple[float, float], tuple[float, float]]:
    raw = sc.raw("region")
    if not isinstance(raw, list) or len(raw) != 2:
        raise sc.fail("region", f"must be [[xmin, xmax], [ymin, ymax]], got {brief(raw)}")
    out = []
    for axis, row in zip("xy", raw, strict=True):
        if not isinstance(row, list) or len(row) != 2 or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in row
        ):
            raise sc.fail("region", f"must be [[xmin, xmax], [ymin, ymax]], got {brief(raw)}")
        lo, hi = float(row[0]), float(row[1])
        if max(abs(lo), abs(hi)) > MAX_COORDINATE:
            raise sc.fail("region", f"has {axis} = {max(lo, hi, key=abs):g} m, beyond "
                                    f"+-{MAX_COORDINATE:g} m")
        if not lo < hi:
            raise sc.fail("region", f"has {axis}min {lo:g} >= {axis}max {hi:g} (an empty area)")
        out.append((lo, hi))
    return out[0], out[1]


def _target(t: Table) -> TargetSpec:
    birth = t.integer("birth_scan", minimum=1)
    death = t.integer("death_scan")
    if death < birth:
        raise t.fail("death_scan", f"is {death}, before birth_scan {birth}")
    start, end = t.position("start"), t.position("end")
    return TargetSpec(birth, death, (start[0], start[1]), (end[0], end[1]))


def _sensors(top: Table, ctx: Context) -> tuple[SensorSpec, ...]:
    raw = top.tables("sensors")
    if not raw:
        raise top.fail("sensors", "must list at least one sensor ([[sensors]])")
    if len(raw) > MAX_SENSORS:
        raise top.fail("sensors", f"lists {len(raw):,} sensors, over the limit of "
                                  f"{MAX_SENSORS} (one peer each)")
    out: list[SensorSpec] = []
    seen: dict[str, int] = {}
    for i, entry in enumerate(raw):
        s = Table(entry, f"sensors[{i}]", ctx, [
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


def _birth(b: Table) -> BirthSpec:
    model = b.choice("model", BIRTH_MODELS, "paper")
    if b.has("paper"):
        paper = []
        for i, entry in enumerate(b.tables("paper")):
            c = Table(entry, f"birth.paper[{i}]", b.ctx, ["weight", "mean", "cov_diag", "cov"])
            paper.append(BirthComponent(
                weight=c.number("weight", minimum=0.0),
                mean=c.vector("mean", STATE_DIM),
                cov=c.covariance(STATE_DIM),
            ))
        paper_t = tuple(paper)
    else:
        paper_t = PAPER_BIRTH
    tr = Table(b.raw("truth", {}), "birth.truth", b.ctx, ["weight", "cov_diag", "cov"])
    return BirthSpec(
        model=model,
        paper=paper_t,
        truth_weight=tr.number("weight", 0.1, minimum=0.0),
        truth_cov=tr.covariance(STATE_DIM, default=TRUTH_BIRTH_COV),
    )


def _filter(f: Table) -> FilterSpec:
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


def _fusion(f: Table, sensor_names: list[str]) -> FusionSpec:
    fuser = f.choice("fusing_sensor", sensor_names, sensor_names[0])
    return FusionSpec(
        rule=f.choice("rule", FUSION_RULES, "hybrid"),
        omega=f.choice("omega", OMEGA_RULES, "uniform"),
        level2_pruning=f.flag("level2_pruning", True),
        level2_threshold=f.number("level2_threshold", 0.5, minimum=0.0),
        fusing_sensor=fuser,
        cardinality=f.choice("cardinality", CARDINALITY_RULES, "separate"),
        trust=f.flag("trust", False),
        trust_register=f.flag("trust_register", True),
        trust_repair=f.flag("trust_repair", True),
        lie=_lie(f, sensor_names),
    )


def _lie(f: Table, sensor_names: list[str]) -> str:
    """``fusion.lie = "PEER:KIND"`` (test hook, :mod:`sim.lying`): that peer tells lie KIND."""
    v = f.raw("lie", "")
    if v == "":
        return ""
    peer, _, kind = str(v).partition(":")
    if not isinstance(v, str) or peer not in sensor_names or kind not in LIE_KINDS:
        raise f.fail("lie", f"must be \"PEER:KIND\" with a sensor's name and KIND one of "
                            f"{listing(LIE_KINDS)}, got {brief(v)}")
    return v


def _network(t: Table, sensor_names: list[str]) -> NetworkSpec:
    topology = t.choice("topology", TOPOLOGIES, "full")
    edges: list[tuple[str, str]] = []
    raw = t.raw("edges", [])
    if not isinstance(raw, list):
        raise t.fail("edges", f"must be a list of [name, name] pairs, got {brief(raw)}")
    for i, e in enumerate(raw):
        if (not isinstance(e, list) or len(e) != 2 or not all(isinstance(x, str) for x in e)
                or e[0] == e[1]):
            raise t.fail("edges", f"entry {i} must be a pair of two different sensor names, "
                                  f"got {brief(e)}")
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


def _extended(t: Table) -> ExtendedSpec:
    # heavy dependency: scipy.stats (tracking.partition pulls in scipy.stats and scipy.ndimage,
    # about 1 s of start-up on 2 busy cores, which only extended-target scenarios need)
    from sensornet.tracking.partition import DistancePartitioner, GridSpectralPartitioner

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


def _metrics(m: Table) -> MetricsSpec:
    order = m.number("ospa_order", 2.0)
    if order < 1:
        raise m.fail("ospa_order", f"must be >= 1, got {order:g}")
    return MetricsSpec(ospa_cutoff=m.number("ospa_cutoff", 200.0, positive=True), ospa_order=order)



