"""Versioned msgpack codec with validation of everything decoded.

A message is a msgpack array ``[version, type, fields...]`` (positional, to keep the
per-message overhead near 25 bytes). Arrays travel as raw little-endian float64 bytes; their
row count follows from the byte length and the declared width. A Gaussian mixture is one
``(n, 1 + d + d(d+1)/2)`` block: weight, mean, and the upper triangle of the covariance
(symmetric by construction), so a 4-D component is 15 numbers, the raw tuple count of
docs/seed004.md.

``decode`` never trusts its input: any problem raises :class:`Rejected` with a short
``reason`` code (counted by the receiver) and a human-readable detail.

The wire format shared by every type (versions, field tables, limits, header, field readers)
is in :mod:`protocol.codec_format`, each type's encoder and decoder in
:mod:`protocol.codec_messages`; this module is the API and re-exports their public names.
"""

from __future__ import annotations

import msgpack
from sensornet.protocol.codec_format import (
    _FIELDS,
    _FIELDS_V2,
    DEFAULT_LIMITS,
    LABELS_VERSION,
    MASKS_VERSION,
    REASONS,
    TRACKS_VERSION,
    VERSION,
    VERSIONS,
    Limits,
    Rejected,
    pack_mixture,
    read_header,
    unpack_mixture,
)
from sensornet.protocol.codec_messages import DECODERS, ENCODERS
from sensornet.protocol.messages import Message


def encode(msg: Message) -> bytes:
    """Serialise a message: a msgpack array ``[version, type, fields...]`` (see ``_FIELDS``)."""
    entry = next((ENCODERS[c] for c in type(msg).__mro__ if c in ENCODERS), None)
    if entry is None:
        raise TypeError(f"cannot encode {type(msg).__name__}")
    t, body = entry[0], entry[1](msg)
    version = body.get("v", VERSION)
    return msgpack.packb([version, t, *(body[f] for f in VERSIONS[version][t])],
                         use_bin_type=True)


def decode(data: bytes, limits: Limits = DEFAULT_LIMITS) -> Message:
    """Parse and validate bytes into a message, or raise :class:`Rejected`: the header
    (:func:`protocol.codec_format.read_header`), then the type's decoder
    (:data:`protocol.codec_messages.DECODERS`)."""
    version, kind, body = read_header(data, limits)
    try:
        return DECODERS[kind](body, limits, version)
    except Rejected:
        raise
    except (ValueError, TypeError, OverflowError) as exc:
        raise Rejected("field", f"{type(exc).__name__}: {exc}") from None


__all__ = ["DEFAULT_LIMITS", "LABELS_VERSION", "MASKS_VERSION", "REASONS", "TRACKS_VERSION",
           "VERSION",
           "VERSIONS", "Limits", "Rejected", "_FIELDS", "_FIELDS_V2", "decode", "encode",
           "pack_mixture", "unpack_mixture"]
