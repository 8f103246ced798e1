"""peers.ros2_cdr packs the CDR of the peers' ROS 2 messages directly; rosbags' serializer
(peers.ros2's message objects through ``serialize_cdr``) is the reference: equal bytes for
random messages of each type, with empty arrays, absent fields and names of every length mod 4
(the alignment of what follows a string depends on it)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")
from sensornet.peers import ros2, ros2_cdr  # noqa: E402
from sensornet.protocol.messages import Tracks  # noqa: E402

STAMP = 1_764_800_000_123_456_789


def _random_tracks(rng, n: int, d: int, name: str, fields: tuple[bool, ...]) -> Tracks:
    A = rng.normal(size=(n, d, d))
    ids, covs, existence, status = fields
    return Tracks(name, int(rng.integers(0, 10_000)), rng.normal(size=(n, d)) * 300,
                  ids=rng.integers(-1, 100_000, size=(n, 3)) if ids else None,
                  covs=A @ A.transpose(0, 2, 1) + np.eye(d) if covs else None,
                  existence=rng.uniform(size=n) if existence else None,
                  status=rng.integers(0, 2, n).astype(np.int8) if status else None)


def _cases(seed: int = 11):
    rng = np.random.default_rng(seed)
    names = ["s", "s1", "abc", "peer", "radar_10", "very_long_peer_name_7"]
    for n in (0, 1, 2, 5):
        for d in (4, 6):
            for name in names:
                fields = tuple(bool(b) for b in rng.integers(0, 2, 4))
                yield _random_tracks(rng, n, d, name, fields)
    yield _random_tracks(rng, 3, 4, "s2", (True, True, True, True))
    yield _random_tracks(rng, 3, 4, "s2", (False, False, False, False))


def test_tracks_bytes_equal_rosbags():
    cases = list(_cases())
    assert any(t.covs is None for t in cases) and any(t.covs is not None for t in cases)
    for t in cases:
        for period in (1.0, 0.25):
            ref = ros2.serialize(ros2.tracks_message(t, STAMP, period), ros2.TRACKS)
            assert ros2_cdr.tracks_cdr(t, STAMP, period) == ref, (t.sender, len(t.states))


def test_tracks_without_any_track_or_state_columns():
    for states in (np.zeros((0, 4)), np.zeros((0,)), np.zeros((2, 0))):
        t = Tracks("s1", 3, states)
        ref = ros2.serialize(ros2.tracks_message(t, STAMP), ros2.TRACKS)
        assert ros2_cdr.tracks_cdr(t, STAMP) == ref
        assert len(ros2.deserialize(ref, ros2.TRACKS).tracks) == len(states)


def test_markers_bytes_equal_rosbags():
    for i, t in enumerate(_cases(12)):
        ref = ros2.serialize(ros2.markers_message(t, STAMP + i, color_index=i), ros2.MARKERS)
        assert ros2_cdr.markers_cdr(t, STAMP + i, color_index=i) == ref, (t.sender, i)


def test_cloud_bytes_equal_rosbags():
    rng = np.random.default_rng(5)
    for m in (0, 1, 2, 7):
        xy = rng.normal(size=(m, 2)) * 1e3
        ref = ros2.serialize(ros2.cloud_message(xy, STAMP + m), ros2.CLOUD)
        assert ros2_cdr.cloud_cdr(xy, STAMP + m) == ref


def test_layout_aligns_each_field_from_its_start():
    """An int64 after a 1-byte string pads to 8 from the body's start; a string after a bool
    pads its length to 4; the size counts from ``start``."""
    st, size = ros2_cdr.layout((1, "q"), 0)  # 4 + 1 + NUL = 6, pad 2, int64
    assert size == 16 and st.pack(2, b"a", 7) == b"\x02\0\0\0a\0\0\0" + (7).to_bytes(8, "little")
    st, size = ros2_cdr.layout(("?", 0), 5)  # bool at 5, pad to 8, length 1, NUL
    assert size == 8 and st.pack(True, 1, b"") == b"\x01\0\0\x01\0\0\0\0"
