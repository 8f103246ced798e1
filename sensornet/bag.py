"""Bag-style tools: ``sensornet record`` (a live network's every key into one MCAP file) and
``sensornet play`` (the file put back onto a network at the recorded pace, or ``rate`` times
faster), like ``ros2 bag record/play``.

A bag has one MCAP channel per Zenoh key (topic = the key, ``sensornet/<network>/...``), each
message a JSON object (:data:`SAMPLE_SCHEMA`): the receive time, the key, the declared
encoding, the exact bytes (base64: what ``play`` puts back) and every field decoded
(protocol.json_fields), so ``mcap``'s reader and ``json.loads`` alone read it. Liveliness
tokens (a peer's ``alive``/``ready``, the world's) are the channel ``@liveliness``: ``play``
declares and undeclares them at their times, so peers started by hand see a world. The
metadata ``sensornet.bag`` names the network, the key space heard (keys, kinds, counts) and the
run's start parameters if its ``start`` message was heard (the world publishes no scenario).

``play`` can put back a part of a bag (:func:`select`): ``only="world"`` keeps what the world
published (scans, scan bundles, truth, control and its ``alive/world`` token), so fresh peers
fed from it compute their own estimates and tracks (``only="peers"``: the rest); and, as the
world does, it can wait for peers' ``ready`` tokens before its first message
(:func:`await_peers`, the ``gate`` of :func:`play`).
"""

from __future__ import annotations

import base64
import json
import queue
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from sensornet.peers.session import open_session
from sensornet.protocol.codec import Rejected, decode
from sensornet.protocol.json_fields import MESSAGE_SCHEMA, dumps, fields
from sensornet.protocol.keys import ROOT, WORLD
from sensornet.protocol.messages import Control

META = "sensornet.bag"
LIVELINESS = "@liveliness"
"""The channel of liveliness changes (not a Zenoh key: ``@`` cannot start one of ours)."""
SAMPLE_SCHEMA = {
    "title": "sensornet.sample", "type": "object",
    "properties": {
        "t": {"type": "number", "description": "receive time (s since the epoch)"},
        "key": {"type": "string", "description": "Zenoh key expression"},
        "encoding": {"type": "string", "description": "the put's declared encoding"},
        "payload": {"type": "string", "contentEncoding": "base64",
                    "description": "the exact bytes (protocol.codec), what play puts back"},
        "message": {**MESSAGE_SCHEMA, "type": ["object", "null"],
                    "description": "every field decoded (null: not decodable, e.g. sealed)"},
    },
    "required": ["t", "key", "encoding", "payload", "message"],
}
LIVELINESS_SCHEMA = {
    "title": "sensornet.liveliness", "type": "object",
    "properties": {"t": {"type": "number"}, "key": {"type": "string"},
                   "alive": {"type": "boolean", "description": "token declared (or gone)"}},
    "required": ["t", "key", "alive"],
}


class NoNetwork(RuntimeError):
    """Nothing of the network answered within the wait (one line: what to pass)."""


def hint(tool: str, network: str, connect: Sequence[str], wait: float) -> str:
    """The one line a tool prints when nothing of ``network`` answered within ``wait`` s."""
    if connect:
        return (f"{tool}: nothing of network {network!r} answered within {wait:g} s at "
                f"{', '.join(connect)}: is the run still going, and is that its name "
                f"(sensornet run --network) and the world's --listen endpoint?")
    return (f"{tool}: no network {network!r} answered within {wait:g} s: pass --connect "
            f"tcp/127.0.0.1:PORT (the world's --listen endpoint: 'sensornet run' prints it, "
            f"the run folder's commands.json has it)")


def network_answers(session, network: str, heard: Callable[[], bool], wait: float) -> bool:
    """Whether, within ``wait`` s, a sample was ``heard()`` or a liveliness token of
    ``network`` answers a query (a network between scans still has its tokens)."""
    end = time.monotonic() + wait
    expr = f"{ROOT}/{network}/**"
    while True:
        if heard():
            return True
        left = end - time.monotonic()
        if left <= 0:
            return False
        try:
            replies = session.liveliness().get(expr, timeout=min(0.5, max(left, 0.05)))
            if any(getattr(r, "ok", None) is not None for r in replies):
                return True
        except Exception:  # a session closing under us: no answer
            pass
        if heard():
            return True
        time.sleep(min(0.1, max(end - time.monotonic(), 0)))


@dataclass
class Bag:
    """Writes a network's samples and liveliness changes to an MCAP file (:func:`record`)."""

    path: Path
    network: str
    q: queue.Queue = field(default_factory=lambda: queue.Queue(maxsize=100_000))
    dropped: int = 0
    count: int = 0
    keys: Counter = field(default_factory=Counter)
    kinds: dict = field(default_factory=dict)
    start: dict | None = None
    ended: threading.Event = field(default_factory=threading.Event)

    def on_sample(self, sample) -> None:
        """Zenoh's callback: the sample queued as it came (written by the recording thread)."""
        item = ("s", time.time(), str(sample.key_expr), str(sample.encoding),
                sample.payload.to_bytes())
        self._put(item)

    def on_token(self, sample) -> None:
        alive = str(sample.kind).upper().endswith("PUT")
        self._put(("l", time.time(), str(sample.key_expr), alive))

    def _put(self, item: tuple) -> None:
        try:
            self.q.put_nowait(item)
        except queue.Full:
            self.dropped += 1

    def open(self) -> None:
        # heavy dependency: mcap (only the bag tools need it)
        from mcap.writer import CompressionType, Writer

        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = Path(self.path).open("wb")
        self._w = Writer(self._fh, compression=CompressionType.ZSTD)
        self._w.start(profile="", library="sensornet")
        self._sid = self._w.register_schema("sensornet.sample", "jsonschema",
                                            json.dumps(SAMPLE_SCHEMA).encode())
        lsid = self._w.register_schema("sensornet.liveliness", "jsonschema",
                                       json.dumps(LIVELINESS_SCHEMA).encode())
        self._ch = {LIVELINESS: self._w.register_channel(LIVELINESS, "json", lsid)}
        self._seq = 0

    def drain(self, timeout: float = 0.1) -> int:
        """Write what the callbacks queued (waiting up to ``timeout`` s for the first)."""
        n = 0
        try:
            item = self.q.get(timeout=timeout)
        except queue.Empty:
            return 0
        while True:
            self._write(item)
            n += 1
            try:
                item = self.q.get_nowait()
            except queue.Empty:
                return n

    def _write(self, item: tuple) -> None:
        self._seq += 1
        t = item[1]
        ns = max(0, int(t * 1e9))
        if item[0] == "l":
            body = {"t": t, "key": item[2], "alive": item[3]}
            self._w.add_message(self._ch[LIVELINESS], ns, dumps(body).encode(), ns,
                                sequence=self._seq)
            return
        _, t, key, encoding, payload = item
        try:
            msg = decode(payload)
        except Rejected:
            msg = None
        if key not in self._ch:
            self._ch[key] = self._w.register_channel(key, "json", self._sid)
        body = {"t": t, "key": key, "encoding": encoding,
                "payload": base64.b64encode(payload).decode("ascii"),
                "message": None if msg is None else fields(msg)}
        self._w.add_message(self._ch[key], ns, dumps(body).encode(), ns, sequence=self._seq)
        self.count += 1
        self.keys[key] += 1
        if msg is not None:
            self.kinds.setdefault(key, set()).add(body["message"]["type"])
            if isinstance(msg, Control):
                if msg.command == "start":
                    self.start = {"run_id": msg.run_id, **msg.params}
                elif msg.command == "end":
                    self.ended.set()

    def write_item(self, it: Item) -> None:
        """Write ``it`` as if heard at ``it.t`` (a bag made offline, e.g. from the twin:
        :mod:`sensornet.bag_twin`); after :meth:`open`."""
        self._write(("s", it.t, it.key, it.encoding, it.payload) if it.alive is None
                    else ("l", it.t, it.key, it.alive))

    def close(self) -> None:
        if getattr(self, "_fh", None) is None:
            return
        while self.drain(timeout=0):
            pass
        space = {k: {"messages": n, "kinds": sorted(self.kinds.get(k, ()))}
                 for k, n in sorted(self.keys.items())}
        meta = {"network": self.network, "messages": str(self.count),
                "dropped": str(self.dropped), "key_space": json.dumps(space)}
        if self.start is not None:
            meta["start"] = json.dumps(self.start)
        self._w.add_metadata(META, meta)
        self._w.finish()
        self._fh.close()
        self._fh = None


def record(path: Path, network: str, connect: Sequence[str] = (), config: str | None = None,
           duration: float | None = None, count: int | None = None, until_end: bool = False,
           wait: float = 3.0, stop: threading.Event | None = None,
           say: Callable[[str], None] = print) -> Bag:
    """Record every key of ``network`` (and its liveliness tokens) into ``path`` until
    ``duration`` s, ``count`` messages, the run's ``end`` message (``until_end``: 2 s after
    it) or ``stop``; :class:`NoNetwork` if nothing answered within ``wait`` s."""
    stop = stop or threading.Event()
    bag = Bag(Path(path), network)
    session = open_session((), list(connect), config)
    subs = []
    try:
        expr = f"{ROOT}/{network}/**"
        subs.append(session.declare_subscriber(expr, bag.on_sample))
        subs.append(session.liveliness().declare_subscriber(expr, bag.on_token, history=True))
        if not network_answers(session, network, lambda: bag.q.qsize() > 0, wait):
            raise NoNetwork(hint("record", network, connect, wait))
        bag.open()
        say(f"record: {expr} -> {path} (Ctrl-C to stop)")
        t0 = time.monotonic()
        ended_at = None
        try:
            while not stop.is_set():
                bag.drain(timeout=0.1)
                now = time.monotonic()
                if duration is not None and now - t0 >= duration:
                    break
                if count is not None and bag.count >= count:
                    break
                if until_end and bag.ended.is_set():
                    ended_at = ended_at or now
                    if now - ended_at >= 2.0:
                        break
        except KeyboardInterrupt:
            pass
    finally:
        for s in subs:
            try:
                s.undeclare()
            except Exception:
                pass
        session.close()
        bag.close()
    return bag


@dataclass(frozen=True)
class Item:
    """One thing ``play`` does at ``t`` (s since the epoch, as recorded): put ``payload`` on
    ``key`` (``alive`` None) or declare/undeclare a liveliness token (``alive`` True/False)."""

    t: float
    key: str
    payload: bytes = b""
    encoding: str = ""
    alive: bool | None = None


def read_bag(path: Path) -> tuple[dict[str, str], list[Item]]:
    """The metadata and the items of a bag, in time order; a peer's recording (``run
    --record``) plays too: its ``receive`` records are what it heard. A file that is not a
    complete MCAP file is a one-line :class:`ValueError`."""
    # heavy dependency: mcap
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    items: list[Item] = []
    meta: dict[str, str] = {}
    with Path(path).open("rb") as fh:
        try:
            reader = make_reader(fh)
            for m in reader.iter_metadata():
                if m.name in (META, "sensornet"):
                    meta = {**meta, **dict(m.metadata)}
            fh.seek(0)
            reader = make_reader(fh)
            for _, ch, msg in reader.iter_messages(log_time_order=True):
                if ch.message_encoding != "json":
                    continue
                body = json.loads(msg.data)
                if ch.topic == LIVELINESS:
                    items.append(Item(body["t"], body["key"], alive=bool(body["alive"])))
                elif ch.topic == "receive" or ch.topic.startswith(f"{ROOT}/"):
                    items.append(Item(body["t"], body["key"], base64.b64decode(body["payload"]),
                                      body.get("encoding", "")))
        except McapError as exc:
            raise ValueError(f"{path}: not a complete MCAP file ({type(exc).__name__})") \
                from None
    return meta, items


WORLD_CHANNELS = ("scan", "scans", "truth", "ctl")
"""The channels the world publishes on (``sensornet/<network>/<channel>[/...]``; sim.run
.world_process); with its ``alive/world`` liveliness token, a bag's world part."""
PARTS = ("world", "peers")
"""What ``only`` may name (:func:`select`)."""


def is_world(item: Item) -> bool:
    """Whether the world published ``item``: a message on one of :data:`WORLD_CHANNELS`, or its
    ``alive/world`` token (the peers' ``alive``/``ready`` tokens, estimates, tracks and
    telemetry are the peers' part)."""
    parts = item.key.split("/")
    if len(parts) < 3 or parts[0] != ROOT:
        return False
    if item.alive is not None:
        return parts[2:] == ["alive", WORLD]
    return parts[2] in WORLD_CHANNELS


def select(items: Sequence[Item], only: str | None = None,
           keys: Sequence[str] = ()) -> list[Item]:
    """The items of a bag to play: ``only`` ``"world"`` (what the world published,
    :func:`is_world`) or ``"peers"`` (the rest), None for both; ``keys``: Zenoh key
    expressions (``sensornet/*/scan/**``), an item kept if one includes its recorded key (its
    liveliness tokens too); both given: both hold. A bad ``only`` or expression is a one-line
    :class:`ValueError`."""
    if only is not None and only not in PARTS:
        raise ValueError(f"only {only!r}: one of {', '.join(PARTS)}")
    exprs = []
    for k in keys:
        try:
            exprs.append(zenoh.KeyExpr(k))
        except Exception:  # zenoh.ZError: its message spans a source path
            raise ValueError(f"{k!r}: not a Zenoh key expression (e.g. "
                             f"sensornet/*/scan/**)") from None
    out = []
    for it in items:
        if only is not None and is_world(it) != (only == "world"):
            continue
        if exprs and not any(e.includes(zenoh.KeyExpr(it.key)) for e in exprs):
            continue
        out.append(it)
    return out


def network_of(items: Sequence[Item]) -> str | None:
    """The network name of a bag's keys (``sensornet/<network>/...``), None if it has none."""
    for it in items:
        parts = it.key.split("/")
        if len(parts) > 2 and parts[0] == ROOT:
            return parts[1]
    return None


class PeersMissing(RuntimeError):
    """The peers ``play`` waits for did not come up in time (one line: which)."""


def await_peers(session, network: str, names: Sequence[str], timeout: float,
                stop: threading.Event | None = None) -> Callable[[dict], None]:
    """A ``gate`` for :func:`play`, as the world waits for its peers: until every peer of
    ``names`` has its ``sensornet/<network>/ready/<name>`` token up (it sees all its
    neighbours) and, of the publishers ``play`` declared, those of these peers' scans have a
    subscriber; :class:`PeersMissing` after ``timeout`` s or on ``stop``. The liveliness
    subscriber is declared at once (tokens up before the gate runs are its history)."""
    stop = stop or threading.Event()
    ready: set[str] = set()
    cond = threading.Condition()

    def on_token(sample) -> None:
        name = str(sample.key_expr).rsplit("/", 1)[-1]
        with cond:
            if sample.kind == zenoh.SampleKind.PUT:
                ready.add(name)
            else:
                ready.discard(name)
            cond.notify_all()

    sub = session.liveliness().declare_subscriber(f"{ROOT}/{network}/ready/*", on_token,
                                                  history=True)

    def gate(pubs: dict) -> None:
        try:
            end = time.monotonic() + timeout
            with cond:
                while not set(names) <= ready:
                    if stop.is_set() or time.monotonic() >= end:
                        missing = sorted(set(names) - ready)
                        why = "interrupted" if stop.is_set() else f"not within {timeout:g} s"
                        raise PeersMissing(f"play: peers {', '.join(missing)} not ready on "
                                           f"network {network!r} ({why})")
                    cond.wait(timeout=0.2)
            # as the world: a peer's subscription can reach us after its ready token
            wanted = {f"{ROOT}/{network}/scan/{n}" for n in names}
            probes = [p for (key, _), p in pubs.items() if key in wanted]
            while not stop.is_set() and time.monotonic() < end:
                if all(p.matching_status.matching for p in probes):
                    return
                stop.wait(0.01)
        finally:
            sub.undeclare()

    return gate


def rename(key: str, network: str | None) -> str:
    """``key`` moved under ``sensornet/<network>/`` (None: as it is)."""
    if network is None:
        return key
    parts = key.split("/", 2)
    return "/".join([parts[0], network, *parts[2:]]) if len(parts) > 1 else key


def play(items: Sequence[Item], session, rate: float = 1.0, network: str | None = None,
         stop: threading.Event | None = None, clock: Callable[[], float] = time.monotonic,
         sleep: Callable[[float], None] = time.sleep,
         gate: Callable[[dict], None] | None = None) -> int:
    """Put ``items`` onto ``session`` at their recorded pace divided by ``rate`` (their keys
    under ``network`` if given); liveliness tokens declared and undeclared as recorded, all
    undeclared at the end. Returns the samples put.

    ``gate`` (e.g. :func:`await_peers`): called once before the first sample with the
    publishers, every one declared first (``{(key, encoding): publisher}``); the liveliness
    changes before that sample are made at once (the world's token is up while it waits, as
    a live world's is) and the pace counts from that sample."""
    if not rate > 0:
        raise ValueError(f"rate {rate}: must be positive")
    stop = stop or threading.Event()
    tokens: dict[str, object] = {}
    pubs: dict[tuple[str, str], object] = {}

    def publisher(key: str, encoding: str):
        pub = pubs.get((key, encoding))
        if pub is None:
            kw = {"encoding": encoding} if encoding else {}
            pub = pubs[(key, encoding)] = session.declare_publisher(key, **kw)
        return pub

    n = 0
    try:
        if not items:
            return 0
        t0, c0 = items[0].t, clock()
        first = next((i for i, it in enumerate(items) if it.alive is None), len(items))
        for i, it in enumerate(items):
            if gate is not None and i == first:
                for x in items:
                    if x.alive is None:
                        publisher(rename(x.key, network), x.encoding)
                gate(pubs)
                t0, c0 = it.t, clock()
            if gate is None or i >= first:
                due = c0 + (it.t - t0) / rate
                while not stop.is_set() and (left := due - clock()) > 0:
                    sleep(min(left, 0.1))
            if stop.is_set():
                break
            key = rename(it.key, network)
            if it.alive is True:
                if key not in tokens:
                    tokens[key] = session.liveliness().declare_token(key)
            elif it.alive is False:
                tok = tokens.pop(key, None)
                if tok is not None:
                    tok.undeclare()
            else:
                publisher(key, it.encoding).put(it.payload)
                n += 1
    finally:
        for tok in tokens.values():
            try:
                tok.undeclare()
            except Exception:
                pass
        for pub in pubs.values():
            try:
                pub.undeclare()
            except Exception:
                pass
    return n
