"""Playing a bag (``sensornet play``, :mod:`sensornet.bag` records): reading an MCAP bag into
:class:`Item` s, choosing a part of it (:func:`select`), waiting for peers (:func:`await_peers`)
and putting it back onto a network at the recorded pace (:func:`play`), each message's send time
set as it is put (:func:`restamp`: as a live sender stamps it, so the receivers' latency counts
from the put); apart from the recorder so each stays a module of one concern.
"""

from __future__ import annotations

import base64
import json
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import msgpack
import zenoh

from sensornet.protocol.codec_format import VERSIONS
from sensornet.protocol.keys import ROOT, WORLD
from sensornet.protocol.report_bundle import REPORTS_HEAD

META = "sensornet.bag"
LIVELINESS = "@liveliness"
"""The channel of liveliness changes (not a Zenoh key: ``@`` cannot start one of ours)."""


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
    neighbours) and, of the publishers ``play`` declared, those of these peers' scans and
    every scan bundle's (``scans/<host>``: peer hosts) have a subscriber (as the world waits,
    at most until ``timeout``); :class:`PeersMissing` after ``timeout`` s or on ``stop``. The
    liveliness subscriber is declared at once (tokens up before the gate runs are its
    history)."""
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
            bundles = f"{ROOT}/{network}/scans/"  # a peer host's (the bag says which hosts)
            probes = [p for (key, _), p in pubs.items()
                      if key in wanted or key.startswith(bundles)]
            while not stop.is_set() and time.monotonic() < end:
                if all(p.matching_status.matching for p in probes):
                    return
                stop.wait(0.01)
        finally:
            sub.undeclare()

    return gate


def _stamped(payload: bytes, now: float) -> bytes | None:
    """An encoded message (``[version, type, fields...]``, :mod:`protocol.codec`) with its
    ``ts`` field set to ``now``, or None if ``payload`` is not one."""
    try:
        body = msgpack.unpackb(payload, raw=False)
    except Exception:  # msgpack raises several unrelated types (a sealed message: ExtraData)
        return None
    if not isinstance(body, list) or len(body) < 2 or type(body[0]) is not int:
        return None
    names = VERSIONS.get(body[0], {}).get(body[1]) if isinstance(body[1], str) else None
    if not names or len(body) != 2 + len(names) or "ts" not in names:
        return None
    i = 2 + names.index("ts")
    if not isinstance(body[i], float | int) or isinstance(body[i], bool):
        return None
    body[i] = float(now)
    return msgpack.packb(body, use_bin_type=True)


BUNDLES = ("scans", "telemetries")
"""Channels whose messages are bundles (:mod:`protocol.bundle`, ``[k, [[name, message], ...]]``):
the world's scans for a peer host, a host's peers' telemetry (now as :mod:`protocol.report_bundle`:
its entries and send time restamped); a peer of its own process puts its tracks and report as
one bundle on ``telemetry/<peer>`` (``0x92``, a message never is)."""


def restamp(key: str, payload: bytes, now: float) -> bytes | None:
    """``payload`` (put on ``key``) with its send time set to ``now`` and every other byte as
    recorded: a message of :mod:`protocol.codec` (its ``ts``), or a bundle (:data:`BUNDLES`:
    each entry's); None for anything else, e.g. a signed message (:mod:`protocol.envelope`),
    whose signature covers the payload: :func:`play` puts those as recorded."""
    parts = key.split("/")
    if len(parts) > 2 and parts[0] == ROOT and (parts[2] in BUNDLES or (
            parts[2] == "telemetry" and payload[:1] == b"\x92")):  # a peer's own bundle
        try:
            body = msgpack.unpackb(payload, raw=False)
        except Exception:  # as above
            return None
        reports = payload[:1] == REPORTS_HEAD  # a host's: [ts, entries, reports, vx, pf]
        if (not isinstance(body, list) or len(body) != (5 if reports else 2)
                or not isinstance(body[1], list)
                or not all(isinstance(e, list) and len(e) == 2 for e in body[1])):
            return None
        entries = [_stamped(e[1], now) if isinstance(e[1], bytes) else None for e in body[1]]
        if any(e is None for e in entries):
            return None
        body[1] = [[e[0], x] for e, x in zip(body[1], entries, strict=True)]
        if reports:  # its reports' send time
            body[0] = float(now)
        return msgpack.packb(body, use_bin_type=True)
    return _stamped(payload, now)


def rename(key: str, network: str | None) -> str:
    """``key`` moved under ``sensornet/<network>/`` (None: as it is)."""
    if network is None:
        return key
    parts = key.split("/", 2)
    return "/".join([parts[0], network, *parts[2:]]) if len(parts) > 1 else key


def play(items: Sequence[Item], session, rate: float = 1.0, network: str | None = None,
         stop: threading.Event | None = None, clock: Callable[[], float] = time.monotonic,
         sleep: Callable[[float], None] = time.sleep,
         gate: Callable[[dict], None] | None = None,
         stamp: Callable[[], float] | None = time.time) -> int:
    """Put ``items`` onto ``session`` at their recorded pace divided by ``rate`` (their keys
    under ``network`` if given); liveliness tokens declared and undeclared as recorded, all
    undeclared at the end. Returns the samples put.

    ``stamp``: each message's send time is set to ``stamp()`` as it is put (:func:`restamp`),
    as a live sender stamps it, so the receivers' scan -> tracks latency, transit and run
    clock count from the put, not from the recording; None: the recorded bytes exactly.

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
                payload = it.payload if stamp is None else (
                    restamp(it.key, it.payload, stamp()) or it.payload)
                publisher(key, it.encoding).put(payload)
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
