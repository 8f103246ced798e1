"""A peer's Zenoh side: session, subscriptions, publishers, liveliness tokens, one inbox queue.

Zenoh callbacks only check the key and the sender's rate (:class:`peers.admission.Admission`,
a dictionary lookup) and put admitted payloads on the queue; calling Zenoh from a callback can
deadlock, and a slow callback holds up receiving. The driver's main thread takes items off the
queue and hands them to the sans-I/O core.
"""

from __future__ import annotations

import os
import queue
import time

import zenoh
import zenoh.ext as zx
from sensornet.peers.admission import Admission, parse_key
from sensornet.peers.inbound import Delivered
from sensornet.peers.refusal_log import RefusalLog
from sensornet.peers.session import SessionError, open_session
from sensornet.protocol.encodings import encoding_text, letter_of
from sensornet.protocol.keys import Keys

RECOVER_CACHE = 64
"""Messages each publisher keeps per key for subscribers that missed them (``recover``): at
4 scans/s a 16 s outage of a router."""
RECOVER_HEARTBEAT = 0.5
"""Seconds between a recovering publisher's heartbeats (its last sequence number): how a
subscriber that missed the publisher's last messages notices and asks for them."""

DIRECT_CALLBACKS = os.environ.get("SENSORNET_ZENOH_CALLBACKS", "thread") == "direct"
"""``SENSORNET_ZENOH_CALLBACKS=direct``: run the subscribers' callbacks on Zenoh's own threads
(they only admit and queue, no Zenoh call inside) instead of Zenoh's default, a Python thread
per subscriber. Measured (``benchmarks/bench_network.py --callbacks``, load 5-7 on 2 cores):
no gain in hosts once co-hosted estimates are handed over (50 peers of degree 4 in 2 hosts:
3.63 vs 3.67 ms per peer per scan), none for 3 peers (three runs each: 4.26-4.36 vs
3.88-4.34 ms, median scan -> fused 6.7-8.8 vs 6.5-7.9 ms): so not the default."""


def recovering_publisher(session, key: str, express: bool = True):
    """Zenoh's advanced publisher on ``key``: numbered messages, a cache of the last
    :data:`RECOVER_CACHE` and heartbeats, so a subscriber that missed some (a router's outage)
    gets them from the cache. Replies to such queries are not ``express``: the subscriber
    tells a recovered message from a live one by that (``express`` must be true here)."""
    return zx.declare_advanced_publisher(
        session, key, congestion_control=zenoh.CongestionControl.BLOCK, express=express,
        cache=zx.CacheConfig(RECOVER_CACHE, replies_config=zx.RepliesConfig(express=False)),
        sample_miss_detection=zx.MissDetectionConfig(heartbeat=RECOVER_HEARTBEAT))


def recovering_subscriber(session, key: str, callback, on_miss):
    """Zenoh's advanced subscriber on ``key``: asks a :func:`recovering_publisher` for what it
    missed (on a gap in the numbers or a heartbeat ahead of it) and delivers in order;
    ``on_miss(n)`` for ``n`` messages the publisher's cache no longer held."""
    sub = zx.declare_advanced_subscriber(session, key, callback,
                                         recovery=zx.RecoveryConfig(heartbeat=True))
    listener = sub.sample_miss_listener(lambda miss: on_miss(miss.nb))
    return sub, listener


def settle(session, first: float = 2.0, stable: float = 0.2, cap: float = 1.5) -> None:
    """Wait until ``session`` has links and gossip has stopped adding peers (a peer does not
    route for others, so a liveliness query reaches only the peers linked to us); a client of
    a router is linked once it has the router."""
    info = session.info

    def linked() -> int:  # peers, or the routers a client reaches everyone through
        return len(list(info.peers_zid())) + len(list(info.routers_zid()))

    end = time.monotonic() + first
    while not linked() and time.monotonic() < end:
        time.sleep(0.01)
    n, since, end = -1, time.monotonic(), time.monotonic() + cap
    while time.monotonic() < end:
        now_n = linked()
        if now_n != n:
            n, since = now_n, time.monotonic()
        elif time.monotonic() - since >= stable:
            return
        time.sleep(0.02)


def callback(fn):
    """``fn`` as a Zenoh callback run on the Zenoh thread that received the sample
    (:data:`DIRECT_CALLBACKS`) or, Zenoh's default, on a Python thread of its own per
    subscriber (a thread hop per message, and a thread per subscription: 8 per peer)."""
    if not DIRECT_CALLBACKS:
        return fn
    return zenoh.handlers.Callback(fn, indirect=False)


_ENCODINGS: dict[tuple[str, int, bool], zenoh.Encoding] = {}


def zenoh_encoding(payload: bytes, sealed: bool = False) -> zenoh.Encoding:
    """The Zenoh encoding a put of ``payload`` declares (protocol.encodings; cached per
    message type and protocol version, ``payload[1]``: protocol 1 and 2 of one type, e.g. a
    labelled and an unlabelled estimate, declare different encodings; about a microsecond a
    put)."""
    letter = letter_of(payload)
    key = (letter, payload[1] if letter != "?" else 0, sealed)
    enc = _ENCODINGS.get(key)
    if enc is None:
        enc = _ENCODINGS[key] = zenoh.Encoding(encoding_text(payload, sealed))
    return enc


class DuplicatePeer(SessionError):
    """Another process already runs a peer of this name on this network."""


class Transport:
    """Subscriptions and publishers of peer ``name`` (items on :attr:`q`:
    ``("msg", key, payload)`` as a :class:`peers.inbound.Delivered` carrying the parsed key,
    ``("live", name, joined)``, ``("stop", "", b"")``)."""

    def __init__(self, keys: Keys, name: str, sensor: str, neighbours: tuple[str, ...],
                 admission: Admission, session_args: tuple, security=None,
                 truth: bool = True, recover: bool = False, inbox=None) -> None:
        self.keys, self.name, self.sensor = keys, name, sensor
        self.neighbours = neighbours
        self.admission = admission
        self.session_args = session_args
        self.security = security  # peers.security.Security: mutual TLS + access control
        self.truth = truth  # subscribe to the world's truth (only a peer without its own)
        self.refusals = None  # peers.security.RefusalLog in secure mode
        self._scan_key = keys.scan(sensor)
        self._recovering: dict[str, str] = {}  # key -> channel of the recovering subscribers
        self.recover = recover  # estimates and scans through Zenoh's advanced pub/sub
        self.recovered = {"estimate": 0, "scan": 0}  # delivered late from a publisher's cache
        self.unrecovered = {"estimate": 0, "scan": 0}  # missed, no longer in the cache
        self.signer = self.verifier = None  # protocol.envelope, in secure mode
        self.check_signatures = True  # see open(): off where the links prove the sender
        self.q = queue.Queue() if inbox is None else inbox
        """Where the callbacks put their items: this peer's own queue, or (a peer in a
        :class:`peers.host.PeerHost`) an inbox that tags them with the peer and puts them on
        the host's one queue (anything with ``put``)."""
        self.seen_alive: set[str] = set()
        self.session = None
        self._decl: list = []
        self._ready = None
        self._pubs: dict[str, object] = {}
        self._owns_session = True
        self.local: frozenset[str] = frozenset()
        """Neighbours whose estimates are handed over in-process (co-hosted peers): not
        subscribed to through Zenoh, so nothing arrives twice."""
        self.shared: frozenset[str] = frozenset()
        """Remote neighbours whose estimates the host subscribes to once for all its peers
        (:meth:`peers.host.PeerHost._fan_out`): not subscribed to here."""
        self.handoff = None
        """``handoff(key, payload)``: called with each estimate this peer publishes (a host's
        direct hand-off to co-hosted neighbours), before it is put on Zenoh for the others."""

    # -- callbacks (Zenoh threads) ----------------------------------------------------------
    def _on_sample(self, sample) -> None:
        key = str(sample.key_expr)
        # a reply from a recovering publisher's cache (not express; ctl is never express)
        if self.recover and not sample.express and key in self._recovering:
            self.recovered[self._recovering[key]] += 1
        self.deliver(key, sample.payload.to_bytes())

    def deliver(self, key: str, payload: bytes, head: tuple | None = None,
                inbox=None) -> None:
        """What arrived on ``key``, from Zenoh or handed over by a co-hosted neighbour
        (:mod:`peers.host`): the same admission (per sender) and signature check either way.
        Bounded before anything is decoded or verified (peers.admission): window, slot, the
        sender's bucket and a place in the inbox, given back by the main loop (taken).
        ``head``: the payload's :func:`peers.admission.peek`, if the caller has it;
        ``inbox``: where to put it instead of :attr:`q` (a host's hand-off, on its loop's
        thread, straight into the peer's backlog)."""
        route = parse_key(key, self.keys.network)  # the one parse: the item carries it
        if self.admission.arrive(route, time.monotonic(), payload, head):
            if self.verifier is not None:  # secure mode: signed by the key's owner, not a copy
                size = len(payload)
                payload, why = self.verifier.open(key, payload, self.check_signatures)
                if why is not None:
                    self.admission.rejected[why] += 1
                    self.admission.taken(key, size, route)
                    return
                self.admission.shrink(size - len(payload))  # the trailer stays here
            (self.q if inbox is None else inbox).put(Delivered(key, payload, route))

    def deliver_item(self, item: Delivered, head: tuple | None, inbox=None) -> None:
        """:meth:`deliver` of an item whose key the caller parsed already (a host hands one
        :class:`peers.inbound.Delivered` to every co-hosted receiver of an estimate): the
        same admission, the item itself put on (it is immutable); signed messages (secure
        mode, never in a host) go through :meth:`deliver`."""
        if self.verifier is not None:
            self.deliver(item[1], item[2], head, inbox)
        elif self.admission.arrive(item.route, time.monotonic(), item[2], head):
            (self.q if inbox is None else inbox).put(item)

    def _missed(self, channel: str, n: int) -> None:
        self.unrecovered[channel] += n

    def recovery(self) -> dict:
        """What the advanced subscribers recovered and missed (``recover`` only), per channel."""
        return {"recovered": dict(self.recovered), "unrecovered": dict(self.unrecovered)}

    def _on_live(self, sample) -> None:
        self.q.put(("live", Keys.last(str(sample.key_expr)),
                    sample.kind == zenoh.SampleKind.PUT))

    # -- life cycle -------------------------------------------------------------------------
    def _settle(self) -> None:
        settle(self.session)

    def arm_signatures(self) -> None:
        """Secure mode: a signer for what this peer puts, a verifier for what it receives.

        Every message is signed. Its signature is checked on arrival where a member's link does
        not already prove who put it: with a router in the network (the access control lets a
        router put on every key) or with recovery (a publisher's cache answers on any member's
        ingress), or with a user's Zenoh config file (its links are the user's). Without any of
        these, this peer's ingress refuses every put on a key unless it comes over a mutual-TLS
        link from the key's owner, so the check (an Ed25519 verify, 0.1-0.3 ms a message here)
        would only repeat what the transport proved; the trailer and the replay check still run.
        """
        if self.security is None or self.signer is not None:
            return
        self.signer, self.verifier = self.security.signer(), self.security.verifier()
        config_file = self.session_args[2] if len(self.session_args) > 2 else None
        self.check_signatures = bool(self.security.routers or self.recover or config_file)

    def open(self, duplicate_wait: float = 0.5, session=None) -> None:
        """Open the session; refuse to start if a peer of the same name is alive already.

        ``session``: an open session shared with other peers (a host's, already settled):
        declared on, never closed here (:meth:`close` undeclares this peer's part only)."""
        self.arm_signatures()
        if self.security is not None and self.refusals is None:
            self.refusals = RefusalLog().start()  # counts what the access control refuses
        self._owns_session = session is None
        if session is None:
            session = open_session(*self.session_args, security=self.security)
        self.session = session
        try:
            if self._owns_session and self.session_args[1]:  # let the links come up first
                self._settle()
            replies = session.liveliness().get(self.keys.alive(self.name),
                                               timeout=duplicate_wait)
            if any(r.ok is not None for r in replies):
                raise DuplicatePeer(f"a peer named {self.name!r} is already running on network "
                                    f"{self.keys.network!r}; pick another name or stop it")
            block = zenoh.CongestionControl.BLOCK  # nothing dropped under load
            for ch in ("estimate", "tracks"):  # express: no batching delay
                key = getattr(self.keys, ch)(self.name)
                self._pubs[ch] = (recovering_publisher(session, key)
                                  if self.recover and ch == "estimate" else
                                  session.declare_publisher(key, congestion_control=block,
                                                            express=True))
            keys = [self._scan_key, self.keys.ctl(),
                    *([self.keys.truth()] if self.truth else []),
                    # only the neighbours' estimates: routing filters, not decoding
                    *(self.keys.estimate(n) for n in self.neighbours
                      if n not in self.local and n not in self.shared)]
            if self.recover:
                self._recovering = {self._scan_key: "scan",
                                    **{self.keys.estimate(n): "estimate"
                                       for n in self.neighbours}}
            for k in keys:
                if k in self._recovering:
                    ch = self._recovering[k]
                    self._decl.extend(recovering_subscriber(
                        session, k, self._on_sample,
                        lambda n, ch=ch: self._missed(ch, n)))
                else:
                    self._decl.append(session.declare_subscriber(k, callback(self._on_sample)))
            self._decl.append(session.liveliness().declare_subscriber(
                self.keys.alive("*"), callback(self._on_live), history=True))
            self._decl.append(session.liveliness().declare_token(self.keys.alive(self.name)))
        except BaseException:
            self.close()
            raise

    def saw(self, name: str, joined: bool) -> None:
        """Note a liveliness change; declare ``ready`` once every neighbour has been seen.

        The world starts the run when all peers are ready, so no peer misses its neighbours'
        first estimates while links are still being set up.
        """
        if joined:
            self.seen_alive.add(name)
        if (self._ready is None and self.session is not None
                and set(self.neighbours) <= self.seen_alive):
            self._ready = self.session.liveliness().declare_token(self.keys.ready(self.name))

    def publish(self, channel: str, payload: bytes) -> None:
        enc = zenoh_encoding(payload, self.signer is not None)
        if self.signer is not None:
            payload = self.signer.seal(getattr(self.keys, channel)(self.name), payload)
        if channel == "estimate" and self.handoff is not None:
            self.handoff(self.keys.estimate(self.name), payload)
        self._pubs[channel].put(payload, encoding=enc)

    def wake(self) -> None:
        """Make the main loop look at its flags now (signal handlers)."""
        self.q.put(("stop", "", b""))

    def close(self) -> None:
        for d in [*reversed(self._decl), self._ready, *self._pubs.values()]:
            if d is not None:
                try:
                    d.undeclare()
                except Exception:  # already undeclared, or the session is gone
                    pass
        self._decl, self._ready, self._pubs = [], None, {}
        if self.session is not None:
            if self._owns_session:
                self.session.close()
            self.session = None
        if self.refusals is not None:
            self.refusals.stop()
