"""A scenario document to a :class:`Scenario`: each section read and checked."""

from __future__ import annotations

import dataclasses
import math
from datetime import datetime
from pathlib import Path

from sensornet.protocol.keys import check_name
from sensornet.sim.kinds import kind as peer_kind
from sensornet.sim.scenario.common import parse_lie
from sensornet.sim.scenario.faults import _faults
from sensornet.sim.scenario.model import (
    LIE_KINDS,
    MAX_COORDINATE,
    MAX_SENSORS,
    STATE_DIM,
    BirthComponent,
    BirthSpec,
    ClusteringSpec,
    ExtendedSpec,
    FilterSpec,
    FusionSpec,
    LmbSpec,
    ManoeuvreSpec,
    MetricsSpec,
    NetworkSpec,
    PdaSpec,
    Scenario,
    SensorSpec,
    TargetSpec,
    TrafficSpec,
    listing,
)
from sensornet.sim.scenario.options import keys
from sensornet.sim.scenario.parse_study import read_manoeuvre, read_pda
from sensornet.sim.scenario.reading import read, value
from sensornet.sim.scenario.tables import Context, Table, brief


def _section(top: Table, name: str, cls: type) -> Table:
    """Table ``[name]`` (empty when absent), accepting ``cls``'s keys."""
    return Table(top.raw(name, {}), name, top.ctx, keys(cls))


# --------------------------------------------------------------------------------------------
# The document
# --------------------------------------------------------------------------------------------


def parse_document(data: dict, ctx: Context, default_name: str, origin: str) -> Scenario:
    top = Table(data, "", ctx, keys(Scenario))
    sc = Table(top.raw("scenario"), "scenario", ctx, keys(Scenario, "scenario"))
    mo = Table(top.raw("motion", {}), "motion", ctx, keys(Scenario, "motion"))
    values = read(sc, Scenario, "scenario")
    region = _region(sc)
    targets = tuple(
        _target(Table(t, f"targets[{i}]", ctx, keys(TargetSpec)))
        for i, t in enumerate(top.tables("targets", []))
    )
    truth = values["truth"]
    traffic = None
    if top.has("traffic") or truth == "recorded":
        traffic = _traffic(_section(top, "traffic", TrafficSpec), origin)
    sensors = _sensors(top, ctx, truth, traffic)
    names = [s.name for s in sensors]
    scn = Scenario(
        **values,
        **read(mo, Scenario, "motion"),
        name=sc.text("name", default_name),
        region=region,
        targets=targets,
        sensors=sensors,
        birth=_birth(_section(top, "birth", BirthSpec)),
        filter=FilterSpec(**read(_section(top, "filter", FilterSpec), FilterSpec)),
        fusion=_fusion(_section(top, "fusion", FusionSpec), names),
        metrics=MetricsSpec(**read(_section(top, "metrics", MetricsSpec), MetricsSpec)),
        network=_network(_section(top, "network", NetworkSpec), names),
        traffic=traffic,
        source=origin,
    )
    if top.has("extended"):
        scn = dataclasses.replace(scn, extended=_extended(_section(top, "extended",
                                                                   ExtendedSpec)))
    if top.has("clustering"):
        scn = dataclasses.replace(scn, clustering=ClusteringSpec(
            **read(_section(top, "clustering", ClusteringSpec), ClusteringSpec)))
    if top.has("lmb"):
        scn = dataclasses.replace(scn, lmb=LmbSpec(**read(_section(top, "lmb", LmbSpec),
                                                          LmbSpec)))
    if top.has("pda"):
        scn = dataclasses.replace(scn, pda=read_pda(_section(top, "pda", PdaSpec),
                                                        len(sensors)))
    if top.has("manoeuvre"):
        t = _section(top, "manoeuvre", ManoeuvreSpec)
        if truth != "seed001":
            raise top.fail("manoeuvre", f"is only for truth 'seed001' (scenario.truth is "
                                        f"{truth!r})")
        scn = dataclasses.replace(scn, manoeuvre=read_manoeuvre(t))
    kind = peer_kind(scn.network.filter)
    if scn.fusion.rule not in kind.rules:
        raise ctx.fail("fusion.rule", f"key 'fusion.rule' is {scn.fusion.rule!r}, which "
                       f"{kind.name!r} peers do not take (they take: {', '.join(kind.rules)})")
    if kind.check is not None and (bad := kind.check(scn)) is not None:
        raise ctx.fail(*bad)
    if top.has("security"):
        sec = Table(top.raw("security"), "security", ctx, keys(Scenario, "security"))
        keys_dir = Path(sec.text("keys"))
        if not keys_dir.is_absolute() and not origin.startswith("builtin:"):
            keys_dir = Path(origin).parent / keys_dir
        scn = dataclasses.replace(scn, security=str(keys_dir))
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
    spec = TargetSpec(**read(t, TargetSpec))
    if spec.death_scan < spec.birth_scan:
        raise t.fail("death_scan", f"is {spec.death_scan}, before birth_scan {spec.birth_scan}")
    return spec


def _site(s: Table, traffic: TrafficSpec | None) -> tuple[tuple[float, float],
                                                         tuple[float, float] | None]:
    """A sensor's ``(position, site)``: ``position`` as given, or its ``site`` (latitude,
    longitude) as the east-north point about ``traffic.centre`` (pymap3d, heights 0)."""
    if not s.has("site"):
        if not s.has("position"):
            raise s.ctx.fail(s.key("position"), f"missing required key '{s.key('position')}' "
                                                f"(or 'site' = [latitude, longitude])")
        return s.position("position"), None
    if s.has("position"):
        raise s.fail("site", "and 'position' are both given; use one")
    lat, lon = s.vector("site", 2)
    if not (abs(lat) <= 90 and abs(lon) <= 180):
        raise s.fail("site", f"is [{lat:g}, {lon:g}], not a [latitude, longitude] in degrees")
    if traffic is None or traffic.centre is None:
        raise s.fail("site", "needs 'traffic.centre' (the origin of the local frame)")
    # heavy optional dependency: pymap3d (25 ms of CPU at every process's start, for sites)
    import pymap3d
    e, n, _ = pymap3d.geodetic2enu(lat, lon, 0.0, *traffic.centre, 0.0)
    return (float(e), float(n)), (lat, lon)


def _sensors(top: Table, ctx: Context, truth: str = "straight",
             traffic: TrafficSpec | None = None) -> tuple[SensorSpec, ...]:
    raw = top.tables("sensors")
    if not raw:
        raise top.fail("sensors", "must list at least one sensor ([[sensors]])")
    if len(raw) > MAX_SENSORS:
        raise top.fail("sensors", f"lists {len(raw):,} sensors, over the limit of "
                                  f"{MAX_SENSORS} (one peer each)")
    out: list[SensorSpec] = []
    seen: dict[str, int] = {}
    for i, entry in enumerate(raw):
        s = Table(entry, f"sensors[{i}]", ctx, keys(SensorSpec))
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
        values = read(s, SensorSpec)
        if values["kind"] == "range-bearing" or truth == "recorded":
            if not s.has("sigma_theta_deg"):
                why = ("kind 'range-bearing'" if values["kind"] == "range-bearing"
                       else "a radar of recorded traffic")
                raise ctx.fail(s.key("sigma_theta_deg"), f"missing required key "
                               f"'{s.key('sigma_theta_deg')}' ({why} needs it)")
        elif s.has("sigma_theta_deg"):
            raise s.fail("sigma_theta_deg", "is only for kind 'range-bearing'")
        if truth == "recorded" and values["kind"] == "linear" and not s.has("plot_sigma"):
            raise ctx.fail(s.key("plot_sigma"), f"missing required key '{s.key('plot_sigma')}' "
                                                f"(a linear radar of recorded traffic needs it)")
        if s.has("plot_sigma") and (truth != "recorded" or values["kind"] != "linear"):
            raise s.fail("plot_sigma", "is only for linear sensors of recorded traffic")
        recorded = ("rotation_period", "phase", "max_range")
        if truth != "recorded":
            for k in recorded:
                if s.has(k):
                    raise s.fail(k, f"is only for recorded traffic (scenario.truth is {truth!r})")
        elif not s.has("max_range"):
            raise ctx.fail(s.key("max_range"), f"missing required key '{s.key('max_range')}' "
                                               f"(recorded traffic needs each sensor's coverage)")
        if s.has("phase") and not s.has("rotation_period"):
            raise s.fail("phase", "needs 'rotation_period'")
        position, site = _site(s, traffic)
        out.append(SensorSpec(**values, name=name, position=position, site=site,
                              sigma_theta_deg=value(s, SensorSpec, "sigma_theta_deg")))
    return tuple(out)


def _when(t: Table, name: str) -> float | str | None:
    """``traffic.start``/``end``: an ISO 8601 time (checked here) or seconds (a number)."""
    if not t.has(name):
        return None
    v = t.raw(name)
    if isinstance(v, str):
        try:
            datetime.fromisoformat(v)
        except ValueError:
            raise t.fail(name, f"must be an ISO 8601 time or a number of seconds, got "
                               f"{brief(v)}") from None
        return v
    if isinstance(v, datetime):  # a TOML date-time
        return v.isoformat()
    return t._number(name, v, "an ISO 8601 time or a number of seconds")


def _traffic(t: Table, origin: str) -> TrafficSpec:
    """``[traffic]``: the file resolved against the scenario file's folder, the window, the
    region; centre and radius go together."""
    values = read(t, TrafficSpec)
    file = ""
    if t.has("file"):
        path = Path(t.text("file"))
        if not path.is_absolute() and not origin.startswith("builtin:"):
            path = Path(origin).parent / path
        file = str(path)
    centre = None
    if t.has("centre"):
        lat, lon = t.vector("centre", 2)
        if not (abs(lat) <= 90 and abs(lon) <= 180):
            raise t.fail("centre", f"is [{lat:g}, {lon:g}], not a [latitude, longitude] in "
                                   f"degrees")
        centre = (lat, lon)
    if values["radius"] is not None and centre is None:
        raise t.fail("radius", "needs 'traffic.centre'")
    start, end = _when(t, "start"), _when(t, "end")
    if isinstance(start, float) and isinstance(end, float) and not start < end:
        raise t.fail("end", f"is {end:g} s, not after start {start:g} s")
    return TrafficSpec(**values, file=file, centre=centre, start=start, end=end)


def _birth(b: Table) -> BirthSpec:
    values = read(b, BirthSpec)
    paper = BirthSpec().paper
    if b.has("paper"):
        paper = tuple(
            BirthComponent(**read(c, BirthComponent), mean=c.vector("mean", STATE_DIM),
                           cov=c.covariance(STATE_DIM))
            for c in (Table(entry, f"birth.paper[{i}]", b.ctx, [*keys(BirthComponent),
                                                                 "cov_diag"])
                      for i, entry in enumerate(b.tables("paper")))
        )
    tr = Table(b.raw("truth", {}), "birth.truth", b.ctx, [*keys(BirthSpec, "truth"),
                                                          "cov_diag"])
    me = Table(b.raw("measurements", {}), "birth.measurements", b.ctx,
               keys(BirthSpec, "measurements"))
    return BirthSpec(**values, **read(tr, BirthSpec, "truth"),
                     **read(me, BirthSpec, "measurements"), paper=paper,
                     truth_cov=tr.covariance(STATE_DIM, default=BirthSpec().truth_cov))


def _fusion(f: Table, sensor_names: list[str]) -> FusionSpec:
    return FusionSpec(**read(f, FusionSpec),
                      fusing_sensor=f.choice("fusing_sensor", sensor_names, sensor_names[0]),
                      lie=_lie(f, sensor_names))


def _lie(f: Table, sensor_names: list[str]) -> str:
    """``fusion.lie = "PEER:KIND"`` (test hook, :mod:`sim.lying`): that peer tells lie KIND."""
    v = f.raw("lie", "")
    if v == "":
        return ""
    peer, _, kind = str(v).partition(":")
    if not isinstance(v, str) or peer not in sensor_names:
        raise f.fail("lie", f"must be \"PEER:KIND\" with a sensor's name and KIND one of "
                            f"{listing(LIE_KINDS)} (\"drift:RATE\", m/scan), got {brief(v)}")
    try:
        parse_lie(kind)
    except ValueError as e:
        raise f.fail("lie", str(e)) from None
    return v


def _network(t: Table, sensor_names: list[str]) -> NetworkSpec:
    values = read(t, NetworkSpec)
    topology = values["topology"]
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
    return NetworkSpec(**values, edges=tuple(edges))


def _extended(t: Table) -> ExtendedSpec:
    # heavy dependency: scipy.stats (tracking.partition pulls in scipy.stats and scipy.ndimage,
    # about 1 s of start-up on 2 busy cores, which only extended-target scenarios need)
    from sensornet.tracking.partition import DistancePartitioner, GridSpectralPartitioner

    spec = ExtendedSpec(**read(t, ExtendedSpec))
    try:
        DistancePartitioner(20.0, spec.p_lower, spec.p_upper)
    except ValueError:
        raise t.fail("p_upper", f"must be >= p_lower and both in (0, 1), got p_lower "
                                f"{spec.p_lower:g}, p_upper {spec.p_upper:g}") from None
    GridSpectralPartitioner(compression=spec.compression, cell_factor=spec.cell_factor,
                            core_level=spec.core_level, rho=spec.rho, k_rule=spec.k_rule,
                            k_spread=spec.k_spread, units=spec.units)
    return spec
