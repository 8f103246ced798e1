"""What a peer checks before it spends anything on a message: key, scan window, slot, rate.

All of it runs before decoding (the runtime calls :meth:`Admission.admit` on Zenoh's callback
thread), reading only the first bytes of the message (a few microseconds):

- the key must be one of the network's;
- a scan, estimate or truth names its scan index (and round and kind) in its first fields:
  stamped outside the window the peer still fuses it is refused at once (``stale``/``future``),
  an estimate of a round the peer does not run (``round``) or of a kind it does not fuse
  (``incompatible``) too; inside, each slot ``(sender, k, round, kind)`` is let through at most
  :data:`SLOT_ATTEMPTS` times (``duplicate``), so replays and floods of valid-looking messages
  cost a dictionary lookup each;
- every message that would go on to be decoded (or, in secure mode, have its signature
  verified) is charged to its sender's token bucket (``rate``), a few times what an honest sender
  needs: however a member stamps its messages, what it costs a receiver is bounded;
- an estimate's bytes are charged to its sender's byte budget (``bytes``, with
  ``estimate_bytes``, :mod:`peers.budget`): a member that sends its whole message rate in
  estimates of the largest size is bounded by size, not only by count (issue 36);
- what the callbacks hand to the main loop waits in an inbox bounded per sender
  (:data:`INBOX_SCANS` scans' worth, ``inbox``) and in total (:data:`INBOX_TOTAL` messages,
  :data:`INBOX_BYTES` bytes, ``inbox-total``): a main loop that falls behind drops, it does not
  grow (:meth:`Admission.arrive`, :meth:`Admission.taken`).
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import lru_cache

import msgpack
from sensornet.protocol.keys import ROOT

SLOT_ATTEMPTS = 4
"""Messages per (sender, scan, round, kind) let through to decoding: a duplicated delivery
is normal, a few more leave room for a genuine message after junk on the same slot."""
MAX_SLOTS = 100_000
SCAN_BURST = 32
"""Scans the world's bucket holds: a peer frozen for a few seconds gets every queued scan to
its catch-up (peers.runtime), which skips or works them off; each is small and decoded once."""
INBOX_SCANS = 16
"""Messages one sender may have waiting for the main loop, in scans of its honest rate (at
least :data:`INBOX_MIN`): a loop this far behind skips to the newest scans anyway."""
INBOX_MIN = 32
INBOX_TOTAL = 4096
"""Messages waiting for one peer's main loop, from all senders together."""
INBOX_BYTES = 32 << 20
"""Bytes waiting for one peer's main loop (32 MiB: what a flood of large messages may hold)."""
ESTIMATE_KINDS = ("posterior", "prediction", "returns")
"""Estimate kinds by their index in the wire header (``o``, protocol.codec)."""
_HEAD = 192  # bytes holding every field read by peek()

CHANNELS = ("scan", "estimate", "truth", "ctl")
"""Keys a peer listens on (``tracks`` are for observers)."""


@dataclass(frozen=True)
class Route:
    """A parsed key: ``channel`` and the name in it (sensor or peer; ``""`` for truth/ctl)."""

    channel: str
    name: str
    tag: str = field(init=False, repr=False, compare=False)
    """``channel/name``: the sender's entry in the per-sender counters (made once a route,
    not once a message: :func:`parse_key` keeps its routes)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "tag", f"{self.channel}/{self.name}")


def parse_key(key: str, network: str) -> Route | None:
    """``sensornet/<network>/<channel>[/<name>]`` -> Route, or None if it is not one of ours.

    A peer's transport parses each message's key once (the inbox item carries the answer,
    :class:`peers.inbound.Delivered`); drivers feeding the core themselves parse it there. It
    sees the same few dozen keys all run: the answers for string keys are kept (bounded,
    least recently used first out; a :class:`Route` is immutable, so sharing it is safe)."""
    if type(key) is str:
        return _parse_key_kept(key, network)
    return _parse_key(str(key), network)


@lru_cache(maxsize=4096)
def _parse_key_kept(key: str, network: str) -> Route | None:
    return _parse_key(key, network)


def _parse_key(key: str, network: str) -> Route | None:
    parts = key.split("/")
    if len(parts) < 3 or parts[0] != ROOT or parts[1] != network:
        return None
    channel = parts[2]
    if channel in ("truth", "ctl"):
        return Route(channel, "") if len(parts) == 3 else None
    if channel in ("scan", "estimate") and len(parts) == 4 and parts[3]:
        return Route(channel, parts[3])
    return None


_OTHER_KINDS = {"F": 100, "R": 101}
"""Slot kinds of flooding forwards (seed 004) and shared returns (seed 003): apart from the
estimate kinds (0, 1), so they never share a slot with an estimate."""


def peek(payload: bytes) -> tuple[str, int, int, int] | None:
    """``(type, k, round, kind)`` from a message's first fields, or None if they do not parse.

    Layouts (protocol.codec): ``[v, "E", s, k, r, q, ts, p, o, ...]``, ``[v, "S", s, k, ...]``,
    ``[v, "F"|"R", s, k, r, ...]``, ``[v, "T", k, ...]``. Nothing here is trusted: the full
    decode checks it all again.
    """
    try:
        u = msgpack.Unpacker(raw=False, max_buffer_size=_HEAD)
        u.feed(payload[:_HEAD])
        n = u.read_array_header()
        if n < 4:
            return None
        u.skip()
        kind = u.unpack()
        if kind == "E" and n >= 9:
            u.skip()
            k, r = u.unpack(), u.unpack()
            u.skip(), u.skip(), u.skip()
            o = u.unpack()
        elif kind == "S":
            u.skip()
            k, r, o = u.unpack(), 0, 0
        elif kind in _OTHER_KINDS and n >= 6:  # [v, "F"|"R", s, k, r, ...]
            u.skip()
            k, r, o = u.unpack(), u.unpack(), _OTHER_KINDS[kind]
        elif kind == "T":
            k, r, o = u.unpack(), 0, 0
        else:
            return None
    except Exception:  # truncated, wrong types, ...: the bucket and the full decode decide
        return None
    ints = all(type(x) is int for x in (k, r, o))
    return (kind, k, r, o) if ints and 0 <= k < 1 << 53 else None


class TokenBucket:
    """``rate`` tokens per second, at most ``capacity`` saved up."""

    __slots__ = ("rate", "capacity", "tokens", "last")

    def __init__(self, rate: float, capacity: float) -> None:
        self.rate, self.capacity = rate, capacity
        self.tokens, self.last = capacity, None

    def take(self, now: float) -> bool:
        if self.last is not None and now > self.last:
            self.tokens = min(self.capacity, self.tokens + (now - self.last) * self.rate)
        self.last = now if self.last is None else max(self.last, now)
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


class ByteBudget:
    """``rate`` bytes per second, at most ``capacity`` saved up; a message is let in while the
    balance is not negative and then charged its size, at most ``capacity`` (it may go into
    debt: a message larger than the capacity is not refused for ever, its sender waits until
    the debt is paid; and one message, say a forger's 50 MB in a member's name, never shuts
    the member out for longer than ``capacity / rate`` seconds)."""

    __slots__ = ("rate", "capacity", "balance", "last")

    def __init__(self, rate: float, capacity: float) -> None:
        self.rate, self.capacity = rate, capacity
        self.balance, self.last = capacity, None

    def open(self, now: float) -> bool:
        """Refill to ``now`` and say whether a message may be let in."""
        if self.last is not None and now > self.last:
            self.balance = min(self.capacity, self.balance + (now - self.last) * self.rate)
        self.last = now if self.last is None else max(self.last, now)
        return self.balance >= 0.0

    def charge(self, n: int) -> None:
        self.balance -= min(n, self.capacity)


class Admission:
    """Per-sender rate limits, sized from what an honest sender sends per scan.

    An honest world sends one scan per sensor and one truth per scan interval; an honest
    neighbour ``rounds x kinds`` estimates. Each sender may send ``factor`` times that on
    average, with bursts of ``burst`` scans' worth (duplicates, catching up after a pause).
    Over the limit a message is dropped and counted as ``rate``. With ``estimate_bytes``
    (bytes per scan for each estimate a sender may send, on average:
    :meth:`peers.budget.EstimateBudget.slot_bytes`), each sender's estimates also draw on a
    :class:`ByteBudget` of that (bursts of ``burst`` scans' worth): over it, ``bytes``,
    counted per sender in :attr:`over_budget`.
    """

    def __init__(self, network: str, interval: float, per_scan: dict[str, float],
                 factor: float = 4.0, burst: float = 8.0, max_senders: int = 256,
                 window: Callable[[str], tuple[int, int]] | None = None,
                 rounds: int | None = None, kinds: Iterable[str] | None = None,
                 estimate_bytes: int | None = None) -> None:
        """``rounds``: consensus rounds the peer runs (estimates of round ``0 <= r < rounds``
        are taken); ``kinds``: estimate kinds it fuses (None: no check before decoding);
        ``estimate_bytes``: bytes per scan and estimate slot of the per-sender byte budget
        of estimates (None: none)."""
        self.network = network
        self.window = window
        """``channel -> (lo, hi)``: scan indices the peer keeps for that channel now."""
        self.rounds = rounds
        self.kinds = (None if kinds is None else
                      frozenset(ESTIMATE_KINDS.index(k) for k in kinds if k in ESTIMATE_KINDS))
        self._lock = threading.Lock()  # Zenoh calls back on several threads
        self._queued: Counter = Counter()  # (channel, name) -> messages in the inbox
        self._bounds: dict[str, int] = {}  # channel -> _inbox_bound(channel), kept
        self.queued_total = 0
        self.queued_bytes = 0
        self.inbox_peak = 0
        """Most messages ever waiting in the inbox at once."""
        self.admitted: Counter = Counter()
        """Messages let through to decoding, by ``channel/sender``."""
        self._slots: dict[str, dict[tuple, int]] = {}
        self._slots_lo: dict[str, int] = {}
        self.interval = max(interval, 1e-6)
        self.per_scan = per_scan
        self.factor, self.burst = factor, burst
        self.max_senders = max_senders
        self._buckets: dict[tuple[str, str], TokenBucket] = {}
        self.rejected: Counter = Counter()
        if estimate_bytes is not None and estimate_bytes <= 0:
            raise ValueError(f"estimate_bytes must be positive, got {estimate_bytes}")
        self.estimate_bytes = estimate_bytes
        self._budgets: dict[str, ByteBudget] = {}
        self.over_budget: Counter = Counter()
        """Estimates refused for their size (``bytes``), by ``estimate/sender``."""
        self.over_budget_bytes: Counter = Counter()
        """Their bytes, by ``estimate/sender``."""

    def _bucket(self, route: Route) -> TokenBucket | None:
        key = (route.channel, route.name)
        b = self._buckets.get(key)
        if b is None:
            if len(self._buckets) >= self.max_senders:  # names are bounded too
                return None
            n = self.per_scan.get(route.channel, 1.0)
            burst = max(self.burst, SCAN_BURST) if route.channel == "scan" else self.burst
            b = TokenBucket(self.factor * n / self.interval, max(4.0, burst * n))
            self._buckets[key] = b
        return b

    def admit(self, route: Route | None, now: float, payload: bytes = b"") -> bool:
        """Whether a message on ``route`` at ``now`` may be decoded (counts the refusals)."""
        with self._lock:
            return self._admit(route, now, payload, inbox=False)

    def arrive(self, route: Route | None, now: float, payload: bytes = b"",
               head: tuple | None = None) -> bool:
        """:meth:`admit`, and a place in the inbox for it: call :meth:`taken` with its key
        when the main loop takes it off the queue (or when it is dropped before that).
        ``head``: ``peek(payload)`` if the caller has it (a host peeks an estimate it hands
        to several co-hosted receivers once)."""
        with self._lock:
            return self._admit(route, now, payload, inbox=True, head=head)

    def taken(self, key: str, size: int, route: Route | None = None) -> None:
        """A message :meth:`arrive` let in has left the inbox (handled, skipped or refused;
        ``route``: its key parsed already, as the inbox item carries it): :meth:`taken_all`
        of one."""
        self.taken_all(((parse_key(key, self.network) if route is None else route, size),))

    def taken_all(self, routes_sizes) -> None:
        """Messages :meth:`arrive` let in have left the inbox (``(route, size)`` each, the
        route parsed already, None for a key that is not one of ours): one lock for a step's
        items; a message no :meth:`arrive` counted (a driver feeding its own queue) is
        skipped."""
        with self._lock:
            queued = self._queued
            for route, size in routes_sizes:
                if route is None:
                    continue
                name = (route.channel, route.name)
                n = queued.get(name, 0)
                if n <= 0:
                    continue  # not one arrive() counted (a driver feeding its own queue)
                if n == 1:
                    del queued[name]
                else:
                    queued[name] = n - 1
                self.queued_total -= 1
                self.queued_bytes -= size

    def shrink(self, n: int) -> None:
        """A message in the inbox became ``n`` bytes shorter (its signature trailer removed)."""
        with self._lock:
            self.queued_bytes -= n

    def _admit(self, route: Route | None, now: float, payload: bytes, inbox: bool,
               head: tuple | None = None) -> bool:
        if route is None:
            self.rejected["wrong-key"] += 1
            return False
        channel = route.channel
        if self.window is None or channel == "ctl":
            head = None
        elif head is None:
            head = peek(payload)
        slot = self._slot(route, head) if head is not None else None
        if slot is False:
            return False
        name = (channel, route.name)
        size = len(payload)
        if inbox:
            bound = self._bounds.get(channel)
            if bound is None:
                bound = self._bounds[channel] = self._inbox_bound(channel)
            if self._queued.get(name, 0) >= bound:
                self.rejected["inbox"] += 1
                return False
            if self.queued_total >= INBOX_TOTAL or self.queued_bytes + size > INBOX_BYTES:
                self.rejected["inbox-total"] += 1
                return False
        budget = (self._budget(route, head, payload)
                  if channel == "estimate" and self.estimate_bytes is not None else None)
        if budget is not None and not budget.open(now):
            self.rejected["bytes"] += 1
            self.over_budget[route.tag] += 1
            self.over_budget_bytes[route.tag] += size
            return False
        b = self._buckets.get(name)
        if b is None:
            b = self._bucket(route)
        if b is None or not b.take(now):
            self.rejected["rate"] += 1
            return False
        if budget is not None:
            budget.charge(size)
        if slot is not None:
            slots, key = slot
            slots[key] = slots.get(key, 0) + 1
        self.admitted[route.tag] += 1
        if inbox:
            self._queued[name] += 1
            self.queued_total += 1
            self.queued_bytes += size
            if self.queued_total > self.inbox_peak:
                self.inbox_peak = self.queued_total
        return True

    def _budget(self, route: Route, head: tuple | None, payload: bytes) -> ByteBudget | None:
        """The sender's byte budget if this message draws on it: estimates (``E``, or
        anything on the estimate key whose header does not parse), not scan forwards or
        returns (``F``/``R``: measurements, sized by clutter, not by the receiver's limit)."""
        if self.estimate_bytes is None or route.channel != "estimate":
            return None
        if head is None and self.window is None:
            head = peek(payload)
        if head is not None and head[0] != "E":
            return None
        b = self._budgets.get(route.name)
        if b is None:
            if len(self._budgets) >= self.max_senders:
                return None  # the message bucket refuses unknown names past the bound
            n = self.per_scan.get("estimate", 1.0) * self.estimate_bytes
            b = ByteBudget(n / self.interval, self.burst * n)
            self._budgets[route.name] = b
        return b

    def _inbox_bound(self, channel: str) -> int:
        return max(INBOX_MIN, int(INBOX_SCANS * self.per_scan.get(channel, 1.0)))

    def queued(self) -> dict:
        """What waits in the inbox now (messages per sender, in total, bytes)."""
        with self._lock:
            return {"senders": {f"{c}/{n}": q for (c, n), q in self._queued.items()},
                    "messages": self.queued_total, "bytes": self.queued_bytes}

    def _slot(self, route: Route, head: tuple[str, int, int, int]):
        """Window, round, kind and slot verdict for a parsed header: False (refused, counted),
        None (no slot: the bucket decides) or ``(slots, slot)`` to count once it is let in."""
        _, k, r, o = head
        lo, hi = self.window(route.channel)
        if k > hi or k < lo:
            if route.channel == "scan":
                return None  # maybe a restart of the numbering: the core decides, rate-limited
            self.rejected["future" if k > hi else "stale"] += 1
            return False
        if route.channel == "estimate":
            if self.rounds is not None and not 0 <= r < self.rounds:
                self.rejected["round"] += 1
                return False
            if self.kinds is not None and head[0] == "E" and o not in self.kinds:
                self.rejected["incompatible"] += 1
                return False
        slots = self._slots.setdefault(route.channel, {})
        if lo > self._slots_lo.get(route.channel, lo - 1):  # forget slots that left the window
            self._slots[route.channel] = slots = {s: n for s, n in slots.items() if s[1] >= lo}
            self._slots_lo[route.channel] = lo
        slot = (route.name, k, r, o)
        n = slots.get(slot, 0)
        if n == 0 and len(slots) >= MAX_SLOTS:
            return None
        if n >= SLOT_ATTEMPTS:
            self.rejected["duplicate"] += 1
            return False
        return slots, slot
