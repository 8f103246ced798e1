"""How what arrives reaches a peer host's peers (:class:`peers.host.PeerHost`): a co-hosted
neighbour's estimates handed over in the process, a remote neighbour's through one Zenoh
subscriber for the whole host, the world's scan bundles unpacked to the peers of their sensors;
each through the receiving peer's own admission (its transport's ``deliver``)."""

from __future__ import annotations

import time

from sensornet.peers.admission import parse_key, peek
from sensornet.peers.inbound import Delivered
from sensornet.protocol.bundle import unpack_bundle
from sensornet.protocol.codec import Rejected


class HostDelivery:
    """What :class:`~peers.host.PeerHost` does with what arrives; it uses the host's ``peers``,
    ``by_name``, ``_active``, ``_inboxes``, ``_by_sensor``, ``bundles``, ``_bundle_rate`` and
    ``_bundle_lock``."""

    def _wire_handoff(self) -> None:
        """Each peer's co-hosted neighbours: not subscribed to through Zenoh, handed over."""
        listeners: dict[str, list[int]] = {}
        for i, rt in enumerate(self.peers):
            t = rt.transport
            t.local = frozenset(n for n in t.neighbours if n in self.by_name)
            for n in t.local:
                listeners.setdefault(n, []).append(i)
        for name, subs in listeners.items():
            self.peers[self.by_name[name]].transport.handoff = (
                lambda key, payload, subs=tuple(subs): self._hand_over(subs, key, payload))

    def _share_remote(self) -> dict[str, tuple[int, ...]]:
        """Remote neighbours' estimate keys -> the peers that listen to them: one Zenoh
        subscriber each for the whole host (:meth:`_fan_out`), not one per listening peer (a
        subscriber per peer made Zenoh call back, copy and queue each remote estimate once per
        co-hosted listener). Not with recovery (each peer's advanced subscriber keeps its own
        cache state) or a recording (each peer records what its own transport received)."""
        if any(rt.o.recover or rt.o.record is not None for rt in self.peers):
            return {}
        listeners: dict[str, list[int]] = {}
        for i, rt in enumerate(self.peers):
            t = rt.transport
            t.shared = frozenset(n for n in t.neighbours if n not in t.local)
            for n in t.shared:
                listeners.setdefault(t.keys.estimate(n), []).append(i)
        return {k: tuple(v) for k, v in listeners.items()}

    def _unbundle(self, sample) -> None:
        """A scan bundle from the world (Zenoh's callback thread, :mod:`protocol.bundle`):
        each scan to the peer of its sensor, through that peer's own admission, as if it had
        come on the peer's ``scan/<sensor>`` key. Bounded before it is unpacked: at most as
        many bundles as the hosted sensors' own scan messages were allowed (:attr:`_bundle_rate`)
        and at most one entry per hosted peer in each. A refused bundle, or an entry for a
        sensor not hosted here, is counted (``host.bundles`` in the summaries), never
        delivered."""
        payload = sample.payload.to_bytes()
        with self._bundle_lock:  # Zenoh may call back on several threads
            why = None if self._bundle_rate.take(time.monotonic()) else "rate"
            if why is None:
                try:
                    bundle = unpack_bundle(payload, max_entries=len(self.peers))
                except Rejected as exc:
                    why = exc.reason
            if why is not None:
                self.bundles["rejected"] += 1
                self.bundles["why"][why] = self.bundles["why"].get(why, 0) + 1
                return
            self.bundles["received"] += 1
            hosted = [(self._by_sensor.get(sensor), sensor, data)
                      for sensor, data in bundle.entries]
            self.bundles["unknown_sensor"] += sum(j is None for j, _, _ in hosted)
        for j, sensor, data in hosted:
            if j is not None and j in self._active:
                t = self.peers[j].transport
                t.deliver(t.keys.scan(sensor), data)

    def _fan_out(self, subs: tuple[int, ...], sample) -> None:
        """A remote estimate (Zenoh's callback thread) to each co-hosted peer listening to it,
        through each one's own admission, as if each had its own subscriber."""
        self._deliver(subs, str(sample.key_expr), sample.payload.to_bytes(), backlog=False)

    def _hand_over(self, subs: tuple[int, ...], key: str, payload: bytes) -> None:
        """An estimate published on ``key`` to the co-hosted peers ``subs`` (the loop's
        thread: straight into their backlogs)."""
        self._deliver(subs, key, payload, backlog=True)

    def _deliver(self, subs: tuple[int, ...], key: str, payload: bytes, backlog: bool) -> None:
        """``payload`` to each of the peers ``subs`` still running, its header read and its
        key parsed once for all of them (one :class:`peers.inbound.Delivered`, immutable,
        shared); each admits it on its own (``backlog``: into the peer's backlog, from the
        loop's thread; else onto the host's queue)."""
        active, head = self._active, peek(payload)
        item = network = None
        for j in subs:
            if j in active:
                t = self.peers[j].transport
                if t.keys.network != network:  # (a host's peers share one network)
                    network = t.keys.network
                    item = Delivered(key, payload, parse_key(key, network))
                t.deliver_item(item, head, self._inboxes[j] if backlog else None)
