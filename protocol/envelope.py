"""Signed messages (secure mode): who sent a message, checked end to end, and replays refused.

Mutual TLS authenticates a *link*; behind a router, or in a recording, a message carries no
proof of its sender. In secure mode every message is sealed by its sender's Ed25519 key and
opened by every receiver against the network's roster (the members' public keys,
``members.json`` of the keys folder) before anything in it is decoded:

    sealed = payload | stamp (8 bytes, big-endian) | signature (64 bytes) | TAG (4 bytes)

The signature covers a domain string, the full key expression (network, channel, name) the
message is put on, the stamp and the payload: a message moved to another key, another network
or edited in any byte fails (``unauthenticated``), and so does one signed by any key but the
key owner's (``estimate/<p>`` and ``tracks/<p>``: member ``p``; ``scan/*``, ``truth``, ``ctl``:
the world). The stamp is the sender's own clock in nanoseconds, forced strictly increasing
(``max(last + 1, now)``), so it orders every message of a sender across restarts; a receiver
keeps the newest stamp it accepted per key, and a copy whose stamp is not newer (a replay, or a
message reordered after a newer one of the same key) is refused as ``replayed``. (Zenoh keeps
the order of one publisher's messages on a path: an honest stream never comes out of order.)

What the freshness rule assumes, and how it recovers: the members' clocks agree to within
:data:`MAX_AHEAD` (NTP does, by milliseconds). A stamp more than that ahead of the receiver's
clock is refused (``ahead``) and never becomes the bar, so a sender whose clock ran ahead (an
hour, say) is refused while it is wrong, and taken again as soon as its clock is corrected:
its signer, seeing its clock more than :data:`MAX_AHEAD` behind its last stamp, follows the
clock again instead of counting on from the far future. A receiver whose own clock stepped back
(a bar more than :data:`MAX_AHEAD` after its clock) lowers that bar to its clock minus
:data:`MAX_AHEAD`. Either way honest messages are taken again at once, or within
:data:`MAX_AHEAD` where a sender's stamps were less than that ahead, not after the whole skew.
What that gives up: when a receiver's bar is lowered, a copy of a message stamped in the
:data:`MAX_AHEAD` before its clock may be taken once more.

The trailer leaves the payload's first bytes where they were: the admission's header peek
(``peers.admission``) works on a sealed message unchanged.

A receiver whose links already prove the sender (a mesh of mutual-TLS links whose access
control refuses every put but the key owner's: no router, no recovery) opens with
``check_signature=False``: the trailer and the stamps are still checked, the Ed25519 verify
is not repeated (``peers.transport.Transport.arm_signatures``).
"""

from __future__ import annotations

import struct
import threading
import time

TAG = b"SNs1"
"""Last bytes of a sealed message (format version 1)."""
_STAMP = struct.Struct(">Q")
SIG_BYTES = 64
TRAILER = _STAMP.size + SIG_BYTES + len(TAG)
_DOMAIN = b"sensornet-envelope-1\x00"
WORLD = "world"
UNAUTHENTICATED, REPLAYED, AHEAD = "unauthenticated", "replayed", "ahead"
MAX_AHEAD = 10 * 10**9
"""Nanoseconds a stamp may be ahead of the receiver's clock (the clock skew the freshness rule
tolerates, and how long a corrected clock may still be refused)."""


def owner(key: str, world: str = WORLD) -> str | None:
    """The member that may sign a message on ``key`` (``sensornet/<net>/<channel>[/<name>]``)."""
    parts = str(key).split("/")
    if len(parts) == 3 and parts[2] in ("truth", "ctl"):
        return world
    if len(parts) == 4 and parts[3]:
        if parts[2] == "scan":
            return world
        if parts[2] in ("estimate", "tracks"):
            return parts[3]
    return None


def _signed(key: str, stamp: bytes, payload: bytes) -> bytes:
    return b"".join((_DOMAIN, key.encode(), b"\x00", stamp, payload))


def is_sealed(payload: bytes) -> bool:
    return len(payload) >= TRAILER and payload[-len(TAG):] == TAG


def inner(payload: bytes) -> bytes:
    """The payload of a sealed message *without checking it* (tools that only read a clock)."""
    return payload[:-TRAILER] if is_sealed(payload) else payload


class Signer:
    """Seals what one member puts (its Ed25519 private key)."""

    def __init__(self, private_key, clock=None) -> None:
        self._key = private_key
        self._last = 0
        self._clock = clock  # nanoseconds; None: time.time_ns (tests set their own)
        self._lock = threading.Lock()

    def stamp(self) -> bytes:
        with self._lock:
            now = self._clock() if self._clock is not None else time.time_ns()
            # strictly increasing, unless the clock was set back by more than MAX_AHEAD (it
            # ran ahead and was corrected): then the clock again, which receivers take
            self._last = now if self._last - now > MAX_AHEAD else max(self._last + 1, now)
            return _STAMP.pack(self._last)

    def seal(self, key: str, payload: bytes) -> bytes:
        st = self.stamp()
        return b"".join((payload, st, self._key.sign(_signed(key, st, payload)), TAG))


class Verifier:
    """Opens sealed messages against the network's roster (member name -> Ed25519 public key).

    Thread-safe: Zenoh calls subscribers on several threads; the signature check runs outside
    the lock (``cryptography`` releases the GIL for it), only the stamp bookkeeping inside.
    """

    def __init__(self, roster: dict, world: str = WORLD, clock=None) -> None:
        self.roster = dict(roster)
        self.world = world
        self._clock = clock
        self._newest: dict[str, int] = {}
        self._lock = threading.Lock()

    def open(self, key: str, payload: bytes, check_signature: bool = True
             ) -> tuple[bytes | None, str | None]:
        """``(payload without the trailer, None)``, or ``(None, reason)``: ``unauthenticated``
        (no or a bad signature, no roster key for the key's owner), ``replayed`` or ``ahead``
        (stamped more than :data:`MAX_AHEAD` after this receiver's clock).

        ``check_signature=False``: the trailer and the replay check only, for a message whose
        sender the transport has already proven (a direct mutual-TLS link whose access control
        lets only the key's owner put on it: see ``peers.transport``)."""
        # heavy dependency: cryptography (its OpenSSL bindings load only where messages are signed)
        from cryptography.exceptions import InvalidSignature

        if not is_sealed(payload):
            return None, UNAUTHENTICATED
        pub = self.roster.get(owner(key, self.world))
        if pub is None:
            return None, UNAUTHENTICATED
        body = payload[:-TRAILER]
        st = payload[-TRAILER:-TRAILER + _STAMP.size]
        if check_signature:
            sig = payload[-SIG_BYTES - len(TAG):-len(TAG)]
            try:
                pub.verify(sig, _signed(key, st, body))
            except InvalidSignature:
                return None, UNAUTHENTICATED
        stamp = _STAMP.unpack(st)[0]
        limit = (self._clock() if self._clock is not None else time.time_ns()) + MAX_AHEAD
        if stamp > limit:
            return None, AHEAD  # the sender's clock is wrong: not a bar for later messages
        with self._lock:
            bar = self._newest.get(key, 0)
            if bar > limit:  # our own clock stepped back: that bar came from its future
                bar = self._newest[key] = limit - 2 * MAX_AHEAD
            if stamp <= bar:
                return None, REPLAYED
            self._newest[key] = stamp
        return body, None
