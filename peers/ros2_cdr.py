"""The CDR bytes of :mod:`peers.ros2`'s three messages, packed directly: no message objects.

``rosbags``' serializer (``typestore().serialize_cdr``) needs one Python object per message,
track, marker, pose, point, colour and header, about 40 us a Marker; a peer publishing its
tracks and their markers at every scan paid +40 % CPU for it. Here each message is packed from
the :class:`~sensornet.protocol.messages.Tracks` arrays: the tracks as one NumPy record array
(every ``Track`` of a message has the same layout), the markers and the point cloud with one
precompiled :class:`struct.Struct` per field layout. ``rosbags`` stays the reference:
``tests/test_ros2_cdr.py`` checks these bytes equal ``serialize_cdr``'s for random messages.

CDR (XCDR1, little-endian, the 4-byte encapsulation header ``00 01 00 00``): every primitive
aligned to its size from the start of the body (after the header), a string as uint32 length
(with its NUL), the bytes and the NUL, a sequence as uint32 count and its elements (no padding
when it is empty).
"""

from __future__ import annotations

import struct
from functools import cache

import numpy as np
from sensornet.peers.rerun_layout import PALETTE, position_columns
from sensornet.protocol.messages import Tracks

ENCAPSULATION = b"\x00\x01\x00\x00"
"""CDR little-endian (``CDR_LE``), no options."""
FRAME = b"map"
UNKNOWN_STATUS = 255
_SIZES = {"?": 1, "B": 1, "i": 4, "I": 4, "q": 8, "d": 8, "f": 4}
ARROW, CYLINDER, TEXT_VIEW_FACING = 0, 3, 9
"""``visualization_msgs/msg/Marker`` types used."""
ADD, DELETEALL = 0, 3
"""``visualization_msgs/msg/Marker`` actions used."""
FLOAT32 = 7
"""``sensor_msgs/msg/PointField.FLOAT32``."""


@cache
def layout(tokens: tuple, start: int) -> tuple[struct.Struct, int]:
    """The :class:`struct.Struct` packing CDR fields ``tokens`` that begin at body offset
    ``start`` (0-7: only the offset mod 8 matters), and its size. A token is a string of
    primitive codes (``"iI"``: int32, uint32; each aligned to its size) or an int ``n``: a
    string of ``n`` bytes, packed from two values (``n + 1``, the bytes)."""
    fmt, pos = ["<"], start
    for tok in tokens:
        if isinstance(tok, int):
            pad = -pos % 4
            fmt.append(f"{pad}xI{tok}sx")
            pos += pad + 4 + tok + 1
            continue
        for code in tok:
            size = _SIZES[code]
            pad = -pos % size
            fmt.append(f"{pad}x{code}")
            pos += pad + size
    return struct.Struct("".join(fmt)), pos - start


def _stamp(stamp_ns: int) -> tuple[int, int]:
    return int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000)


# -- the arrays both the rosbags messages and these bytes come from -----------------------------
def states(tracks: Tracks) -> np.ndarray:
    """``tracks.states`` as an ``(n, d)`` float array (also when there are none)."""
    X = np.asarray(tracks.states, dtype=float)
    n = len(X)
    d = X.shape[1] if X.ndim == 2 else (X.size // n if n else 0)
    return X.reshape(n, d)


def track_columns(tracks: Tracks) -> tuple[np.ndarray, ...]:
    """``(X (n, d), ids (n, 3) int64, status (n,) uint8, existence (n,), covs (n, d*d) or
    (n, 0), xy (n, 2))`` of ``tracks``, absent fields as ``sensornet_msgs/Track`` sends them
    (-1 labels, status 255, NaN existence, no covariance)."""
    X = states(tracks)
    n, d = X.shape
    ids = (np.full((n, 3), -1, np.int64) if tracks.ids is None
           else np.asarray(tracks.ids, np.int64).reshape(n, 3))
    status = (np.full(n, UNKNOWN_STATUS, np.uint8) if tracks.status is None
              else np.asarray(tracks.status).astype(np.uint8))
    r = np.full(n, np.nan) if tracks.existence is None else np.asarray(tracks.existence, float)
    covs = (np.zeros((n, 0)) if tracks.covs is None
            else np.asarray(tracks.covs, float).reshape(n, d * d))
    xy = X[:, position_columns(d)] if d >= 3 else np.zeros((n, 2))
    return X, ids, status, r, covs, xy


def ellipse_axes(covs: np.ndarray, sigma: float = 2.0) -> tuple[np.ndarray, ...]:
    """``sigma``-ellipses of ``(n, 2, 2)`` position covariances in closed form: full axis
    lengths ``(n,)`` major, minor and the major axis' angle from x (radians)."""
    a, b, d = covs[:, 0, 0], covs[:, 0, 1], covs[:, 1, 1]
    half, root = (a + d) / 2, np.hypot((a - d) / 2, b)
    big, small = np.maximum(half + root, 0.0), np.maximum(half - root, 0.0)
    return 2 * sigma * np.sqrt(big), 2 * sigma * np.sqrt(small), 0.5 * np.arctan2(2 * b, a - d)


def marker_columns(tracks: Tracks) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                              list[str]]:
    """``(xy (n, 2), major, minor, angle, labels)``: each track's 2-sigma position ellipse
    (no covariance: a 20 m disc) and its label ``origin.birth.index`` (``?`` unlabelled)."""
    X = states(tracks)
    n, d = X.shape
    c = position_columns(d)
    if tracks.covs is not None and n and d >= 3:
        major, minor, angle = ellipse_axes(np.asarray(tracks.covs, float)[:, c][:, :, c])
    else:
        major, minor, angle = np.full(n, 20.0), np.full(n, 20.0), np.zeros(n)
    labels = (["?"] * n if tracks.ids is None
              else [".".join(map(str, row)) for row in np.asarray(tracks.ids).tolist()])
    return (X[:, c] if d >= 3 else np.zeros((n, 2))), major, minor, angle, labels


def cloud_points(points: np.ndarray) -> np.ndarray:
    """``(m, 3)`` float32 x, y, z (z = 0) of ``(m, 2)`` x-y points."""
    P = np.asarray(points, float).reshape(-1, 2)
    xyz = np.zeros((len(P), 3), np.float32)
    xyz[:, :2] = P
    return xyz


# -- sensornet_msgs/msg/Tracks ------------------------------------------------------------------
@cache
def _track_dtype(d: int, has_cov: bool) -> tuple[np.dtype, int]:
    """One ``Track``'s record (it starts 8-aligned: its first field is an int64) and the
    bytes of its last field's end (the record's itemsize pads that to 8 for the next)."""
    names = ["origin", "birth", "index", "status", "existence", "position", "n_state"]
    formats: list = ["<i8", "<i8", "<i8", "u1", "<f8", ("<f8", (3,)), "<u4"]
    offsets = [0, 8, 16, 24, 32, 40, 64]
    pos = 68
    if d:
        names.append("state"), formats.append(("<f8", (d,))), offsets.append(72)
        pos = 72 + 8 * d
    names.append("n_cov"), formats.append("<u4"), offsets.append(pos)
    pos += 4
    if has_cov and d:
        pos += -pos % 8
        names.append("cov"), formats.append(("<f8", (d * d,))), offsets.append(pos)
        pos += 8 * d * d
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets,
                      "itemsize": pos + -pos % 8})
    return dtype, pos


def tracks_cdr(tracks: Tracks, stamp_ns: int, scan_period: float = 1.0) -> bytes:
    """``sensornet_msgs/msg/Tracks`` of ``tracks`` as CDR (peers.ros2.tracks_message's)."""
    X, ids, status, r, covs, xy = track_columns(tracks)
    n, d = X.shape
    peer = tracks.sender.encode()
    head, size = layout(("iI", 3, len(peer), "I", "d", "I"), 0)
    sec, nsec = _stamp(stamp_ns)
    out = [ENCAPSULATION, head.pack(sec, nsec, 4, FRAME, len(peer) + 1, peer, int(tracks.k),
                                    tracks.k * scan_period, n)]
    if n:
        has_cov = covs.shape[1] > 0
        dtype, end = _track_dtype(d, has_cov)
        rec = np.zeros(n, dtype)
        rec["origin"], rec["birth"], rec["index"] = ids[:, 0], ids[:, 1], ids[:, 2]
        rec["status"], rec["existence"] = status, r
        rec["position"][:, :2] = xy
        rec["n_state"] = d
        if d:
            rec["state"] = X
        if has_cov and d:
            rec["n_cov"], rec["cov"] = d * d, covs
        out += [bytes(-size % 8), rec.tobytes()[:(n - 1) * dtype.itemsize + end]]
    return b"".join(out)


# -- visualization_msgs/msg/MarkerArray ---------------------------------------------------------
@cache
def _marker_layout(ns: int, text: int, start: int) -> tuple[struct.Struct, int]:
    """A ``Marker`` with an ``ns`` of ``ns`` bytes and a ``text`` of ``text`` bytes, every
    sequence empty, beginning at ``start`` mod 8."""
    return layout((
        "iI", 3, ns, "iii",  # header (stamp, frame_id), ns, id, type, action
        "ddddddd", "ddd", "ffff", "iI", "?",  # pose, scale, color, lifetime, frame_locked
        "I", "I", 0, "iI", 3, 0, "I",  # points, colors, texture_resource, texture
        "I", text, 0, 0, "I", "?",  # uv_coordinates, text, mesh_resource, mesh_file, embedded
    ), start)


def markers_cdr(tracks: Tracks, stamp_ns: int, color_index: int = 0) -> bytes:
    """``visualization_msgs/msg/MarkerArray`` as CDR (peers.ros2.markers_message's): a
    DELETEALL, then per track a flat cylinder on its 2-sigma ellipse and a text label."""
    xy, major, minor, angle, labels = marker_columns(tracks)
    n = len(xy)
    ns = tracks.sender.encode()
    sec, nsec = _stamp(stamp_ns)
    rgb = [c / 255 for c in PALETTE[color_index % len(PALETTE)]]
    head = (sec, nsec, 4, FRAME, len(ns) + 1, ns)
    # lifetime .. uv_coordinates: all zero or empty
    tail = (0, 0, False, 0, 0, 1, b"", sec, nsec, 4, FRAME, 1, b"", 0, 0)
    end = (1, b"", 1, b"", 0, False)
    half = angle / 2
    rows = zip(range(1, 2 * n, 2), xy.tolist(), major.tolist(), minor.tolist(),
               np.sin(half).tolist(), np.cos(half).tolist(), labels, strict=True)
    out, pos = [ENCAPSULATION, struct.pack("<I", 1 + 2 * n)], 4
    st, size = _marker_layout(len(ns), 0, pos % 8)
    out.append(st.pack(*head, 0, ARROW, DELETEALL, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0,
                       1.0, 1.0, 1.0, *rgb, 0.0, *tail, 1, b"", *end))
    pos += size
    for i, (x, y), big, small, qz, qw, label in rows:
        out.append(bytes(-pos % 4))
        pos += -pos % 4
        st, size = _marker_layout(len(ns), 0, pos % 8)
        out.append(st.pack(*head, i, CYLINDER, ADD, x, y, 0.0, 0.0, 0.0, qz, qw,
                           big, small, 1.0, *rgb, 0.35, *tail, 1, b"", *end))
        pos += size
        out.append(bytes(-pos % 4))
        pos += -pos % 4
        text = label.encode()
        st, size = _marker_layout(len(ns), len(text), pos % 8)
        out.append(st.pack(*head, i + 1, TEXT_VIEW_FACING, ADD, x, y, 5.0, 0.0, 0.0, 0.0, 1.0,
                           0.0, 0.0, 30.0, *rgb, 1.0, *tail, len(text) + 1, text, *end))
        pos += size
    return b"".join(out)


# -- sensor_msgs/msg/PointCloud2 ----------------------------------------------------------------
_CLOUD_HEAD = ("iI", 3, "II", "I", 1, "IBI", 1, "IBI", 1, "IBI", "?", "II", "I")


def cloud_cdr(points: np.ndarray, stamp_ns: int) -> bytes:
    """``sensor_msgs/msg/PointCloud2`` of ``(m, 2)`` x-y points as CDR (peers.ros2's
    cloud_message): fields x, y, z float32, one row, dense."""
    xyz = cloud_points(points)
    m = len(xyz)
    st, _ = layout(_CLOUD_HEAD, 0)
    sec, nsec = _stamp(stamp_ns)
    head = st.pack(sec, nsec, 4, FRAME, 1, m, 3, 2, b"x", 0, FLOAT32, 1, 2, b"y", 4, FLOAT32, 1,
                   2, b"z", 8, FLOAT32, 1, False, 12, 12 * m, 12 * m)
    return b"".join([ENCAPSULATION, head, xyz.tobytes(), b"\x01"])
