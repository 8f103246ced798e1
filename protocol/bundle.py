"""A scan bundle: the world's scans of one scan index for the sensors of one peer host, in one
message (``sensornet/<network>/scans/<host>``).

Each entry is the exact bytes the world would have put on that sensor's own key
(``scan/<sensor>``, an encoded :class:`protocol.messages.Scan`); the host hands each to its
peer as if it had arrived there (the same admission, decoding and checks), so a bundle changes
how many messages cross processes, not what a peer receives. One message instead of one per
hosted sensor: at 50 peers in one host, 50 callbacks (each a GIL hand-over between Zenoh's
thread and the loop's) per scan became one. Layout (msgpack): ``[k, [[sensor, payload], ...]]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import msgpack
from sensornet.protocol.codec import Rejected

BUNDLE_BYTES = 256 * 1024
"""A bundle is cut here (the world starts another): far under the transport's largest
message, so a network with big scans sends a few bundles, never one it cannot carry."""
BUNDLE_HEAD = b"\x92"
"""A bundle's first byte (a msgpack array of 2); a message is an array of 3 or more
(``[version, type, fields...]``, :mod:`protocol.codec`), so the two never share it."""
MAX_ENTRIES = 1024
"""Most scans in one bundle a receiver accepts (a host of that many peers)."""


@dataclass(frozen=True)
class Bundle:
    k: int
    entries: list[tuple[str, bytes]]
    """``(sensor, payload)``: each an encoded scan for ``scan/<sensor>``."""


def pack_bundles(k: int, entries: list[tuple[str, bytes]],
                 max_bytes: int = BUNDLE_BYTES) -> list[bytes]:
    """``entries`` of scan ``k`` as one bundle, or several of at most ``max_bytes`` each (an
    entry larger than that alone goes in a bundle of its own)."""
    out, chunk, size = [], [], 0
    for sensor, payload in entries:
        n = len(payload) + len(sensor) + 16
        if chunk and size + n > max_bytes:
            out.append(msgpack.packb([k, chunk], use_bin_type=True))
            chunk, size = [], 0
        chunk.append([sensor, payload])
        size += n
    if chunk:
        out.append(msgpack.packb([k, chunk], use_bin_type=True))
    return out


def unpack_bundle(data: bytes, max_bytes: int = 2 * BUNDLE_BYTES,
                  max_entries: int = MAX_ENTRIES) -> Bundle:
    """A bundle's entries, or :class:`Rejected` (``too-large``, ``malformed``): bounded in
    size and entries (``max_entries``: a host's, its number of peers) before anything is
    built; the entries themselves are checked by each receiving peer as any scan is."""
    if len(data) > max_bytes:
        raise Rejected("too-large", f"bundle of {len(data)} bytes > {max_bytes}")
    try:
        body = msgpack.unpackb(bytes(data), raw=False, max_bin_len=max_bytes,
                               max_str_len=256, max_array_len=max(2, min(max_entries,
                                                                         MAX_ENTRIES)),
                               max_map_len=0)
    except Exception as exc:  # msgpack raises several unrelated types on bad input
        raise Rejected("malformed", f"not a msgpack bundle ({type(exc).__name__})") from None
    if (not isinstance(body, list) or len(body) != 2 or type(body[0]) is not int
            or body[0] < 0 or not isinstance(body[1], list)):
        raise Rejected("malformed", "a bundle is [k, [[sensor, payload], ...]]")
    entries = []
    for e in body[1]:
        if (not isinstance(e, list) or len(e) != 2 or not isinstance(e[0], str)
                or not isinstance(e[1], bytes)):
            raise Rejected("malformed", "a bundle entry is [sensor, payload]")
        entries.append((e[0], e[1]))
    return Bundle(body[0], entries)
