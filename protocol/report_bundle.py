"""A peer host's watched reports in one message on ``telemetries/<host>`` (issue 38).

A host's peers' per-scan reports (each a :class:`protocol.messages.Telemetry`) packed
together, not each encoded alone into a :mod:`protocol.bundle`: per report its sender, scan,
value names, events, point-set names and row counts; the values of all the reports in one
float64 block and their map points in one float32 block, so a host's flush converts and
checks 50 reports' arrays once, not 50 times. Beside them ride entries as in a bundle (each
scan's tracks, the bytes the peer published; a report that cannot go in the blocks, encoded
alone). Layout (msgpack): ``[ts, [[peer, payload], ...], [[peer, k, vn, ev, pn, pc], ...],
vx, pf]``; its first byte is 0x95 (an array of 5), which neither a bundle (0x92) nor a message
(``[version, type, fields...]``, 6 or more) has. A receiver splits it back into the reports
each checked by the codec's own Telemetry decoder (protocol 2), so a report draws as it would
have sent alone. Hostile input: the size is bounded before anything is unpacked, the layout and
the blocks' sizes are checked before a report is split off; a report that fails its checks is
refused alone (the others kept), a message whose layout fails is refused whole.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgpack
import numpy as np
from sensornet.protocol.bundle import BUNDLE_BYTES, MAX_ENTRIES
from sensornet.protocol.codec import TRACKS_VERSION, Rejected, encode
from sensornet.protocol.codec_format import DEFAULT_LIMITS, Limits
from sensornet.protocol.codec_messages import DECODERS
from sensornet.protocol.messages import Telemetry

REPORTS_HEAD = b"\x95"
"""A host reports message's first byte (a msgpack array of 5)."""
_F4_MAX = float(np.finfo(np.float32).max)
_F4 = np.dtype("<f4")


@dataclass(frozen=True)
class HostReportsMessage:
    send_time: float
    entries: list[tuple[str, bytes]]
    """``(peer, payload)``: bytes as the peer would have put them on ``telemetry/<peer>``."""
    reports: list[Telemetry | Rejected]
    """The reports in the order packed; a refused one as its :class:`Rejected`."""


def _size(r: Telemetry) -> int:
    """A report's packed bytes, roughly (names and framing at 40 bytes a value)."""
    return (48 * len(r.values) + sum(len(e) + 4 for e in r.events) + 40 * len(r.points)
            + 8 * sum(len(z) for z in r.points.values()) + 64)


def pack_reports(items: list[tuple[str, bytes | None, Telemetry]], send_time: float,
                 max_bytes: int = BUNDLE_BYTES) -> list[bytes]:
    """``(peer, tracks bytes or None, report)`` items as host reports messages of about
    ``max_bytes`` at most each (an item larger alone in one of its own). A report with a
    mixture, or whose points do not fit float32 (or are not finite), goes encoded alone
    among the entries (protocol 1), as :func:`protocol.codec.encode` writes it."""
    out, chunk, size = [], [], 0
    for item in items:
        n = _size(item[2]) + (len(item[1]) + 32 if item[1] else 0)
        if chunk and size + n > max_bytes:
            out.append(_pack(chunk, send_time))
            chunk, size = [], 0
        chunk.append(item)
        size += n
    if chunk:
        out.append(_pack(chunk, send_time))
    return out


def _pack(items: list[tuple[str, bytes | None, Telemetry]], send_time: float) -> bytes:
    """One message of ``items`` (:func:`pack_reports`)."""
    entries, meta, values, points, alone = [], [], [], [], []
    for peer, tracks, r in items:
        if tracks is not None:
            entries.append([peer, tracks])
        if r.mixture is not None:
            alone.append(r)
            continue
        names = list(r.points)
        pts = [np.asarray(r.points[n], dtype=float).reshape(-1, 2) for n in names]
        meta.append([r.sender, int(r.k), list(r.values), list(r.events), names,
                     [len(z) for z in pts]])
        values.extend(r.values.values())
        points.extend(pts)
    z = np.concatenate(points) if points else np.zeros((0, 2))
    if z.size and not float(np.abs(z).max()) <= _F4_MAX:  # NaN compares False
        alone = [r for _, _, r in items]  # each alone: protocol 1 where it must be
        meta, values, z = [], [], np.zeros((0, 2))
    entries += [[r.sender, encode(r)] for r in alone]
    return msgpack.packb([float(send_time), entries, meta,
                          np.array(values, dtype=float).tobytes(),
                          z.astype(_F4).tobytes()], use_bin_type=True)


def unpack_reports(data: bytes, max_bytes: int = 2 * BUNDLE_BYTES,
                   limits: Limits = DEFAULT_LIMITS) -> HostReportsMessage:
    """A host reports message split, or :class:`Rejected` (``too-large``, ``malformed``,
    ``shape``) for the whole: bounded in bytes, arrays and strings before anything is built,
    then its layout and the blocks' sizes against the counts; each report then decoded as a
    protocol-2 Telemetry (a refused one in its place as its :class:`Rejected`)."""
    ts, entries, meta, spans, vx, pf = _layout(data, max_bytes, limits)
    return HostReportsMessage(ts, entries, _each_alone(ts, meta, spans, vx, pf, limits))


def _layout(data: bytes, max_bytes: int, limits: Limits) -> tuple:
    """``(ts, entries, meta, spans, vx, pf)`` of a host reports message whose size, layout
    and blocks' sizes hold (:func:`unpack_reports`), else :class:`Rejected` for the whole;
    ``spans``: each report's first value and first point in the blocks."""
    if len(data) > max_bytes:
        raise Rejected("too-large", f"host reports of {len(data)} bytes > {max_bytes}")
    try:
        body = msgpack.unpackb(bytes(data), raw=False, max_bin_len=max_bytes,
                               max_str_len=1600, max_array_len=max(MAX_ENTRIES,
                                                                  4 * limits.max_entries),
                               max_map_len=0)
    except Exception as exc:  # msgpack raises several unrelated types on bad input
        raise Rejected("malformed", f"not msgpack host reports ({type(exc).__name__})") from None
    if (not isinstance(body, list) or len(body) != 5 or type(body[0]) is not float
            or not all(isinstance(x, list) for x in body[1:3])
            or not all(isinstance(x, bytes) for x in body[3:])):
        raise Rejected("malformed", "host reports are [ts, entries, reports, vx, pf]")
    ts, raw, meta, vx, pf = body
    entries = []
    for e in raw:
        if (not isinstance(e, list) or len(e) != 2 or not isinstance(e[0], str)
                or not isinstance(e[1], bytes)):
            raise Rejected("malformed", "an entry is [peer, payload]")
        entries.append((e[0], e[1]))
    spans, nv, nz = [], 0, 0
    for m in meta:
        if (not isinstance(m, list) or len(m) != 6 or not isinstance(m[2], list)
                or not isinstance(m[5], list)
                or not all(type(c) is int and 0 <= c <= limits.max_measurements
                           for c in m[5])):
            raise Rejected("malformed", "a report is [peer, k, vn, ev, pn, pc]")
        spans.append((nv, nz))
        nv, nz = nv + len(m[2]), nz + sum(m[5])
    if len(vx) != 8 * nv or len(pf) != 8 * nz:
        raise Rejected("shape", f"{len(vx)} value bytes and {len(pf)} point bytes for "
                                f"{nv} values and {nz} points")
    return ts, entries, meta, spans, vx, pf


def _each_alone(ts: float, meta: list, spans: list, vx: bytes, pf: bytes,
                limits: Limits) -> list[Telemetry | Rejected]:
    """Each report of a laid-out message decoded alone by the codec's Telemetry decoder."""
    decode = DECODERS["Y"]
    reports: list[Telemetry | Rejected] = []
    for m, (a, b) in zip(meta, spans, strict=True):
        fields = {"s": m[0], "k": m[1], "ts": ts, "vn": m[2],
                  "vx": vx[8 * a:8 * (a + len(m[2]))], "ev": m[3], "pn": m[4], "pc": m[5],
                  "pf": pf[8 * b:8 * (b + sum(m[5]))], "d": 0, "x": b""}
        try:
            reports.append(decode(fields, limits, TRACKS_VERSION))
        except Rejected as exc:
            reports.append(exc)
        except (ValueError, TypeError, OverflowError) as exc:
            reports.append(Rejected("field", f"{type(exc).__name__}: {exc}"))
    return reports


def unpack_reports_together(data: bytes, max_bytes: int = 2 * BUNDLE_BYTES,
                            limits: Limits = DEFAULT_LIMITS) -> HostReportsMessage:
    """:func:`unpack_reports` for the view (issue 38): the same layout checks, then every
    report's checks of the codec's Telemetry decoder (protocol 2) made once for all the
    message's reports (names' types and lengths over all names, values and points converted
    and checked finite in one NumPy call each, not ~6 calls a report). Any check failing
    anywhere: each report decoded alone as :func:`unpack_reports` does, which refuses
    exactly the bad ones (counted) and keeps the others."""
    ts, entries, meta, spans, vx, pf = _layout(data, max_bytes, limits)
    reports = _together(ts, meta, spans, vx, pf, limits)
    if reports is None:
        reports = _each_alone(ts, meta, spans, vx, pf, limits)
    return HostReportsMessage(ts, entries, reports)


_SAFE_K = 1 << 53


def _together(ts: float, meta: list, spans: list, vx: bytes, pf: bytes,
              limits: Limits) -> list[Telemetry] | None:
    """The reports of a laid-out message as ``_decode_telemetry`` (protocol 2, no mixture)
    would give each, or None if any report fails one of its checks: sender a name, scan an
    index, send time finite, value and point-set names of 1-``max_name`` characters (at most
    ``4 max_entries`` / 16 a report), at most 64 events of at most 400 characters, a count
    per point set, at most ``max_measurements`` points a report, values and points finite."""
    if not math.isfinite(ts):
        return None
    most, mv = limits.max_name, 4 * limits.max_entries
    for m in meta:
        s, k, vn, ev, pn, pc = m
        if (type(s) is not str or not 0 < len(s) <= most or type(k) is not int
                or not 0 <= k < _SAFE_K or len(vn) > mv or not isinstance(ev, list)
                or len(ev) > 64 or not isinstance(pn, list) or len(pn) > 16
                or len(pc) != len(pn) or sum(pc) > limits.max_measurements):
            return None
    names = [n for m in meta for n in m[2]] + [n for m in meta for n in m[4]]
    if names and (set(map(type, names)) != {str} or min(map(len, names)) == 0
                  or max(map(len, names)) > most):
        return None
    events = [e for m in meta for e in m[3]]
    if events and (set(map(type, events)) != {str} or max(map(len, events)) > 400):
        return None
    values = np.frombuffer(vx, dtype="<f8")
    z = np.frombuffer(pf, dtype=_F4).reshape(-1, 2).astype(float)
    if not (np.isfinite(values).all() and np.isfinite(z).all()):
        return None
    values = values.tolist()
    out = []
    for (s, k, vn, ev, pn, pc), (a, b) in zip(meta, spans, strict=True):
        points = {}
        for name, c in zip(pn, pc, strict=True):
            points[name], b = z[b:b + c], b + c
        out.append(Telemetry(sender=s, k=k, values=dict(zip(vn, values[a:a + len(vn)],
                                                            strict=True)),
                             events=tuple(ev), points=points, mixture=None, send_time=ts))
    return out
