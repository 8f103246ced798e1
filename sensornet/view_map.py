"""The live view on a real map (issue 34 item 5): a scenario with a geographic origin (recorded
traffic, drawn in the east-north frame about ``traffic.centre``) is also drawn in Rerun's map
view, in WGS84 latitude and longitude, beside the local-frame map.

Entities (under ``map/``, the blueprint's map view, :func:`peers.rerun_layout.default_blueprint`
with ``geo``): ``map/truth`` the aircraft (gold) and ``map/truth/paths`` their paths over the
last :data:`peers.rerun_layout.TRUTH_PATH_KEEP` scans;
``map/sensors`` the radar sites and ``map/sensors/coverage`` their range circles (geodesic,
``pymap3d.vincenty.vreckon``), ``map/region`` the traffic disc (static); ``map/peers/<peer>/
tracks`` each peer's fused tracks (one colour per track id, as on the 2-D map) and
``map/peers/<peer>/trails`` their last :data:`sensornet.view_state.TAIL` scans as lines. Rows
go through the view's :class:`sensornet.view_columns.Batcher` (one ``send_columns`` per entity
per flush, never a call per aircraft) in the local frame, converted when flushed (one
:func:`lat_lon` per entity per flush: pymap3d costs about 0.3 ms a call, whatever its size).

Rerun 0.41's map view draws no text (rerun issue 9452): each point carries a class id whose
annotation (``map``) is its name, the aircraft's icao24, the track's id or the radar's name,
shown on hover and selection.

Conversion (:func:`lat_lon`): the inverse of the loader's transform
(:class:`sim.traffic.opensky.LocalFrame`, pymap3d at the frame's origin) with its up
coordinate dropped, as the scenario drops it for the truth and the sites: the point at
height 0 with the given east and north. The truth and the tracks carry no height, so an
aircraft at height ``h`` is drawn about ``h d / R`` from where it was reported (about 100 m at
10 km up and 70 km out), in the same horizontal frame as the 2-D map and the metrics.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from functools import partial

import numpy as np
import pyarrow as pa
from pymap3d import vincenty
from rerun.components import GeoLineStringBatch

from sensornet.peers.rerun_sink import (
    REGION_COLOR,
    TRUTH_COLOR,
    TRUTH_PATH_KEEP,
    TrackLabels,
    position_columns,
)
from sensornet.protocol.messages import Tracks, Truth
from sensornet.sim.scenario import Scenario
from sensornet.sim.traffic.opensky import LocalFrame
from sensornet.sim.traffic.recorded import recorded_world
from sensornet.view_columns import Batcher, list_array
from sensornet.view_state import TAIL, ViewState, id_color, id_labels

GEO_POINTS, GEO_STRIPS = "geopoints", "geostrips"
"""The :class:`Batcher` kinds this module adds."""
CIRCLE_POINTS = 73
"""Points of a range circle (every 5 degrees of azimuth, closed)."""
UP_STEPS = 3
"""Fixed-point steps of :func:`lat_lon` (measured east-north error after them: 1e-9 m at
100 km from the origin, 5e-5 m at 500 km)."""
MAX_CLASSES = 65_535
"""Rerun class ids are 16-bit; names beyond this many get class 0 (no name)."""


def lat_lon(frame: LocalFrame, xy, height: float = 0.0) -> np.ndarray:
    """``(n, 2)`` [latitude, longitude] (degrees) of the points at ``height`` (m) whose east and
    north in ``frame`` are ``xy (n, 2)`` (m): the inverse of the loader's
    :meth:`LocalFrame.to_enu` with the up coordinate dropped (as the truth and the sites drop
    it). pymap3d's ``enu2geodetic`` (:meth:`LocalFrame.to_geodetic`) on ``(e, n, u)``, the
    unknown ``u`` found by :data:`UP_STEPS` fixed-point steps ``u -= h(e, n, u) - height``
    (the height changes about 1:1 with ``u`` near the frame: each step leaves ``1 -
    cos(d / R)``, 1e-4 at 100 km, of the error)."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    enu = np.column_stack([xy, np.zeros(len(xy))])
    for _ in range(UP_STEPS):
        lat, lon, h = frame.to_geodetic(enu)
        enu[:, 2] -= np.atleast_1d(h) - height
    lat, lon, _ = frame.to_geodetic(enu)
    return np.column_stack([np.atleast_1d(lat), np.atleast_1d(lon)]).reshape(-1, 2)


def circle(lat: float, lon: float, radius_m: float, n: int = CIRCLE_POINTS) -> np.ndarray:
    """``(n, 2)`` [lat, lon] of the closed geodesic circle of ``radius_m`` about a point (the
    direct problem on WGS84, ``pymap3d.vincenty.vreckon``)."""
    if not radius_m > 0:
        raise ValueError(f"radius_m must be positive, got {radius_m}")
    az = np.linspace(0.0, 360.0, n)
    la, lo = vincenty.vreckon(lat, lon, float(radius_m), az)
    out = np.column_stack([la, lo])
    out[-1] = out[0]
    return out


@dataclass(frozen=True)
class GeoMap:
    """What places a scenario on the Earth: its local frame and its static marks."""

    frame: LocalFrame
    """The east-north frame the truth, scans and tracks are in (the loader's)."""
    sites: dict[str, tuple[float, float]]
    """Sensor name -> (lat, lon) of its position, in the scenario's order."""
    ranges: dict[str, float]
    """Sensor name -> its maximum range (m), the sensors that have one."""
    radius: float | None = None
    """The traffic disc (``traffic.radius``, m) about the frame's origin, if any."""


def geo_frame(scn: Scenario) -> LocalFrame | None:
    """The scenario's frame on WGS84 if it has a geographic origin (``truth = "recorded"``),
    else None: ``traffic.centre`` at height 0 as the loader takes it, else (no centre) the
    loaded traffic's own frame."""
    if scn.truth != "recorded" or scn.traffic is None:
        return None
    if scn.traffic.centre is not None:
        return LocalFrame(*map(float, scn.traffic.centre), 0.0)
    return recorded_world(scn).frame


def geo_map(scn: Scenario) -> GeoMap | None:
    """The scenario's :class:`GeoMap`, or None without a geographic origin."""
    frame = geo_frame(scn)
    if frame is None:
        return None
    ll = lat_lon(frame, [s.position for s in scn.sensors])
    return GeoMap(frame=frame,
                  sites={s.name: (float(a), float(b)) for s, (a, b) in zip(scn.sensors, ll,
                                                                             strict=True)},
                  ranges={s.name: float(s.max_range) for s in scn.sensors
                          if s.max_range is not None},
                  radius=scn.traffic.radius)


class _Classes:
    """Names as Rerun class ids (1, 2, ... in order of first use; 0: none), with the
    annotation context that names them."""

    def __init__(self) -> None:
        self.ids: dict[str, int] = {}
        self.changed = False

    def of(self, names: list[str]) -> np.ndarray:
        out = np.zeros(len(names), np.uint16)
        for i, name in enumerate(names):  # one dict look-up per mark
            c = self.ids.get(name)
            if c is None and len(self.ids) < MAX_CLASSES:
                c = self.ids[name] = len(self.ids) + 1
                self.changed = True
            out[i] = c or 0
        return out

    def context(self, rr):
        self.changed = False
        return rr.AnnotationContext([(c, name) for name, c in self.ids.items()])


@dataclass(eq=False)
class _Marks:
    """One scan's marks of one entity: kept in the local frame until a flush converts them
    (:func:`_convert`, once, whichever row or path first needs them)."""

    keys: np.ndarray
    """(n,) what joins a mark to its line: truth id or track class id."""
    xy: np.ndarray
    """(n, 2) east, north (m)."""
    colors: np.ndarray
    """(n, 3) uint8."""
    ll: np.ndarray | None = None
    """(n, 2) [lat, lon] once converted."""


def _convert(frame: LocalFrame, marks) -> None:
    """Give every not yet converted one of ``marks`` its ``ll``, in one :func:`lat_lon`."""
    todo = list({id(m): m for m in marks if m.ll is None}.values())
    if not todo:
        return
    ll = lat_lon(frame, np.concatenate([m.xy for m in todo]))
    for m, part in zip(todo, np.split(ll, np.cumsum([len(m.xy) for m in todo])[:-1]),
                       strict=True):
        m.ll = part


def _lines(hist) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The converted :class:`_Marks` of the scans in ``hist`` (oldest first) as one line per
    key with 2 or more points: ``(points (P, 2) [lat, lon], lengths (s,), colors (s, 3))``,
    each line in time order (a stable sort by key). Key 0 draws no line (a track past the
    class ids; no aircraft has the icao24 000000)."""
    if not hist:
        return np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros((0, 3), np.uint8)
    keys = np.concatenate([h.keys for h in hist])
    pts = np.concatenate([h.ll for h in hist])
    cols = np.concatenate([h.colors for h in hist])
    order = np.argsort(keys, kind="stable")
    ukeys, first, counts = np.unique(keys[order], return_index=True, return_counts=True)
    keep = (counts >= 2) & (ukeys != 0)
    take = np.repeat(keep, counts)
    return pts[order][take], counts[keep].astype(np.int64), cols[order][first[keep]]


class GeoViewState(ViewState):
    """:class:`ViewState` that also draws truth and fused tracks on the map view (WGS84), and
    the sites, coverage and region once (static) when made. ``geo``: the scenario's
    :class:`GeoMap`; the other arguments are :class:`ViewState`'s."""

    def __init__(self, batcher: Batcher, *args, geo: GeoMap, **kwargs) -> None:
        super().__init__(batcher, *args, **kwargs)
        self.geo = geo
        batcher.builders.update({GEO_POINTS: self._points_columns,
                                 GEO_STRIPS: partial(geo_strips_columns, geo.frame)})
        self.classes = _Classes()
        self.truth_hist: deque = deque(maxlen=TRUTH_PATH_KEEP)
        self.trails: dict[str, deque] = {}
        self.track_labels: dict[str, TrackLabels] = {}
        self._static()

    def _static(self) -> None:
        rr, log, g = self.b.rr, self.b.rec.log, self.geo
        names = list(g.sites)
        if names:
            colors = np.array([self.color(n) for n in names], np.uint8)
            log("map/sensors", rr.GeoPoints(lat_lon=np.array([g.sites[n] for n in names]),
                                            colors=colors, radii=-8.0,
                                            class_ids=self.classes.of(names)), static=True)
            ranged = [n for n in names if n in g.ranges]
            if ranged:
                log("map/sensors/coverage", rr.GeoLineStrings(
                    lat_lon=[circle(*g.sites[n], g.ranges[n]) for n in ranged],
                    colors=np.array([self.color(n) for n in ranged], np.uint8), radii=-1.0),
                    static=True)
        if g.radius is not None:
            log("map/region", rr.GeoLineStrings(
                lat_lon=[circle(g.frame.lat0, g.frame.lon0, g.radius)], colors=REGION_COLOR,
                radii=-1.5), static=True)
        self._name_classes()

    def _name_classes(self) -> None:
        """The annotation context naming the class ids, logged (static) if names were added:
        at most once a flush (:meth:`_points_columns`), not once per new aircraft or id."""
        if self.classes.changed:
            self.b.rec.log("map", self.classes.context(self.b.rr), static=True)

    def _points_columns(self, rr, data: list) -> list:
        self._name_classes()
        return geo_points_columns(self.geo.frame, rr, data)

    def truth(self, msg: Truth) -> None:
        super().truth(msg)
        k, t = msg.k, self._t(msg.k)
        X = np.asarray(msg.states, float)
        ids = np.asarray(msg.ids, np.int64).reshape(-1)
        xy = X[:, position_columns(X.shape[1])] if len(X) else np.zeros((0, 2))
        gold = np.broadcast_to(np.asarray(TRUTH_COLOR, np.uint8), (len(xy), 3))
        names = [f"{i:06x}" for i in ids.tolist()]  # the icao24 (truth id int(icao24, 16))
        marks = _Marks(ids, xy, gold)
        self.b._add("map/truth", GEO_POINTS, k, t, (marks, -6.0, self.classes.of(names)))
        self.truth_hist.append(marks)
        self.b._add("map/truth/paths", GEO_STRIPS, k, t, (tuple(self.truth_hist), -1.5))

    def tracks(self, msg: Tracks) -> None:
        super().tracks(msg)
        n, k, t = msg.sender, msg.k, self._t(msg.k)
        X = np.asarray(msg.states, float)
        xy = X[:, position_columns(X.shape[1])] if len(X) else np.zeros((0, 2))
        if msg.ids is not None:  # the colours and labels of the 2-D map
            colors, names = id_color(msg.ids), id_labels(msg.ids)
        else:  # the 2-D map's display numbers: the same association on the same input
            gate = self.track_labels.setdefault(n, TrackLabels(self.label_gate))
            colors = np.broadcast_to(np.asarray(self.color(n), np.uint8), (len(xy), 3))
            names = [f"{n}/{i}" for i in gate.assign(xy)]
        classes = self.classes.of(names)
        marks = _Marks(classes, xy, np.asarray(colors, np.uint8))
        self.b._add(f"map/peers/{n}/tracks", GEO_POINTS, k, t, (marks, -5.0, classes))
        trail = self.trails.setdefault(n, deque(maxlen=TAIL))
        trail.append(marks)
        self.b._add(f"map/peers/{n}/trails", GEO_STRIPS, k, t, (tuple(trail), -1.5))


def geo_points_columns(frame: LocalFrame, rr, data: list) -> list:
    """Rows ``(marks, radius, class_ids (n,))`` (:class:`_Marks`) as GeoPoints columns, the
    rows' marks converted in one :func:`lat_lon`."""
    _convert(frame, [d[0] for d in data])
    lengths = [len(d[0].xy) for d in data]
    return [*rr.GeoPoints.columns(
        positions=np.concatenate([d[0].ll for d in data]),
        colors=np.concatenate([d[0].colors for d in data]),
        radii=np.repeat([d[1] for d in data], lengths),
        class_ids=np.concatenate([d[2] for d in data])).partition(lengths)]


def geo_strips_columns(frame: LocalFrame, rr, data: list) -> list:
    """Rows ``(marks of the scans so far, radius)`` as GeoLineStrings columns, one line per
    key (:func:`_lines`; the marks not converted yet in one :func:`lat_lon`; the lines as one
    Arrow array, as :func:`sensornet.view_columns.strip_array`)."""
    _convert(frame, [m for d in data for m in d[0]])
    rows = [_lines(d[0]) for d in data]
    lines = [len(r[1]) for r in rows]
    return [*rr.GeoLineStrings.columns(
        line_strings=geo_strip_array(np.concatenate([r[0] for r in rows]),
                                     np.concatenate([r[1] for r in rows])),
        colors=np.concatenate([r[2] for r in rows]),
        radii=np.repeat([d[1] for d in data], lines)).partition(lines)]


def geo_strip_array(points: np.ndarray, lengths: np.ndarray) -> pa.Array:
    """Geo line strings as Rerun's Arrow type in one go: ``points (P, 2)`` [lat, lon] end to
    end, ``lengths (s,)`` points per line."""
    return list_array(points, lengths, GeoLineStringBatch._ARROW_DATATYPE, np.float64)
