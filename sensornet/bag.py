"""Bag-style tools: ``sensornet record`` (a live network's every key into one MCAP file) and
``sensornet play`` (the file put back onto a network at the recorded pace, or ``rate`` times
faster), like ``ros2 bag record/play``.

A bag has one MCAP channel per Zenoh key (topic = the key, ``sensornet/<network>/...``), each
message a JSON object (:data:`SAMPLE_SCHEMA`): the receive time, the key, the declared
encoding, the exact bytes (base64: what ``play`` puts back, its send time set as it puts
it, :func:`sensornet.bag_play.restamp`) and every field decoded
(protocol.json_fields), so ``mcap``'s reader and ``json.loads`` alone read it. Liveliness
tokens (a peer's ``alive``/``ready``, the world's) are the channel ``@liveliness``: ``play``
declares and undeclares them at their times, so peers started by hand see a world. The
metadata ``sensornet.bag`` names the network, the key space heard (keys, kinds, counts), the
run's start parameters if its ``start`` message was heard and, given to ``record`` (the world
publishes none), the run's scenario: its text, file name and ``--set`` items, as a peer's
recording holds them (:func:`sensornet.bag_twin.bag_scenario` loads it).

``play`` can put back a part of a bag (:func:`select`): ``only="world"`` keeps what the world
published (scans, scan bundles, truth, control and its ``alive/world`` token), so fresh peers
fed from it compute their own estimates and tracks (``only="peers"``: the rest); and, as the
world does, it can wait for peers' ``ready`` tokens before its first message
(:func:`await_peers`, the ``gate`` of :func:`play`). Those live in :mod:`sensornet.bag_play`
(re-exported here); this module records.
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

from sensornet.bag_play import (  # noqa: F401  (re-exported: bag's public names stay here)
    LIVELINESS,
    META,
    PARTS,
    WORLD_CHANNELS,
    Item,
    PeersMissing,
    await_peers,
    is_world,
    network_of,
    play,
    read_bag,
    rename,
    restamp,
    select,
)
from sensornet.peers.session import open_session
from sensornet.protocol.bundle import BUNDLE_HEAD, unpack_bundle
from sensornet.protocol.codec import Rejected, decode
from sensornet.protocol.json_fields import MESSAGE_SCHEMA, dumps, fields
from sensornet.protocol.keys import ROOT
from sensornet.protocol.messages import Control
from sensornet.protocol.report_bundle import REPORTS_HEAD, unpack_reports

SAMPLE_SCHEMA = {
    "title": "sensornet.sample", "type": "object",
    "properties": {
        "t": {"type": "number", "description": "receive time (s since the epoch)"},
        "key": {"type": "string", "description": "Zenoh key expression"},
        "encoding": {"type": "string", "description": "the put's declared encoding"},
        "payload": {"type": "string", "contentEncoding": "base64",
                    "description": "the exact bytes (protocol.codec), what play puts back "
                                   "(with its send time set as it puts it)"},
        "message": {**MESSAGE_SCHEMA, "type": ["object", "null"],
                    "description": "every field decoded (null: not decodable, e.g. sealed, "
                                   "or a bundle)"},
        "entries": {"type": "array", "description": "a bundle's entries (a host's scans or "
                    "its peers' reports, a peer's tracks and report), each decoded",
                    "items": {"type": "object", "required": ["name", "message"],
                              "properties": {"name": {"type": "string"},
                                             "message": {**MESSAGE_SCHEMA,
                                                         "type": ["object", "null"]}}}},
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


def _entries(payload: bytes) -> list[dict]:
    """A bundle's entries decoded for the JSON body (each as the codec reads it; an entry it
    refuses, or a payload that is no bundle, gives ``message: null`` / no entries); a host's
    reports message (:mod:`protocol.report_bundle`): its entries, then each report."""
    if payload[:1] == REPORTS_HEAD:
        try:
            msg = unpack_reports(payload)
        except Rejected:
            return []
        return [*_decoded(msg.entries), *({"name": r.sender, "message": fields(r)}
                                          for r in msg.reports if not isinstance(r, Rejected))]
    try:
        entries = unpack_bundle(payload).entries
    except Rejected:
        return []
    return _decoded(entries)


def _decoded(entries: list[tuple[str, bytes]]) -> list[dict]:
    """``(name, payload)`` entries each decoded (``message: null`` where the codec refuses)."""
    out = []
    for name, entry in entries:
        try:
            out.append({"name": name, "message": fields(decode(entry))})
        except Rejected:
            out.append({"name": name, "message": None})
    return out


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
    scenario: dict[str, str] | None = None
    """``scenario_text``, ``scenario_file``, ``overrides`` (JSON list of ``--set`` items)."""
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
        if msg is None and payload[:1] in (BUNDLE_HEAD, REPORTS_HEAD):
            body["entries"] = _entries(payload)
        self._w.add_message(self._ch[key], ns, dumps(body).encode(), ns, sequence=self._seq)
        self.count += 1
        self.keys[key] += 1
        for e in body.get("entries", ()):
            if e["message"] is not None:
                self.kinds.setdefault(key, set()).add(e["message"]["type"])
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
        meta.update(self.scenario or {})
        self._w.add_metadata(META, meta)
        self._w.finish()
        self._fh.close()
        self._fh = None


def record(path: Path, network: str, connect: Sequence[str] = (), config: str | None = None,
           duration: float | None = None, count: int | None = None, until_end: bool = False,
           wait: float = 3.0, stop: threading.Event | None = None,
           say: Callable[[str], None] = print, scenario: dict[str, str] | None = None) -> Bag:
    """Record every key of ``network`` (and its liveliness tokens) into ``path`` until
    ``duration`` s, ``count`` messages, the run's ``end`` message (``until_end``: 2 s after
    it) or ``stop``; :class:`NoNetwork` if nothing answered within ``wait`` s. ``scenario``:
    the run's (:attr:`Bag.scenario`), written to the metadata."""
    stop = stop or threading.Event()
    bag = Bag(Path(path), network, scenario=scenario)
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
