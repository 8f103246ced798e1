"""The Zenoh encoding each put declares, so generic Zenoh tools can tell payloads apart.

``application/msgpack;sensornet/<type>/v<version>`` for a plain message, with ``+sealed``
when it carries secure mode's signed trailer (protocol.envelope: the msgpack array comes first,
the 76-byte trailer after it). The type is read from the message's own first bytes, never
decoded: ``[version, "<letter>", ...]`` (protocol.codec).
"""

from __future__ import annotations

from sensornet.protocol.codec import VERSION, VERSIONS

MIME = "application/msgpack"
TYPES = {"E": "estimate", "S": "scan", "K": "tracks", "T": "truth", "F": "forward",
         "R": "returns", "C": "control", "Y": "telemetry"}
"""Message type letters (protocol.codec) and the names their encodings carry."""


def schema(letter: str, sealed: bool = False, version: int = VERSION) -> str:
    """``sensornet/<type>/v<version>[+sealed]`` of a message type letter."""
    return f"sensornet/{TYPES.get(letter, 'unknown')}/v{version}{'+sealed' if sealed else ''}"


def encoding_text(payload: bytes, sealed: bool = False) -> str:
    """The encoding string of an encoded message (``.../unknown/...`` if its head is not a
    message's: the bytes are sent as they are, the receiver's decode decides)."""
    letter = letter_of(payload)
    version = payload[1] if letter != "?" else VERSION
    return f"{MIME};{schema(letter, sealed, version)}"


def letter_of(payload: bytes) -> str:
    """The type letter of ``[version, "<letter>", ...]`` from its first 4 bytes, or ``"?"``:
    a fixarray, a version the codec has (a positive fixint), a one-character fixstr naming a
    type of that version (protocol 2 has Tracks and Estimate)."""
    if (len(payload) >= 4 and 0x90 <= payload[0] <= 0x9F and payload[1] in VERSIONS
            and payload[2] == 0xA1 and chr(payload[3]) in VERSIONS[payload[1]]):
        return chr(payload[3])
    return "?"


def parse(encoding: str) -> tuple[str, int, bool] | None:
    """``(type, version, sealed)`` of a sensornet encoding string, else None."""
    mime, _, sch = str(encoding).partition(";")
    parts = sch.split("/")
    if mime != MIME or len(parts) != 3 or parts[0] != "sensornet":
        return None
    version, _, flag = parts[2].partition("+")
    if not version.startswith("v") or not version[1:].isdigit():
        return None
    return parts[1], int(version[1:]), flag == "sealed"
