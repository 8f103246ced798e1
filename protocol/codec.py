"""Versioned msgpack codec with validation of everything decoded.

A message is a msgpack array ``[version, type, fields...]`` (positional, to keep the
per-message overhead near 25 bytes). Arrays travel as raw little-endian float64 bytes; their
row count follows from the byte length and the declared width. A Gaussian mixture is one
``(n, 1 + d + d(d+1)/2)`` block: weight, mean, and the upper triangle of the covariance
(symmetric by construction), so a 4-D component is 15 numbers, the raw tuple count of
docs/seed004.md.

``decode`` never trusts its input: any problem raises :class:`Rejected` with a short
``reason`` code (counted by the receiver) and a human-readable detail.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import msgpack
import numpy as np

try:
    from numpy.linalg import _umath_linalg as _lapack
except ImportError:  # pragma: no cover
    _lapack = None

from sensornet.protocol.messages import (
    Control,
    Estimate,
    Forward,
    Message,
    Returns,
    Scan,
    ScanSet,
    Telemetry,
    Tracks,
    Truth,
)
from sensornet.tracking.mixture import GaussianMixture

VERSION = 1
"""The protocol version of every message type: the first element of ``[version, type, ...]``."""
TRACKS_VERSION = 2
"""Protocol 2 exists for two types: Tracks (``"K"``) with identities, covariances, existence
and status, and Estimate (``"E"``) with component labels; a message without them is still
written (and read) as protocol 1, byte for byte."""
LABELS_VERSION = TRACKS_VERSION
"""The protocol of a labelled Estimate."""
_F8 = np.dtype("<f8")
_I8 = np.dtype("<i8")

REASONS = (
    "malformed",  # not msgpack, truncated, or not a map
    "version",  # unknown protocol version
    "type",  # unknown message type
    "field",  # missing field or wrong field type
    "shape",  # array bytes do not match the declared shape
    "nonfinite",  # NaN or infinity
    "weight",  # negative weight
    "not-psd",  # covariance not positive definite
    "too-many",  # more components / measurements / dimensions than allowed
    "too-large",  # message larger than allowed
)


class Rejected(ValueError):
    """A decoded message failed validation; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass(frozen=True)
class Limits:
    """What a receiver accepts; anything larger is rejected before it costs memory."""

    max_bytes: int = 1 << 20
    max_components: int = 2000
    max_measurements: int = 20000
    max_dim: int = 6
    max_name: int = 64
    max_entries: int = 256
    """Scans (origins) in one flooding forward."""


DEFAULT_LIMITS = Limits()


# -- encoding -------------------------------------------------------------------------------
@lru_cache(maxsize=16)
def _tri_index(d: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices of the upper triangle of a ``d x d`` matrix (cached)."""
    return np.triu_indices(d)


@lru_cache(maxsize=16)
def _tri_to_full(d: int) -> np.ndarray:
    """For each of the ``d * d`` entries of a symmetric matrix, its column in the packed upper
    triangle (cached): ``tri[:, _tri_to_full(d)]`` is the full matrix, one gather."""
    r, c = _tri_index(d)
    col = np.empty((d, d), dtype=np.intp)
    col[r, c] = np.arange(r.size)
    col[c, r] = np.arange(r.size)
    return col.reshape(-1)


@lru_cache(maxsize=16)
def _row_to_full(d: int) -> np.ndarray:
    """:func:`_tri_to_full` as columns of a whole packed row (weight, mean, triangle)."""
    return _tri_to_full(d) + 1 + d


def pack_mixture(mix: GaussianMixture) -> bytes:
    """``(n, 1 + d + d(d+1)/2)`` float64 rows: weight, mean, upper triangle of covariance."""
    iu = _tri_index(mix.dim)
    rows = np.concatenate(
        [mix.weights[:, None], mix.means, mix.covs[:, iu[0], iu[1]]], axis=1
    )
    return np.ascontiguousarray(rows, dtype=_F8).tobytes()


def _array(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=_F8).tobytes()


_KINDS = ("posterior", "prediction", "returns")  # "returns": seed 003 before Returns ("R")
_FIELDS = {
    # type letter: field names after [version, type], in wire order
    "E": ("s", "k", "r", "q", "ts", "p", "o", "d", "x"),
    "S": ("s", "k", "q", "ts", "x"),
    "K": ("s", "k", "q", "ts", "d", "x"),
    "T": ("k", "ts", "d", "x", "i"),
    "C": ("c", "id", "pa", "ts"),
    "F": ("s", "k", "r", "q", "ts", "o", "n", "x"),
    "R": ("s", "k", "r", "q", "ts", "x"),
    # Telemetry (live views only): value names "vn" and their float64 "vx", event lines
    # "ev", point sets' names "pn", row counts "pc" and (m, 2) float64 rows "px", the fused
    # mixture's dimension "d" (0: none) and packed rows "x"
    "Y": ("s", "k", "ts", "vn", "vx", "ev", "pn", "pc", "px", "d", "x"),
}
_FIELDS_V2 = {
    # Tracks with identities: ids "i" (n, 3) int64, covariances "c" (n, d(d+1)/2) upper
    # triangles, existence "e" (n,) float64, status "u" (n,) int8; each bytes or nil (not
    # sent). The states "x" stay last, as in protocol 1.
    "K": ("s", "k", "q", "ts", "d", "i", "c", "e", "u", "x"),
    # Estimate with component labels: "i" (n, 3) int64 bytes, one row per component of "x"
    "E": ("s", "k", "r", "q", "ts", "p", "o", "d", "i", "x"),
}
VERSIONS = {VERSION: _FIELDS, TRACKS_VERSION: _FIELDS_V2}
"""Protocol version -> the message types it has -> their field names in wire order."""


def _estimate(msg: Estimate) -> dict:
    """Protocol 1 without labels (byte for byte as always), protocol 2 with them."""
    body = {"s": msg.sender, "k": int(msg.k), "r": int(msg.round), "q": int(msg.seq),
            "ts": float(msg.send_time), "p": int(msg.pruning), "o": _KINDS.index(msg.kind),
            "d": msg.mixture.dim, "x": pack_mixture(msg.mixture)}
    if msg.labels is not None:
        n = len(msg.mixture)
        lab = np.asarray(msg.labels)
        if lab.shape != (n, 3) or (n and lab.dtype.kind not in "iu"):
            raise ValueError(f"Estimate.labels must be ({n}, 3) integers, got {lab.shape} "
                             f"{lab.dtype}")
        body["v"] = LABELS_VERSION
        body["i"] = np.ascontiguousarray(lab, dtype=_I8).tobytes()
    return body


def _scan(msg: Scan) -> dict:
    z = np.asarray(msg.z, dtype=float).reshape(-1, 2)
    return {"s": msg.sensor, "k": int(msg.k), "q": int(msg.seq), "ts": float(msg.send_time),
            "x": _array(z)}


def _states(states) -> np.ndarray:
    x = np.asarray(states, dtype=float)
    return x.reshape(len(x), -1) if x.size else x.reshape(0, 4)


def _tracks(msg: Tracks) -> dict:
    """Protocol 1 (states only) when no optional field is set, byte for byte what it always
    was; protocol 2 (``"v": 2`` here) otherwise."""
    x = _states(msg.states)
    body = {"s": msg.sender, "k": int(msg.k), "q": int(msg.seq), "ts": float(msg.send_time),
            "d": x.shape[1], "x": _array(x)}
    if not msg.labelled:
        return body
    n, d = x.shape
    body["v"] = TRACKS_VERSION
    body["i"] = body["c"] = body["e"] = body["u"] = None
    if msg.ids is not None:
        ids = np.asarray(msg.ids)
        if ids.shape != (n, 3) or (n and ids.dtype.kind not in "iu"):
            raise ValueError(f"Tracks.ids must be ({n}, 3) integers, got {ids.shape} {ids.dtype}")
        body["i"] = np.ascontiguousarray(ids, dtype=_I8).tobytes()
    if msg.covs is not None:
        P = np.asarray(msg.covs, dtype=float)
        if P.shape != (n, d, d):
            raise ValueError(f"Tracks.covs must be ({n}, {d}, {d}), got {P.shape}")
        iu = _tri_index(d)
        body["c"] = _array(P[:, iu[0], iu[1]])
    if msg.existence is not None:
        r = np.asarray(msg.existence, dtype=float)
        if r.shape != (n,):
            raise ValueError(f"Tracks.existence must be ({n},), got {r.shape}")
        body["e"] = _array(r)
    if msg.status is not None:
        u = np.asarray(msg.status)
        if u.shape != (n,):
            raise ValueError(f"Tracks.status must be ({n},), got {u.shape}")
        body["u"] = np.ascontiguousarray(u, dtype=np.int8).tobytes()
    return body


def _truth(msg: Truth) -> dict:
    x = _states(msg.states)
    ids = np.ascontiguousarray(msg.ids, dtype=_I8)
    return {"k": int(msg.k), "ts": float(msg.send_time), "d": x.shape[1], "x": _array(x),
            "i": ids.tobytes()}


def _forward(msg: Forward) -> dict:
    origins = list(msg.scans.scans)
    zs = [np.asarray(msg.scans.scans[o], dtype=float).reshape(-1, 2) for o in origins]
    return {"s": msg.sender, "k": int(msg.k), "r": int(msg.round), "q": int(msg.seq),
            "ts": float(msg.send_time), "o": origins, "n": [len(z) for z in zs],
            "x": _array(np.concatenate(zs) if zs else np.zeros((0, 2)))}


def _returns(msg: Returns) -> dict:
    z = np.asarray(msg.z, dtype=float).reshape(-1, 2)
    return {"s": msg.sender, "k": int(msg.k), "r": int(msg.round), "q": int(msg.seq),
            "ts": float(msg.send_time), "x": _array(z)}


def _control(msg: Control) -> dict:
    return {"c": msg.command, "id": msg.run_id, "pa": dict(msg.params),
            "ts": float(msg.send_time)}


def _telemetry(msg: Telemetry) -> dict:
    names = list(msg.points)
    pts = [np.asarray(msg.points[n], dtype=float).reshape(-1, 2) for n in names]
    mix = msg.mixture
    return {"s": msg.sender, "k": int(msg.k), "ts": float(msg.send_time),
            "vn": list(msg.values), "vx": _array(np.fromiter(msg.values.values(), float,
                                                              len(msg.values))),
            "ev": list(msg.events), "pn": names, "pc": [len(z) for z in pts],
            "px": _array(np.concatenate(pts) if pts else np.zeros((0, 2))),
            "d": 0 if mix is None else mix.dim,
            "x": b"" if mix is None else pack_mixture(mix)}


_ENCODERS: dict[type, tuple[str, Callable[[Any], dict]]] = {
    Estimate: ("E", _estimate), Scan: ("S", _scan), Tracks: ("K", _tracks),
    Truth: ("T", _truth), Forward: ("F", _forward), Returns: ("R", _returns),
    Control: ("C", _control), Telemetry: ("Y", _telemetry),
}
"""Message type -> (wire type letter, the fields of its body by name); ``_FIELDS`` orders them."""


def encode(msg: Message) -> bytes:
    """Serialise a message: a msgpack array ``[version, type, fields...]`` (see ``_FIELDS``)."""
    entry = next((_ENCODERS[c] for c in type(msg).__mro__ if c in _ENCODERS), None)
    if entry is None:
        raise TypeError(f"cannot encode {type(msg).__name__}")
    t, body = entry[0], entry[1](msg)
    version = body.get("v", VERSION)
    return msgpack.packb([version, t, *(body[f] for f in VERSIONS[version][t])],
                         use_bin_type=True)


def _rows(blob: bytes, width: int, limit: int, what: str) -> int:
    """Number of rows of ``width`` float64 in ``blob``, checked against ``limit``."""
    if width <= 0 or len(blob) % (8 * width):
        raise Rejected("shape", f"{len(blob)} bytes is not a whole number of {what}")
    n = len(blob) // (8 * width)
    if n > limit:
        raise Rejected("too-many", f"{n} {what} > {limit}")
    return n


# -- decoding -------------------------------------------------------------------------------
def _get(body: dict, key: str, kind: type | tuple[type, ...]):
    if key not in body:
        raise Rejected("field", f"missing field {key!r}")
    value = body[key]
    if isinstance(value, bool) and kind is not bool:
        raise Rejected("field", f"field {key!r} has type bool")
    if not isinstance(value, kind):
        raise Rejected("field", f"field {key!r} has type {type(value).__name__}")
    return value


def _name(body: dict, key: str, limits: Limits) -> str:
    s = _get(body, key, str)
    if not s or len(s) > limits.max_name:
        raise Rejected("field", f"field {key!r} must be a name of 1-{limits.max_name} characters")
    return s


def _index(body: dict, key: str) -> int:
    v = _get(body, key, int)
    if not 0 <= v < 1 << 53:
        raise Rejected("field", f"field {key!r}={v} is not a valid index")
    return v


def _time(body: dict) -> float:
    v = float(_get(body, "ts", (float, int)))
    if not math.isfinite(v):  # a Python float: no NumPy scalar call
        raise Rejected("nonfinite", "send time is not finite")
    return v


def _count(body: dict, key: str, limit: int) -> int:
    n = _get(body, key, int)
    if n < 0 or n > limit:
        raise Rejected("too-many", f"{key}={n} outside [0, {limit}]")
    return n


def _floats(blob: bytes, shape: tuple[int, ...]) -> np.ndarray:
    expected = math.prod(shape) * 8
    if len(blob) != expected:
        raise Rejected("shape", f"{len(blob)} bytes for shape {shape} ({expected} expected)")
    a = np.frombuffer(blob, dtype=_F8).reshape(shape).astype(float)
    if not np.isfinite(a).all():
        raise Rejected("nonfinite", "array holds NaN or infinity")
    return a


def unpack_mixture(blob: bytes, n: int, d: int) -> GaussianMixture:
    """Inverse of :func:`pack_mixture`, validating weights and covariances."""
    t = d * (d + 1) // 2
    rows = _floats(blob, (n, 1 + d + t))
    w, m = rows[:, 0], rows[:, 1:1 + d]
    if n and np.minimum.reduce(w) < 0:  # finite by now: the smallest weight decides
        raise Rejected("weight", "negative component weight")
    P = rows.take(_row_to_full(d), axis=1).reshape(n, d, d)
    if n and not _positive_definite(P):
        raise Rejected("not-psd", "a covariance is not positive definite")
    return GaussianMixture.trusted(w, m, P)  # float, (n,), (n, d), (n, d, d) by construction


def _positive_definite(P: np.ndarray) -> bool:
    """Whether every matrix of the finite stack ``P`` has a Cholesky factor: the LAPACK call of
    ``np.linalg.cholesky`` without its wrapper (which costs more than a few 4x4 factors); a
    matrix that is not positive definite gives NaN there instead of an exception."""
    if _lapack is None:  # pragma: no cover (NumPy without the private module)
        try:
            np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            return False
        return True
    with np.errstate(all="ignore"):
        L = _lapack.cholesky_lo(P, signature="d->d")
    return bool(np.isfinite(L).all())


def _optional(body: dict, key: str, nbytes: int, what: str) -> bytes | None:
    """Field ``key``: nil (not sent) or exactly ``nbytes`` bytes (checked before decoding)."""
    blob = body[key]
    if blob is None:
        return None
    if not isinstance(blob, bytes):
        raise Rejected("field", f"field {key!r} has type {type(blob).__name__}")
    if len(blob) != nbytes:
        raise Rejected("shape", f"{len(blob)} bytes of {what} ({nbytes} expected)")
    return blob


def _tracks_v2(body: dict, limits: Limits) -> Tracks:
    """Tracks with identities: the row count comes from the states and is checked against
    ``max_components``, and every optional block's length against it, before any decoding."""
    d = _count(body, "d", limits.max_dim)
    blob = _get(body, "x", bytes)
    n = _rows(blob, d, limits.max_components, "tracks") if d else 0
    t = d * (d + 1) // 2
    ib = _optional(body, "i", 24 * n, "track ids")
    cb = _optional(body, "c", 8 * n * t, "track covariances")
    eb = _optional(body, "e", 8 * n, "existence probabilities")
    ub = _optional(body, "u", n, "track status")
    sender, k, seq, ts = _name(body, "s", limits), _index(body, "k"), _index(body, "q"), _time(body)
    states = _floats(blob, (n, d))
    ids = covs = existence = status = None
    if ib is not None:
        ids = np.frombuffer(ib, dtype=_I8).reshape(n, 3).astype(np.int64)
        if n and ids.min() < 0:
            raise Rejected("field", "a track id is negative")
    if cb is not None:
        covs = _floats(cb, (n, t)).take(_tri_to_full(d), axis=1).reshape(n, d, d)
        if n and not _positive_definite(covs):
            raise Rejected("not-psd", "a track covariance is not positive definite")
    if eb is not None:
        existence = _floats(eb, (n,))
        if n and (existence.min() < 0.0 or existence.max() > 1.0):
            raise Rejected("field", "an existence probability is outside [0, 1]")
    if ub is not None:
        status = np.frombuffer(ub, dtype=np.int8).copy()
        if n and not np.isin(status, (Tracks.TENTATIVE, Tracks.CONFIRMED)).all():
            raise Rejected("field", "a track status is not 0 (tentative) or 1 (confirmed)")
    return Tracks(sender=sender, k=k, states=states, seq=seq, send_time=ts, ids=ids, covs=covs,
                  existence=existence, status=status)


def _forward(body: dict, limits: Limits) -> Forward:
    """A flooding forward: origin names (unique), points per origin, one block of points."""
    origins = _get(body, "o", list)
    counts = _get(body, "n", list)
    if len(origins) > limits.max_entries:
        raise Rejected("too-many", f"{len(origins)} scans > {limits.max_entries}")
    if len(counts) != len(origins):
        raise Rejected("shape", f"{len(counts)} counts for {len(origins)} scans")
    if not all(type(o) is str and 0 < len(o) <= limits.max_name for o in origins):
        raise Rejected("field", f"origins must be names of 1-{limits.max_name} characters")
    if len(set(origins)) != len(origins):
        raise Rejected("field", "a scan's origin appears twice")
    if not all(type(c) is int for c in counts):
        raise Rejected("field", "point counts must be integers")
    if any(c < 0 or c > limits.max_measurements for c in counts):
        raise Rejected("too-many", f"a point count outside [0, {limits.max_measurements}]")
    blob = _get(body, "x", bytes)
    n = _rows(blob, 2, limits.max_measurements, "measurements")
    if sum(counts) != n:
        raise Rejected("shape", f"{n} measurements for counts summing to {sum(counts)}")
    z = _floats(blob, (n, 2))
    scans, a = {}, 0
    for o, c in zip(origins, counts, strict=True):
        scans[o] = z[a:a + c]
        a += c
    return Forward(sender=_name(body, "s", limits), k=_index(body, "k"),
                   scans=ScanSet(scans), round=_index(body, "r"), seq=_index(body, "q"),
                   send_time=_time(body))


def _names(body: dict, key: str, limits: Limits, most: int) -> list[str]:
    """A list of at most ``most`` names of 1-``max_name`` characters."""
    names = _get(body, key, list)
    if len(names) > most:
        raise Rejected("too-many", f"{len(names)} entries in {key!r} > {most}")
    if not all(type(n) is str and 0 < len(n) <= limits.max_name for n in names):
        raise Rejected("field", f"{key!r} must hold names of 1-{limits.max_name} characters")
    return names


def _telemetry_msg(body: dict, limits: Limits) -> Telemetry:
    """A peer's per-scan telemetry: every list and block checked before decoding."""
    vn = _names(body, "vn", limits, 4 * limits.max_entries)
    vx = _floats(_get(body, "vx", bytes), (len(vn),))
    events = _get(body, "ev", list)
    if len(events) > 64 or not all(type(e) is str and len(e) <= 400 for e in events):
        raise Rejected("field", "events must be at most 64 lines of at most 400 characters")
    pn = _names(body, "pn", limits, 16)
    pc = _get(body, "pc", list)
    if len(pc) != len(pn) or not all(type(c) is int and 0 <= c for c in pc):
        raise Rejected("shape", f"{len(pc)} point counts for {len(pn)} point sets")
    blob = _get(body, "px", bytes)
    n = _rows(blob, 2, limits.max_measurements, "points")
    if sum(pc) != n:
        raise Rejected("shape", f"{n} points for counts summing to {sum(pc)}")
    z, points, a = _floats(blob, (n, 2)), {}, 0
    for name, c in zip(pn, pc, strict=True):
        points[name], a = z[a:a + c], a + c
    d = _count(body, "d", limits.max_dim)
    mixture = None
    if d:
        xb = _get(body, "x", bytes)
        mixture = unpack_mixture(xb, _rows(xb, 1 + d + d * (d + 1) // 2,
                                           limits.max_components, "components"), d)
    return Telemetry(sender=_name(body, "s", limits), k=_index(body, "k"),
                     values=dict(zip(vn, vx.tolist(), strict=True)), events=tuple(events),
                     points=points, mixture=mixture, send_time=_time(body))


def decode(data: bytes, limits: Limits = DEFAULT_LIMITS) -> Message:
    """Parse and validate bytes into a message, or raise :class:`Rejected`."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise Rejected("malformed", f"payload of type {type(data).__name__}")
    if len(data) > limits.max_bytes:
        raise Rejected("too-large", f"{len(data)} bytes > {limits.max_bytes}")
    try:
        body = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True,
                               max_bin_len=limits.max_bytes, max_str_len=4096,
                               max_array_len=1024, max_map_len=64)
    except Exception as exc:  # msgpack raises several unrelated types on bad input
        raise Rejected("malformed", f"not a msgpack message ({type(exc).__name__})") from None
    if not isinstance(body, list) or len(body) < 2:
        raise Rejected("malformed", f"top level is {type(body).__name__}, not a message array")
    version = body[0]
    if type(version) is not int or version not in VERSIONS:
        raise Rejected("version", f"protocol version {version!r}, expected one of "
                                  f"{sorted(VERSIONS)}")
    kind = body[1]
    if not isinstance(kind, str) or kind not in _FIELDS:
        raise Rejected("type", f"unknown message type {kind!r}")
    if kind not in VERSIONS[version]:
        raise Rejected("version", f"protocol version {version} has no message type {kind!r}")
    names = VERSIONS[version][kind]
    if len(body) != 2 + len(names):
        raise Rejected("field", f"{len(body) - 2} fields for type {kind}, {len(names)} expected")
    body = dict(zip(names, body[2:], strict=True))
    try:
        if kind == "E":
            d = _count(body, "d", limits.max_dim)
            if d < 1:
                raise Rejected("field", "dimension must be at least 1")
            blob = _get(body, "x", bytes)
            n = _rows(blob, 1 + d + d * (d + 1) // 2, limits.max_components, "components")
            labels = None
            if version == LABELS_VERSION:  # checked before the mixture is decoded
                ib = _get(body, "i", bytes)
                if len(ib) != 24 * n:
                    raise Rejected("shape", f"{len(ib)} bytes of labels for {n} components "
                                            f"({24 * n} expected)")
                labels = np.frombuffer(ib, dtype=_I8).reshape(n, 3).astype(np.int64)
                if n and labels.min() < 0:
                    raise Rejected("field", "a component label is negative")
            mix = unpack_mixture(blob, n, d)
            pruning = _get(body, "p", int)
            kind_i = _get(body, "o", int)
            if not 0 <= kind_i < len(_KINDS):
                raise Rejected("field", f"unknown estimate kind {kind_i!r}")
            return Estimate(sender=_name(body, "s", limits), k=_index(body, "k"),
                            mixture=mix, round=_index(body, "r"), seq=_index(body, "q"),
                            send_time=_time(body), pruning=pruning, kind=_KINDS[kind_i],
                            labels=labels)
        if kind == "S":
            blob = _get(body, "x", bytes)
            n = _rows(blob, 2, limits.max_measurements, "measurements")
            return Scan(sensor=_name(body, "s", limits), k=_index(body, "k"),
                        z=_floats(blob, (n, 2)), seq=_index(body, "q"), send_time=_time(body))
        if kind == "K" and version == TRACKS_VERSION:
            return _tracks_v2(body, limits)
        if kind == "K":  # protocol 1: states only, the optional fields None
            d = _count(body, "d", limits.max_dim)
            blob = _get(body, "x", bytes)
            n = _rows(blob, d, limits.max_components, "tracks") if d else 0
            return Tracks(sender=_name(body, "s", limits), k=_index(body, "k"),
                          states=_floats(blob, (n, d)), seq=_index(body, "q"),
                          send_time=_time(body))
        if kind == "T":
            d = _count(body, "d", limits.max_dim)
            blob = _get(body, "x", bytes)
            n = _rows(blob, d, limits.max_components, "targets") if d else 0
            x = _floats(blob, (n, d))
            ib = _get(body, "i", bytes)
            if len(ib) != 8 * n:
                raise Rejected("shape", f"{len(ib)} id bytes for {n} targets")
            ids = np.frombuffer(ib, dtype=_I8).astype(np.int64)
            return Truth(k=_index(body, "k"), ids=ids, states=x, send_time=_time(body))
        if kind == "F":
            return _forward(body, limits)
        if kind == "Y":
            return _telemetry_msg(body, limits)
        if kind == "R":
            sender, k, rnd = _name(body, "s", limits), _index(body, "k"), _index(body, "r")
            seq, ts = _index(body, "q"), _time(body)
            blob = _get(body, "x", bytes)
            n = _rows(blob, 2, limits.max_measurements, "returns")
            return Returns(sender=sender, k=k, z=_floats(blob, (n, 2)), round=rnd, seq=seq,
                           send_time=ts)
        params = _get(body, "pa", dict)
        for key, value in params.items():
            if not isinstance(key, str) or not isinstance(value, str | int | float | bool):
                raise Rejected("field", "control parameters must map names to scalars")
        return Control(command=_get(body, "c", str), run_id=_get(body, "id", str),
                       params=params, send_time=_time(body))
    except Rejected:
        raise
    except (ValueError, TypeError, OverflowError) as exc:
        raise Rejected("field", f"{type(exc).__name__}: {exc}") from None
