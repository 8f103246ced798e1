"""Link faults injected: keyed, logged delay, loss, duplication, reordering and partitions.

One model, two drivers. The discrete-event twin (``sim.run.twin``) asks
:meth:`FaultInjector.deliveries` when a peer's estimate leaves for another peer and schedules
one delivery per returned delay; the Zenoh runtime asks the same question when the estimate
arrives and holds it that long (:class:`HoldQueue`) before handing it on. Nothing here imports
Zenoh or touches a clock. The plan (what can go wrong on each link) is
:class:`peers.faultplan.FaultPlan`, built by the scenario loader from the ``[faults]`` table.

Per message on the link ``sender -> receiver`` (:meth:`FaultInjector.decide`), at the
message's time ``t`` (for an estimate of scan ``k``: its scan time ``k * plan.interval``):

1. inside a partition interval of the link: dropped (``"drop-partition"``);
2. lost with probability ``loss`` (``"drop-loss"``);
3. otherwise one copy, or two with probability ``duplicate``; each copy waits a draw of the
   link's ``delay``; with probability ``reorder`` the message is *reordered*: each copy waits a
   further draw of ``reorder_delay``, so later messages overtake it;
4. a copy whose flight ``[t, t + delay]`` reaches into a partition is lost with the link
   (``"drop-partition"`` if no copy is left).

The action logged is the first that applies of ``drop-partition``, ``drop-loss``,
``duplicate`` (two copies delivered), ``reorder``, ``deliver``; :attr:`FaultRecord.reordered`
says whether the extra delay was applied, also for a duplicate.

Random numbers are counter-based, not a stream: every draw about a message comes from its own
generator, ``default_rng(SeedSequence([seed, crc32(sender), crc32(receiver), k, round,
crc32(kind), stream]))`` (:func:`decision_rng`), stream 0 for the three uniforms (loss,
duplicate, reorder) and stream ``1 + c`` for copy ``c``'s delay and extra delay. A decision
is thus a function of the seed, the link, the message and the plan only: the twin and the real
processes take the same decisions whatever order the messages come in and whichever are lost,
and two plans differ only in the faults they differ in (common random numbers).
"""

from __future__ import annotations

import csv
import heapq
import itertools
import zlib
from collections import Counter
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sensornet.peers.faultplan import (
    Constant,
    Delay,
    Exponential,
    FaultPlan,
    LinkFaults,
    MultiStep,
    OneStep,
    Scans,
    ShortDelay,
    Uniform,
)

ACTIONS = ("deliver", "drop-loss", "drop-partition", "duplicate", "reorder")
"""Every action a :class:`FaultRecord` can carry."""

_WORD = 0xFFFFFFFF
_NOT_A_ROUND = _WORD  # the round word of a key made from a bare message id


@dataclass(frozen=True)
class FaultRecord:
    """One decision about one message on one link."""

    t: float
    """Run-clock time of the decision (s): the message's scan time when known, else the time
    the caller passed (:meth:`FaultInjector.decision_time`)."""
    sender: str
    """Sending peer."""
    receiver: str
    """Receiving peer."""
    msg_id: str
    """The message, as the caller names it (e.g. ``"s1:k12:r0"``)."""
    action: str
    """One of :data:`ACTIONS`."""
    delays: tuple[float, ...]
    """Delay of each delivered copy (s); empty when dropped."""
    reordered: bool = False
    """Whether the copies carry the reorder extra delay (also when duplicated)."""


def default_msg_id(msg: Any) -> str:
    """``"<sender>:k<k>:r<round>"`` for an :class:`~protocol.messages.Estimate`-like message,
    with ``":<kind>"`` appended for a kind other than ``"posterior"``."""
    sender, k = getattr(msg, "sender", None), getattr(msg, "k", None)
    if sender is None or k is None:
        return str(msg)
    kind = getattr(msg, "kind", "posterior")
    return f"{sender}:k{k}:r{getattr(msg, 'round', 0)}" + (
        "" if kind == "posterior" else f":{kind}")


def _crc(text: str) -> int:
    return zlib.crc32(text.encode("utf-8"))


def message_key(msg: Any) -> tuple[int, int, int] | None:
    """``(k, round, crc32(kind))`` of an estimate-like message (``None`` without ``k``);
    ``k`` and ``round`` as 32-bit words, so any integer is a key."""
    k = getattr(msg, "k", None)
    if k is None:
        return None
    return (int(k) & _WORD, int(getattr(msg, "round", 0)) & _WORD,
            _crc(str(getattr(msg, "kind", "posterior"))))


def id_key(msg_id: Hashable) -> tuple[int, int, int]:
    """The key of a message known only by its id: ``(crc32(str(msg_id)), 2**32 - 1, 0)``."""
    return (_crc(str(msg_id)), _NOT_A_ROUND, 0)


def decision_rng(seed: int, sender: str, receiver: str, key: Sequence[int],
                 stream: int) -> np.random.Generator:
    """The generator of one ``stream`` of draws about the message ``key`` on one link."""
    return np.random.default_rng(np.random.SeedSequence(
        [seed, _crc(sender), _crc(receiver), *key, stream]))


class FaultInjector:
    """Decides, draws and logs what happens to each message on each link of a :class:`FaultPlan`.

    A decision depends only on the seed, the link's names and faults, the message's key and
    time: not on what the injector decided before (see the module docstring). The log and the
    counts are the only state; call it from one thread (the twin's loop, the runtime's main
    thread).
    """

    def __init__(self, plan: FaultPlan, seed: int,
                 msg_id: Callable[[Any], Hashable] = default_msg_id) -> None:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
        self.plan = plan
        self.seed = int(seed)
        self.msg_id = msg_id
        self.log: list[FaultRecord] = []
        self._counts: Counter = Counter()

    def decide(self, sender: str, receiver: str, t: float, msg_id: Hashable,
               key: Sequence[int] | None = None) -> list[float]:
        """The delivery delays (s) of one message at run-clock time ``t``: ``[]`` dropped,
        one entry delivered once, two entries duplicated. Logged as a :class:`FaultRecord`.

        ``key`` names the message in the draws (:func:`message_key`); default
        :func:`id_key` of ``msg_id``. The same ``(sender, receiver, t, key)`` always gets the
        same answer.
        """
        faults = self.plan.for_link(sender, receiver)
        key = id_key(msg_id) if key is None else tuple(key)
        delays: list[float] = []
        reordered = False
        if faults.partitioned(t):
            action = "drop-partition"
        else:
            u_loss, u_dup, u_reorder = decision_rng(self.seed, sender, receiver, key,
                                                    0).random(3)
            reordered = bool(u_reorder < faults.reorder)
            if u_loss < faults.loss:
                action = "drop-loss"
            else:
                for copy in range(2 if u_dup < faults.duplicate else 1):
                    rng = decision_rng(self.seed, sender, receiver, key, 1 + copy)
                    d = float(faults.delay.sample(rng))
                    if reordered:
                        d += float(faults.reorder_delay.sample(rng))
                    if not faults.partitioned(t, t + d):
                        delays.append(d)
                if not delays:
                    action = "drop-partition"
                elif len(delays) == 2:
                    action = "duplicate"
                else:
                    action = "reorder" if reordered else "deliver"
        self.log.append(FaultRecord(float(t), sender, receiver, str(msg_id), action,
                                    tuple(delays), reordered and bool(delays)))
        self._counts[action] += 1
        return delays

    def decision_time(self, msg: Any, t: float) -> float:
        """When a message counts as sent, for the partitions: its scan time
        ``k * plan.interval`` if it has a scan ``k`` and the plan an interval, else ``t``."""
        k = getattr(msg, "k", None)
        if k is None or self.plan.interval is None:
            return float(t)
        return k * self.plan.interval

    def deliveries(self, sender: str, receiver: str, t: float, msg: Any) -> list[float]:
        """:meth:`decide` for a message object: named by the injector's ``msg_id`` function,
        keyed by :func:`message_key`, at :meth:`decision_time` (``t``: its run-clock send
        time, used only when the message has no scan time)."""
        return self.decide(sender, receiver, self.decision_time(msg, t), self.msg_id(msg),
                           message_key(msg))

    def as_link_delay(self, msg_id_fn: Callable[[Any], Hashable] | None = None,
                      time_fn: Callable[[Any], float] | None = None
                      ) -> Callable[[str, str, Any], float | None]:
        """A ``(sender, receiver, msg) -> delay | None`` callable (the twin's ``LinkDelay``).

        It can deliver one copy only: a duplicated message is delivered once (its first copy;
        the log still says ``"duplicate"``); use :meth:`deliveries` to deliver both.
        ``time_fn`` gives the run-clock send time of a message (default: its ``send_time``,
        which the twin sets to the virtual time), used as in :meth:`deliveries`.
        """
        name = msg_id_fn or self.msg_id
        when = time_fn or (lambda msg: float(msg.send_time))

        def delay(sender: str, receiver: str, msg: Any) -> float | None:
            out = self.decide(sender, receiver, self.decision_time(msg, when(msg)), name(msg),
                              message_key(msg))
            return out[0] if out else None

        return delay

    def counts(self) -> dict[str, int]:
        """How many decisions took each action (every action present, zeros included)."""
        return {a: self._counts.get(a, 0) for a in ACTIONS}

    def write_log(self, path: str | Path, append: bool = False) -> None:
        """The log as CSV: a header, then one line per decision; ``delays`` joined by ``;``.

        ``append``: add the records to an existing file (header only if it is new) and clear
        the in-memory log, so a long run's memory stays flat (:meth:`counts` is kept apart).
        """
        new = not append or not Path(path).exists()
        with open(path, "a" if append else "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            if new:
                w.writerow(["t", "sender", "receiver", "msg_id", "action", "reordered",
                            "delays"])
            for r in self.log:
                w.writerow([repr(r.t), r.sender, r.receiver, r.msg_id, r.action,
                            int(r.reordered), ";".join(repr(d) for d in r.delays)])
        if append:
            self.log.clear()


class HoldQueue:
    """Messages held back until their delivery time: what a runtime transport wrapper needs.

    ``push(due, item)`` holds ``item`` until the clock reads ``due``; ``pop_due(now)`` returns
    the items due by ``now`` in order of ``due`` (ties in push order). The caller owns the
    clock (e.g. ``time.monotonic()``) and polls, e.g. in the loop that fires fusion deadlines:
    wait at most ``next_due() - now``.
    """

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Any]] = []
        self._order = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, due: float, item: Any) -> None:
        """Hold ``item`` until ``due``."""
        heapq.heappush(self._heap, (float(due), next(self._order), item))

    def next_due(self) -> float | None:
        """When the next item is due, or ``None`` if nothing is held."""
        return self._heap[0][0] if self._heap else None

    def pop_due(self, now: float) -> list[Any]:
        """The items due at or before ``now``, earliest first; they are no longer held."""
        out = []
        while self._heap and self._heap[0][0] <= now:
            out.append(heapq.heappop(self._heap)[2])
        return out


__all__ = [
    "ACTIONS",
    "Constant",
    "Delay",
    "Exponential",
    "FaultInjector",
    "FaultPlan",
    "FaultRecord",
    "HoldQueue",
    "LinkFaults",
    "MultiStep",
    "OneStep",
    "Scans",
    "ShortDelay",
    "Uniform",
    "decision_rng",
    "default_msg_id",
    "id_key",
    "message_key",
]
