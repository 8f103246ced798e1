"""Live inspection of a running network: ``sensornet echo`` and ``sensornet topics``.

A Zenoh session in peer mode joins the network (``--connect`` to any process of it, e.g. the
world's ``--listen`` endpoint), subscribes to ``sensornet/<network>/<KEY>`` and decodes each
message with the peers' own codec (protocol.codec, the same limits: a hostile payload is a
``rejected`` line, never a crash). Secure mode (``--secure DIR --as MEMBER``): the session
speaks mutual TLS with that member's certificate, subscribes only to the keys the network's
access control lets the member hear (peers.access_control) and verifies every signature
against the roster (protocol.envelope).
"""

from __future__ import annotations

import queue
import sys
import threading
import time
from collections import Counter, defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import zenoh

from sensornet.bag import hint, network_answers
from sensornet.peers.session import open_session
from sensornet.protocol.codec import Rejected, decode
from sensornet.protocol.encodings import parse
from sensornet.protocol.envelope import inner, is_sealed
from sensornet.protocol.json_fields import dumps, fields
from sensornet.protocol.keys import ROOT, Keys
from sensornet.protocol.messages import Control, Estimate, Forward, Returns, Scan, Tracks, Truth


@dataclass(frozen=True)
class Line:
    """What one message was, for a line of ``echo`` and a row of ``topics``."""

    key: str
    kind: str
    sender: str
    scan: int | None
    items: str
    nbytes: int
    note: str = ""

    def text(self, t0: float, now: float) -> str:
        scan = "-" if self.scan is None else str(self.scan)
        note = f"  {self.note}" if self.note else ""
        return (f"{now - t0:8.3f}s  {self.key:<34} {self.kind:<8} from {self.sender:<8} "
                f"scan {scan:>5}  {self.items:<22} {self.nbytes:>7} B{note}")


def describe(key: str, payload: bytes, encoding: str = "", verifier=None) -> Line:
    """Decode one message into a :class:`Line` (a refused or undecodable one says why)."""
    nbytes = len(payload)
    sealed = is_sealed(payload)
    note = "sealed" if sealed else ""
    body = payload
    if verifier is not None:
        opened, why = verifier.open(key, payload)
        if opened is None:
            return Line(key, "refused", "?", None, why or "", nbytes, "signature check")
        body, note = opened, "signature ok"
    elif sealed:
        body = inner(payload)
    declared = parse(encoding) if encoding else None
    try:
        msg = decode(body)
    except Rejected as exc:
        return Line(key, "rejected", "?", None, exc.reason, nbytes, str(exc)[:60])
    if isinstance(msg, Estimate):
        line = Line(key, "estimate", msg.sender, msg.k,
                    f"{len(msg.mixture.weights)} comp, round {msg.round}", nbytes, note)
    elif isinstance(msg, Scan):
        line = Line(key, "scan", msg.sensor, msg.k, f"{len(msg.z)} returns", nbytes, note)
    elif isinstance(msg, Tracks):
        line = Line(key, "tracks", msg.sender, msg.k, f"{len(msg.states)} tracks", nbytes, note)
    elif isinstance(msg, Truth):
        line = Line(key, "truth", "world", msg.k, f"{len(msg.states)} targets", nbytes, note)
    elif isinstance(msg, Forward):
        n = sum(len(z) for z in msg.scans.scans.values())
        line = Line(key, "forward", msg.sender, msg.k,
                    f"{len(msg.scans.scans)} scans, {n} returns", nbytes, note)
    elif isinstance(msg, Returns):
        line = Line(key, "returns", msg.sender, msg.k, f"{len(msg.z)} returns", nbytes, note)
    elif isinstance(msg, Control):
        line = Line(key, "control", "world", None, msg.command, nbytes, note)
    else:  # pragma: no cover - decode returns only the types above
        line = Line(key, type(msg).__name__.lower(), "?", None, "", nbytes, note)
    if declared is not None and declared[0] not in (line.kind, "unknown"):
        line = Line(line.key, line.kind, line.sender, line.scan, line.items, line.nbytes,
                    f"{line.note} (declared {declared[0]})".strip())
    return line


@dataclass(frozen=True)
class JsonLine:
    """One message as a JSON object (``echo --json``): the key, the receive time, the declared
    encoding, the size, and every field decoded (protocol.json_fields) or why not."""

    body: dict

    def text(self, t0: float, now: float) -> str:
        return dumps(self.body)


def as_json(key: str, payload: bytes, encoding: str = "", verifier=None) -> JsonLine:
    """Decode one message into a :class:`JsonLine` (a refused or undecodable one says why)."""
    body = {"key": key, "t": time.time(), "encoding": encoding, "nbytes": len(payload)}
    inside = payload
    if verifier is not None:
        opened, why = verifier.open(key, payload)
        if opened is None:
            return JsonLine({**body, "error": f"signature check: {why}"})
        inside = opened
    elif is_sealed(payload):
        inside = inner(payload)
    try:
        body["message"] = fields(decode(inside))
    except Rejected as exc:
        body["error"] = f"rejected ({exc.reason}): {exc}"
    return JsonLine(body)


def secure_keys(keys: Keys, member: str, peers: Sequence[str]) -> list[str]:
    """The key expressions a member may subscribe to (peers.access_control: its own scan,
    the truth, control and every estimate; the world also hears every scan)."""
    if member == "world":
        return [keys.scan("*")]
    return [keys.scan(member), keys.truth(), keys.ctl(), keys.estimate("*")]


@dataclass
class Tap:
    """A subscription on a network's keys that hands each message, described, to a queue."""

    network: str
    key: str = "**"
    connect: Sequence[str] = ()
    config: str | None = None
    security: object = None
    """A :class:`peers.security.Security` of the member the tool speaks as."""
    q: queue.Queue = field(default_factory=lambda: queue.Queue(maxsize=10_000))
    dropped: int = 0
    json_lines: bool = False
    """Queue :class:`JsonLine` (every field) instead of one-line :class:`Line` summaries."""

    def open(self) -> None:
        keys = Keys(self.network)
        self.verifier = self.security.verifier() if self.security is not None else None
        self.session = open_session((), list(self.connect), self.config,
                                    security=self.security)
        exprs = [f"{ROOT}/{self.network}/{self.key}"]
        if self.security is not None:
            exprs = secure_keys(keys, self.security.member, self.security.peers)
            if self.key != "**":
                exprs = [e for e in exprs if _overlaps(e, f"{ROOT}/{self.network}/{self.key}")]
        self._subs = [self.session.declare_subscriber(e, self._on_sample) for e in exprs]
        self.exprs = exprs

    def _on_sample(self, sample) -> None:
        try:
            line = (as_json if self.json_lines else describe)(
                str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding),
                self.verifier)
        except Exception as exc:  # a tool must outlive any payload
            line = (JsonLine({"key": str(sample.key_expr), "error": type(exc).__name__})
                    if self.json_lines else
                    Line(str(sample.key_expr), "error", "?", None, type(exc).__name__, 0))
        try:
            self.q.put_nowait(line)
        except queue.Full:
            self.dropped += 1

    def answers(self, wait: float) -> bool:
        """Whether the network answered (a message, or a liveliness token of it) within
        ``wait`` s (:func:`bag.network_answers`; the messages stay queued)."""
        return network_answers(self.session, self.network, lambda: self.q.qsize() > 0, wait)

    def hint(self, tool: str, wait: float) -> str:
        """The one line saying nothing answered, and what to pass."""
        return hint(tool, self.network, list(self.connect), wait)

    def close(self) -> None:
        for s in getattr(self, "_subs", []):
            try:
                s.undeclare()
            except Exception:
                pass
        if getattr(self, "session", None) is not None:
            self.session.close()


def _overlaps(a: str, b: str) -> bool:
    """Whether key expressions ``a`` and ``b`` can match a common key (Zenoh's rule)."""
    return zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b))


def echo(tap: Tap, count: int | None = None, duration: float | None = None,
         out: Callable[[str], None] = print, stop: threading.Event | None = None) -> int:
    """Print one line per message until ``count`` messages, ``duration`` seconds or ``stop``;
    the number of messages printed."""
    stop = stop or threading.Event()
    t0 = time.monotonic()
    end = t0 + duration if duration else None
    n = 0
    while not stop.is_set() and (count is None or n < count):
        wait = 0.2 if end is None else min(0.2, end - time.monotonic())
        if wait <= 0:
            break
        try:
            line = tap.q.get(timeout=wait)
        except queue.Empty:
            continue
        out(line.text(t0, time.monotonic()))
        n += 1
    return n


def topics(tap: Tap, duration: float = 3.0, stop: threading.Event | None = None,
           count: int | None = None) -> str:
    """Listen for ``duration`` seconds (or until ``count`` messages), then a table: per key,
    messages, rate, bytes, kinds, senders and the newest scan."""
    stop = stop or threading.Event()
    t0 = time.monotonic()
    seen: dict[str, Counter] = defaultdict(Counter)
    nbytes: Counter = Counter()
    newest: dict[str, int] = {}
    kinds: dict[str, set] = defaultdict(set)
    heard = 0
    while (not stop.is_set() and time.monotonic() - t0 < duration
           and (count is None or heard < count)):
        try:
            line = tap.q.get(timeout=0.1)
        except queue.Empty:
            continue
        heard += 1
        seen[line.key][line.sender] += 1
        nbytes[line.key] += line.nbytes
        kinds[line.key].add(line.kind)
        if line.scan is not None:
            newest[line.key] = max(newest.get(line.key, 0), line.scan)
    secs = max(time.monotonic() - t0, 1e-9)
    rows = ["| key | messages | per s | bytes | kinds | newest scan |",
            "|---|---:|---:|---:|---|---:|"]
    for key in sorted(seen):
        n = sum(seen[key].values())
        rows.append(f"| {key} | {n} | {n / secs:.1f} | {nbytes[key]} | "
                    f"{', '.join(sorted(kinds[key]))} | {newest.get(key, '-')} |")
    if len(rows) == 2:
        rows.append(f"| (nothing heard in {secs:.1f} s) | 0 | 0 | 0 | - | - |")
    return "\n".join(rows)


WAIT = 3.0
"""Seconds ``echo`` and ``topics`` wait for the network to answer before saying it did not
(without ``--connect`` nothing can: the sessions do not scout)."""
WAIT_CONNECT = 20.0
"""The same with ``--connect``: Zenoh keeps trying the endpoint, and a run just started takes
seconds before its world listens."""


def default_wait(connect: Sequence[str]) -> float:
    """:data:`WAIT_CONNECT` with endpoints to try, else :data:`WAIT`."""
    return WAIT_CONNECT if connect else WAIT


def main_echo(tap: Tap, count: int | None, duration: float | None,
              wait: float | None = None) -> int:
    """``echo``: lines until ``count``/``duration``/Ctrl-C; 1 (and a one-line hint) if
    nothing of the network answered within ``wait`` s (default :func:`default_wait`)."""
    wait = default_wait(tap.connect) if wait is None else wait
    if duration:
        wait = min(wait, duration)
    tap.open()
    try:
        if not tap.answers(wait):
            print(tap.hint("echo", wait), file=sys.stderr, flush=True)
            return 1
        print(f"echo: {', '.join(tap.exprs)} (Ctrl-C to stop)", file=sys.stderr, flush=True)
        try:
            echo(tap, count, duration, out=lambda s: print(s, flush=True))
        except KeyboardInterrupt:
            pass
    finally:
        tap.close()
    if tap.dropped:
        print(f"echo: {tap.dropped} messages not shown (printing fell behind)", file=sys.stderr)
    return 0
