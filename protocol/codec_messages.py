"""Per-message-type encoders and decoders of the codec (:mod:`protocol.codec`).

Each message type has an encoder, message -> its body by field name (:data:`ENCODERS`, with
its type letter; :data:`protocol.codec_format.VERSIONS` orders the fields on the wire), and a
decoder, body -> validated message (:data:`DECODERS`), which checks every count and byte length
before it decodes an array. A new message type is one entry in each table and one in the
field tables.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from sensornet.protocol.codec_format import (
    _F4,
    _F8,
    _I8,
    _KINDS,
    LABELS_VERSION,
    MASKS_VERSION,
    TRACKS_VERSION,
    Limits,
    Rejected,
    _array,
    _count,
    _floats,
    _get,
    _index,
    _name,
    _names,
    _optional,
    _positive_definite,
    _rows,
    _time,
    _tri_index,
    _tri_to_full,
    pack_mixture,
    unpack_mixture,
)
from sensornet.protocol.messages import (
    Control,
    Estimate,
    Forward,
    Returns,
    Scan,
    ScanSet,
    Telemetry,
    Tracks,
    Truth,
)


# -- encoding: message -> body by field name ------------------------------------------------
def _encode_estimate(msg: Estimate) -> dict:
    """Protocol 1 without labels (byte for byte as always), protocol 2 with them, protocol 3
    with holder-mask words beyond the labels' origin column (``label_masks``)."""
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
        if msg.label_masks is not None:
            m = np.asarray(msg.label_masks)
            if (m.ndim != 2 or len(m) != n or m.shape[1] < 1
                    or (m.size and (m.dtype.kind not in "iu" or m.min() < 0))):
                raise ValueError(f"Estimate.label_masks must be ({n}, W >= 1) non-negative "
                                 f"integers, got {m.shape} {m.dtype}")
            body["v"] = MASKS_VERSION
            body["m"] = np.ascontiguousarray(m, dtype=_I8).tobytes()
    return body


def _encode_scan(msg: Scan) -> dict:
    """Protocol 1 without ages (byte for byte as always), protocol 2 with them."""
    z = np.asarray(msg.z, dtype=float).reshape(-1, 2)
    body = {"s": msg.sensor, "k": int(msg.k), "q": int(msg.seq), "ts": float(msg.send_time),
            "x": _array(z)}
    if msg.ages is not None:
        a = np.asarray(msg.ages, dtype=float)
        if a.shape != (len(z),):
            raise ValueError(f"Scan.ages must be ({len(z)},), got {a.shape}")
        body["v"] = TRACKS_VERSION
        body["a"] = _array(a)
    return body


def _states(states) -> np.ndarray:
    x = np.asarray(states, dtype=float)
    return x.reshape(len(x), -1) if x.size else x.reshape(0, 4)


def _encode_tracks(msg: Tracks) -> dict:
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


def _encode_truth(msg: Truth) -> dict:
    x = _states(msg.states)
    ids = np.ascontiguousarray(msg.ids, dtype=_I8)
    return {"k": int(msg.k), "ts": float(msg.send_time), "d": x.shape[1], "x": _array(x),
            "i": ids.tobytes()}


def _encode_forward(msg: Forward) -> dict:
    origins = list(msg.scans.scans)
    zs = [np.asarray(msg.scans.scans[o], dtype=float).reshape(-1, 2) for o in origins]
    return {"s": msg.sender, "k": int(msg.k), "r": int(msg.round), "q": int(msg.seq),
            "ts": float(msg.send_time), "o": origins, "n": [len(z) for z in zs],
            "x": _array(np.concatenate(zs) if zs else np.zeros((0, 2)))}


def _encode_returns(msg: Returns) -> dict:
    z = np.asarray(msg.z, dtype=float).reshape(-1, 2)
    return {"s": msg.sender, "k": int(msg.k), "r": int(msg.round), "q": int(msg.seq),
            "ts": float(msg.send_time), "x": _array(z)}


def _encode_control(msg: Control) -> dict:
    return {"c": msg.command, "id": msg.run_id, "pa": dict(msg.params),
            "ts": float(msg.send_time)}


_F4_MAX = float(np.finfo(np.float32).max)


def _encode_telemetry(msg: Telemetry) -> dict:
    """Protocol 2: the points as float32 (map marks for the eye); protocol 1 (float64) if
    one does not fit (beyond float32's range, or not finite: then the receiver says so)."""
    names = list(msg.points)
    pts = [np.asarray(msg.points[n], dtype=float).reshape(-1, 2) for n in names]
    mix = msg.mixture
    z = np.concatenate(pts) if pts else np.zeros((0, 2))
    body = {"s": msg.sender, "k": int(msg.k), "ts": float(msg.send_time),
            "vn": list(msg.values), "vx": _array(np.fromiter(msg.values.values(), float,
                                                              len(msg.values))),
            "ev": list(msg.events), "pn": names, "pc": [len(z) for z in pts],
            "d": 0 if mix is None else mix.dim,
            "x": b"" if mix is None else pack_mixture(mix)}
    if not z.size or float(np.abs(z).max()) <= _F4_MAX:  # NaN compares False: protocol 1
        body["v"], body["pf"] = TRACKS_VERSION, z.astype(_F4).tobytes()
    else:
        body["px"] = _array(z)
    return body


ENCODERS: dict[type, tuple[str, Callable[[Any], dict]]] = {
    Estimate: ("E", _encode_estimate), Scan: ("S", _encode_scan), Tracks: ("K", _encode_tracks),
    Truth: ("T", _encode_truth), Forward: ("F", _encode_forward),
    Returns: ("R", _encode_returns), Control: ("C", _encode_control),
    Telemetry: ("Y", _encode_telemetry),
}
"""Message type -> (wire type letter, the fields of its body by name); ``_FIELDS`` orders them."""


# -- decoding: body by field name -> validated message --------------------------------------
def _decode_estimate(body: dict, limits: Limits, version: int) -> Estimate:
    """A mixture: its dimension, row count and (protocol 2) labels checked before decoding.

    Each field is checked by its exact type first (what msgpack gives for a valid message)
    and only otherwise by the general readers (``_get``, ``_count``, ...), which raise the
    same :class:`Rejected` as always: the checks and reasons are unchanged, their per-field
    call is not paid on every estimate a peer receives (about 2 decodes a peer-scan in a
    host, issue 38)."""
    d = body["d"]  # read_header made every field of the version's table a key
    if type(d) is not int or not 1 <= d <= limits.max_dim:
        d = _count(body, "d", limits.max_dim)
        if d < 1:
            raise Rejected("field", "dimension must be at least 1")
    blob = body["x"]
    if type(blob) is not bytes:
        blob = _get(body, "x", bytes)
    width = 1 + d + d * (d + 1) // 2
    n = _rows(blob, width, limits.max_components, "components")
    labels = masks = None
    if version in (LABELS_VERSION, MASKS_VERSION):  # checked before the mixture is decoded
        ib = body["i"]
        if type(ib) is not bytes:
            ib = _get(body, "i", bytes)
        if len(ib) != 24 * n:
            raise Rejected("shape", f"{len(ib)} bytes of labels for {n} components "
                                    f"({24 * n} expected)")
        labels = np.frombuffer(ib, dtype=_I8).reshape(n, 3).astype(np.int64)
        if n and np.minimum.reduce(labels, None) < 0:
            raise Rejected("field", "a component label is negative")
    if version == MASKS_VERSION:
        mb = _get(body, "m", bytes)
        if (len(mb) % (8 * n) if n else len(mb)) or (n and not mb):
            raise Rejected("shape", f"{len(mb)} bytes of label masks for {n} components "
                                    "(a whole number of words, at least one, a component)")
        if n and len(mb) // (8 * n) > limits.max_mask_words:
            raise Rejected("too-many", f"{len(mb) // (8 * n)} label mask words a component > "
                                       f"{limits.max_mask_words}")
        masks = np.frombuffer(mb, dtype=_I8).reshape(n, -1 if n else 1).astype(np.int64)
        if n and masks.min() < 0:
            raise Rejected("field", "a label mask word is negative")
    mix = unpack_mixture(blob, n, d)
    pruning, kind_i = body["p"], body["o"]
    if type(pruning) is not int:
        pruning = _get(body, "p", int)
    if type(kind_i) is not int:
        kind_i = _get(body, "o", int)
    if not 0 <= kind_i < len(_KINDS):
        raise Rejected("field", f"unknown estimate kind {kind_i!r}")
    s, k, r, q, ts = body["s"], body["k"], body["r"], body["q"], body["ts"]
    if type(s) is not str or not 0 < len(s) <= limits.max_name:
        s = _name(body, "s", limits)
    if type(k) is not int or not 0 <= k < _INDEX_END:
        k = _index(body, "k")
    if type(r) is not int or not 0 <= r < _INDEX_END:
        r = _index(body, "r")
    if type(q) is not int or not 0 <= q < _INDEX_END:
        q = _index(body, "q")
    if type(ts) is not float or not math.isfinite(ts):
        ts = _time(body)
    return Estimate(sender=s, k=k, mixture=mix, round=r, seq=q, send_time=ts,
                    pruning=pruning, kind=_KINDS[kind_i], labels=labels, label_masks=masks)


_INDEX_END = 1 << 53
"""Scan indices, rounds and sequence numbers are below this (as ``_index`` checks)."""


def _decode_scan(body: dict, limits: Limits, version: int) -> Scan:
    blob = _get(body, "x", bytes)
    n = _rows(blob, 2, limits.max_measurements, "measurements")
    ages = None
    if version == TRACKS_VERSION:  # each plot's age: one float64 per row of "x"
        ages = _floats(_get(body, "a", bytes), (n,))
    return Scan(sensor=_name(body, "s", limits), k=_index(body, "k"),
                z=_floats(blob, (n, 2)), seq=_index(body, "q"), send_time=_time(body),
                ages=ages)


def _decode_tracks(body: dict, limits: Limits, version: int) -> Tracks:
    """Protocol 1: states only, the optional fields None; protocol 2: :func:`_tracks_v2`."""
    if version == TRACKS_VERSION:
        return _tracks_v2(body, limits)
    d = _count(body, "d", limits.max_dim)
    blob = _get(body, "x", bytes)
    n = _rows(blob, d, limits.max_components, "tracks") if d else 0
    return Tracks(sender=_name(body, "s", limits), k=_index(body, "k"),
                  states=_floats(blob, (n, d)), seq=_index(body, "q"),
                  send_time=_time(body))


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
        # two comparisons, not np.isin (~60 us a call, most of a tracks message's decoding)
        if n and not ((status == Tracks.TENTATIVE) | (status == Tracks.CONFIRMED)).all():
            raise Rejected("field", "a track status is not 0 (tentative) or 1 (confirmed)")
    return Tracks(sender=sender, k=k, states=states, seq=seq, send_time=ts, ids=ids, covs=covs,
                  existence=existence, status=status)


def _decode_truth(body: dict, limits: Limits, version: int) -> Truth:
    d = _count(body, "d", limits.max_dim)
    blob = _get(body, "x", bytes)
    n = _rows(blob, d, limits.max_components, "targets") if d else 0
    x = _floats(blob, (n, d))
    ib = _get(body, "i", bytes)
    if len(ib) != 8 * n:
        raise Rejected("shape", f"{len(ib)} id bytes for {n} targets")
    ids = np.frombuffer(ib, dtype=_I8).astype(np.int64)
    return Truth(k=_index(body, "k"), ids=ids, states=x, send_time=_time(body))


def _decode_forward(body: dict, limits: Limits, version: int) -> Forward:
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


def _decode_returns(body: dict, limits: Limits, version: int) -> Returns:
    sender, k, rnd = _name(body, "s", limits), _index(body, "k"), _index(body, "r")
    seq, ts = _index(body, "q"), _time(body)
    blob = _get(body, "x", bytes)
    n = _rows(blob, 2, limits.max_measurements, "returns")
    return Returns(sender=sender, k=k, z=_floats(blob, (n, 2)), round=rnd, seq=seq,
                   send_time=ts)


def _decode_control(body: dict, limits: Limits, version: int) -> Control:
    params = _get(body, "pa", dict)
    for key, value in params.items():
        if not isinstance(key, str) or not isinstance(value, str | int | float | bool):
            raise Rejected("field", "control parameters must map names to scalars")
    return Control(command=_get(body, "c", str), run_id=_get(body, "id", str),
                   params=params, send_time=_time(body))


def _decode_telemetry(body: dict, limits: Limits, version: int) -> Telemetry:
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
    blob, dtype = (_get(body, "pf", bytes), _F4) if version == TRACKS_VERSION else (
        _get(body, "px", bytes), _F8)
    n = _rows(blob, 2, limits.max_measurements, "points", dtype.itemsize)
    if sum(pc) != n:
        raise Rejected("shape", f"{n} points for counts summing to {sum(pc)}")
    z, points, a = _floats(blob, (n, 2), dtype), {}, 0
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

DECODERS: dict[str, Callable[[dict, Limits, int], Any]] = {
    "E": _decode_estimate, "S": _decode_scan, "K": _decode_tracks, "T": _decode_truth,
    "F": _decode_forward, "R": _decode_returns, "C": _decode_control, "Y": _decode_telemetry,
}
"""Wire type letter -> ``(body, limits, version) -> message`` (every letter of ``_FIELDS``)."""
