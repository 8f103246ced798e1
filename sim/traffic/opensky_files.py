"""OpenSky state-vector files read and checked: :func:`load_states` -> :class:`StateVectors`
(issue 34, item 1; :mod:`sim.traffic.opensky` places them in a frame and interpolates them).

Files: a list of records as JSON (``.json`` or ``.json.gz``), or a table as CSV (``.csv``,
``.csv.gz``) or Parquet (``.parquet``, ``.pq``), one row per report, with the fields of the
``traffic`` library's OpenSky collections:

* ``timestamp``: milliseconds since 1970 UTC. Numbers are read by magnitude (below 1e11:
  seconds; below 1e14: milliseconds; below 1e17: microseconds; else nanoseconds), strings as a
  number or as ISO 8601 (no zone = UTC), and Parquet/CSV timestamp columns as they are typed.
* ``icao24``: the transponder address in hexadecimal, the aircraft's identity (kept as the
  truth id).
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

A bad file raises one ``ValueError`` line naming the file and the field.
"""

from __future__ import annotations

import gzip
import json
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

FOOT = 0.3048
"""Metres per foot (international foot)."""
_TIME = ("timestamp", "time")
_LAT = ("latitude", "lat")
_LON = ("longitude", "lon")
_ALT = (("altitude", FOOT), ("baroaltitude", 1.0))
_STRING_COLUMNS = ("icao24", "callsign", "squawk")
_SUFFIXES = {".json": "json", ".json.gz": "json", ".csv": "csv", ".csv.gz": "csv",
             ".parquet": "parquet", ".pq": "parquet"}


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
    not_hex = np.flatnonzero(np.char.strip(icao, "0123456789abcdef") != "")
    if len(not_hex):  # the truth id is int(icao24, 16) (sim.traffic.recorded.truth_ids)
        raise _fail(source, f"field 'icao24': record {not_hex[0] + 1} is not a hexadecimal "
                            f"transponder address ({icao[not_hex[0]]!r})")
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
