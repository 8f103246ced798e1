"""The one place a :class:`peers.core.PeerCore` parses a key and decodes a payload (issue 37
item 5): its receive entry points and a host's look ahead at a coming scan (``scan_step``).

A driver that parsed the key already (the transport's :class:`peers.inbound.Delivered`) hands
the route on, and one that decoded the payload hands the message on, so neither is done twice;
what a message then does on its channel is the core's (``_scan``, ``_estimate``, ...).
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from sensornet.peers.admission import Admission, Route, parse_key
from sensornet.peers.consensus import Consensus
from sensornet.peers.core_types import CoreConfig, Output
from sensornet.protocol.codec import Rejected
from sensornet.protocol.messages import (
    Control,
    Estimate,
    Forward,
    Message,
    Returns,
    Scan,
    Truth,
)

EXPECTED = {"scan": Scan, "estimate": (Estimate, Forward, Returns), "truth": Truth,
            "ctl": Control}
"""The message types each channel carries (anything else on it is 'wrong-key')."""


class CoreReceive:
    """The receive side of :class:`peers.core.PeerCore` (its base): bytes and a key to the
    channel handlers the core defines (``_reject``, ``_scan``, ``_estimate``, ``_truth``,
    ``_control``)."""

    cfg: CoreConfig
    name: str
    consensus: Consensus
    admission: Admission
    received: Counter
    received_bytes: Counter
    decode: object
    _predecoded: tuple[bytes, Scan] | None

    def receive(self, key: str, payload: bytes, now: float, admitted: bool = False
                ) -> list[Output]:
        """One message as it came off the network (``admitted``: the rate check already ran)."""
        route = parse_key(key, self.cfg.network)
        if route is not None and route.channel == "estimate" and route.name == self.name:
            return []  # our own publication
        if not admitted and not self.admission.admit(route, now, payload):
            return []
        return self.receive_routed(route, payload, now)

    def receive_routed(self, route: Route | None, payload: bytes, now: float,
                       msg: Message | Rejected | None = None) -> list[Output]:
        """An admitted message whose key the driver parsed already (``route``, the transport's
        :class:`peers.inbound.Delivered`) and, with ``msg``, whose payload it decoded already
        (:meth:`decoded`): the runtime's entry, so neither is done twice (issue 37 item 5)."""
        if route is None:
            return self._reject("wrong-key")
        if route.channel == "estimate" and route.name == self.name:
            return []  # our own publication
        self.received[route.channel] += 1
        self.received_bytes[route.channel] += len(payload)
        pre, self._predecoded = self._predecoded, None
        if msg is None:
            msg = pre[1] if pre is not None and pre[0] is payload else self.decoded(payload)
        if isinstance(msg, Rejected):
            return self._reject(msg.reason)
        if not isinstance(msg, EXPECTED[route.channel]):
            return self._reject("wrong-key")
        if route.channel == "scan":
            return self._scan(route, msg, now)
        if route.channel == "estimate":
            return self._estimate(route, msg, now)
        if route.channel == "truth":
            return self._truth(msg)
        return self._control(msg, now)

    def decoded(self, payload: bytes) -> Message | Rejected:
        """``payload`` decoded with this peer's limits, or the :class:`Rejected` it raised
        (returned: a driver decodes once and hands the result to :meth:`receive_routed`)."""
        try:
            return self.decode(payload, self.cfg.limits)
        except Rejected as exc:
            return exc

    def scan_step(self, key: str | Route | None, payload: bytes
                  ) -> tuple[int, np.ndarray] | None:
        """``(steps, z)``: the local step this scan message would make if it came next, for a
        host to compute its peers' steps together (``peers.batching.prepare_local_steps``);
        None if it would not make one plainly (not a scan of ours, a fusion to finish first).
        ``key`` may be the route its transport parsed (a host's backlog item, a
        :class:`peers.inbound.Delivered`), then not parsed again. The message is decoded here
        once: :meth:`receive_routed` of the same bytes object reuses it (after its admission,
        as always). A guess only: the estimator uses a prepared step solely when it is the
        very step asked for."""
        route = key if key is None or isinstance(key, Route) else parse_key(key,
                                                                            self.cfg.network)
        if route is None or route.channel != "scan" or route.name != self.cfg.sensor:
            return None
        c = self.consensus
        if c.busy():  # (the first scan too: its steps count from scan 0, as in _scan)
            return None
        try:
            msg = self.decode(payload, self.cfg.limits)
        except Rejected:
            return None
        if type(msg) is not Scan or msg.sensor != route.name:
            return None
        self._predecoded = (payload, msg)
        if not c.last_k < msg.k <= c.last_k + self.cfg.horizon:
            return None
        return msg.k - c.last_k, msg.z

