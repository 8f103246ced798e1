"""The small parts of a peer host (:class:`peers.host.PeerHost`): one decode shared by the
co-hosted receivers of an estimate, the inboxes a hosted peer's transport puts on, and the line
a hosted peer prints when it stops."""

from __future__ import annotations

import queue
import time
from collections import deque

from sensornet.peers.runtime import PeerRuntime
from sensornet.protocol.codec import decode
from sensornet.protocol.messages import Estimate, Forward


class SharedDecode:
    """One decode of an estimate handed to several co-hosted neighbours: the hand-off gives
    each the same bytes object, so the last :data:`SIZE` estimates' messages (mixtures, and
    flooding's forwarded scan sets) are kept by payload (a bytes object caches its hash)
    with their arrays read-only (a receiver that wrote into one would raise, not change its
    neighbours'). Anything else (a large payload too), and every refusal, is decoded per
    receiver as before."""

    SIZE = 256
    LARGEST = 65536
    """Bytes of the largest payload kept (at most SIZE x LARGEST = 16 MiB held)."""

    def __init__(self) -> None:
        self._memo: dict[bytes, tuple[object, Estimate]] = {}
        """payload -> (the limits it was decoded with, the message): looked up by the bytes
        alone (their hash is cached), the limits compared by identity first (a host's peers
        share one), not hashed a call."""
        self.hits = 0

    def __call__(self, payload: bytes, limits):
        kept = self._memo.get(payload)
        if kept is not None and (kept[0] is limits or kept[0] == limits):
            self.hits += 1
            return kept[1]
        msg = decode(payload, limits)
        kind = type(msg)
        if (kind is Estimate or kind is Forward) and len(payload) <= self.LARGEST:
            # a Forward (flooding) reaches each co-hosted neighbour of its sender, as an
            # estimate does: its scans were decoded once per receiver (issue 38)
            for a in ((msg.mixture.weights, msg.mixture.means, msg.mixture.covs, msg.labels,
                       msg.label_masks) if kind is Estimate else msg.scans.scans.values()):
                if a is not None:  # labels and masks too (protocol 2/3): shared as well
                    a.flags.writeable = False
            if payload not in self._memo and len(self._memo) >= self.SIZE:
                del self._memo[next(iter(self._memo))]  # the oldest
            self._memo[payload] = (limits, msg)  # (other limits: the last decode's)
        return msg


class QueueInbox:
    """What one peer's transport puts on: the host's queue, tagged with the peer's slot."""

    def __init__(self, q: queue.Queue, slot: int) -> None:
        self._q, self._slot = q, slot

    def put(self, item) -> None:
        self._q.put((self._slot, item))


class BacklogInbox:
    """A hand-off's inbox: the peer's backlog itself, stamped now. The hand-off runs on the
    loop's thread, so it needs neither the thread-safe queue nor another wake-up (the loop
    sees a non-empty backlog and comes straight back)."""

    def __init__(self, backlog: deque) -> None:
        self._backlog = backlog

    def put(self, item) -> None:
        self._backlog.append((time.time(), item))



def rt_line(rt: PeerRuntime) -> str:
    """The line a peer prints when it stops (as ``sensornet peer`` does)."""
    s = rt.summary()
    fused, local = s.get("mean_ospa_fused"), s.get("mean_ospa_local")

    def f(v) -> str:
        return "-" if v is None else f"{v:.1f}"

    return (f"peer {rt.name}: stopped ({s['stop_reason']}); {s['scans']} scans, mean OSPA "
            f"local {f(local)} fused {f(fused)}, rejected {s['rejected_total']}")

