"""Zenoh encodings of sensornet messages (issue 26): read from a message's first bytes, for
every message type the codec writes, and parsed back."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.protocol.codec import VERSION, encode
from sensornet.protocol.encodings import encoding_text, letter_of, parse
from sensornet.protocol.messages import Control, Scan, Tracks, Truth

MESSAGES = {
    "scan": Scan("s1", 3, np.zeros((2, 2)), send_time=1.0),
    "tracks": Tracks("s1", 3, np.zeros((1, 4)), send_time=1.0),
    "truth": Truth(3, np.array([1]), np.zeros((1, 4)), send_time=1.0),
    "control": Control("start", "net", {"speed": 1.0}, send_time=0.0),
}


@pytest.mark.parametrize("name", list(MESSAGES))
def test_the_encoding_names_the_message_type(name):
    payload = encode(MESSAGES[name])
    text = encoding_text(payload)
    assert text == f"application/msgpack;sensornet/{name}/v{VERSION}"
    assert parse(text) == (name, VERSION, False)
    assert parse(encoding_text(payload, sealed=True)) == (name, VERSION, True)


def test_every_codec_type_letter_is_read_without_decoding():
    from sensornet.protocol.codec import _FIELDS
    from sensornet.protocol.encodings import TYPES

    assert set(TYPES) == set(_FIELDS)
    for letter in _FIELDS:
        head = bytes([0x92, VERSION, 0xA1, ord(letter)])
        assert letter_of(head) == letter


@pytest.mark.parametrize("junk", [b"", b"\x00\x01\x02\x03", b"\x92\x02\xa1T", b"\x92\x01\xa2EE"])
def test_junk_is_unknown_not_an_error(junk):
    assert letter_of(junk) == "?"
    assert parse(encoding_text(junk)) == ("unknown", VERSION, False)


def test_foreign_encodings_are_not_ours():
    assert parse("application/json") is None
    assert parse("application/msgpack;other/estimate/v1") is None
    assert parse("application/msgpack;sensornet/estimate/x1") is None
