"""The Tracks message with identities (protocol 2 of type "K"): round trip, the protocol-1
payload of the old encoder still decodes, each malformed field is a counted one-line rejection,
and the size limits apply before any heavy field is decoded."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from sensornet.protocol.codec import (
    TRACKS_VERSION,
    VERSION,
    Limits,
    Rejected,
    decode,
    encode,
)
from sensornet.protocol.encodings import encoding_text, letter_of, parse
from sensornet.protocol.messages import Tracks

STATES = np.array([[1.0, 2.0, -3.0, 0.5], [10.0, 0.0, 20.0, -1.0]])
V1_FIXTURE = bytes.fromhex(
    "9801a14ba273310904cb400400000000000004c4400000000000"
    "00f03f000000000000004000000000000008c0000000000000e03f"
    "000000000000244000000000000000000000000000003440000000000000f0bf")
"""``encode(Tracks("s1", 9, STATES, seq=4, send_time=2.5))`` by the encoder before protocol 2
(commit 51521bb's protocol/codec.py): ``[1, "K", "s1", 9, 4, 2.5, 4, states]``."""


def spd(rng, n, d=4):
    A = rng.normal(size=(n, d, d))
    return A @ A.swapaxes(1, 2) + np.eye(d)


def full_tracks(rng, n=3):
    return Tracks("s2", 17, rng.normal(size=(n, 4)) * 100, seq=5, send_time=1.25,
                  ids=np.stack([np.full(n, 2), np.arange(n) + 3, np.arange(n)], axis=1),
                  covs=spd(rng, n), existence=rng.uniform(0, 1, n),
                  status=(np.arange(n) % 2).astype(np.int8))


def reason(data, limits=None) -> str:
    with pytest.raises(Rejected) as exc:
        decode(data, limits) if limits else decode(data)
    assert "\n" not in str(exc.value)
    return exc.value.reason


# -- round trips ---------------------------------------------------------------------------------
def test_round_trip_of_every_field():
    rng = np.random.default_rng(0)
    msg = full_tracks(rng)
    payload = encode(msg)
    assert msgpack.unpackb(payload)[0] == TRACKS_VERSION
    out = decode(payload)
    assert isinstance(out, Tracks)
    assert (out.sender, out.k, out.seq, out.send_time) == ("s2", 17, 5, 1.25)
    np.testing.assert_array_equal(out.states, msg.states)
    np.testing.assert_array_equal(out.ids, msg.ids)
    assert out.ids.dtype == np.int64 and out.ids.shape == (3, 3)
    np.testing.assert_array_equal(out.covs, msg.covs)  # symmetric: the triangle is exact
    np.testing.assert_array_equal(out.existence, msg.existence)
    np.testing.assert_array_equal(out.status, msg.status)
    assert out.status.dtype == np.int8


@pytest.mark.parametrize("field", ["ids", "covs", "existence", "status"])
def test_round_trip_with_one_optional_field(field):
    rng = np.random.default_rng(1)
    full = full_tracks(rng)
    msg = Tracks("s2", 3, full.states, **{field: getattr(full, field)})
    out = decode(encode(msg))
    np.testing.assert_array_equal(getattr(out, field), getattr(full, field))
    for other in {"ids", "covs", "existence", "status"} - {field}:
        assert getattr(out, other) is None


def test_round_trip_of_no_tracks():
    msg = Tracks("s1", 2, np.zeros((0, 4)), ids=np.zeros((0, 3), dtype=np.int64),
                 covs=np.zeros((0, 4, 4)), existence=np.zeros(0), status=np.zeros(0, np.int8))
    out = decode(encode(msg))
    assert out.states.shape == (0, 4) and out.ids.shape == (0, 3)
    assert out.covs.shape == (0, 4, 4) and out.existence.shape == (0,)


def test_a_tracks_message_without_identities_is_still_protocol_1_byte_for_byte():
    payload = encode(Tracks("s1", 9, STATES, seq=4, send_time=2.5))
    assert payload == V1_FIXTURE
    assert payload == msgpack.packb([1, "K", "s1", 9, 4, 2.5, 4, STATES.tobytes()],
                                    use_bin_type=True)


def test_a_protocol_1_payload_decodes_with_the_new_fields_none():
    out = decode(V1_FIXTURE)
    assert isinstance(out, Tracks) and not out.labelled
    np.testing.assert_array_equal(out.states, STATES)
    assert (out.sender, out.k, out.seq, out.send_time) == ("s1", 9, 4, 2.5)
    assert out.ids is None and out.covs is None and out.existence is None and out.status is None


def test_encodings_name_the_version():
    rng = np.random.default_rng(2)
    v2 = encode(full_tracks(rng))
    assert letter_of(v2) == "K" and letter_of(V1_FIXTURE) == "K"
    assert parse(encoding_text(v2)) == ("tracks", 2, False)
    assert parse(encoding_text(V1_FIXTURE)) == ("tracks", VERSION, False)


# -- malformed payloads --------------------------------------------------------------------------
def v2(n=2, d=4, **over):
    """A protocol-2 Tracks payload built field by field (``over`` replaces wire fields)."""
    rng = np.random.default_rng(3)
    P = spd(rng, n, d)
    iu = np.triu_indices(d)
    fields = {"s": "s1", "k": 3, "q": 0, "ts": 1.0, "d": d,
              "i": np.arange(3 * n, dtype="<i8").tobytes(),
              "c": np.ascontiguousarray(P[:, iu[0], iu[1]], "<f8").tobytes(),
              "e": np.full(n, 0.5, "<f8").tobytes(), "u": np.ones(n, np.int8).tobytes(),
              "x": np.zeros((n, d), "<f8").tobytes()}
    fields.update(over)
    order = ("s", "k", "q", "ts", "d", "i", "c", "e", "u", "x")
    return msgpack.packb([2, "K", *(fields[f] for f in order)], use_bin_type=True)


def test_the_builder_makes_a_valid_payload():
    out = decode(v2())
    assert out.ids.tolist() == [[0, 1, 2], [3, 4, 5]] and out.status.tolist() == [1, 1]


def f8(*values):
    return np.array(values, "<f8").tobytes()


BAD_PSD = np.array([[1.0, 2.0, 0, 0], [2.0, 1.0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
_IU = np.triu_indices(4)


@pytest.mark.parametrize("over,want", [
    ({"i": b"\x00" * 40}, "shape"),  # 40 bytes for 2 ids of 24
    ({"i": np.array([0, 1, 2, 3, -4, 5], "<i8").tobytes()}, "field"),  # negative id
    ({"i": "ids"}, "field"),  # not bytes
    ({"c": b"\x00" * 8}, "shape"),
    ({"c": np.concatenate([BAD_PSD[_IU]] * 2).astype("<f8").tobytes()}, "not-psd"),
    ({"c": np.concatenate([np.eye(4)[_IU], np.full(10, np.nan)]).astype("<f8").tobytes()},
     "nonfinite"),
    ({"e": f8(0.5, 1.5)}, "field"),
    ({"e": f8(-0.1, 0.5)}, "field"),
    ({"e": f8(0.5, np.inf)}, "nonfinite"),
    ({"e": f8(0.5)}, "shape"),
    ({"u": bytes([1, 2])}, "field"),
    ({"u": bytes([1, 255])}, "field"),  # -1 as int8
    ({"u": bytes([1])}, "shape"),
    ({"x": f8(*[0.0] * 7)}, "shape"),
    ({"x": f8(*[0.0] * 7, np.nan)}, "nonfinite"),
    ({"d": 9}, "too-many"),
    ({"s": ""}, "field"),
])
def test_each_malformed_field_is_rejected(over, want):
    assert reason(v2(**over)) == want


def test_rejections_name_the_culprit():
    with pytest.raises(Rejected, match="existence probability is outside"):
        decode(v2(e=f8(0.5, 1.5)))
    with pytest.raises(Rejected, match="track status is not 0"):
        decode(v2(u=bytes([1, 2])))
    with pytest.raises(Rejected, match="bytes of track ids"):
        decode(v2(i=b"\x00" * 40))
    with pytest.raises(Rejected, match="track covariance is not positive definite"):
        decode(v2(c=np.concatenate([BAD_PSD[_IU]] * 2).astype("<f8").tobytes()))


def test_protocol_2_has_only_tracks_estimates_and_scans_with_ages():
    assert reason(msgpack.packb([2, "T", 3, b"", b""])) == "version"
    assert reason(msgpack.packb([2, "S", "s1", 3, 0, 1.0, b""])) == "field"  # no ages
    assert reason(msgpack.packb([3, "K"])) == "version"
    assert reason(msgpack.packb([2, "K", "s1"])) == "field"  # wrong field count


def test_size_limits_hold_before_the_heavy_fields_are_decoded():
    lim = Limits(max_components=3)
    # four tracks: refused on the states' row count, whatever the other blocks hold
    assert reason(v2(n=4, i=b"junk", c=b"junk", u=b"junk"), lim) == "too-many"
    assert decode(v2(n=3), lim).ids.shape == (3, 3)
    # the whole message is refused on its length before msgpack parses it
    big = v2(n=40)
    assert reason(big, Limits(max_bytes=len(big) - 1)) == "too-large"
    # a block of the wrong length is refused before it is decoded (no NaN check reached)
    assert reason(v2(e=b"\xff" * 24)) == "shape"


def test_the_encoder_refuses_inconsistent_fields():
    rng = np.random.default_rng(4)
    ok = full_tracks(rng)
    with pytest.raises(ValueError, match=r"Tracks.ids must be \(3, 3\) integers"):
        encode(Tracks("s1", 1, ok.states, ids=np.zeros((3, 2), dtype=int)))
    with pytest.raises(ValueError, match=r"Tracks.ids must be \(3, 3\) integers"):
        encode(Tracks("s1", 1, ok.states, ids=np.zeros((3, 3))))
    with pytest.raises(ValueError, match=r"Tracks.covs must be \(3, 4, 4\)"):
        encode(Tracks("s1", 1, ok.states, covs=np.zeros((3, 2, 2))))
    with pytest.raises(ValueError, match=r"Tracks.existence must be \(3,\)"):
        encode(Tracks("s1", 1, ok.states, existence=np.zeros(2)))
    with pytest.raises(ValueError, match=r"Tracks.status must be \(3,\)"):
        encode(Tracks("s1", 1, ok.states, status=np.zeros((3, 1))))
