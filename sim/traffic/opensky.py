"""Recorded aircraft as the truth: OpenSky state vectors loaded, filtered, placed in a local
east-north-up frame and interpolated to any time (issue 34, item 1).

Files: a list of records as JSON (``.json`` or ``.json.gz``), or a table as CSV (``.csv``,
``.csv.gz``) or Parquet (``.parquet``, ``.pq``), one row per report, with the fields of the
``traffic`` library's OpenSky collections:

* ``timestamp``: milliseconds since 1970 UTC. Numbers are read by magnitude (below 1e11:
  seconds; below 1e14: milliseconds; below 1e17: microseconds; else nanoseconds), strings as a
  number or as ISO 8601 (no zone = UTC), and Parquet/CSV timestamp columns as they are typed.
* ``icao24``: the transponder address, the aircraft's identity (kept as the truth id).
* ``latitude``, ``longitude``: degrees WGS84.
* ``altitude``: barometric altitude in **feet**.
* ``onground`` (optional, null = airborne), ``callsign`` (optional).

Aliases, for OpenSky's own history CSV: ``time`` for ``timestamp``; ``lat``/``lon`` for
``latitude``/``longitude``; ``baroaltitude`` (**metres**) when there is no ``altitude``.
(``geoaltitude`` is not read: it is in metres in OpenSky's files and in feet in ``traffic``'s.)
Other columns (speeds, track, squawk) are ignored: velocities come from the positions.

Rows without a latitude or longitude are dropped (OpenSky writes a row per contact, with or
without position); rows are sorted per aircraft by time and a repeated (icao24, time) keeps
the first row in file order. A report repeating its aircraft's previous position exactly is
OpenSky's stale copy of the last decoded position and is dropped before interpolation
(``trajectories(drop_stale=...)``). The barometric altitude is used as the height above the
ellipsoid (a bias of tens of metres in height, none in the horizontal plane).

Gaps: each aircraft's reports are cut into pieces wherever two consecutive reports are more
than ``max_gap_s`` apart (default 20 s: ADS-B is received about once a second, so 20 s is a
real loss of contact, not jitter). An aircraft is present at time ``t`` only inside a piece of
at least two reports: never extrapolated before its first report, after its last, or across
a gap. Inside a piece positions are linear in ENU between the bracketing reports and the
velocity is that segment's slope (so the truth position is the integral of the truth
velocity, and files without speed columns work the same).

A bad file raises one ``ValueError`` line naming the file and the field.
"""

from __future__ import annotations

import gzip
import json
import math
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from functools import cached_property
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pymap3d
from pymap3d import vincenty

FOOT = 0.3048
"""Metres per foot (international foot)."""
DEFAULT_MAX_GAP_S = 20.0
"""Longest time between two reports that is still interpolated (see the module docstring)."""

_TIME = ("timestamp", "time")
_LAT = ("latitude", "lat")
_LON = ("longitude", "lon")
_ALT = (("altitude", FOOT), ("baroaltitude", 1.0))
_STRING_COLUMNS = ("icao24", "callsign", "squawk")
_SUFFIXES = {".json": "json", ".json.gz": "json", ".csv": "csv", ".csv.gz": "csv",
             ".parquet": "parquet", ".pq": "parquet"}


@dataclass(frozen=True)
class LocalFrame:
    """A local east-north-up frame tangent to the WGS84 ellipsoid at ``(lat0, lon0, h0)``."""

    lat0: float
    lon0: float
    h0: float = 0.0

    def to_enu(self, lat, lon, h) -> np.ndarray:
        """ENU ``(..., 3)`` metres of geodetic points (degrees, metres), via ``pymap3d``."""
        e, n, u = pymap3d.geodetic2enu(np.asarray(lat, float), np.asarray(lon, float),
                                       np.asarray(h, float), self.lat0, self.lon0, self.h0)
        return np.stack(np.broadcast_arrays(e, n, u), axis=-1)

    def to_geodetic(self, enu) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Latitude, longitude (degrees) and height (metres) of ENU points ``(..., 3)``."""
        enu = np.asarray(enu, float)
        return pymap3d.enu2geodetic(enu[..., 0], enu[..., 1], enu[..., 2],
                                    self.lat0, self.lon0, self.h0)


@dataclass(frozen=True)
class StateVectors:
    """Reports of one file, sorted by (icao24, time): every array is ``(N,)``."""

    t: np.ndarray
    """Seconds since 1970 UTC (float64)."""
    icao: np.ndarray
    """Transponder address (lower-case str): the truth id."""
    lat: np.ndarray
    lon: np.ndarray
    alt_m: np.ndarray
    """Barometric altitude in metres; NaN where the report had none."""
    onground: np.ndarray
    callsign: np.ndarray
    source: str = "<memory>"
    """Where the reports came from (named in errors)."""
    centre: tuple[float, float] | None = None
    """Centre of the region the reports were selected in (``select``), else None."""

    def __len__(self) -> int:
        return len(self.t)

    @property
    def aircraft(self) -> np.ndarray:
        """The distinct ids, sorted."""
        return np.unique(self.icao)

    def take(self, mask: np.ndarray) -> StateVectors:
        """The reports where ``mask (N,)`` holds (order kept)."""
        return replace(self, t=self.t[mask], icao=self.icao[mask], lat=self.lat[mask],
                       lon=self.lon[mask], alt_m=self.alt_m[mask],
                       onground=self.onground[mask], callsign=self.callsign[mask])


def _fail(source: str, msg: str) -> ValueError:
    return ValueError(f"{source}: {msg}")


def _format_of(path: Path) -> str:
    name = path.name.lower()
    for suffix in sorted(_SUFFIXES, key=len, reverse=True):
        if name.endswith(suffix):
            return _SUFFIXES[suffix]
    raise _fail(str(path), "unknown format by extension (expected .json, .json.gz, .csv, "
                           ".csv.gz, .parquet or .pq)")


def _read_json(path: Path) -> dict[str, np.ndarray]:
    with open(path, "rb") as f:
        gzipped = f.read(2) == b"\x1f\x8b"  # by content: a .json may be gzipped all the same
    opener = gzip.open if gzipped else open
    try:
        with opener(path, "rt", encoding="utf-8") as f:
            records = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise _fail(str(path), f"not readable as JSON ({e})") from None
    if not isinstance(records, list) or not all(isinstance(r, dict) for r in records):
        raise _fail(str(path), "expected a JSON list of records (objects)")
    names = set().union(*records) if records else set()
    return {k: np.array([r.get(k) for r in records], dtype=object) for k in names}


def _read_table(path: Path, fmt: str) -> dict[str, np.ndarray]:
    try:
        if fmt == "csv":
            opts = pacsv.ConvertOptions(column_types={c: pa.string() for c in _STRING_COLUMNS},
                                        strings_can_be_null=True)
            table = pacsv.read_csv(path, convert_options=opts)
        else:
            table = pq.read_table(path)
    except (OSError, pa.ArrowException) as e:
        raise _fail(str(path), f"not readable as {fmt.upper()} ({str(e).splitlines()[0]})") \
            from None
    out = {}
    for name in table.column_names:
        col = table.column(name)
        if pa.types.is_timestamp(col.type):
            scale = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[col.type.unit]
            ints = col.cast(pa.int64()).to_numpy(zero_copy_only=False)
            out[name] = ("seconds", ints * scale)
        elif pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
            out[name] = col.cast(pa.float64()).to_numpy(zero_copy_only=False)
        else:
            out[name] = np.array(col.to_pylist(), dtype=object)
    return out


def _column(cols: dict, names: tuple[str, ...], source: str):
    for name in names:
        if name in cols:
            return name, cols[name]
    raise _fail(source, f"missing column {names[0]!r}"
                + (f" (or {', '.join(repr(n) for n in names[1:])})" if len(names) > 1 else ""))


def _floats(values, field: str, source: str) -> np.ndarray:
    """Numbers ``(N,)`` with None/NaN as NaN; an unparsable value names its record."""
    if isinstance(values, np.ndarray) and values.dtype != object:
        return values.astype(float)
    try:  # the common case, all numbers or null: one conversion
        return np.array([np.nan if v is None or v == "" else v for v in values], dtype=float)
    except (TypeError, ValueError):
        pass
    for i, v in enumerate(values):
        try:
            float(np.nan if v is None or v == "" else v)
        except (TypeError, ValueError):
            raise _fail(source, f"field {field!r}: record {i + 1} is not a number ({v!r})") \
                from None
    raise AssertionError("unreachable")


def _seconds(numbers: np.ndarray) -> np.ndarray:
    """Epoch numbers to seconds by magnitude (see the module docstring)."""
    mag = np.abs(numbers)
    scale = np.select([mag < 1e11, mag < 1e14, mag < 1e17], [1.0, 1e-3, 1e-6], 1e-9)
    return numbers * scale


def _iso(v, field: str, source: str, i: int) -> float:
    """Seconds since 1970 of an ISO 8601 string (no zone = UTC)."""
    try:
        d = datetime.fromisoformat(str(v))
    except ValueError:
        raise _fail(source, f"field {field!r}: record {i + 1} is not a time ({v!r})") from None
    return (d if d.tzinfo else d.replace(tzinfo=UTC)).timestamp()


def _times(values, field: str, source: str) -> np.ndarray:
    if isinstance(values, tuple):  # a typed timestamp column, already in seconds
        t = values[1]
    elif isinstance(values, np.ndarray) and values.dtype != object:
        t = _seconds(values.astype(float))
    else:
        try:  # numbers (or numeric strings): one conversion, scaled by magnitude
            t = _seconds(np.array([np.nan if v is None else v for v in values], dtype=float))
        except (TypeError, ValueError):
            t = np.array([np.nan if v is None else _iso(v, field, source, i)
                          for i, v in enumerate(values)])
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise _fail(source, f"field {field!r}: record {bad[0] + 1} has no time")
    return t


def _strings(values, field: str, source: str, required: bool) -> np.ndarray:
    out = np.array(["" if v is None else str(v).strip().lower() for v in values], dtype=str) \
        if len(values) else np.array([], dtype=str)
    if required and len(out):
        empty = np.flatnonzero(out == "")
        if len(empty):
            raise _fail(source, f"field {field!r}: record {empty[0] + 1} is empty")
    return out


def _bools(values) -> np.ndarray:
    if isinstance(values, np.ndarray) and values.dtype != object:
        return np.nan_to_num(values, nan=0.0) != 0
    return np.array([v is True or str(v).strip().lower() in ("true", "1", "t", "yes")
                     for v in values], dtype=bool)


def load_states(path: str | Path) -> StateVectors:
    """Every report with a position in an OpenSky state-vector file (see the module docstring).

    Raises ``ValueError`` naming the file and the field: unknown extension, unreadable file,
    missing column, unparsable or missing time, latitude/longitude out of range, no report.
    """
    path = Path(path)
    source = str(path)
    fmt = _format_of(path)
    if not path.is_file():
        raise _fail(source, "no such file")
    cols = _read_json(path) if fmt == "json" else _read_table(path, fmt)
    if not cols or all(len(c[1] if isinstance(c, tuple) else c) == 0 for c in cols.values()):
        raise _fail(source, "no reports in the file")
    tname, tcol = _column(cols, _TIME, source)
    _, icol = _column(cols, ("icao24",), source)
    latname, latcol = _column(cols, _LAT, source)
    lonname, loncol = _column(cols, _LON, source)
    altname = next((n for n, _ in _ALT if n in cols), None)
    if altname is None:
        raise _fail(source, "missing column 'altitude' (feet; or 'baroaltitude', metres)")
    t = _times(tcol, tname, source)
    icao = _strings(icol, "icao24", source, required=True)
    lat = _floats(latcol, latname, source)
    lon = _floats(loncol, lonname, source)
    alt = _floats(cols[altname], altname, source) * dict(_ALT)[altname]
    for name, v, lim in ((latname, lat, 90.0), (lonname, lon, 180.0)):
        out = np.flatnonzero(np.abs(v) > lim)
        if len(out):
            raise _fail(source, f"field {name!r}: record {out[0] + 1} is out of range "
                                f"({v[out[0]]!r}, not within ±{lim:g}°)")
    onground = _bools(cols["onground"]) if "onground" in cols else np.zeros(len(t), bool)
    callsign = (_strings(cols["callsign"], "callsign", source, required=False)
                if "callsign" in cols else np.full(len(t), "", dtype=str))
    keep = np.isfinite(lat) & np.isfinite(lon)
    if not keep.any():
        raise _fail(source, f"fields {latname!r}/{lonname!r}: no report has a position")
    order = np.flatnonzero(keep)[np.lexsort((t[keep], icao[keep]))]  # stable: file order kept
    first = np.ones(len(order), bool)
    first[1:] = (icao[order][1:] != icao[order][:-1]) | (t[order][1:] != t[order][:-1])
    order = order[first]
    return StateVectors(t=t[order], icao=icao[order], lat=lat[order], lon=lon[order],
                        alt_m=alt[order], onground=onground[order],
                        callsign=np.char.upper(callsign[order]), source=source)


def to_epoch(value: float | str, what: str = "time") -> float:
    """Seconds since 1970 UTC of a number or an ISO 8601 string (no zone = UTC)."""
    if isinstance(value, str):
        try:
            d = datetime.fromisoformat(value)
        except ValueError:
            raise ValueError(f"{what}: not an ISO 8601 time ({value!r})") from None
        return (d if d.tzinfo else d.replace(tzinfo=UTC)).timestamp()
    return float(value)


def select(states: StateVectors, *, start: float | str | None = None,
           end: float | str | None = None,
           box: tuple[float, float, float, float] | None = None,
           centre: tuple[float, float] | None = None, radius_m: float | None = None,
           airborne_only: bool = True) -> StateVectors:
    """The reports in a time window and a region.

    ``start``/``end``: seconds since 1970 or ISO 8601 (inclusive). ``box``: ``(lat_min,
    lat_max, lon_min, lon_max)`` degrees. ``centre`` + ``radius_m``: within that geodesic
    distance (Vincenty, ``pymap3d.vincenty.vdist``) of the centre. ``airborne_only`` drops
    reports flagged on the ground. Raises ``ValueError`` if nothing is left.
    """
    keep = np.ones(len(states), bool)
    if start is not None:
        keep &= states.t >= to_epoch(start, "start")
    if end is not None:
        keep &= states.t <= to_epoch(end, "end")
    region_centre = None
    if box is not None:
        lat_min, lat_max, lon_min, lon_max = map(float, box)
        if not (lat_min < lat_max and lon_min < lon_max):
            raise ValueError(f"box: expected (lat_min, lat_max, lon_min, lon_max), got {box}")
        keep &= ((states.lat >= lat_min) & (states.lat <= lat_max)
                 & (states.lon >= lon_min) & (states.lon <= lon_max))
        region_centre = ((lat_min + lat_max) / 2, (lon_min + lon_max) / 2)
    if (centre is None) != (radius_m is None):
        raise ValueError("centre and radius_m go together")
    if centre is not None:
        if radius_m <= 0:
            raise ValueError(f"radius_m must be positive, got {radius_m}")
        idx = np.flatnonzero(keep)
        if len(idx):
            dist, _ = vincenty.vdist(centre[0], centre[1], states.lat[idx], states.lon[idx])
            keep[idx] = np.atleast_1d(dist) <= radius_m
        region_centre = (float(centre[0]), float(centre[1]))
    if airborne_only:
        keep &= ~states.onground
    if not keep.any():
        raise _fail(states.source, f"no reports left after filtering (start={start}, end={end}, "
                                   f"box={box}, centre={centre}, radius_m={radius_m}, "
                                   f"airborne_only={airborne_only})")
    return replace(states.take(keep), centre=region_centre or states.centre)


def default_frame(states: StateVectors) -> LocalFrame:
    """The frame at the centre of the selected region, else of the reports' lat/lon box, h=0."""
    if states.centre is not None:
        return LocalFrame(*states.centre, 0.0)
    return LocalFrame((states.lat.min() + states.lat.max()) / 2,
                      (states.lon.min() + states.lon.max()) / 2, 0.0)


@dataclass(frozen=True)
class TruthGrid:
    """Aircraft states at given times: ``states (T, A, 6)`` = ENU position and velocity
    ``[e, n, u, ve, vn, vu]`` (m, m/s), NaN where the aircraft is absent."""

    times: np.ndarray
    """(T,) seconds since 1970 UTC."""
    ids: np.ndarray
    """(A,) icao24 of the aircraft present at one of the times at least."""
    states: np.ndarray
    present: np.ndarray
    """(T, A) bool."""
    frame: LocalFrame

    def at(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Ids ``(n,)`` and states ``(n, 6)`` of the aircraft present at ``times[k]``."""
        m = self.present[k]
        return self.ids[m], self.states[k, m]

    def planar(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Ids ``(n,)`` and ``(n, 4)`` states ``[px, vx, py, vy]`` (tracking.models' order)."""
        ids, s = self.at(k)
        return ids, s[:, [0, 3, 1, 4]]


@dataclass(frozen=True)
class Trajectories:
    """Each aircraft's reports in one ENU frame, evaluated at any time (module docstring)."""

    frame: LocalFrame
    ids: np.ndarray
    """(A,) icao24, sorted."""
    t: np.ndarray
    """(N,) report times, sorted within each aircraft."""
    enu: np.ndarray
    """(N, 3) report positions."""
    starts: np.ndarray
    """(A + 1,) the reports of aircraft ``a`` are ``starts[a]:starts[a + 1]``."""
    max_gap_s: float = DEFAULT_MAX_GAP_S

    @property
    def span(self) -> tuple[float, float]:
        """First and last report time."""
        return float(self.t.min()), float(self.t.max())

    @cached_property
    def _gaps(self) -> np.ndarray:
        """(N,) True where segment ``k -> k + 1`` is not interpolated (gap or next aircraft)."""
        gap = np.ones(len(self.t), bool)
        gap[:-1] = np.diff(self.t) > self.max_gap_s
        gap[self.starts[1:] - 1] = True
        return gap

    @cached_property
    def _keys(self) -> tuple[float, float, np.ndarray]:
        """Origin, band width and ``(N,)`` sorted search keys: each aircraft's times live in
        their own band, so one ``searchsorted`` serves all aircraft."""
        t0 = float(self.t.min())
        width = float(self.t.max() - t0) + 2.0
        owner = np.repeat(np.arange(len(self.ids)), np.diff(self.starts))
        return t0, width, owner * width + (self.t - t0)

    def evaluate(self, aircraft: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States ``(K, 6)`` (NaN where absent) and presence ``(K,)`` of aircraft indices
        ``aircraft (K,)`` at ``times (K,)``: one vectorised search over all reports."""
        a = np.asarray(aircraft, dtype=np.intp)
        tq = np.asarray(times, dtype=float)
        out = np.full((len(a), 6), np.nan)
        n_all = len(self.t)
        if n_all < 2 or len(a) == 0:
            return out, np.zeros(len(a), bool)
        lo, hi = self.starts[a], self.starts[a + 1]
        t0, width, key = self._keys
        q = a * width + np.clip(tq - t0, -0.5, width - 1.0)
        i = np.clip(np.searchsorted(key, q, side="right") - 1, lo, np.maximum(hi - 2, lo))
        i = np.clip(i, 0, n_all - 2)
        inside = (hi - lo >= 2) & (tq >= self.t[lo]) & (tq <= self.t[np.maximum(hi - 1, lo)])
        gap = self._gaps
        back = (tq == self.t[i]) & gap[i] & (i > lo) & ~gap[np.maximum(i - 1, 0)]
        i = np.where(back, i - 1, i)
        present = inside & ~gap[i]
        dt = self.t[i + 1] - self.t[i]
        vel = (self.enu[i + 1] - self.enu[i]) / dt[:, None]
        pos = self.enu[i] + (tq - self.t[i])[:, None] * vel
        out[present] = np.concatenate([pos, vel], axis=1)[present]
        return out, present

    def grid(self, times: np.ndarray) -> TruthGrid:
        """Every aircraft at ``times (T,)``; columns are the aircraft present at least once."""
        times = np.asarray(times, dtype=float).ravel()
        A, T = len(self.ids), len(times)
        s, p = self.evaluate(np.tile(np.arange(A), T), np.repeat(times, A))
        s, p = s.reshape(T, A, 6), p.reshape(T, A)
        cols = p.any(axis=0)
        return TruthGrid(times=times, ids=self.ids[cols], states=s[:, cols], present=p[:, cols],
                         frame=self.frame)


def trajectories(states: StateVectors, frame: LocalFrame | tuple[float, ...] | None = None,
                 max_gap_s: float = DEFAULT_MAX_GAP_S, drop_stale: bool = True) -> Trajectories:
    """The reports in ENU about ``frame`` (``LocalFrame`` or ``(lat0, lon0[, h0])``; default
    :func:`default_frame`). Reports without an altitude are dropped (no 3-D position), and with
    ``drop_stale`` so is a report repeating its aircraft's previous latitude and longitude
    exactly: OpenSky repeats the last position until a new one is decoded (7 % of the airborne
    reports of the Paris file, in runs up to 311 s), a stale fix, not a stationary aircraft."""
    if not (max_gap_s > 0 and math.isfinite(max_gap_s)):
        raise ValueError(f"max_gap_s must be positive and finite, got {max_gap_s}")
    if frame is None:
        frame = default_frame(states)
    elif not isinstance(frame, LocalFrame):
        frame = LocalFrame(*map(float, frame))
    states = states.take(np.isfinite(states.alt_m))
    if len(states) == 0:
        raise _fail(states.source, "field 'altitude': no report with a position has one")
    if drop_stale:
        stale = np.zeros(len(states), bool)
        stale[1:] = ((states.icao[1:] == states.icao[:-1]) & (states.lat[1:] == states.lat[:-1])
                     & (states.lon[1:] == states.lon[:-1]))
        states = states.take(~stale)
    ids, first = np.unique(states.icao, return_index=True)  # rows are sorted by icao already
    starts = np.append(first, len(states)).astype(np.intp)
    enu = frame.to_enu(states.lat, states.lon, states.alt_m)
    return Trajectories(frame=frame, ids=ids, t=states.t, enu=enu, starts=starts,
                        max_gap_s=float(max_gap_s))


def truth_at(states: StateVectors, times: np.ndarray,
             frame: LocalFrame | tuple[float, ...] | None = None,
             max_gap_s: float = DEFAULT_MAX_GAP_S, drop_stale: bool = True) -> TruthGrid:
    """The aircraft at ``times (T,)`` as a dense :class:`TruthGrid` (NaN where absent)."""
    return trajectories(states, frame, max_gap_s, drop_stale).grid(times)
