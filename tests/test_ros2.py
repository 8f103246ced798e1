"""ROS 2 without ROS (peers.ros2, issue 35 item 1): keys, liveliness tokens and attachments as
rmw_zenoh's design document (design.md in ros2/rmw_zenoh) gives them (its own examples are
the reference), CDR that
rosbags decodes back, type hashes that ROS 2 itself printed; and a run with ``--ros2`` whose
puts a plain Zenoh subscriber decodes with rosbags alone."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402
from sensornet.peers import ros2  # noqa: E402
from sensornet.peers.session import free_port, open_session  # noqa: E402
from sensornet.protocol.codec import decode  # noqa: E402
from sensornet.protocol.keys import Keys  # noqa: E402
from sensornet.protocol.messages import Tracks  # noqa: E402

from tests.processes import env, wait_for  # noqa: E402

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
"""std_msgs/msg/String's hash in design.md's examples."""


def test_topic_keys_are_design_md_examples():
    """design.md, "Topic and Service name mapping": the chatter topic, plain and namespaced."""
    assert ros2.topic_key(0, "/chatter", "std_msgs/msg/String") == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
    assert ros2.topic_key(0, "/robot1/chatter", "std_msgs/msg/String") == (
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
    with pytest.raises(ValueError, match="fully qualified"):
        ros2.topic_key(0, "chatter", "std_msgs/msg/String")
    with pytest.raises(ValueError, match="msgtype"):
        ros2.dds_type_name("String")


def test_liveliness_tokens_are_design_md_examples():
    """design.md, "Graph Cache": the listener node's token and the talker's publisher token
    (depth 7, every other QoS policy rmw_zenoh's default)."""
    assert ros2.node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "listener",
                           namespace="/") == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener")
    assert ros2.publisher_token(
        2, "8b20917502ee955ac4476e0266340d5c", 0, 10, "talker", "/chatter",
        "std_msgs/msg/String", qos=ros2.qos_string(7), namespace="/") == (
        "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
        f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,")
    assert ros2.qos_string(10) == "::,10:,:,:,,"  # the subscription examples' depth
    assert ros2.qos_string(42) == "::,:,:,:,,"  # 42 is rmw_zenoh's default depth: left out
    assert ros2.qos_string(5, reliability=2, durability=1) == "2:1:,5:,:,:,,"
    # our node: namespace /sensornet mangled
    tok = ros2.node_token(0, "abc", 3, "s1")
    assert tok == "@ros2_lv/0/abc/3/3/NN/%/%sensornet/s1"


def test_attachment_bytes_are_design_md_layout():
    """design.md, "Publishers": 8 bytes sequence number LE, 8 bytes timestamp LE, one byte the
    GID's length (16), the 16-byte GID: 33 bytes."""
    gid = bytes(range(16))
    a = ros2.attachment(7, 1_700_000_000_123_456_789, gid)
    assert len(a) == 33
    assert a[:8] == (7).to_bytes(8, "little")
    assert a[8:16] == (1_700_000_000_123_456_789).to_bytes(8, "little")
    assert a[16] == 16 and a[17:] == gid
    assert ros2.parse_attachment(a) == (7, 1_700_000_000_123_456_789, gid)
    with pytest.raises(ValueError, match="gid"):
        ros2.attachment(1, 1, b"short")
    gid2 = ros2.gid_of("@ros2_lv/0/a/0/1/MP/%/%/n/%t/x/y/z")
    assert len(gid2) == 16 and gid2 == ros2.gid_of("@ros2_lv/0/a/0/1/MP/%/%/n/%t/x/y/z")


def test_type_hashes_match_what_ros2_printed():
    """RIHS01 hashes of rosbags' type store against values printed by ROS 2 tools and
    generated code (design.md's String; PointCloud2 from `ros2 topic info -v`, MarkerArray from
    generated rosidl code): the algorithm that also hashes sensornet_msgs."""
    assert ros2.type_hash("std_msgs/msg/String") == STRING_HASH
    assert ros2.type_hash(ros2.CLOUD) == (
        "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5")
    assert ros2.type_hash(ros2.MARKERS) == (
        "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf")
    assert ros2.type_hash(ros2.TRACKS).startswith("RIHS01_") and len(
        ros2.type_hash(ros2.TRACKS)) == 71


def _tracks(n: int = 5, labelled: bool = True) -> Tracks:
    rng = np.random.default_rng(3)
    A = rng.normal(size=(n, 4, 4))
    covs = A @ A.transpose(0, 2, 1) + np.eye(4)
    if not labelled:
        return Tracks("s2", 17, rng.normal(size=(n, 4)) * 100)
    return Tracks("s2", 17, rng.normal(size=(n, 4)) * 100,
                  ids=rng.integers(0, 1000, size=(n, 3)), covs=covs,
                  existence=rng.uniform(size=n), status=rng.integers(0, 2, n).astype(np.int8))


def _plain_store():
    """A Jazzy type store with sensornet_msgs registered by rosbags calls only."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in ros2.MESSAGE_DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def test_tracks_cdr_round_trips_through_rosbags():
    t = _tracks()
    data = ros2.serialize(ros2.tracks_message(t, 1_234_567_890_000_000_001, 2.0), ros2.TRACKS)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation header
    back = _plain_store().deserialize_cdr(data, ros2.TRACKS)
    assert back.peer == "s2" and back.scan == 17 and back.scan_time == 34.0
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (1_234_567_890, 1)
    assert back.header.frame_id == "map"
    ids = np.array([[r.origin, r.birth_scan, r.index] for r in back.tracks])
    np.testing.assert_array_equal(ids, t.ids)
    np.testing.assert_array_equal([r.state for r in back.tracks], t.states)
    np.testing.assert_array_equal([r.covariance.reshape(4, 4) for r in back.tracks], t.covs)
    np.testing.assert_array_equal([r.existence for r in back.tracks], t.existence)
    np.testing.assert_array_equal([r.status for r in back.tracks], t.status)
    np.testing.assert_array_equal([[r.position.x, r.position.y] for r in back.tracks],
                                  t.states[:, [0, 2]])
    # unlabelled: -1 labels, status 255, NaN existence, no covariance
    u = _plain_store().deserialize_cdr(ros2.serialize(
        ros2.tracks_message(_tracks(2, labelled=False), 0), ros2.TRACKS), ros2.TRACKS)
    assert [(r.origin, r.status, len(r.covariance)) for r in u.tracks] == [(-1, 255, 0)] * 2
    assert np.isnan(u.tracks[0].existence)


def test_markers_round_trip_with_2_sigma_ellipses():
    """MarkerArray: a DELETEALL, then per track a cylinder whose axes are the 2-sigma
    ellipse's (checked against numpy.linalg.eigh) and a text with the label."""
    t = _tracks(4)
    data = ros2.serialize(ros2.markers_message(t, 5, color_index=1), ros2.MARKERS)
    back = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(data, ros2.MARKERS)
    m = back.markers
    assert len(m) == 1 + 2 * 4 and m[0].action == 3  # DELETEALL
    P = t.covs[:, [0, 2]][:, :, [0, 2]]
    lam, vec = np.linalg.eigh(P)  # ascending
    for i in range(4):
        cyl, text = m[1 + 2 * i], m[2 + 2 * i]
        assert cyl.type == 3 and text.type == 9
        np.testing.assert_allclose([cyl.scale.x, cyl.scale.y], 4 * np.sqrt(lam[i, ::-1]),
                                   rtol=1e-9)
        angle = 2 * np.arctan2(cyl.pose.orientation.z, cyl.pose.orientation.w)
        major = vec[i, :, 1]
        assert abs(abs(np.cos(angle) * major[0] + np.sin(angle) * major[1]) - 1) < 1e-9
        assert text.text == ".".join(str(v) for v in t.ids[i])
        assert (cyl.pose.position.x, cyl.pose.position.y) == (t.states[i, 0], t.states[i, 2])


def test_detections_point_cloud_round_trips():
    xy = np.array([[1.5, -2.0], [300.25, 40.0], [0.0, 0.0]])
    back = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(
        ros2.serialize(ros2.cloud_message(xy, 0), ros2.CLOUD), ros2.CLOUD)
    assert (back.width, back.height, back.point_step) == (3, 1, 12)
    assert [f.name for f in back.fields] == ["x", "y", "z"]
    pts = np.frombuffer(back.data.tobytes(), np.float32).reshape(-1, 3)
    np.testing.assert_array_equal(pts[:, :2], xy.astype(np.float32))
    assert (pts[:, 2] == 0).all()


def test_ros_names_are_valid_tokens():
    assert ros2.ros_name("s1") == "s1"
    assert ros2.ros_name("radar-north.2") == "radar_north_2"
    assert ros2.ros_name("7a") == "n7a"


@pytest.mark.network
def test_a_run_with_ros2_is_decoded_by_rosbags_from_a_plain_subscriber(tmp_path):
    """``sensornet run --ros2``: a plain Zenoh session subscribed to ``0/**`` gets CDR that
    rosbags decodes into sensornet_msgs/Tracks equal to the peers' own tracks messages (ids,
    states), under keys and attachments laid out as design.md says; the world's detections
    arrive as PointCloud2; ``liveliness.get("@ros2_lv/**")`` lists every node and publisher."""
    port = free_port()
    world = f"tcp/127.0.0.1:{port}"
    network = f"ros{port}"
    out = tmp_path / "run"
    store = _plain_store()
    tracks_hash = store.hash_rihs01("sensornet_msgs/msg/Tracks")
    tracks_type = f"sensornet_msgs::msg::dds_::Tracks_/{tracks_hash}"
    peers = ("s1", "s2", "s3")
    ros_samples, native, tokens = [], [], []
    proc = subprocess.Popen(
        [sys.executable, "-m", "sensornet", "run", "--listen", world, "--network", network,
         "--ros2", "--set", "scenario.num_scans=25", "--speed", "4", "--no-rerun",
         "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        cwd=tmp_path, env=env())
    session = None
    try:
        wait_for(lambda: (out / "logs" / "world.log").exists(), 60, "the world's log")
        session = open_session((), [world])
        subs = [
            session.declare_subscriber("0/**", lambda s: ros_samples.append(
                (str(s.key_expr), s.payload.to_bytes(),
                 None if s.attachment is None else s.attachment.to_bytes()))),
            session.declare_subscriber(Keys(network).tracks(), lambda s: native.append(
                decode(s.payload.to_bytes())))]
        wait_for(lambda: all(any(k.startswith(f"0/sensornet/{p}/tracks/")
                                 for k, _, _ in list(ros_samples)) for p in peers),
                 90, "every peer's ROS 2 tracks")
        tokens = [str(r.ok.key_expr) for r in
                  session.liveliness().get("@ros2_lv/**", timeout=5.0) if r.ok]
        stdout, stderr = proc.communicate(timeout=180)
        assert proc.returncode == 0, stderr + stdout
        for s in subs:
            s.undeclare()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if session is not None:
            session.close()

    for p in peers:
        assert any(t.startswith("@ros2_lv/0/") and t.endswith(f"/NN/%/%sensornet/{p}")
                   for t in tokens), tokens
        assert any(t.startswith("@ros2_lv/0/") and f"/MP/%/%sensornet/{p}/%sensornet%{p}%tracks/"
                   f"{tracks_type}/::,10:,:,:,," in t for t in tokens), tokens
        assert any(f"/MP/%/%sensornet/{p}/%sensornet%{p}%markers/"
                   "visualization_msgs::msg::dds_::MarkerArray_/" in t for t in tokens), tokens
    assert any(t.endswith("/NN/%/%sensornet/world") for t in tokens), tokens
    by_key: dict[tuple[str, int], object] = {}
    clouds = markers = 0
    for key, payload, att in ros_samples:
        assert att is not None and len(att) == 33 and att[16] == 16, key
        seq, stamp = struct.unpack("<qq", att[:16])
        assert seq >= 1 and abs(stamp / 1e9 - time.time()) < 600
        if key.endswith(tracks_type):
            msg = store.deserialize_cdr(payload, "sensornet_msgs/msg/Tracks")
            assert key == f"0/sensornet/{msg.peer}/tracks/{tracks_type}"
            by_key[(msg.peer, msg.scan)] = msg
        elif "/detections/sensor_msgs::msg::dds_::PointCloud2_/" in key:
            cloud = store.deserialize_cdr(payload, "sensor_msgs/msg/PointCloud2")
            assert cloud.point_step == 12 and len(cloud.data) == 12 * cloud.width
            clouds += 1
        elif "/markers/visualization_msgs::msg::dds_::MarkerArray_/" in key:
            assert store.deserialize_cdr(payload, ros2.MARKERS).markers[0].action == 3
            markers += 1
    assert clouds >= 3 * 10 and markers >= 3 * 10, (clouds, markers)
    compared = 0
    for t in native:
        msg = by_key.get((t.sender, t.k))
        if msg is None:
            continue
        compared += 1
        np.testing.assert_array_equal(
            np.array([r.state for r in msg.tracks]).reshape(t.states.shape), t.states)
        if t.ids is not None:
            np.testing.assert_array_equal(np.array(
                [[r.origin, r.birth_scan, r.index] for r in msg.tracks]).reshape(-1, 3), t.ids)
    assert compared >= 3 * 10, (compared, len(native), len(by_key))
    assert json.loads((out / "peer-s1.json").read_text())["scans"] == 25
