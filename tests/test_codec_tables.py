"""The codec's tables agree: every wire type of every protocol version has a decoder, every
encoder writes a type the field tables know, and ``protocol.codec`` still offers its names."""

from __future__ import annotations

from sensornet.protocol import codec
from sensornet.protocol.codec_format import VERSIONS
from sensornet.protocol.codec_messages import DECODERS, ENCODERS


def test_every_wire_type_has_a_decoder_and_every_encoder_a_wire_type():
    letters = {t for fields in VERSIONS.values() for t in fields}
    assert set(DECODERS) == letters
    assert {t for t, _ in ENCODERS.values()} == letters


def test_codec_keeps_its_public_names():
    for name in ("VERSION", "TRACKS_VERSION", "LABELS_VERSION", "VERSIONS", "REASONS",
                 "DEFAULT_LIMITS", "Limits", "Rejected", "decode", "encode", "pack_mixture",
                 "unpack_mixture", "_FIELDS"):
        assert hasattr(codec, name), name
    assert codec.Rejected("malformed", "x").reason == "malformed"
