"""ROS 2 without ROS: a peer's tracks (and the world's detections) as ROS 2 messages on Zenoh,
laid out as ``rmw_zenoh_cpp`` lays them out, so that a ROS 2 machine on the same Zenoh network
(``RMW_IMPLEMENTATION=rmw_zenoh_cpp``) lists, echoes and draws them (docs/ros2.md).

The format is rmw_zenoh's design document (ros2/rmw_zenoh, design.md: "Topic and Service name
mapping to Zenoh key expressions", "Graph Cache", "Publishers") and
rmw_zenoh_cpp/src/detail/liveliness_utils.cpp (``qos_to_keyexpr``, ``mangle_name``, ``Entity``):

- data key ``<domain>/<topic without leading slash>/<pkg>::msg::dds_::<Name>_/RIHS01_<sha256>``;
- payload: CDR, little-endian, with its 4-byte encapsulation header (``rosbags``);
- attachment: sequence number (int64 LE), source timestamp (int64 LE, ns since the epoch),
  the GID's length (one byte, 16) and the 16-byte publisher GID;
- liveliness tokens ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP>/<enclave>/
  <namespace>/<node>[/<topic>/<type>/<hash>/<qos>]``, ``/`` mangled to ``%``.

Types: ``visualization_msgs/msg/MarkerArray`` (2-sigma ellipses and labels, for RViz/Foxglove)
and ``sensor_msgs/msg/PointCloud2`` (detections) from Jazzy's standard set; the tracks as
``sensornet_msgs/msg/Tracks`` (:data:`MESSAGE_DEFINITIONS`), registered in ``rosbags``' type
store, because no standard ROS 2 message carries a track's label, covariance and existence
(``radar_msgs/RadarTracks`` is not in the store and has neither of the last two).

Messages as ``rosbags`` objects here (the reference); the peers publish the same bytes packed
directly by :mod:`peers.ros2_cdr` (about a fifth of the CPU).

Everything but :class:`Ros2Node` is pure (bytes and strings); :class:`Ros2Node` takes a Zenoh
session object and never imports Zenoh.
"""

from __future__ import annotations

import hashlib
import itertools
import re
import struct
import threading
import time
from dataclasses import dataclass
from functools import cache

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from sensornet.peers import ros2_cdr
from sensornet.peers.rerun_layout import PALETTE
from sensornet.protocol.messages import Tracks

ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER = "NN", "MP"
GID_SIZE = 16
FRAME = "map"
"""``header.frame_id`` of everything sent: the scenario's local x-y frame, metres."""
NAMESPACE = "/sensornet"
"""Every node's namespace: topics ``/sensornet/<peer>/tracks`` and so on."""
DEPTH = 10
"""The publishers' KEEP_LAST depth (reliable, volatile: rclcpp's default profile)."""
UNKNOWN_STATUS = ros2_cdr.UNKNOWN_STATUS
"""``Track.status`` of a track whose status was not sent."""

MESSAGE_DEFINITIONS = {
    "sensornet_msgs/msg/Track": """\
# One track of a sensornet peer (protocol.messages.Tracks, one row).
# Label (tracking.labels): the peer that gave birth, the scan of birth, the index within it;
# -1 -1 -1 when the peer's filter is unlabelled.
int64 origin
int64 birth_scan
int64 index
# 0 tentative, 1 confirmed, 255 not sent.
uint8 status
# Probability of existence in [0, 1] (a PHD weight clipped to 1, an LMB r); NaN: not sent.
float64 existence
# (px, py, 0) in metres in header.frame_id.
geometry_msgs/Point position
# The filter's state, e.g. [px, vx, py, vy] (m, m/s).
float64[] state
# Its covariance, row-major d x d; empty: not sent.
float64[] covariance
""",
    "sensornet_msgs/msg/Tracks": """\
# A sensornet peer's (fused) tracks at one scan.
# stamp: the peer's wall clock at publication; frame_id: map (the scenario's x-y frame, m).
std_msgs/Header header
string peer
# Scan index k (simulated time k T) and that time in seconds.
uint32 scan
float64 scan_time
sensornet_msgs/Track[] tracks
""",
}
"""The message package ``sensornet_msgs`` (docs/ros2.md builds it on a ROS 2 machine)."""

TRACKS = "sensornet_msgs/msg/Tracks"
MARKERS = "visualization_msgs/msg/MarkerArray"
CLOUD = "sensor_msgs/msg/PointCloud2"


@cache
def typestore():
    """Jazzy's standard types plus :data:`MESSAGE_DEFINITIONS` (one per process)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in MESSAGE_DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


# -- names and keys (design.md, liveliness_utils.cpp) ---------------------------------------
def dds_type_name(msgtype: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs::msg::dds_::String_`` (the CDR type name)."""
    parts = msgtype.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"msgtype {msgtype!r} is not 'package/msg/Name'")
    pkg, kind, name = parts
    return f"{pkg}::{kind}::dds_::{name}_"


@cache
def type_hash(msgtype: str) -> str:
    """The type's REP-2016 hash ``RIHS01_<64 hex>`` (rosbags' type store)."""
    return typestore().hash_rihs01(msgtype)


def mangle(name: str) -> str:
    """``mangle_name``: every ``/`` replaced by ``%`` (``/`` -> ``%``, ``/a/b`` -> ``%a%b``)."""
    return name.replace("/", "%")


def ros_name(text: str) -> str:
    """A valid ROS name token from ``text``: other characters become ``_``, a leading digit
    gets an ``n`` in front (ROS names start with a letter)."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", text) or "_"
    return f"n{out}" if out[0].isdigit() else out


def topic_key(domain: int, topic: str, msgtype: str) -> str:
    """The data key of ``topic``: ``<domain>/<topic without leading slash>/<type>/<hash>``."""
    if domain < 0:
        raise ValueError(f"domain {domain} is negative")
    if not topic.startswith("/"):
        raise ValueError(f"topic {topic!r} is not fully qualified (starts with /)")
    return f"{domain}/{topic.strip('/')}/{dds_type_name(msgtype)}/{type_hash(msgtype)}"


def qos_string(depth: int = DEPTH, reliability: int | None = None,
               durability: int | None = None, history: int | None = None) -> str:
    """``qos_to_keyexpr``: each policy's number where it differs from rmw_zenoh's default
    (RELIABLE, VOLATILE, KEEP_LAST 42, infinite deadline/lifespan/lease, AUTOMATIC), else
    empty: ``reliability:durability:history,depth:dl_s,dl_ns:ls_s,ls_ns:lv,lv_s,lv_ns``."""

    def part(v):
        return "" if v is None else str(v)

    return (f"{part(reliability)}:{part(durability)}:{part(history)},"
            f"{'' if depth == 42 else depth}:,:,:,,")


def node_token(domain: int, zid: str, node_id: int, node: str, namespace: str = NAMESPACE,
               enclave: str = "/") -> str:
    """A node's liveliness key (``NN``; its entity id is its node id)."""
    return "/".join([ADMIN_SPACE, str(domain), zid, str(node_id), str(node_id), NODE,
                     mangle(enclave), mangle(namespace), mangle(node)])


def publisher_token(domain: int, zid: str, node_id: int, entity_id: int, node: str,
                    topic: str, msgtype: str, qos: str | None = None,
                    namespace: str = NAMESPACE, enclave: str = "/") -> str:
    """A publisher's liveliness key (``MP``) on ``topic`` (fully qualified)."""
    return "/".join([ADMIN_SPACE, str(domain), zid, str(node_id), str(entity_id), PUBLISHER,
                     mangle(enclave), mangle(namespace), mangle(node), mangle(topic),
                     dds_type_name(msgtype), type_hash(msgtype),
                     qos_string() if qos is None else qos])


def gid_of(token: str) -> bytes:
    """A 16-byte publisher GID from its liveliness key (rmw_zenoh takes XXH3-128 of the same
    string; any stable 16 bytes serve: receivers read the GID, they never recompute it)."""
    return hashlib.blake2b(token.encode(), digest_size=GID_SIZE).digest()


_ATTACHMENT = struct.Struct("<qqB16s")


def attachment(seq: int, stamp_ns: int, gid: bytes) -> bytes:
    """The put's attachment: ``seq`` int64 LE, ``stamp_ns`` int64 LE, 1-byte length 16, GID."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"gid has {len(gid)} bytes, not {GID_SIZE}")
    return _ATTACHMENT.pack(seq, stamp_ns, GID_SIZE, gid)


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """``(seq, stamp_ns, gid)`` from an attachment (:func:`attachment`'s inverse)."""
    if len(data) != 33 or data[16] != GID_SIZE:
        raise ValueError(f"attachment of {len(data)} bytes is not rmw_zenoh's 33-byte layout")
    seq, stamp, _, gid = struct.unpack("<qqB16s", data)
    return seq, stamp, gid


# -- messages ---------------------------------------------------------------------------------
def _stamp(store, stamp_ns: int):
    Time = store.types["builtin_interfaces/msg/Time"]
    return store.types["std_msgs/msg/Header"](
        stamp=Time(sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000)),
        frame_id=FRAME)


def tracks_message(tracks: Tracks, stamp_ns: int, scan_period: float = 1.0):
    """``sensornet_msgs/msg/Tracks`` of a :class:`Tracks` (absent optional fields: -1 labels,
    status 255, NaN existence, empty covariance)."""
    store = typestore()
    Track, Point = store.types["sensornet_msgs/msg/Track"], store.types["geometry_msgs/msg/Point"]
    X, ids, status, r, covs, pos = ros2_cdr.track_columns(tracks)
    rows = [Track(origin=int(i[0]), birth_scan=int(i[1]), index=int(i[2]), status=int(s),
                  existence=float(e), position=Point(x=float(p[0]), y=float(p[1]), z=0.0),
                  state=x, covariance=c)
            for i, s, e, p, x, c in zip(ids, status, r, pos, X, covs, strict=True)]
    return store.types[TRACKS](header=_stamp(store, stamp_ns), peer=tracks.sender,
                               scan=int(tracks.k), scan_time=tracks.k * scan_period,
                               tracks=rows)


def markers_message(tracks: Tracks, stamp_ns: int, color_index: int = 0):
    """``visualization_msgs/msg/MarkerArray``: a DELETEALL, then per track a flat cylinder on
    its 2-sigma position ellipse (no covariance: a 20 m disc) and a text with its label."""
    store = typestore()
    T = store.types
    Marker, Pose, Point, Quat, Vec, Color, Duration = (T[f"{n}/msg/{m}"] for n, m in (
        ("visualization_msgs", "Marker"), ("geometry_msgs", "Pose"), ("geometry_msgs", "Point"),
        ("geometry_msgs", "Quaternion"), ("geometry_msgs", "Vector3"), ("std_msgs", "ColorRGBA"),
        ("builtin_interfaces", "Duration")))
    header = _stamp(store, stamp_ns)
    rgb = [c / 255 for c in PALETTE[color_index % len(PALETTE)]]
    ns = tracks.sender

    def marker(id_, type_, action, pose, scale, alpha, text=""):
        return Marker(header=header, ns=ns, id=id_, type=type_, action=action, pose=pose,
                      scale=scale, color=Color(r=rgb[0], g=rgb[1], b=rgb[2], a=alpha),
                      lifetime=Duration(sec=0, nanosec=0), frame_locked=False, points=[],
                      colors=[], texture_resource="",
                      texture=T["sensor_msgs/msg/CompressedImage"](
                          header=header, format="", data=np.zeros(0, np.uint8)),
                      uv_coordinates=[], text=text, mesh_resource="",
                      mesh_file=T["visualization_msgs/msg/MeshFile"](
                          filename="", data=np.zeros(0, np.uint8)),
                      mesh_use_embedded_materials=False)

    xy, major, minor, angle, labels = ros2_cdr.marker_columns(tracks)
    n = len(xy)
    out = [marker(0, Marker.ARROW, Marker.DELETEALL, Pose(
        position=Point(x=0.0, y=0.0, z=0.0), orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0)),
        Vec(x=1.0, y=1.0, z=1.0), 0.0)]
    for i in range(n):
        p = Point(x=float(xy[i, 0]), y=float(xy[i, 1]), z=0.0)
        q = Quat(x=0.0, y=0.0, z=float(np.sin(angle[i] / 2)), w=float(np.cos(angle[i] / 2)))
        out.append(marker(2 * i + 1, Marker.CYLINDER, Marker.ADD, Pose(position=p, orientation=q),
                          Vec(x=float(major[i]), y=float(minor[i]), z=1.0), 0.35))
        out.append(marker(2 * i + 2, Marker.TEXT_VIEW_FACING, Marker.ADD,
                          Pose(position=Point(x=p.x, y=p.y, z=5.0),
                               orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0)),
                          Vec(x=0.0, y=0.0, z=30.0), 1.0, labels[i]))
    return T[MARKERS](markers=out)


def cloud_message(points: np.ndarray, stamp_ns: int):
    """``sensor_msgs/msg/PointCloud2`` of ``(m, 2)`` x-y points: fields x, y, z float32
    (z = 0), one row, dense."""
    store = typestore()
    T = store.types
    xyz = ros2_cdr.cloud_points(points)
    Field = T["sensor_msgs/msg/PointField"]
    fields = [Field(name=n, offset=4 * i, datatype=Field.FLOAT32, count=1)
              for i, n in enumerate("xyz")]
    return T[CLOUD](header=_stamp(store, stamp_ns), height=1, width=len(xyz), fields=fields,
                    is_bigendian=False, point_step=12, row_step=12 * len(xyz),
                    data=np.frombuffer(xyz.tobytes(), np.uint8), is_dense=True)


def serialize(message, msgtype: str) -> bytes:
    """CDR (little-endian, 4-byte encapsulation header), as rmw_zenoh puts it."""
    return bytes(typestore().serialize_cdr(message, msgtype))


def deserialize(data: bytes, msgtype: str):
    """The message of CDR ``data`` (rosbags)."""
    return typestore().deserialize_cdr(data, msgtype)


# -- on a Zenoh session ----------------------------------------------------------------------
_IDS = itertools.count()
"""Node and entity ids, unique in the process (so in every session it holds)."""
_IDS_LOCK = threading.Lock()


def _next_id() -> int:
    with _IDS_LOCK:
        return next(_IDS)


@dataclass
class Ros2Publisher:
    """One ROS 2 publisher: a Zenoh publisher on the topic's key and its ``MP`` token."""

    msgtype: str
    key: str
    token_key: str
    gid: bytes
    publisher: object
    token: object
    seq: int = 0

    def publish(self, message, stamp_ns: int | None = None) -> bytes:
        """Put ``message`` (a rosbags object, serialised by rosbags); returns the payload."""
        return self.put(serialize(message, self.msgtype), stamp_ns)

    def put(self, payload: bytes, stamp_ns: int | None = None) -> bytes:
        """Put ``payload`` (CDR of :attr:`msgtype`) with the attachment; returns it."""
        self.seq += 1
        now = time.time_ns() if stamp_ns is None else stamp_ns
        self.publisher.put(payload, attachment=_ATTACHMENT.pack(self.seq, now, GID_SIZE,
                                                                self.gid))
        return payload

    def close(self) -> None:
        for entity in (self.token, self.publisher):
            try:
                entity.undeclare()
            except Exception:  # the session may already be closed
                pass


class Ros2Node:
    """A ROS 2 node as ``rmw_zenoh_cpp`` shows one: its ``NN`` liveliness token on
    ``session`` (a Zenoh session), and :meth:`publisher` for its topics."""

    def __init__(self, session, name: str, domain: int = 0, namespace: str = NAMESPACE) -> None:
        if domain < 0:
            raise ValueError(f"ROS 2 domain {domain} is negative")
        self.session = session
        self.name = ros_name(name)
        self.domain = domain
        self.namespace = namespace
        self.zid = str(session.info.zid())
        self.node_id = _next_id()
        self.token_key = node_token(domain, self.zid, self.node_id, self.name, namespace)
        self.token = session.liveliness().declare_token(self.token_key)
        self.publishers: list[Ros2Publisher] = []

    def topic(self, leaf: str) -> str:
        """``/<namespace>/<node>/<leaf>``: this node's topic ``leaf``."""
        return f"{self.namespace.rstrip('/')}/{self.name}/{leaf}"

    def publisher(self, topic: str, msgtype: str) -> Ros2Publisher:
        """A publisher on ``topic`` (fully qualified) of ``msgtype``."""
        key = topic_key(self.domain, topic, msgtype)
        token_key = publisher_token(self.domain, self.zid, self.node_id, _next_id(), self.name,
                                    topic, msgtype, namespace=self.namespace)
        pub = Ros2Publisher(msgtype, key, token_key, gid_of(token_key),
                            self.session.declare_publisher(key),
                            self.session.liveliness().declare_token(token_key))
        self.publishers.append(pub)
        return pub

    def close(self) -> None:
        """Undeclare every publisher and token (the ROS 2 graph sees the node go)."""
        for p in self.publishers:
            p.close()
        self.publishers = []
        try:
            self.token.undeclare()
        except Exception:  # the session may already be closed
            pass


class PeerRos2:
    """A peer's ROS 2 face: node ``<peer>`` publishing ``/sensornet/<peer>/tracks``
    (``sensornet_msgs/msg/Tracks``) and ``/sensornet/<peer>/markers`` (MarkerArray)."""

    def __init__(self, session, peer: str, domain: int = 0, scan_period: float = 1.0,
                 color_index: int = 0) -> None:
        self.node = Ros2Node(session, peer, domain)
        self.scan_period = scan_period
        self.color_index = color_index
        self.tracks_pub = self.node.publisher(self.node.topic("tracks"), TRACKS)
        self.markers_pub = self.node.publisher(self.node.topic("markers"), MARKERS)

    def tracks(self, tracks: Tracks, wall: float) -> None:
        """Publish ``tracks`` (stamped ``wall``, seconds since the epoch) on both topics."""
        ns = int(wall * 1e9)
        self.tracks_pub.put(ros2_cdr.tracks_cdr(tracks, ns, self.scan_period), ns)
        self.markers_pub.put(ros2_cdr.markers_cdr(tracks, ns, self.color_index), ns)

    def close(self) -> None:
        self.node.close()


class WorldRos2:
    """The world's ROS 2 face: node ``world`` publishing each sensor's detections on
    ``/sensornet/world/<sensor>/detections`` (PointCloud2, x-y in metres)."""

    def __init__(self, session, sensors: list[str], domain: int = 0) -> None:
        self.node = Ros2Node(session, "world", domain)
        self.pubs = {s: self.node.publisher(self.node.topic(f"{ros_name(s)}/detections"), CLOUD)
                     for s in sensors}

    def detections(self, sensor: str, xy: np.ndarray, wall: float) -> None:
        """Publish sensor ``sensor``'s detections ``xy (m, 2)`` stamped ``wall``."""
        ns = int(wall * 1e9)
        self.pubs[sensor].put(ros2_cdr.cloud_cdr(xy, ns), ns)

    def close(self) -> None:
        self.node.close()
